"""The contract of ``vjm-pin map`` with its user: Ctrl-C stops it on every backend and keeps
what was finished, bad input is one line (exit 2) and leaves no file, outputs are atomic.

The Ctrl-C tests run the real command in its own session and send SIGINT to the whole
process group, as a terminal does; stderr is a pseudo-terminal so the progress bar shows
when the computation has started (no guessing with sleeps).
"""

import csv
import multiprocessing
import os
import pty
import re
import select
import signal
import subprocess
import sys
import termios
import time

import numpy as np
import pytest

from vjm_pin.analysis.map_backends import check_scheduler
from vjm_pin.analysis.maps import run_map, sample_poses
from vjm_pin.cli import main
from vjm_pin.exceptions import MapInterrupted, SchedulerError
from vjm_pin.model.robots import build_robot

N_BIG = 100_000  # minutes of work: an interrupt, not the end, stops these runs
W = np.array([10.0, 0.0, -100.0, 0.0, 0.0, 0.0])
VJM_PIN = [sys.executable, "-c", "import sys; from vjm_pin.cli import main; sys.exit(main())"]
PROGRESS = re.compile(rb"\b([1-9]\d*)/\d+ \[")  # tqdm's "done/total [" once a chunk is back
WROTE = re.compile(r"^vjm-pin: interrupted: wrote (\d+) of (\d+) poses to (.+)$")


@pytest.fixture(scope="module")
def ur5():
    return build_robot("ur5").vm


# ----------------------------------------------------------------------------- helpers
def _read_until(fd, proc, pattern=None, limit=120.0) -> bytes:
    """Read ``fd`` until ``pattern`` shows, the writer closes it or ``limit`` s pass."""
    buf = b""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                chunk = os.read(fd, 65536)
            except OSError:  # EIO: every writer of the pseudo-terminal is gone
                break
            if not chunk:
                break
            buf += chunk
            if pattern is not None and pattern.search(buf):
                break
        elif proc.poll() is not None and pattern is not None:
            break
    return buf


def interrupt_when_computing(args, cwd, *, group=True):
    """Run ``vjm-pin ARGS`` with stderr on a pseudo-terminal, send SIGINT once the progress
    bar shows finished poses; return (exit status, stderr lines, seconds from SIGINT to exit).
    The seconds are printed for the record, never asserted."""
    master, slave = pty.openpty()
    termios.tcsetwinsize(slave, (24, 120))  # tqdm draws nothing on a 0-column terminal
    proc = subprocess.Popen(
        [*VJM_PIN, *args],
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=slave,
        start_new_session=True,
    )
    os.close(slave)
    try:
        before = _read_until(master, proc, PROGRESS)
        assert proc.poll() is None, before.decode(errors="replace")
        assert PROGRESS.search(before), "no progress within the time limit"
        sent = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT) if group else proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=20)  # a hang guard, not a timing assertion
        latency = time.monotonic() - sent
        after = _read_until(master, proc)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        os.close(master)
    text = (before + after).decode(errors="replace").replace("\r\n", "\n").replace("\r", "\n")
    lines = [ln.strip() for ln in text.split("\n") if ln.strip()]
    print(f"SIGINT -> exit: {latency:.2f} s ({' '.join(args[:6])} ...)")
    return rc, lines, latency


