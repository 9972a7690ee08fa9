"""Run the chunks of a workspace map on one process, a local process pool or Dask.

:func:`run_chunks` calls ``fn(*args, chunk)`` for every chunk and hands each result to
``report(k, result)`` in the calling thread, in completion order. The backends differ
only in where ``fn`` runs, so a map gives the same numbers on all of them.

Ctrl-C (``KeyboardInterrupt`` in the calling thread) stops a run promptly on every
backend, and a terminal's Ctrl-C (SIGINT to the whole foreground process group) is
decided by this process alone:

- only a few chunks are ever in flight (:data:`IN_FLIGHT` per worker), so little is
  queued and nothing has to be drained;
- the local pool's workers are forked with SIGINT blocked and ignore it; on Ctrl-C they
  are terminated (they stop in the middle of a pose);
- Dask runs in a helper thread; the calling thread only waits for results, so Ctrl-C
  lands there at once. The helper cancels the pending futures and closes the client and
  a local cluster with short timeouts (:data:`CLOSE_TIMEOUT`). A local cluster's workers
  are ``dask worker`` processes in sessions of their own (the terminal's SIGINT does not
  reach them; they would print tracebacks) and are killed.

The ``KeyboardInterrupt`` is then re-raised; the results reported so far stay with the
caller.

This is the orchestration layer of :mod:`vjm_pin.analysis.maps`; it knows nothing of robots.
"""

from __future__ import annotations

import contextlib
import queue
import re
import signal
import socket

from vjm_pin.exceptions import InputError, SchedulerError

#: Chunks in flight per worker: enough to keep the workers busy, few enough that an
#: interrupted run has little to cancel.
IN_FLIGHT = 2
#: Seconds to wait for a Dask scheduler to answer (connect) and to close a client/cluster.
CONNECT_TIMEOUT = 3.0
CLOSE_TIMEOUT = 2.0

_ADDRESS = re.compile(r"tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>\d{1,5})")


def check_scheduler(address: str, *, timeout: float = CONNECT_TIMEOUT) -> str:
    """Check that ``address`` has the form ``tcp://HOST:PORT`` (HOST a name, an IPv4 or a
    bracketed IPv6 address; PORT 1 … 65535) and that something accepts a TCP connection
    there within ``timeout`` seconds; return it.

    Raises:
        SchedulerError: the address is malformed or nothing listens there.
    """
    m = _ADDRESS.fullmatch(address.strip()) if isinstance(address, str) else None
    if m is None or not 1 <= int(m["port"]) <= 65535:
        raise SchedulerError(address, "not a Dask scheduler address")
    host = m["host"].strip("[]")
    try:
        with socket.create_connection((host, int(m["port"])), timeout=timeout):
            pass
    except OSError as e:
        why = (
            f"timed out after {timeout:g} s"
            if isinstance(e, TimeoutError)
            else (e.strerror or str(e))
        )
        raise SchedulerError(address, f"nothing answers there ({why})") from None
    return address.strip()


def run_chunks(fn, args, chunks, report, *, backend: str, workers: int, scheduler=None) -> None:
    """Evaluate ``fn(*args, chunk)`` for every chunk on ``backend``; ``report(k, result)``
    for chunk ``k`` in the calling thread as results arrive.

    Args:
        fn: A module-level function (it is pickled by reference).
        backend: ``"serial"``, ``"local"`` (a process pool of ``workers`` processes) or
            ``"dask"`` (a client on ``scheduler``; a local cluster of ``workers`` processes
            when None).

    Raises:
        KeyboardInterrupt: after the workers were stopped (see the module docstring).
        InputError: the Dask scheduler cannot be reached.
    """
    if backend == "serial" or (backend == "local" and (workers == 1 or len(chunks) <= 1)):
        for k, c in enumerate(chunks):
            report(k, fn(*args, c))
    elif backend == "local":
        _run_local(fn, args, chunks, report, min(workers, len(chunks)))
    else:
        _run_dask(fn, args, chunks, report, min(workers, len(chunks)), scheduler)


