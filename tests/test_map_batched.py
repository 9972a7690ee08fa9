"""Batched lockstep maps (vjm_pin.analysis.batched) against the per-pose reference path."""

import numpy as np
import pytest

from vjm_pin.analysis import maps
from vjm_pin.analysis.batched import batch_applicable, shared_chain
from vjm_pin.analysis.maps import grid_poses, run_map, sample_poses
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.robots import build_robot

LINK = {
    "links": {
        "upper_arm_link": {"beam": {"section": "tube", "outer_diameter": 0.09, "wall": 0.004, "E": 7e10, "nu": 0.33}},
        "forearm_link": {"beam": {"section": "tube", "outer_diameter": 0.07, "wall": 0.0035, "E": 7e10, "nu": 0.33}},
    }
}
FIELDS = ("deflection", "k_along", "k_min", "p0", "stable", "status")


@pytest.fixture(scope="module", params=["actuators", "links"])
def ur5(request):
    return build_robot("ur5", springs=LINK if request.param == "links" else None).vm


def _per_pose(monkeypatch, *args, **kw):
    with monkeypatch.context() as m:
        m.setattr(maps, "_batching", False)
        return run_map(*args, **kw)


@pytest.mark.parametrize("wrench", [[0, 0, -100, 0, 0, 0], [30, -20, -150, 4, -3, 2]])
def test_batched_equals_per_pose(ur5, wrench, monkeypatch):
    names, poses = sample_poses(ur5, 24, seed=7)
    w = np.array(wrench, float)
    assert batch_applicable(ur5)
    raw = shared_chain(ur5).solve(names, poses, w)
    assert sum(r is not None for r in raw) >= 20  # the batch really carries the map
    fast = run_map(ur5, names, poses, w, backend="serial")
    ref = _per_pose(monkeypatch, ur5, names, poses, w, backend="serial")
    assert np.array_equal(fast.status, ref.status) and np.array_equal(fast.stable, ref.stable)
    np.testing.assert_allclose(fast.p0, ref.p0, rtol=0, atol=1e-15)
    scale = np.abs(ref.deflection).max()
    np.testing.assert_allclose(fast.deflection, ref.deflection, rtol=0, atol=1e-12 * scale)
    # the per-pose path inverts twice (eq. 28 for K_C, then K_C for C): ~1e-11 of rounding there;
    # the batch takes C = J (K − H)⁻¹ Jᵀ in one solve
    np.testing.assert_allclose(fast.k_along, ref.k_along, rtol=1e-9)
    np.testing.assert_allclose(fast.k_min, ref.k_min, rtol=1e-9)


def test_a_pose_does_not_depend_on_its_chunk(ur5):
    names, poses = sample_poses(ur5, 9, seed=3)
    w = np.array([5.0, 0.0, -120.0, 0.0, 1.0, 0.0])
    chain = shared_chain(ur5)
    together = chain.solve(names, poses, w)
    for i in (0, 4, 8):
        alone = chain.solve(names, poses[i : i + 1], w)[0]
        for f in FIELDS:
            assert np.array_equal(alone[f], together[i][f]), f


def test_the_batch_shares_the_threads_pin_data(ur5):
    """The batch computes on the thread's shared ``pin.Data`` (kinematics/shared.py): other users
    of that Data at other configurations between two batched solves (the per-pose path of a
    hand-back, a solver) change no number, bit for bit."""
    import pinocchio as pin

    from vjm_pin.analysis.batched import BatchedChain
    from vjm_pin.kinematics.shared import data_for
    from vjm_pin.solver import EquilibriumSolver

    names, poses = sample_poses(ur5, 12, seed=21)
    w = np.array([10.0, -5.0, -120.0, 1.0, 0.0, -2.0])
    chain = BatchedChain(ur5)
    first = chain.solve_arrays(names, poses, w)
    EquilibriumSolver(ur5).solve_wrench(2.0 * w)  # another user of the same Data, elsewhere
    data = data_for(ur5.model)
    pin.computeJointJacobians(ur5.model, data, pin.randomConfiguration(ur5.model))
    pin.updateFramePlacements(ur5.model, data)
    again = BatchedChain(ur5).solve_arrays(names, poses[::-1], w)
    assert first[0].sum() >= 10
    for a, b in zip(first, again):
        assert np.array_equal(a, b[::-1], equal_nan=True)


