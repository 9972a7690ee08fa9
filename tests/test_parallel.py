"""Parallel models (``<vjm:leg>`` shorthand) through the mechanism core: aggregation, robot
equilibria, stability, buckling curves."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.analysis.curve import trace_curve
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.model.format import load_vjm
from vjm_pin.model.legs import split_legs
from vjm_pin.solver import loaded_stiffness, unloaded_stiffness
from vjm_pin.solver.mechanism import MechanismSolver

from .parallel_models import columns_xml, mechanism_fd_stiffness, robot_urdf, single_leg_urdf


def _ms(xml, **options) -> MechanismSolver:
    return MechanismSolver(load_vjm(xml), **options)


def _k(ms, res=None):
    return ms.stiffness(ms.solve() if res is None else res).stiffness


def test_two_identical_legs_give_twice_the_stiffness():
    one = _ms(single_leg_urdf(3))
    two = _ms(robot_urdf(3, n_legs=2, passive=False, identical=True))
    k1, k2 = _k(one), _k(two)
    assert np.linalg.matrix_rank(k1) == 6
    np.testing.assert_allclose(k2, 2 * k1, rtol=1e-9, atol=1e-9 * np.abs(k1).max())
    # and loaded, too
    d = np.array([1e-3, -5e-4, 2e-4, 0, 0, 0])
    e1, e2 = one.solve(deflection=d), two.solve(deflection=d)
    np.testing.assert_allclose(
        e2.wrench, 2 * e1.wrench, rtol=1e-7, atol=1e-7 * np.abs(e1.wrench).max()
    )
    np.testing.assert_allclose(
        _k(two, e2), 2 * _k(one, e1), rtol=1e-7, atol=1e-7 * np.abs(k1).max()
    )


@pytest.mark.parametrize("n_passive", [1, 2])
def test_rank_deficient_legs_sum_to_full_rank(n_passive):
    """Legs with 1 (2) passive revolutes have rank-5 (rank-4, the Orthoglide's case) stiffness;
    three legs with differently oriented passive axes give a full-rank robot stiffness."""
    vm = load_vjm(robot_urdf(1, passive=n_passive))
    for name, lv in split_legs(vm).items():
        k = unloaded_stiffness(lv).stiffness
        ev = np.linalg.eigvalsh(0.5 * (k + k.T))
        assert np.sum(ev > 1e-8 * ev.max()) == 6 - n_passive, f"leg {name}: eigenvalues {ev}"
    kc = _k(MechanismSolver(vm))
    ev = np.linalg.eigvalsh(0.5 * (kc + kc.T))
    assert ev.min() > 1e-6 * ev.max(), f"robot stiffness should be full rank, eigenvalues {ev}"


def _transform_stiffness(k_end, r):
    """Unloaded stiffness moved by a rigid offset ``r`` (E → P, world): ``Tᵀ K_E T`` with
    ``T = [[I, [r]×], [0, I]]`` (``δp_E = δp_P + [r]× δφ``)."""
    rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    t = np.eye(6)
    t[:3, 3:] = rx
    return t.T @ k_end @ t


def test_offset_is_the_wrench_transformation_unloaded():
    """The leg model with its offset frame equals the unloaded leg stiffness at the end link moved
    by the rigid offset (Tᵀ K T)."""
    vm = load_vjm(robot_urdf(2, passive=False))
    for leg, lv in zip(vm.legs, split_legs(vm).values()):
        k_p = unloaded_stiffness(lv).stiffness
        fid = lv.model.getFrameId(leg.frame)
        vm_end = type(lv)(**{**lv.__dict__, "frame": leg.frame, "frame_id": int(fid)})
        k_e = unloaded_stiffness(vm_end, kin=Kinematics(lv.model, fid)).stiffness
        data = lv.model.createData()
        pin.framesForwardKinematics(lv.model, data, lv.reference)
        r = data.oMf[lv.frame_id].translation - data.oMf[fid].translation
        assert np.linalg.norm(r) > 0.05
        np.testing.assert_allclose(
            _transform_stiffness(k_e, r), k_p, rtol=1e-8, atol=1e-8 * np.abs(k_p).max()
        )


def test_wrench_and_displacement_driven_equilibria_agree():
    ms = _ms(robot_urdf(4))
    d = np.array([2e-3, -1e-3, 1.5e-3, 2e-3, -1e-3, 3e-3])
    eq = ms.solve(deflection=d)
    assert eq.converged and eq.stable
    back = ms.solve(wrench=eq.wrench)
    assert back.stable
    np.testing.assert_allclose(back.deflection, d, rtol=0, atol=1e-8)
    np.testing.assert_allclose(back.wrench, eq.wrench, rtol=0, atol=1e-7 * np.abs(eq.wrench).max())


def test_loaded_stiffness_matches_finite_differences():
    ms = _ms(robot_urdf(5))
    eq = ms.solve(deflection=np.array([3e-3, 2e-3, -2e-3, 5e-3, 0.0, -4e-3]))
    kc = _k(ms, eq)
    fd = mechanism_fd_stiffness(ms, eq, 1e-6)
    err = np.linalg.norm(fd - kc) / np.linalg.norm(kc)
    assert err < 1e-4, f"relative error of K_C vs finite differences: {err:.2e}"


def _in_plane(d, L=1.0, kr=100.0, ka=1e5):
    """Margin of column A held straight with its tip fixed, pushed by δ (test below)."""
    a, b = L / 2 - d, L / 2
    return kr * (1 + ((a + b) / b) ** 2) - ka * d * a * (a + b) / b


def test_robot_stability_reports_the_buckling_leg():
    """Two orthogonal columns meeting at the platform; pushing the platform by δ along column A
    compresses A (force P = k_a δ). Closed form for A held straight with its tip fixed, segments
    a = L/2 − δ and b = L/2, mode φ₂ = −φ₁(a+b)/b: energy
    ½φ₁²[k_r(1 + ((a+b)/b)²) − P a(a+b)/b], so the mechanism is unstable past the δ_c that
    zeroes it, and its unstable mode lives in column A's joints only."""
    from scipy.optimize import brentq

    L, kr, ka = 1.0, 100.0, 1e5
    d_c = brentq(_in_plane, 0.0, 0.2)
    vm = load_vjm(columns_xml(L, kr, ka))
    ms = MechanismSolver(vm, follow_stable=False)
    below = ms.solve(deflection=[-0.97 * d_c, 0, 0])
    above = ms.solve(deflection=[-1.03 * d_c, 0, 0])
    assert below.stable and ms.unstable_modes(below)[0].size == 0
    assert not above.stable
    ev, modes = ms.unstable_modes(above)
    assert ev.size == 1
    legs = {lg.name: [vm.joint_index(j) for j in lg.joints] for lg in vm.legs}
    assert np.abs(modes[legs["B"], 0]).max() < 1e-9 * np.abs(modes[legs["A"], 0]).max()
    # the multiplier of the closure carries column B's share; A carries the axial force k_a δ
    np.testing.assert_allclose(below.wrench[0], -ka * 0.97 * d_c, rtol=2e-3)
    # the followed (stable) branch runs through buckling: the stiffness along x collapses
    pts = trace_curve(vm, [-1, 0, 0], 1.55 * d_c, 8).points
    assert all(p.stable for p in pts)
    assert pts[0].stiffness > 5 * pts[-1].stiffness, [p.stiffness for p in pts]


def test_bad_parallel_models():
    from vjm_pin.exceptions import FrameNotFound, ModelError

    xml = robot_urdf(0)
    with pytest.raises(FrameNotFound):
        load_vjm(xml.replace('frame="leg2_end"', 'frame="nowhere"'))
    # a wrong offset: the legs no longer meet
    i = xml.index('<vjm:leg name="leg3"')
    j = xml.index("/>", i)
    bad = xml[:i] + '<vjm:leg name="leg3" frame="leg3_end" offset="0 0 0"' + xml[j:]
    with pytest.raises(ModelError, match="leg3"):
        load_vjm(bad)


@pytest.mark.parametrize("free", [False, True])
def test_robot_curve_locates_the_closed_form_critical_point(free):
    """trace_curve on the two-column robot of the previous test, pushed along −x. Platform held
    across x: column A buckles in plane at the closed-form δ_c of the previous test. Platform
    free across x: the platform sways out of plane first, when its z stiffness k_r/(L−δ)² (A,
    shortened by δ) + k_r/L² (B) − P/(L−δ) (A's pendulum term, P = k_a δ) vanishes. Both are
    located to the refinement tolerance and the stiffness falls more than 5×."""
    from scipy.optimize import brentq

    L, kr, ka = 1.0, 100.0, 1e5

    def sway(d):
        return kr / (L - d) ** 2 + kr / L**2 - ka * d / (L - d)

    d_c = brentq(sway if free else _in_plane, 0.0, 0.2)
    c = trace_curve(
        load_vjm(columns_xml(L, kr, ka)),
        [-1, 0, 0],
        3.4e-3 if free else 7e-3,
        7,
        free=free,
        refine_tol=1e-6,
    )
    assert len(c.critical) == 1, c.critical
    cp = c.critical[0]
    assert cp.kind == "bifurcation"
    assert cp.deflection == pytest.approx(d_c, rel=1e-4)
    # straight columns: P = k_a δ (the bending springs of B add less than 0.1 %)
    assert cp.force == pytest.approx(ka * d_c, rel=1e-3)
    assert cp.stiffness_after < cp.stiffness_before / 5


def test_robot_curve_rejects_bad_input():
    from vjm_pin.exceptions import InputError

    vm = load_vjm(columns_xml())
    with pytest.raises(InputError, match="task"):
        trace_curve(vm, [0, 0, 0, 1, 0, 0], 0.01)
    with pytest.raises(InputError, match="max_deflection"):
        trace_curve(vm, [1, 0, 0], -0.01)


def test_leg_wrenches_balance_the_platform_load():
    """The legs split from a loaded mechanism, each solved at the platform pose, carry wrenches
    that sum to the external load (statics of the platform), and their eq. (30) stiffnesses sum
    to the mechanism's (aggregation of §5)."""
    vm = load_vjm(robot_urdf(7))
    ms = MechanismSolver(vm)
    w = np.array([30.0, -20.0, 45.0, 2.0, 1.0, -3.0])
    res = ms.solve(wrench=w)
    from vjm_pin.solver import EquilibriumSolver

    total_w, total_k = np.zeros(6), np.zeros((6, 6))
    for lv in split_legs(vm).values():
        eq = EquilibriumSolver(lv).solve(target=(res.position, res.rotation))
        total_w += eq.wrench
        total_k += loaded_stiffness(lv, eq).stiffness
    np.testing.assert_allclose(total_w, w, rtol=0, atol=1e-8 * np.abs(w).max())
    kc = _k(ms, res)
    assert np.linalg.norm(total_k - kc) < 1e-9 * np.linalg.norm(kc)
