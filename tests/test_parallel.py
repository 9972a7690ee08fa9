"""Parallel assembly (vjm_pin.parallel): aggregation, robot equilibria, stability."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.exceptions import FrameNotFound, ModelError
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.parallel import RobotSolver, load_parallel, trace_robot_curve, transform_stiffness
from vjm_pin.solver import unloaded_stiffness

from .chains import random_spd, robot_fd_stiffness


def _f(v):
    return " ".join(repr(float(x)) for x in v)


def _leg_xml(rng, name, axis, base_xyz, passive_axes=(), k6=None, rpy=(0, 0, 0), k_act=5e5):
    """A leg: prismatic actuator along ``axis`` (spring k_act N/m), a 6-D link spring (SPD k6),
    passive revolutes about ``passive_axes``, an end link ``<name>_end``."""
    k6 = random_spd(rng, 6, 1e4, 1e5) if k6 is None else k6
    j = []
    j.append(f'<link name="{name}_l1"/>')
    j.append(
        f'<joint name="{name}_act" type="prismatic"><parent link="base"/><child link="{name}_l1"/>'
        f'<origin xyz="{_f(base_xyz)}" rpy="{_f(rpy)}"/><axis xyz="{_f(axis)}"/>'
        f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
    )
    prev = f"{name}_l1"
    sj = []
    for i, c in enumerate(("tx", "ty", "tz", "rx", "ry", "rz")):
        ax = np.eye(3)[i % 3]
        kind = "prismatic" if i < 3 else "revolute"
        ln = f"{name}_s{c}"
        j.append(f'<link name="{ln}"/>')
        xyz = (0.2, 0.05, 0.0) if i == 0 else (0, 0, 0)
        j.append(
            f'<joint name="{name}_{c}" type="{kind}"><parent link="{prev}"/><child link="{ln}"/>'
            f'<origin xyz="{_f(xyz)}" rpy="0 0 0"/><axis xyz="{_f(ax)}"/>'
            f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        sj.append(f"{name}_{c}")
        prev = ln
    tags = [f'<vjm:joint name="{name}_act" role="actuated" position="0" stiffness="{k_act!r}"/>']
    tags += [f'<vjm:joint name="{n}" role="spring"/>' for n in sj]
    tags.append(
        f'<vjm:spring name="{name}_link" link="{name}_l1" joints="{" ".join(sj)}">'
        f"<vjm:stiffness>{_f(k6.ravel())}</vjm:stiffness></vjm:spring>"
    )
    for k, pax in enumerate(passive_axes):
        pn = f"{name}_pas{k}"
        j.append(f'<link name="{pn}"/>')
        j.append(
            f'<joint name="{pn}" type="revolute"><parent link="{prev}"/><child link="{pn}"/>'
            f'<origin xyz="0.1 0 0.02" rpy="0.2 0 0"/><axis xyz="{_f(pax)}"/>'
            f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        tags.append(f'<vjm:joint name="{pn}" role="passive" position="0"/>')
        prev = pn
    j.append(f'<link name="{name}_end"/>')
    j.append(
        f'<joint name="{name}_endj" type="fixed"><parent link="{prev}"/><child link="{name}_end"/>'
        f'<origin xyz="0.05 0.1 0" rpy="0 0.3 0"/></joint>'
    )
    return j, tags


def robot_urdf(seed=0, n_legs=3, passive=True, identical=False, platform=(0.6, 0.2, 0.3)):
    """Robot of ``n_legs`` legs; the offsets put every leg's platform point at ``platform``."""
    rng = np.random.default_rng(seed)
    axes = np.eye(3)
    k6 = random_spd(rng, 6, 1e4, 1e5) if identical else None
    body, tags, legs = ['<link name="base"/>'], [], []
    for i in range(n_legs):
        name = f"leg{i + 1}"
        a = axes[0] if identical else axes[i % 3]
        rpy = (0, 0, 0) if identical else tuple(rng.uniform(-0.3, 0.3, 3))
        base = (0, 0, 0) if identical else tuple(rng.uniform(-0.2, 0.2, 3))
        b, t = _leg_xml(
            np.random.default_rng(seed + 100) if identical else rng,
            name,
            a,
            base,
            passive_axes=[axes[(i + k) % 3] for k in range(int(passive))],
            k6=k6,
            rpy=rpy,
        )
        body += b
        tags += t
        legs.append(name)
    xml = (
        '<robot name="synthetic" xmlns:vjm="urn:vjm-pin:1">'
        + "".join(body)
        + "".join(tags)
        + "</robot>"
    )
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    leg_tags = []
    for name in legs:
        m = data.oMf[model.getFrameId(f"{name}_end")]
        off = m.rotation.T @ (np.asarray(platform) - m.translation)
        leg_tags.append(f'<vjm:leg name="{name}" frame="{name}_end" offset="{_f(off)}"/>')
    return xml.replace(
        "</robot>", '<vjm:platform name="platform"/>' + "".join(leg_tags) + "</robot>"
    )


