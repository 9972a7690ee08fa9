"""The Hessian of Ψ in screw form from J (vjm_pin.kinematics.screw) against Pinocchio's kinematic
Hessian contraction and against finite differences of JᵀF; the solver with and without it."""

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.kinematics import chain as kmod
from vjm_pin.kinematics.chain import Kinematics, contract_hessian
from vjm_pin.kinematics.screw import psi_hessian_screw, screw_applicable, support_mask
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver, blocks_at

from .chains import random_vjm


def rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


def fd_psi_hessian(kin, x, w, h=1e-6):
    """Central differences of the generalised force JᵀF (columns: ∂/∂x_j)."""
    n = kin.model.nv
    out = np.zeros((n, n))
    for j in range(n):
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        out[:, j] = (kin.evaluate(xp, hessian=False).jacobian - kin.evaluate(xm, hessian=False).jacobian).T @ w / (2 * h)
    return out


@pytest.mark.parametrize("seed", range(10))
def test_screw_matches_pinocchio_contraction_on_random_chains(seed):
    vm = random_vjm(seed, n_joints=3 + seed % 5, n_passive=seed % 3, link_springs=1 + seed % 3)
    assert screw_applicable(vm.model)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(500 + seed)
    for _ in range(3):
        x = vm.reference + rng.uniform(-0.5, 0.5, vm.model.nq)
        st = kin.evaluate(x)
        for w in (rng.standard_normal(6), np.concatenate([rng.standard_normal(3), np.zeros(3)])):
            ref = contract_hessian(st.hessian, w)
            assert rel(psi_hessian_screw(st.jacobian, w), ref) < 1e-12
            # restricted to and ordered as the solver's (θ, q) columns
            free = np.concatenate([vm.theta_idx, vm.q_idx])
            got = psi_hessian_screw(st.jacobian[:, free], w, support_mask(vm.model.nv, free))
            assert rel(got, ref[np.ix_(free, free)]) < 1e-12
            assert rel(kin.psi_hessian(st, w, free), ref[np.ix_(free, free)]) < 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_screw_matches_finite_differences(seed):
    vm = random_vjm(seed, n_joints=5, n_passive=1, link_springs=2)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(600 + seed)
    x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
    w = rng.standard_normal(6)
    h = psi_hessian_screw(kin.evaluate(x, hessian=False).jacobian, w)
    assert rel(h, fd_psi_hessian(kin, x, w)) < 1e-6
    # a pure force: the Hessian of p(x)·f, symmetric bit for bit in screw form
    f = np.concatenate([w[:3], np.zeros(3)])
    hf = psi_hessian_screw(kin.evaluate(x, hessian=False).jacobian, f)
    assert np.array_equal(hf, hf.T)


def _mixed_joint_model():
    """A chain mixing revolute and prismatic joints (aligned and unaligned axes), prismatic
    first and last, with an end frame off the last axis."""
    rng = np.random.default_rng(7)
    model = pin.Model()
    parent = 0
    joints = [
        pin.JointModelPX(),
        pin.JointModelRZ(),
        pin.JointModelPrismaticUnaligned(*(v / np.linalg.norm(v) for v in [rng.standard_normal(3)])),
        pin.JointModelRevoluteUnaligned(*(v / np.linalg.norm(v) for v in [rng.standard_normal(3)])),
        pin.JointModelRY(),
        pin.JointModelPZ(),
    ]
    for k, jm in enumerate(joints):
        placement = pin.SE3(pin.exp3(rng.uniform(-1, 1, 3)), rng.uniform(-0.5, 0.5, 3))
        parent = model.addJoint(parent, jm, placement, f"j{k}")
    fid = model.addFrame(pin.Frame("tip", parent, 0, pin.SE3(np.eye(3), np.array([0.3, -0.2, 0.4])), pin.FrameType.OP_FRAME))
    return model, fid


def test_screw_with_prismatic_and_unaligned_joints():
    model, fid = _mixed_joint_model()
    assert screw_applicable(model)
    kin = Kinematics(model, fid)
    rng = np.random.default_rng(8)
    for _ in range(4):
        x = rng.uniform(-1, 1, model.nq)
        w = rng.standard_normal(6)
        st = kin.evaluate(x)
        h = psi_hessian_screw(st.jacobian, w)
        assert rel(h, contract_hessian(st.hessian, w)) < 1e-12
        assert rel(h, fd_psi_hessian(kin, x, w)) < 1e-6


