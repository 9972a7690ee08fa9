"""Jacobians and Hessians of eq. (16) against central finite differences."""

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.kinematics.chain import Kinematics, fix_hessian_layout
from vjm_pin.solver import blocks_at

from .chains import random_vjm

H_STEP = 1e-6


def fd_jacobian(kin, x, j, h=H_STEP):
    xp, xm = x.copy(), x.copy()
    xp[j] += h
    xm[j] -= h
    return (kin.evaluate(xp, hessian=False).jacobian - kin.evaluate(xm, hessian=False).jacobian) / (2 * h)


def rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-12)


def test_pinocchio_hessian_layout_matches_finite_differences():
    """Pinocchio 4.1 returns the kinematic Hessian with a scrambled memory order; our fix
    must match finite differences, and the raw array must not (so a fix upstream shows)."""
    model = pin.buildSampleModelManipulator()
    data = model.createData()
    q = pin.randomConfiguration(model)
    fid = model.nframes - 1
    pin.computeJointJacobians(model, data, q)
    pin.computeJointKinematicHessians(model, data)
    raw = pin.getFrameKinematicHessian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    fixed = fix_hessian_layout(raw)
    kin = Kinematics(model, fid)
    for j in range(model.nv):
        fd = fd_jacobian(kin, q, j)
        assert rel(fixed[:, :, j], fd) < 1e-6, f"column derivative d/dq_{j}"
    # the raw layout is wrong in pin 4.1: if this fails, Pinocchio fixed it: drop fix_hessian_layout
    assert max(rel(raw[:, :, j], fd_jacobian(kin, q, j)) for j in range(model.nv)) > 1e-3


@pytest.mark.parametrize("seed", range(8))
def test_jacobian_matches_finite_differences_of_g(seed):
    vm = random_vjm(seed, n_passive=seed % 3, link_springs=2 + seed % 2)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(100 + seed)
    x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
    jac = kin.evaluate(x, hessian=False).jacobian
    for j in range(vm.model.nv):
        xp, xm = x.copy(), x.copy()
        xp[j] += H_STEP
        xm[j] -= H_STEP
        pp, rp = kin.placement(xp)
        pm, rm = kin.placement(xm)
        col = np.concatenate([(pp - pm) / (2 * H_STEP), pin.log3(rp @ rm.T) / (2 * H_STEP)])
        assert rel(jac[:, j], col) < 1e-6


@pytest.mark.parametrize("seed", range(8))
def test_hessian_blocks_match_finite_differences(seed):
    """H_θθ, H_θq, H_qθ, H_qq = ∂(JᵀF)/∂(θ, q) for a random wrench (force and moment)."""
    vm = random_vjm(seed, n_joints=4 + seed % 3, n_passive=1 + seed % 2, link_springs=1 + seed % 3)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(200 + seed)
    x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
    w = rng.standard_normal(6)
    b = blocks_at(vm, x, w, kin)
    n = vm.model.nv
    fd = np.zeros((n, n))
    for j in range(n):
        fd[:, j] = fd_jacobian(kin, x, j).T @ w
    ti, qi = vm.theta_idx, vm.q_idx
    scale = np.abs(fd).max()  # relative to the whole Hessian: a block may be ~0
    for name, blk, ref in (
        ("H_tt", b.H_tt, fd[np.ix_(ti, ti)]),
        ("H_tq", b.H_tq, fd[np.ix_(ti, qi)]),
        ("H_qt", b.H_qt, fd[np.ix_(qi, ti)]),
        ("H_qq", b.H_qq, fd[np.ix_(qi, qi)]),
    ):
        assert np.abs(blk - ref).max() < 1e-6 * scale, name
    assert b.J_theta.shape == (6, vm.n_theta) and b.J_q.shape == (6, vm.n_q)


@pytest.mark.parametrize("seed", range(4))
def test_force_hessian_is_second_derivative_of_psi(seed):
    """For a pure force, H is the symmetric Hessian of Ψ = p(x)·F (eq. 16), checked by
    second-order central differences of Ψ itself."""
    vm = random_vjm(seed, n_joints=4, n_passive=1, link_springs=1)
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(300 + seed)
    x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
    f = np.concatenate([rng.standard_normal(3), np.zeros(3)])
    h_an = kin.evaluate(x).psi_hessian(f)
    psi = lambda xx: kin.placement(xx)[0] @ f[:3]  # noqa: E731
    n = vm.model.nv
    hs = 1e-4
    fd = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            ei, ej = np.zeros(n), np.zeros(n)
            ei[i], ej[j] = hs, hs
            fd[i, j] = (psi(x + ei + ej) - psi(x + ei - ej) - psi(x - ei + ej) + psi(x - ei - ej)) / (4 * hs * hs)
    assert np.abs(h_an - h_an.T).max() < 1e-10 * max(np.abs(h_an).max(), 1)
    assert rel(h_an, fd) < 1e-6


def test_task_rows_restrict_jacobian():
    vm = random_vjm(3, task=("x", "y", "z"), n_passive=1)
    b = blocks_at(vm, vm.reference, np.zeros(6))
    full = Kinematics(vm.model, vm.frame_id).evaluate(vm.reference).jacobian
    assert np.allclose(b.J_theta, full[:3][:, vm.theta_idx])
    assert np.allclose(b.J_q, full[:3][:, vm.q_idx])


def test_single_joint_model_keeps_matrix_shapes():
    """A one-joint model: Pinocchio returns a 1-D Jacobian; ours stays (6, 1), Hessian (6, 1, 1)."""
    from vjm_pin import load_vjm

    text = """<robot name="one" xmlns:vjm="urn:vjm-pin:1"><link name="base"/><link name="arm"/><link name="tip"/>
    <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
    <joint name="t" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="0.5 0 0"/></joint>
    <vjm:task frame="tip" components="y"/><vjm:joint name="j" role="actuated" stiffness="2.0" position="0"/></robot>"""
    vm = load_vjm(text)
    st = Kinematics(vm.model, vm.frame_id).evaluate(vm.reference)
    assert st.jacobian.shape == (6, 1) and st.hessian.shape == (6, 1, 1)
    from vjm_pin import EquilibriumSolver, unloaded_stiffness

    assert unloaded_stiffness(vm).stiffness[1, 1] == pytest.approx(2.0 / 0.25)
    res = EquilibriumSolver(vm).solve_wrench([0, 1.0, 0, 0, 0, 0])
    # closed form: k θ = F_y L cos θ (the force along y acts on the 0.5 m arm)
    assert 2.0 * res.x[0] == pytest.approx(0.5 * np.cos(res.x[0]) * 1.0, rel=1e-7)
    assert res.wrench[1] == pytest.approx(1.0, rel=1e-7)