def single_leg_urdf(seed=0):
    """Leg 1 of the identical-legs robot alone, as a parallel model of one leg."""
    return robot_urdf(seed, n_legs=1, passive=False, identical=True)


def test_two_identical_legs_give_twice_the_stiffness():
    one = RobotSolver(load_parallel(single_leg_urdf(3)))
    two = RobotSolver(load_parallel(robot_urdf(3, n_legs=2, passive=False, identical=True)))
    k1, k2 = one.stiffness(), two.stiffness()
    assert np.linalg.matrix_rank(k1) == 6
    np.testing.assert_allclose(k2, 2 * k1, rtol=1e-9, atol=1e-9 * np.abs(k1).max())
    # and loaded, too
    d = np.array([1e-3, -5e-4, 2e-4, 0, 0, 0])
    e1, e2 = one.solve(d), two.solve(d)
    np.testing.assert_allclose(
        e2.wrench, 2 * e1.wrench, rtol=1e-7, atol=1e-7 * np.abs(e1.wrench).max()
    )
    np.testing.assert_allclose(
        two.stiffness(e2), 2 * one.stiffness(e1), rtol=1e-7, atol=1e-7 * np.abs(k1).max()
    )


@pytest.mark.parametrize("n_passive", [1, 2])
def test_rank_deficient_legs_sum_to_full_rank(n_passive):
    """Legs with 1 (2) passive revolutes have rank-5 (rank-4, the Orthoglide's case) stiffness;
    three legs with differently oriented passive axes give a full-rank robot stiffness."""
    rs = RobotSolver(load_parallel(robot_urdf(1, passive=n_passive)))
    eq = rs.solve(np.zeros(6))
    ks = rs.leg_stiffnesses(eq)
    for name, k in ks.items():
        ev = np.linalg.eigvalsh(0.5 * (k + k.T))
        assert np.sum(ev > 1e-8 * ev.max()) == 6 - n_passive, f"leg {name}: eigenvalues {ev}"
    kc = rs.stiffness(eq)
    ev = np.linalg.eigvalsh(0.5 * (kc + kc.T))
    assert ev.min() > 1e-6 * ev.max(), f"robot stiffness should be full rank, eigenvalues {ev}"


def test_offset_is_the_wrench_transformation_unloaded():
    """The leg model with its offset frame equals the unloaded leg stiffness at the end link moved
    by the rigid offset (Tᵀ K T)."""
    pm = load_parallel(robot_urdf(2, passive=False))
    for leg in pm.legs:
        # the same leg with the platform frame at the end link itself
        vm = leg.vm
        k_p = unloaded_stiffness(vm).stiffness
        fid = vm.model.getFrameId(leg.frame)
        vm_end = type(vm)(**{**vm.__dict__, "frame": leg.frame, "frame_id": int(fid)})
        k_e = unloaded_stiffness(vm_end, kin=Kinematics(vm.model, fid)).stiffness
        data = vm.model.createData()
        pin.framesForwardKinematics(vm.model, data, vm.reference)
        r = data.oMf[vm.frame_id].translation - data.oMf[fid].translation
        assert np.linalg.norm(r) > 0.05
        np.testing.assert_allclose(
            transform_stiffness(k_e, r), k_p, rtol=1e-8, atol=1e-8 * np.abs(k_p).max()
        )


def test_wrench_and_displacement_driven_equilibria_agree():
    rs = RobotSolver(load_parallel(robot_urdf(4)))
    d = np.array([2e-3, -1e-3, 1.5e-3, 2e-3, -1e-3, 3e-3])
    eq = rs.solve(d)
    assert eq.converged and eq.stable
    back = rs.solve_wrench(eq.wrench)
    np.testing.assert_allclose(back.deflection, d, rtol=0, atol=1e-8)
    np.testing.assert_allclose(back.wrench, eq.wrench, rtol=0, atol=1e-7 * np.abs(eq.wrench).max())