def test_singular_and_overloaded_poses_are_handed_back(monkeypatch):
    """Poses the batch cannot vouch for (a stretched elbow: K_C singular; a load the pose
    cannot carry) go to the per-pose path, whose verdict the map reports."""
    vm = build_robot("ur5").vm
    names, poses = grid_poses(vm, {"shoulder_lift_joint": np.array([-1.2, -0.4]), "elbow_joint": np.array([0.0, 1.0])})
    w = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    raw = shared_chain(vm).solve(names, poses, w)
    straight = poses[:, names.index("elbow_joint")] == 0.0
    assert all(raw[i] is None for i in np.flatnonzero(straight))
    assert all(raw[i] is not None for i in np.flatnonzero(~straight))
    fast = run_map(vm, names, poses, w, backend="serial")
    ref = _per_pose(monkeypatch, vm, names, poses, w, backend="serial")
    for f in FIELDS:  # handed back: the per-pose numbers themselves
        a, b = getattr(fast, f)[straight], getattr(ref, f)[straight]
        assert np.array_equal(a, b, equal_nan=f not in ("stable", "status")), f
    np.testing.assert_allclose(fast.k_min, ref.k_min, rtol=1e-9)
    # a load far beyond the actuators' capacity: no batched pose, same verdicts as per pose
    big = np.array([0.0, 0.0, -3e6, 0.0, 0.0, 0.0])
    raw = shared_chain(vm).solve(names, poses, big)
    fast = run_map(vm, names, poses, big, backend="serial")
    ref = _per_pose(monkeypatch, vm, names, poses, big, backend="serial")
    assert np.array_equal(fast.status, ref.status) and np.array_equal(fast.stable, ref.stable)
    for i, r in enumerate(raw):
        if r is not None:  # whatever the batch kept is the per-pose equilibrium
            np.testing.assert_allclose(r["deflection"], ref.deflection[i], rtol=1e-9, atol=1e-12)


def test_batch_scope():
    vm = build_robot("ur5").vm
    assert batch_applicable(vm)
    assert not batch_applicable(vm, gravity=np.array([0, 0, -9.81]))
    assert not batch_applicable(vm, loads=(Load("wrist_3_link", np.array([0, 0, -1.0, 0, 0, 0])),))


def test_local_and_dask_agree_bit_for_bit_on_batched_maps():
    vm = build_robot("ur5").vm
    names, poses = sample_poses(vm, 40, seed=11)
    w = np.array([0.0, 10.0, -100.0, 0.0, 0.0, 0.0])
    local = run_map(vm, names, poses, w, backend="local", workers=2, chunk=8)
    dask = run_map(vm, names, poses, w, backend="dask", workers=2, chunk=8)
    for f in FIELDS:
        assert np.array_equal(getattr(local, f), getattr(dask, f)), f
    assert np.all(local.status == "ok")


