"""Dask maps with the heap kept between a chunk's blocks (issue 14, ``map_backends._kept_heap``):
the same numbers as the serial map, glibc's settings restored after each chunk, nothing changed
where the environment leaves glibc's dynamic threshold on."""

import threading

import numpy as np
import pytest

from vjm_pin.analysis import map_backends as mb
from vjm_pin.analysis.maps import run_map, sample_poses
from vjm_pin.model.robots import build_robot

BEAM = {"section": "tube", "outer_diameter": 0.09, "wall": 0.005, "E": 7.0e10, "nu": 0.33}
LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link")
FIELDS = ("deflection", "k_along", "k_min", "p0", "stable", "status")
W = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def ur5_links():
    """ur5 with 6-D link springs: the batched map whose blocks' temporaries are above 128 KiB."""
    return build_robot("ur5", springs={"links": {ln: {"beam": dict(BEAM)} for ln in LINKS}}).vm


class FakeMallopt:
    def __init__(self):
        self.calls = []

    def __call__(self, param, value):
        self.calls.append((param, value))
        return 1


@pytest.fixture
def fresh_plan(monkeypatch):
    """No plan decided yet in this process, and no MALLOC_* / GLIBC_TUNABLES in the environment."""
    monkeypatch.setattr(mb, "_heap_plan", None)
    monkeypatch.setattr(mb, "_heap_users", 0)
    for k in (*mb._MALLOC_ENV, "GLIBC_TUNABLES"):
        monkeypatch.delenv(k, raising=False)
    return monkeypatch


# ----------------------------------------------------------------------------- the plan
def _glibc() -> bool:
    try:
        return mb.sys.platform.startswith("linux") and mb.os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc")
    except (ValueError, OSError, AttributeError):
        return False


def test_nothing_to_do_without_malloc_variables(fresh_plan):
    assert mb._heap_settings() is None
    with mb._kept_heap():  # a no-op
        pass
    assert mb._heap_users == 0


@pytest.mark.skipif(not _glibc(), reason="glibc only")
@pytest.mark.parametrize(
    ("env", "restore"),
    [
        ({"MALLOC_TRIM_THRESHOLD_": "65536"}, ((mb._M_MMAP_THRESHOLD, 128 << 10), (mb._M_TRIM_THRESHOLD, 65536))),
        ({"MALLOC_TRIM_THRESHOLD_": "0x20000", "MALLOC_MMAP_THRESHOLD_": "262144"},
         ((mb._M_MMAP_THRESHOLD, 262144), (mb._M_TRIM_THRESHOLD, 0x20000))),
        ({"MALLOC_TOP_PAD_": "0"}, ((mb._M_MMAP_THRESHOLD, 128 << 10), (mb._M_TRIM_THRESHOLD, 128 << 10))),
    ],
)  # fmt: skip
def test_the_plan_restores_what_the_environment_set(fresh_plan, env, restore):
    for k, v in env.items():
        fresh_plan.setenv(k, v)
    plan = mb._heap_settings()
    assert plan is not None and plan[1] == restore


@pytest.mark.parametrize(
    "env",
    [
        {"MALLOC_TRIM_THRESHOLD_": "64k"},  # not a number glibc reads: its value unknown here
        {"MALLOC_TRIM_THRESHOLD_": "65536", "GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=4096"},
        {"MALLOC_MMAP_THRESHOLD_": str(64 << 20)},  # above glibc's maximum
    ],
)
def test_unknown_settings_are_left_alone(fresh_plan, env):
    for k, v in env.items():
        fresh_plan.setenv(k, v)
    assert mb._heap_settings() is None


def test_glibc_sizes():
    assert mb._glibc_size("65536") == 65536
    assert mb._glibc_size("0x10000") == 65536
    assert mb._glibc_size("0200000") == 65536
    assert mb._glibc_size(" 0 ") == 0
    assert mb._glibc_size("64k") is None and mb._glibc_size("") is None