def test_loaded_stiffness_matches_finite_differences():
    rs = RobotSolver(load_parallel(robot_urdf(5)))
    eq = rs.solve(np.array([3e-3, 2e-3, -2e-3, 5e-3, 0.0, -4e-3]))
    kc = rs.stiffness(eq)
    fd = robot_fd_stiffness(rs, eq, 1e-6)
    err = np.linalg.norm(fd - kc) / np.linalg.norm(kc)
    assert err < 1e-4, f"relative error of K_C vs finite differences: {err:.2e}"


def _column_leg(name, axis, out_axis, base, length, k_bend, k_axial):
    """A two-segment column along ``axis`` in the plane normal to z: bending springs k_r about z at
    the base and at mid-length, an out-of-plane bending spring about ``out_axis`` at the base, an
    axial prismatic spring k_a at the base; the end (tip) is the platform point."""
    a = np.asarray(axis, float)
    lim = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    xml = [f'<link name="{name}_{n}"/>' for n in ("b1", "b2", "ax", "mid", "end")]
    xml += [
        (
            f'<joint name="{name}_r1" type="revolute"><parent link="base"/><child link="{name}_b1"/>'
            f'<origin xyz="{_f(base)}"/><axis xyz="0 0 1"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_r3" type="revolute"><parent link="{name}_b1"/><child link="{name}_b2"/>'
            f'<axis xyz="{_f(out_axis)}"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_s" type="prismatic"><parent link="{name}_b2"/><child link="{name}_ax"/>'
            f'<axis xyz="{_f(a)}"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_r2" type="revolute"><parent link="{name}_ax"/><child link="{name}_mid"/>'
            f'<origin xyz="{_f(length / 2 * a)}"/><axis xyz="0 0 1"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_tip" type="fixed"><parent link="{name}_mid"/><child link="{name}_end"/>'
            f'<origin xyz="{_f(length / 2 * a)}"/></joint>'
        ),
    ]
    tags = [
        f'<vjm:joint name="{name}_{j}" role="actuated" position="0" stiffness="{k!r}"/>'
        for j, k in (("r1", k_bend), ("r2", k_bend), ("r3", k_bend), ("s", k_axial))
    ]
    tags.append(f'<vjm:leg name="{name}" frame="{name}_end" offset="0 0 0"/>')
    return xml, tags


def test_robot_stability_reports_the_buckling_leg():
    """Two orthogonal columns meeting at the platform; pushing the platform by δ along column A
    compresses A (force P = k_a δ). Closed form for A held straight with its tip fixed, segments
    a = L/2 − δ and b = L/2, mode φ₂ = −φ₁(a+b)/b: energy
    ½φ₁²[k_r(1 + ((a+b)/b)²) − P a(a+b)/b], so A is unstable past the δ_c that zeroes it. B stays stable."""
    from scipy.optimize import brentq

    L, kr, ka = 1.0, 100.0, 1e5
    xa, ta = _column_leg("A", (1, 0, 0), (0, 1, 0), (0, 0, 0), L, kr, ka)
    xb, tb = _column_leg("B", (0, 1, 0), (1, 0, 0), (L, -L, 0), L, kr, ka)
    xml = (
        '<robot name="columns" xmlns:vjm="urn:vjm-pin:1"><link name="base"/>'
        + "".join(xa + xb)
        + '<vjm:platform name="p" components="x y z"/>'
        + "".join(ta + tb)
        + "</robot>"
    )

    def margin(d):
        a, b = L / 2 - d, L / 2
        return kr * (1 + ((a + b) / b) ** 2) - ka * d * a * (a + b) / b

    d_c = brentq(margin, 0.0, 0.2)
    rs = RobotSolver(load_parallel(xml), follow_stable=False)
    below = rs.solve([-0.97 * d_c, 0, 0])
    above = rs.solve([-1.03 * d_c, 0, 0])
    assert below.stable and below.unstable_legs == []
    assert not above.stable and above.unstable_legs == ["A"]
    assert above.to_dict()["legs"][1] == {
        "name": "B",
        "wrench": above.legs[1].wrench.tolist(),
        "stable": True,
    }
    np.testing.assert_allclose(
        below.legs[0].wrench[0], -ka * 0.97 * d_c, rtol=1e-8
    )  # axial force k_a δ
    # the stable-branch curve (default solver) runs through buckling: the directional stiffness collapses
    pts = trace_robot_curve(RobotSolver(load_parallel(xml)), [-1, 0, 0], 1.6 * d_c, n_points=9)
    assert all(p.stable for p in pts)
    assert pts[0].stiffness > 5 * pts[-1].stiffness, [p.stiffness for p in pts]


