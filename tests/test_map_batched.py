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