# ----------------------------------------------------------------------------- issue 14: speed
@pytest.mark.parametrize("wrench", [[0, 0, -100, 0, 0, 0], [30, -20, -150, 4, -3, 2]])
def test_compiled_kernel_equals_numpy_twin(ur5, wrench):
    """The numba kernel (K − H by loops, Cholesky steps and C = YᵀY under a force alone) and its
    numpy twin (stacked products, LU solves) give the same map to rounding."""
    pytest.importorskip("numba")
    from vjm_pin.analysis.batched import BatchedChain

    names, poses = sample_poses(ur5, 30, seed=12)
    w = np.array(wrench, float)
    chain = BatchedChain(ur5)
    twin = chain.solve_arrays(names, poses, w)
    chain.jit = True
    fast = chain.solve_arrays(names, poses, w)
    assert np.array_equal(twin[0], fast[0]) and twin[0].sum() >= 25
    keep = twin[0]
    np.testing.assert_array_equal(twin[1], fast[1])  # p0: the same Pinocchio calls
    scale = np.abs(twin[2][keep]).max()
    np.testing.assert_allclose(fast[2][keep], twin[2][keep], rtol=0, atol=1e-12 * scale)
    for a, b in zip(fast[3:], twin[3:]):
        np.testing.assert_allclose(a[keep], b[keep], rtol=1e-10)


def test_stacked_joint_origins_are_pinocchios(ur5):
    import pinocchio as pin

    from vjm_pin.analysis.batched import BatchedChain

    chain = BatchedChain(ur5)
    names, poses = sample_poses(ur5, 5, seed=4)
    data = ur5.model.createData()
    for sub in (slice(None), slice(1, 3)):  # all motors, or two of them (the rest at the reference)
        nm, ps = names[sub], poses[:, sub]
        got = chain.joint_origins(nm, ps)
        x, _ = chain._start(nm, ps)
        for i in range(len(ps)):
            pin.forwardKinematics(ur5.model, data, x[i])
            ref = np.array([m.translation for m in data.oMi[1:]])
            np.testing.assert_allclose(got[i], ref, rtol=0, atol=1e-14)


def test_stacked_log3_is_pinocchios():
    import pinocchio as pin

    from vjm_pin.analysis.batched import log3_stacked

    rng = np.random.default_rng(5)
    axes = rng.normal(size=(40, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate([[0.0, 1e-12, 1e-8, 5e-5, 2e-4], rng.uniform(0, np.pi, 30), [3.05, 3.1, 3.14, 3.1415926, np.pi]])
    rots = np.array([pin.exp3(a * t) for a, t in zip(axes, angles)])
    got = log3_stacked(rots)
    ref = np.array([pin.log3(r) for r in rots])
    # the rounding of vee(R − Rᵀ) grows as 1/sin θ towards π (beyond LOG3_STACKED_MAX pin.log3 itself)
    err = np.abs(got - ref).max(axis=1)
    assert np.all(err <= 2e-15 / np.maximum(np.sin(angles), 0.1))


def test_compiled_maps_agree_bit_for_bit_on_every_backend(monkeypatch):
    """A map large enough for the compiled kernels (JIT_MIN_POSES lowered here): serial, local
    processes and Dask workers take the map's one choice and give the same bits."""
    pytest.importorskip("numba")
    vm = build_robot("ur5").vm
    names, poses = sample_poses(vm, 32, seed=21)
    w = np.array([0.0, 10.0, -100.0, 0.0, 0.0, 0.0])
    monkeypatch.setenv("VJM_PIN_JIT", "1")  # the test suite runs with 0 (tests/conftest.py)
    monkeypatch.setattr(maps, "JIT_MIN_POSES", 1)
    choice = []
    use = maps._use_jit
    monkeypatch.setattr(maps, "_use_jit", lambda *a: choice.append(use(*a)) or choice[-1])
    serial = run_map(vm, names, poses, w, backend="serial", chunk=8)
    local = run_map(vm, names, poses, w, backend="local", workers=2, chunk=8)
    dask = run_map(vm, names, poses, w, backend="dask", workers=2, chunk=8)
    assert choice == [True, True, True]
    for r in (local, dask):
        for f in FIELDS:
            assert np.array_equal(getattr(r, f), getattr(serial, f)), f
    monkeypatch.setattr(maps, "JIT_MIN_POSES", 10**9)
    twin = run_map(vm, names, poses, w, backend="serial", chunk=8)  # numpy twin: the same to rounding
    np.testing.assert_allclose(twin.k_min, serial.k_min, rtol=1e-10)