def test_screw_matches_pinocchio_on_ur5_with_link_springs():
    pytest.importorskip("example_robot_data")
    from vjm_pin.model.robots import build_robot

    links = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link")
    beam = {"section": "tube", "outer_diameter": 0.09, "wall": 0.005, "E": 7.0e10, "nu": 0.33}
    vm = build_robot("ur5", springs={"links": {ln: {"beam": dict(beam)} for ln in links}}).vm
    assert vm.model.nv > 30 and screw_applicable(vm.model)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(9)
    x = vm.reference + rng.uniform(-0.2, 0.2, vm.model.nq)
    w = np.array([10.0, -5.0, -100.0, 1.0, 0.5, 2.0])
    st = kin.evaluate(x)
    h = psi_hessian_screw(st.jacobian, w)
    assert rel(h, contract_hessian(st.hessian, w)) < 1e-12
    assert rel(h, fd_psi_hessian(kin, x, w)) < 1e-6


def test_other_joint_types_keep_pinocchio_tensor():
    """A spherical or free-flyer joint is not a 1-DoF screw: Kinematics falls back to the tensor."""
    model = pin.buildSampleModelHumanoidRandom()
    assert not screw_applicable(model)
    fid = model.nframes - 1
    kin = Kinematics(model, fid)
    assert not kin.uses_screw
    x = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    w = np.random.default_rng(3).standard_normal(6)
    st = kin.evaluate(x)
    np.testing.assert_array_equal(kin.psi_hessian(st, w), contract_hessian(st.hessian, w))


def test_blocks_with_and_without_screw_form_agree(monkeypatch):
    vm = random_vjm(11, n_joints=6, n_passive=2, link_springs=3)
    rng = np.random.default_rng(12)
    x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
    w = rng.standard_normal(6)
    a = blocks_at(vm, x, w)
    assert a.state.hessian is None  # the screw form needs no kinematic Hessian tensor
    monkeypatch.setattr(kmod, "_screw_enabled", False)
    b = blocks_at(vm, x, w)
    assert b.state.hessian is not None
    for name in ("H_tt", "H_tq", "H_qt", "H_qq"):
        assert rel(getattr(a, name), getattr(b, name)) < 1e-12, name
    np.testing.assert_array_equal(a.J_theta, b.J_theta)


def _solve_both(monkeypatch, fn):
    out = fn()
    monkeypatch.setattr(kmod, "_screw_enabled", False)
    try:
        return out, fn()
    finally:
        monkeypatch.setattr(kmod, "_screw_enabled", True)


def test_solver_results_with_and_without_screw_form_agree(monkeypatch):
    """Warm-started solves along the Model C column past buckling, and a load-controlled solve
    with a moment on a random chain: the same equilibria, wrenches and verdicts to 1e-12."""
    vm = resolve_model("paper-c-s")
    d = np.array([-1.0, 0, 0, 0, 0, 0])

    def column():
        s = EquilibriumSolver(vm)
        prev, out = None, []
        for t in np.linspace(2e-6, 6e-5, 12):
            r = s.solve(t * d, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
            out.append(r)
            prev = r
        return out

    new, old = _solve_both(monkeypatch, column)
    assert any(not np.allclose(r.x, vm.reference, atol=1e-6) for r in new)  # past buckling: it bent
    for a, b in zip(new, old):
        assert a.converged and b.converged and a.stable == b.stable
        assert rel(a.wrench, b.wrench) < 1e-12
        assert np.abs(a.x - b.x).max() < 1e-12
        assert rel(a.stability.eigenvalues, b.stability.eigenvalues) < 1e-10

    ch = random_vjm(5, n_joints=6, n_passive=1, link_springs=2)
    w = np.array([3.0, -2.0, 1.0, 0.4, -0.3, 0.2])
    a, b = _solve_both(monkeypatch, lambda: EquilibriumSolver(ch).solve_wrench(w))
    assert a.converged and b.converged and a.stable == b.stable
    assert np.abs(a.x - b.x).max() < 1e-12 and rel(a.deflection, b.deflection) < 1e-12


def test_screw_applicable_is_remembered_per_model_and_sees_a_new_joint():
    """The answer is kept per model object; a joint added to that model afterwards (a spherical
    one here) is seen, and another model is never given the first one's answer."""
    model = pin.Model()
    jid = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "rz")
    assert screw_applicable(model) and screw_applicable(model)
    model.addJoint(jid, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    assert not screw_applicable(model)
    other = pin.Model()
    other.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "px")
    assert screw_applicable(other)
    assert not screw_applicable(pin.buildSampleModelHumanoidRandom())