def assert_partial_csv(path, n, requested_poses):
    """The CSV holds exactly ``n`` rows, each one of the requested poses with a result."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n > 0
    joints = [k for k in rows[0] if k.endswith("_joint")]
    got = np.array([[float(r[j]) for j in joints] for r in rows])
    requested = {tuple(p) for p in requested_poses.tolist()}
    assert all(tuple(p) in requested for p in got.tolist())  # exact round trip of repr floats
    assert all(r["status"] == "ok" and np.isfinite(float(r["dz_m"])) for r in rows)


def _children(pid) -> list:
    """Process ids of the children of ``pid`` (Linux /proc)."""
    kids = []
    try:
        for t in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{t}/children") as fh:
                kids += fh.read().split()
    except OSError:
        pass
    return kids


def no_leftovers(folder, keep=()):
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


# ----------------------------------------------------------------------------- Ctrl-C
def test_ctrl_c_local_pool_stops_and_writes_the_finished_poses(tmp_path, ur5):
    rc, lines, _ = interrupt_when_computing(
        [
            "map",
            "ur5",
            "--samples",
            str(N_BIG),
            "--workers",
            "2",
            "--out",
            "m.csv",
            "--plot",
            "m.png",
        ],
        tmp_path,
    )
    assert rc == 130 and not any("Traceback" in ln for ln in lines), lines
    m = WROTE.match(lines[-1])
    assert m and m[2] == str(N_BIG) and m[3] == "m.csv and m.png", lines[-1]
    _, poses = sample_poses(ur5, N_BIG, seed=0)
    assert_partial_csv(tmp_path / "m.csv", int(m[1]), poses)
    assert (tmp_path / "m.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert no_leftovers(tmp_path) == ["m.csv", "m.png"]  # no temporary files


def test_ctrl_c_dask_local_cluster_stops_and_writes_the_finished_poses(tmp_path, ur5):
    rc, lines, _ = interrupt_when_computing(
        [
            "map",
            "ur5",
            "--samples",
            str(N_BIG),
            "--backend",
            "dask",
            "--workers",
            "1",
            "--out",
            "m.npz",
        ],
        tmp_path,
    )
    assert rc == 130 and not any("Traceback" in ln for ln in lines), lines
    m = WROTE.match(lines[-1])
    assert m and m[2] == str(N_BIG) and m[3] == "m.npz", lines[-1]
    z = np.load(tmp_path / "m.npz")
    n = int(m[1])
    assert z["poses"].shape == (n, 6) and n > 0 and np.all(z["status"] == "ok")
    _, poses = sample_poses(ur5, N_BIG, seed=0)
    requested = {tuple(p) for p in poses.tolist()}
    assert all(tuple(p) in requested for p in z["poses"].tolist())
    assert no_leftovers(tmp_path) == ["m.npz"]


def test_ctrl_c_dask_scheduler_cancels_its_tasks(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", dashboard_address=":0"
    ) as cluster:
        rc, lines, _ = interrupt_when_computing(
            ["map", "ur5", "--samples", str(N_BIG), "--scheduler", cluster.scheduler_address],
            tmp_path,
            group=False,  # the scheduler is not ours: only the command is interrupted
        )
        assert rc == 130 and not any("Traceback" in ln for ln in lines), lines
        m = re.match(r"^vjm-pin: interrupted after (\d+) of (\d+) poses$", lines[-1])
        assert m and int(m[1]) > 0 and m[2] == str(N_BIG), lines[-1]
        end = time.monotonic() + 20
        while cluster.scheduler.tasks and time.monotonic() < end:
            time.sleep(0.1)
        assert not cluster.scheduler.tasks  # nothing left queued for the other 99 % of the map
    assert no_leftovers(tmp_path) == []


def test_ctrl_c_without_a_terminal_is_one_line(tmp_path):
    proc = subprocess.Popen(
        [*VJM_PIN, "map", "ur5", "--samples", str(N_BIG), "--workers", "2"],
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        end = time.monotonic() + 120
        while not _children(proc.pid) and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.1)  # until the pool's workers exist: the map has started
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    lines = err.decode().splitlines()
    assert proc.returncode == 130 and len(lines) == 1, lines  # no progress bar in a log
    assert re.match(r"^vjm-pin: interrupted after \d+ of 100000 poses$", lines[0]), lines


# ----------------------------------------------------------------------------- library
def test_an_interrupt_keeps_exactly_the_finished_chunks(ur5):
    names, poses = sample_poses(ur5, 12, seed=3)
    full = run_map(ur5, names, poses, W, backend="serial")

    def stop_after_two_chunks(done):
        if done >= 6:
            raise KeyboardInterrupt

    with pytest.raises(MapInterrupted) as ei:
        run_map(ur5, names, poses, W, backend="serial", chunk=3, progress=stop_after_two_chunks)
    part = ei.value.result
    assert isinstance(ei.value, KeyboardInterrupt) and ei.value.requested == 12
    assert np.array_equal(part.poses, poses[:6])
    for f in ("deflection", "k_along", "k_min", "p0", "stable", "status"):
        assert np.array_equal(getattr(part, f), getattr(full, f)[:6]), f


def test_an_interrupted_pool_leaves_no_worker_and_keeps_its_results(ur5):
    names, poses = sample_poses(ur5, 40, seed=5)
    full = run_map(ur5, names, poses, W, backend="serial")

    def interrupt(done):
        raise KeyboardInterrupt

    with pytest.raises(MapInterrupted) as ei:
        run_map(ur5, names, poses, W, backend="local", workers=2, chunk=2, progress=interrupt)
    part = ei.value.result
    assert part.poses.shape == (2, 6)  # the one chunk that was reported, no more
    i = [int(np.flatnonzero((poses == p).all(axis=1))[0]) for p in part.poses]
    assert np.array_equal(part.deflection, full.deflection[i])
    assert multiprocessing.active_children() == []


def test_outputs_are_atomic(tmp_path, ur5, monkeypatch):
    from vjm_pin.analysis import maps

    names, poses = sample_poses(ur5, 4, seed=1)
    res = run_map(ur5, names, poses, W, backend="serial")
    out = tmp_path / "m.csv"
    out.write_text("previous\n")
    def failing(*args):  # the header is written, the rows are not
        raise KeyboardInterrupt

    monkeypatch.setattr(maps, "_csv_lines", failing)
    with pytest.raises(KeyboardInterrupt):
        res.to_csv(out)
    assert out.read_text() == "previous\n" and no_leftovers(tmp_path) == ["m.csv"]
    monkeypatch.undo()
    res.to_npz(tmp_path / "m.data")  # exactly that name (np.savez would add .npz to a path)
    assert np.array_equal(np.load(tmp_path / "m.data")["deflection"], res.deflection)
    assert no_leftovers(tmp_path) == ["m.csv", "m.data"]


@pytest.mark.parametrize(
    "address, fragment",
    [
        ("not-an-address", "not a Dask scheduler address"),
        ("127.0.0.1:8786", "not a Dask scheduler address"),
        ("tls://127.0.0.1:8786", "not a Dask scheduler address"),  # no TLS settings to use
        ("tcp://127.0.0.1", "not a Dask scheduler address"),
        ("tcp://127.0.0.1:99999", "not a Dask scheduler address"),
        ("tcp://127.0.0.1:1", "nothing answers there"),
        (8786, "not a Dask scheduler address"),
    ],
)
def test_scheduler_addresses_are_checked(address, fragment):
    with pytest.raises(SchedulerError, match=fragment) as ei:
        check_scheduler(address)
    assert "tcp://HOST:PORT" in str(ei.value) and ei.value.address == address


# ----------------------------------------------------------------------------- bad input
BAD = [
    # (arguments after 'map', fragment of the one-line message)
    (["ur5", "--samples", "0"], "--samples must be a positive integer"),
    (["ur5", "--samples", "-5"], "--samples must be a positive integer"),
    (["ur5", "--samples", "abc"], "--samples"),
    (["ur5", "--samples", "100000000000"], "more than one map holds"),
    (["ur5", "--samples", "3", "--seed", "-1"], "--seed"),
    (["ur5", "--grid", "elbow_joint"], "NAME=LO:HI:N"),
    (["ur5", "--grid", "elbow_joint=0:1"], "NAME=LO:HI:N"),
    (["ur5", "--grid", "elbow_joint=0:1:2.5"], "NAME=LO:HI:N"),
    (["ur5", "--grid", "=0:1:3"], "no joint name"),
    (["ur5", "--grid", "nope=0:1:3"], "unknown joint 'nope'"),
    (["ur5", "--grid", "elbow_joint=1:0:3"], "LO 1 is above HI 0"),
    (["ur5", "--grid", "elbow_joint=0:1:0"], "N ≥ 1"),
    (["ur5", "--grid", "elbow_joint=0.5:0.5:3"], "equal values"),
    (["ur5", "--grid", "elbow_joint=0:nan:3"], "finite"),
    (["ur5", "--grid", "elbow_joint=0:1:3", "elbow_joint=0:2:2"], "given twice"),
    (["ur5", "--grid", "elbow_joint=0:100:3"], "joint limits"),
    (
        ["ur5", "--grid", "shoulder_pan_joint=0:1:100000", "elbow_joint=0:1:1000"],
        "more than one map",
    ),
    (["paper-c-s", "--grid", "link1_vjm_tx=0:0.1:3"], "virtual spring joint"),
    (["paper-c-s", "--samples", "3"], "no actuated joint"),
    (["four-bar", "--grid", "elbow=0:1:3"], "passive joint of a closed mechanism"),
    (["four-bar", "--samples", "3", "--wrench", "0", "10", "0"], "outside the task"),
    (["ur5", "--samples", "3", "--load", "nope", "0", "0", "-1"], "unknown frame 'nope'"),
    (["ur5", "--samples", "3", "--load", "tool0", "0", "-1"], "load 'tool0 0 -1'"),
    (["ur5", "--samples", "3", "--load", "tool0", "0", "x", "-1"], "tool0"),
    (["ur5", "--samples", "3", "--workers", "0"], "--workers must be positive"),
    (["ur5", "--samples", "3", "--workers", "-2"], "--workers must be positive"),
    (["ur5", "--samples", "3", "--backend", "mpi"], "invalid choice: 'mpi'"),
    (["ur5"], "one of the arguments --samples --grid is required"),
    (["ur5", "--samples", "3", "--grid", "elbow_joint=0:1:3"], "not allowed with"),
    (["ur5", "--samples", "3", "--wrench", "1", "2"], "--wrench needs 3 or 6 numbers"),
    (["ur5", "--samples", "3", "--wrench", "1", "2", "3", "4"], "--wrench needs 3 or 6 numbers"),
    (["ur5", "--samples", "3", "--wrench", "nan", "0", "0"], "--wrench contains NaN"),
    (["ur5", "--samples", "3", "--workers", "100000"], "--workers 100000: more than"),
    (["ur5", "--samples", "3", "--payload", "-1"], "payload"),
    (["ur5", "--samples", "3", "--payload", "1e308"], "--payload 1e+308 kg"),
    (["ur5", "--samples", "3", "--frame", "nope"], "unknown frame 'nope'"),
    (["no-such-model", "--samples", "3"], "no-such-model"),
    (["ur5", "--samples", "3", "--scheduler", "not-an-address"], "--scheduler 'not-an-address'"),
    (["ur5", "--samples", "3", "--scheduler", "tcp://127.0.0.1:1"], "nothing answers there"),
    (["ur5", "--samples", "3", "--scheduler", ""], "--scheduler ''"),
    (
        ["ur5", "--samples", "3", "--scheduler", "tcp://127.0.0.1:1", "--backend", "local"],
        "needs the dask",
    ),
    (["ur5", "--samples", "3", "--out", "m.txt"], "m.txt"),
    (["ur5", "--samples", "3", "--out", "missing/m.csv"], "does not exist"),
    (["ur5", "--samples", "3", "--plot", "m.xyz"], "m.xyz"),
]


@pytest.mark.parametrize("args, fragment", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_is_one_line_and_writes_nothing(args, fragment, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    if "--out" not in args and "--plot" not in args:
        args = [*args, "--out", "out.csv", "--plot", "out.png"]
    try:
        rc = main(["map", *args, "--no-progress"])
    except SystemExit as e:  # argparse's usage errors
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("vjm-pin: error: ") and fragment in err, err
    assert no_leftovers(tmp_path) == []