def test_bad_parallel_models():
    xml = robot_urdf(0)
    with pytest.raises(FrameNotFound):
        load_parallel(xml.replace('frame="leg2_end"', 'frame="nowhere"'))
    # a wrong offset: the legs no longer meet
    i = xml.index('<vjm:leg name="leg3"')
    j = xml.index("/>", i)
    bad = xml[:i] + '<vjm:leg name="leg3" frame="leg3_end" offset="0 0 0"' + xml[j:]
    with pytest.raises(ModelError, match="leg3"):
        load_parallel(bad)
    with pytest.raises(ModelError, match="no <vjm:leg"):
        load_parallel(xml.split("<vjm:platform")[0] + "</robot>")


def _columns_xml(L=1.0, kr=100.0, ka=1e5):
    xa, ta = _column_leg("A", (1, 0, 0), (0, 1, 0), (0, 0, 0), L, kr, ka)
    xb, tb = _column_leg("B", (0, 1, 0), (1, 0, 0), (L, -L, 0), L, kr, ka)
    return (
        '<robot name="columns" xmlns:vjm="urn:vjm-pin:1"><link name="base"/>'
        + "".join(xa + xb)
        + '<vjm:platform name="p" components="x y z"/>'
        + "".join(ta + tb)
        + "</robot>"
    )


@pytest.mark.parametrize("free", [False, True])
def test_robot_curve_locates_the_closed_form_critical_point(free):
    """trace_robot_force_curve on the two-column robot of the previous test, pushed along −x.
    Platform held across x: column A buckles in plane at the closed-form δ_c of the previous
    test (a per-leg bifurcation, bisection on the stiffness drop). Platform free across x: the
    platform sways out of plane first, when its z stiffness k_r/(L−δ)² (A, shortened by δ) +
    k_r/L² (B) − P/(L−δ) (A's pendulum term, P = k_a δ) vanishes (regula falsi on BᵀK_C B).
    Both are located to the refinement tolerance and the stiffness falls more than 5×."""
    from scipy.optimize import brentq

    from vjm_pin.parallel import trace_robot_force_curve

    L, kr, ka = 1.0, 100.0, 1e5

    def in_plane(d):
        a, b = L / 2 - d, L / 2
        return kr * (1 + ((a + b) / b) ** 2) - ka * d * a * (a + b) / b

    def sway(d):
        return kr / (L - d) ** 2 + kr / L**2 - ka * d / (L - d)

    d_c = brentq(sway if free else in_plane, 0.0, 0.2)
    rs = RobotSolver(load_parallel(_columns_xml(L, kr, ka)))
    c = trace_robot_force_curve(
        rs, [-1, 0, 0], 3.4e-3 if free else 7e-3, 7, free=free, refine_tol=1e-6
    )
    assert len(c.critical) == 1, c.critical
    cp = c.critical[0]
    assert cp.kind == ("platform" if free else "drop")
    assert cp.deflection == pytest.approx(d_c, rel=1e-4)
    # straight columns: P = k_a δ (the bending springs of B add less than 0.1 %)
    assert cp.force == pytest.approx(ka * d_c, rel=1e-3)
    assert cp.stiffness_after < cp.stiffness_before / 5
    assert c.free is free


def test_robot_curve_rejects_bad_input():
    from vjm_pin.exceptions import InputError
    from vjm_pin.parallel import trace_robot_force_curve

    rs = RobotSolver(load_parallel(_columns_xml()))
    with pytest.raises(InputError, match="translation"):
        trace_robot_force_curve(rs, [0, 0, 0, 1, 0, 0], 0.01)
    with pytest.raises(InputError, match="max_deflection"):
        trace_robot_force_curve(rs, [1, 0, 0], -0.01)
