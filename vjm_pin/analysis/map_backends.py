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

On a Dask worker a chunk runs with the heap kept between its blocks (:func:`_kept_heap`):
Dask's nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which turns glibc's
dynamic mmap threshold off, so without it every large temporary of a batched chunk is a fresh
``mmap`` page-faulted anew (issue 14: about a quarter of the per-pose cost of ur5 with link
springs on a running cluster). Where arrays live does not change the numbers computed in them.

This is the orchestration layer of :mod:`vjm_pin.analysis.maps`; it knows nothing of robots.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import socket
import sys
import threading
import uuid

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
        name = getattr(fn, "__name__", "chunk")

        def submit() -> None:
            for k, c in todo:  # keys named after fn, as the dashboard showed them before
                f = client.submit(_dask_task, fn, *args, c, key=f"{name}-{uuid.uuid4().hex}")
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


def _dask_task(fn, *args):
    """A chunk on a Dask worker: ``fn(*args)`` with the heap kept (:func:`_kept_heap`)."""
    with _kept_heap():
        return fn(*args)


# glibc's mallopt parameters
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: While a chunk runs: blocks up to this size come from the heap (glibc's largest mmap threshold
#: on 64-bit), and free memory at the top of the heap is kept up to twice that (glibc's own rule
#: for its dynamic threshold).
_KEPT_MMAP = 32 << 20
_KEPT_TRIM = 64 << 20
_GLIBC_DEFAULT = 128 << 10  # M_MMAP_THRESHOLD and M_TRIM_THRESHOLD when not set
_MALLOC_ENV = (
    "MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_MAX_",
)  # fmt: skip
_heap_lock = threading.Lock()
_heap_users = 0
_heap_plan = None  # (mallopt, restore [(param, value)]), or False: leave the heap alone


def _glibc_size(text: str):
    """A size as glibc reads it from a ``MALLOC_*_`` variable (decimal, 0x… hex, 0… octal),
    or None."""
    t = text.strip()
    try:
        if t[:2].lower() == "0x":
            return int(t[2:], 16)
        return int(t, 8) if len(t) > 1 and t[0] == "0" else int(t, 10)
    except ValueError:
        return None


def _heap_settings():
    """How this process's heap is set, when a chunk should change it: ``(mallopt, restore)``,
    ``restore`` the ``(parameter, value)`` pairs in force now; else None.

    Only where glibc's dynamic mmap threshold is off because the environment sets a ``MALLOC_*_``
    variable, as Dask's nanny does for every worker (``distributed.nanny.pre-spawn-environ``:
    ``MALLOC_TRIM_THRESHOLD_=65536``). Then every array above 128 KiB is a fresh ``mmap`` and goes
    back to the system when freed, so each block of a batched chunk page-faults its temporaries
    anew (a few faults per pose, as much kernel time as a quarter of the pose's own work on
    ur5 with link springs; issue 14); with the dynamic threshold (any process without the
    variables) glibc keeps them. The values in force are then the environment's (or glibc's
    defaults), so they can be restored exactly. Not with ``GLIBC_TUNABLES`` malloc settings (their
    values are not read here), nor off glibc."""
    global _heap_plan
    if _heap_plan is None:
        _heap_plan = False
        env = os.environ
        try:
            libc = os.confstr("CS_GNU_LIBC_VERSION") if sys.platform.startswith("linux") else None
            glibc = bool(libc) and libc.startswith("glibc")
        except (ValueError, OSError, AttributeError):
            glibc = False
        tunables = "malloc" in env.get("GLIBC_TUNABLES", "")
        if glibc and any(k in env for k in _MALLOC_ENV) and not tunables:
            trim = _glibc_size(env.get("MALLOC_TRIM_THRESHOLD_", str(_GLIBC_DEFAULT)))
            mmap = _glibc_size(env.get("MALLOC_MMAP_THRESHOLD_", str(_GLIBC_DEFAULT)))
            # (mallopt takes an int; glibc ignores an mmap threshold above its maximum)
            known = trim is not None and mmap is not None
            if known and 0 <= mmap <= _KEPT_MMAP and 0 <= trim < 1 << 31:
                with contextlib.suppress(Exception):
                    import ctypes

                    mallopt = ctypes.CDLL(None).mallopt
                    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
                    _heap_plan = (mallopt, ((_M_MMAP_THRESHOLD, mmap), (_M_TRIM_THRESHOLD, trim)))
    return _heap_plan or None


@contextlib.contextmanager
def _kept_heap():
    """While the body runs (a chunk on a Dask worker), arrays up to :data:`_KEPT_MMAP` come from
    the heap and freed memory stays there, so the blocks of a chunk reuse the same pages; when the
    last chunk running in this process ends, the settings in force before are restored (the heap
    then gives its free top back as glibc would). Only where :func:`_heap_settings` says so;
    nothing else changes (where an array lives does not change the numbers computed in it).
    Process-wide (glibc's settings are), counted under a lock for workers with several threads."""
    global _heap_users
    plan = _heap_settings()
    if plan is None:
        yield
        return
    mallopt, restore = plan
    with _heap_lock:
        _heap_users += 1
        if _heap_users == 1:
            mallopt(_M_MMAP_THRESHOLD, _KEPT_MMAP)
            mallopt(_M_TRIM_THRESHOLD, _KEPT_TRIM)
    try:
        yield
    finally:
        with _heap_lock:
            _heap_users -= 1
            if _heap_users == 0:
                for param, value in restore:
                    mallopt(param, value)


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