# ----------------------------------------------------------------------------- signals
@contextlib.contextmanager
def _sigint_blocked():
    """Block SIGINT in the calling thread for the ``with`` body.

    Threads started and processes forked inside inherit the blocked mask (``exec``, as
    in a spawned process, does not keep it), so the kernel hands SIGINT to the main
    thread only. A Ctrl-C that arrives inside the body is delivered when it ends."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - Windows
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


# ----------------------------------------------------------------------------- local
def _ignore_sigint() -> None:
    """Pool initializer: Ctrl-C is the parent's business."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_local(fn, args, chunks, report, workers: int) -> None:
    import multiprocessing as mp

    done: queue.SimpleQueue = queue.SimpleQueue()
    todo = iter(enumerate(chunks))
    pool = None
    finished = False
    try:
        with _sigint_blocked():
            pool = mp.get_context().Pool(workers, initializer=_ignore_sigint)
        in_flight = 0

        def submit() -> None:
            nonlocal in_flight
            for k, c in todo:
                pool.apply_async(
                    fn,
                    (*args, c),
                    callback=lambda r, k=k: done.put((k, r, None)),
                    error_callback=lambda e, k=k: done.put((k, None, e)),
                )
                in_flight += 1
                return

        for _ in range(IN_FLIGHT * workers):
            submit()
        while in_flight:
            try:
                k, r, err = done.get(timeout=0.2)
            except queue.Empty:
                continue
            in_flight -= 1
            if err is not None:
                raise err
            report(k, r)
            submit()
        pool.close()
        pool.join()
        finished = True
    finally:
        if pool is not None and not finished:
            pool.terminate()  # SIGTERM to the workers: they stop in the middle of a pose


# ----------------------------------------------------------------------------- dask
def _run_dask(fn, args, chunks, report, workers: int, scheduler) -> None:
    """Dask runs in a helper thread started with SIGINT blocked (so are the event-loop
    threads it starts); this thread only waits for results, and on Ctrl-C tells the
    helper to cancel and close, waits a little for it and re-raises."""
    import threading

    try:
        import distributed  # noqa: F401
    except ImportError as e:  # pragma: no cover - the test extra installs it
        raise InputError(f"the dask backend needs 'dask[distributed]' ({e})") from None
    if scheduler:
        scheduler = check_scheduler(scheduler)  # a clear error before any thread starts
    results: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()
    helper = threading.Thread(
        target=_dask_helper,
        args=(fn, args, chunks, workers, scheduler, results, stop),
        name="vjm-pin-dask",
        daemon=True,
    )
    try:
        with _sigint_blocked():
            helper.start()
        while True:
            try:
                kind, k, value = results.get(timeout=0.2)
            except queue.Empty:
                continue
            if kind == "result":
                report(k, value)
            elif kind == "error":
                raise value
            else:
                break
    except BaseException:
        stop.set()
        helper.join(timeout=2 * CLOSE_TIMEOUT + 1)
        raise
    helper.join()