# ----------------------------------------------------------------------------- the guard
def test_kept_heap_raises_then_restores_once_even_on_error(fresh_plan):
    fake = FakeMallopt()
    restore = ((mb._M_MMAP_THRESHOLD, 128 << 10), (mb._M_TRIM_THRESHOLD, 65536))
    fresh_plan.setattr(mb, "_heap_plan", (fake, restore))
    raised = [(mb._M_MMAP_THRESHOLD, mb._KEPT_MMAP), (mb._M_TRIM_THRESHOLD, mb._KEPT_TRIM)]
    with mb._kept_heap():
        assert fake.calls == raised
        with mb._kept_heap():  # a second chunk in another thread of the worker: nothing more
            assert fake.calls == raised
        assert fake.calls == raised  # still one chunk running: not restored yet
    assert fake.calls == raised + list(restore) and mb._heap_users == 0
    fake.calls.clear()
    with pytest.raises(RuntimeError), mb._kept_heap():
        raise RuntimeError("a failing chunk")
    assert fake.calls == raised + list(restore) and mb._heap_users == 0


def test_kept_heap_counts_concurrent_chunks(fresh_plan):
    fake = FakeMallopt()
    restore = ((mb._M_MMAP_THRESHOLD, 128 << 10), (mb._M_TRIM_THRESHOLD, 65536))
    fresh_plan.setattr(mb, "_heap_plan", (fake, restore))
    inside, release = threading.Barrier(5), threading.Event()

    def chunk():
        with mb._kept_heap():
            inside.wait(timeout=10)
            release.wait(timeout=10)

    threads = [threading.Thread(target=chunk) for _ in range(4)]
    for t in threads:
        t.start()
    inside.wait(timeout=10)  # all four chunks inside
    assert mb._heap_users == 4 and len(fake.calls) == 2
    release.set()
    for t in threads:
        t.join(timeout=10)
    assert mb._heap_users == 0 and fake.calls[2:] == list(restore)


def test_dask_task_returns_the_chunk_result(fresh_plan):
    fake = FakeMallopt()
    fresh_plan.setattr(mb, "_heap_plan", (fake, ((mb._M_TRIM_THRESHOLD, 65536),)))
    assert mb._dask_task(lambda a, b, chunk: (a, b, chunk), 1, 2, "c") == (1, 2, "c")
    assert len(fake.calls) == 3 and mb._heap_users == 0


# ----------------------------------------------------------------------------- end to end
def _workers_state():
    from vjm_pin.analysis import map_backends

    return map_backends._heap_settings() is not None, map_backends._heap_users


@pytest.mark.skipif(not _glibc(), reason="glibc only")
def test_maps_on_a_nanny_cluster_agree_bit_for_bit_with_serial(ur5_links):
    """A running cluster with nannies (its workers have ``MALLOC_TRIM_THRESHOLD_`` set): the
    chunks run with the heap kept, give the serial numbers bit for bit and leave nothing raised."""
    distributed = pytest.importorskip("distributed")
    names, poses = sample_poses(ur5_links, 2100, seed=5)  # ≥ JIT_MIN_POSES: compiled with VJM_PIN_JIT=1
    serial = run_map(ur5_links, names, poses, W, backend="serial")
    act = build_robot("ur5").vm
    names_a, poses_a = sample_poses(act, 300, seed=6)
    serial_a = run_map(act, names_a, poses_a, W, backend="serial")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    )  # nannies: MALLOC_TRIM_THRESHOLD_ in the workers' environment
    with cluster, distributed.Client(cluster) as client:
        addr = cluster.scheduler_address
        assert all(kept for kept, _ in client.run(_workers_state).values())
        dask = run_map(ur5_links, names, poses, W, backend="dask", scheduler=addr, chunk=300)
        dask_a = run_map(act, names_a, poses_a, W, backend="dask", scheduler=addr, chunk=40)
        # restored after the chunks
        assert all(users == 0 for _, users in client.run(_workers_state).values())
    for r, ref in ((dask, serial), (dask_a, serial_a)):
        for f in FIELDS:
            nan = f not in ("stable", "status")
            assert np.array_equal(getattr(r, f), getattr(ref, f), equal_nan=nan), f
    assert np.sum(serial.status == "ok") > 2000


def test_maps_on_a_local_cluster_with_the_variable_agree_bit_for_bit(monkeypatch):
    """run_map's own cluster (``dask worker`` processes, the environment of this process): with
    ``MALLOC_TRIM_THRESHOLD_`` set the chunks take the kept-heap path; the same numbers."""
    pytest.importorskip("distributed")
    vm = build_robot("ur5").vm
    names, poses = sample_poses(vm, 60, seed=7)
    serial = run_map(vm, names, poses, W, backend="serial")
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    dask = run_map(vm, names, poses, W, backend="dask", workers=2, chunk=8)
    for f in FIELDS:
        assert np.array_equal(getattr(dask, f), getattr(serial, f)), f