def _dask_helper(fn, args, chunks, workers, scheduler, results, stop) -> None:
    """The helper thread of :func:`_run_dask`: connect (or start a local cluster), keep
    ``IN_FLIGHT`` chunks per worker submitted, post ``("result", k, rows)`` and at the end
    ``("error", None, exc)`` or ``("done", None, None)``; on ``stop`` cancel and close."""
    import time

    from distributed import Client, as_completed

    cluster = client = None
    procs: list = []
    futures: dict = {}
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s")
            except (OSError, TimeoutError) as e:
                raise SchedulerError(scheduler, f"no Dask scheduler answers there ({e})") from None
            except Exception:  # noqa: BLE001 - whatever answers there, it is not a scheduler
                raise SchedulerError(
                    scheduler, "what answers there does not speak the Dask protocol"
                ) from None
            slots = IN_FLIGHT * max(1, sum(client.nthreads().values()))
        else:
            cluster, procs, log = _local_cluster(workers)
            if stop.is_set():
                return
            client = Client(cluster)
            slots = IN_FLIGHT * workers
        todo = iter(enumerate(chunks))
        pending = as_completed()

        def submit() -> None:
            for k, c in todo:
                f = client.submit(fn, *args, c, pure=False)
                futures[f.key] = (k, f)
                pending.add(f)
                return

        for _ in range(slots):
            submit()
        while futures and not stop.is_set():
            batch = pending.next_batch(block=False)
            if not batch:
                if procs and all(p.poll() is not None for p in procs):
                    raise InputError(f"the local Dask workers stopped: {_last_line(log)}")
                time.sleep(0.02)
                continue
            for f in batch:
                k, _ = futures.pop(f.key)
                results.put(("result", k, f.result()))
                submit()
    except BaseException as e:  # noqa: BLE001 - handed to the calling thread
        results.put(("error", None, e))
    finally:
        _close_dask(client, cluster, procs, [f for _, f in futures.values()])
        results.put(("done", None, None))


def _local_cluster(workers: int):
    """A scheduler in this process and ``workers`` worker processes (one thread each) of
    ``dask worker``, each in a session of its own: a terminal's Ctrl-C, sent to the
    foreground process group, does not reach them (only this process decides), and they
    are killed when the map stops. Their output goes to a temporary log file (its last
    line is shown if they fail). Returns (cluster, processes, log)."""
    import logging
    import os
    import subprocess
    import sys
    import tempfile

    from distributed import LocalCluster

    cluster = LocalCluster(
        n_workers=0,
        processes=True,
        dashboard_address=":0",  # any free port: no clash with another cluster's 8787
        scheduler_kwargs={"dashboard": False},
        silence_logs=logging.ERROR,
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    # no statistical profiler in the workers (a stack sample every 10 ms: about as much CPU per
    # pose as the pose itself on a loaded 2-core machine, issue 14); the environment may turn it on
    env.setdefault("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", "False")
    cmd = [
        sys.executable, "-m", "distributed.cli.dask_worker", cluster.scheduler_address,
        "--nthreads", "1", "--no-nanny", "--no-dashboard", "--death-timeout", "10",
    ]  # fmt: skip
    log = tempfile.TemporaryFile()  # noqa: SIM115 - open while the workers run, closed by GC
    procs = []
    try:
        for _ in range(workers):
            procs.append(
                subprocess.Popen(
                    cmd,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=log,
                    env=env,
                    start_new_session=True,
                )
            )
    except BaseException:
        _kill(procs)
        with contextlib.suppress(Exception):
            cluster.close(timeout=CLOSE_TIMEOUT)
        raise
    return cluster, procs, log


def _last_line(log) -> str:
    with contextlib.suppress(Exception):
        log.seek(0)
        lines = [ln for ln in log.read().decode(errors="replace").splitlines() if ln.strip()]
        if lines:
            return lines[-1].strip()
    return "no output"


def _kill(procs) -> None:
    for p in procs:
        with contextlib.suppress(OSError):
            p.kill()
    for p in procs:
        with contextlib.suppress(Exception):
            p.wait(timeout=CLOSE_TIMEOUT)


def _close_dask(client, cluster, procs, futures) -> None:
    """Kill the local worker processes, cancel what is still queued, close the client and
    the local cluster with short timeouts; never raises (this runs while an interrupt or
    an error may be on its way up). At the end of a complete map nothing is queued, so
    killing the workers loses nothing."""
    _kill(procs)
    if client is not None:
        with contextlib.suppress(Exception):
            if futures:
                client.cancel(futures, asynchronous=False)
        with contextlib.suppress(Exception):
            client.close(timeout=CLOSE_TIMEOUT)
    if cluster is not None:
        with contextlib.suppress(Exception):
            cluster.close(timeout=CLOSE_TIMEOUT)
