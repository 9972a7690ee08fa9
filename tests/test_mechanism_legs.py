"""Parallel models as mechanisms: the ``<vjm:leg>`` shorthand loads into closures, and with no
cross-links the mechanism's loaded stiffness is the sum of the legs' (paper §5,
``K_C = Σ K_C⁽ⁱ⁾``), each leg solved alone as a serial chain at the same platform location."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.exceptions import FrameNotFound, ModelError
from vjm_pin.model.format import load_vjm
from vjm_pin.model.legs import split_legs
from vjm_pin.solver import EquilibriumSolver, loaded_stiffness
from vjm_pin.solver.mechanism import MechanismSolver

from .parallel_models import columns_xml, robot_urdf

ROOT = Path(__file__).resolve().parent.parent
U3 = np.ones(3) / np.sqrt(3)


def _scaled_rel(a, b, length):
    """Relative difference of two (6, 6) stiffness matrices with every block in N/m."""
    s = np.diag([1, 1, 1, 1 / length, 1 / length, 1 / length])
    return np.linalg.norm(s @ (a - b) @ s) / np.linalg.norm(s @ b @ s)


def _legs_at(vm, res):
    """Each leg (split_legs) solved alone at the platform pose of the mechanism equilibrium
    ``res``, started from the mechanism's configuration of its joints: (Σ wrench, Σ K_C, legs'
    largest configuration difference from the mechanism's)."""
    total_w, total_k, dx = np.zeros(6), np.zeros((6, 6)), 0.0
    for lv in split_legs(vm).values():
        idx = [vm.joint_index(j) for j in lv.joint_names]
        eq = EquilibriumSolver(lv).solve(target=(res.position, res.rotation), x0=res.x[idx])
        assert eq.converged
        total_w += eq.wrench
        total_k += loaded_stiffness(lv, eq).stiffness
        dx = max(dx, float(np.abs(eq.x - res.x[idx]).max()))
    return total_w, total_k, dx


def _loadings():
    return {
        "unloaded": {},
        "held": {"deflection": [2e-3, -1e-3, 1.5e-3, 2e-3, -1e-3, 3e-3]},
        "wrench": {"wrench": [-40.0, 25.0, 30.0, 3.0, -2.0, 1.0]},
    }


@pytest.mark.parametrize("loading", ["unloaded", "held", "wrench"])
@pytest.mark.parametrize("seed,passive", [(4, 1), (5, 2), (6, 0)])
def test_mechanism_stiffness_is_the_sum_of_the_legs(seed, passive, loading):
    """Three legs (actuator spring, 6-D link spring, 0–2 passive revolutes) on a rigid platform:
    the mechanism's wrench and K_C (eq. 28 bordered with the closure rows) equal the sums over
    the legs solved alone at the same platform pose (rel 1e-9), and the legs find the
    mechanism's configuration."""
    vm = load_vjm(robot_urdf(seed, passive=passive))
    ms = MechanismSolver(vm)
    res = ms.solve(**_loadings()[loading])
    assert res.converged and res.redundant == ()
    k = ms.stiffness(res).stiffness
    w, k_legs, dx = _legs_at(vm, res)
    scale = max(np.linalg.norm(res.wrench), 1e-6 * np.abs(k).max())
    assert np.linalg.norm(w - res.wrench) <= 1e-9 * scale, (w, res.wrench)
    assert _scaled_rel(k, k_legs, 0.5) < 1e-9
    assert dx < 1e-9
    if loading == "unloaded":
        assert np.abs(res.wrench).max() == 0.0
    else:  # the load matters: the loaded K_C is not the unloaded one
        k0 = ms.stiffness(ms.solve()).stiffness
        assert _scaled_rel(k, k0, 0.5) > 1e-6


@pytest.mark.parametrize("name", ["orthoglide-q3", "orthoglide-coupled-q1", "orthoglide-2bar-q0"])
def test_orthoglide_mechanism_equals_the_legs_aggregation(name):
    """The Orthoglide through MechanismSolver (one Newton over every leg) against its legs
    solved alone (split_legs + EquilibriumSolver, K_C = Σ K_C⁽ⁱ⁾: today's parallel assembly):
    unloaded, with the platform displaced (held), and under a force along −u of 1 kN (loaded,
    the platform free in every component)."""
    vm = load_vjm(ROOT / "models" / "urdf" / f"{name}.urdf")
    ms = MechanismSolver(vm)
    cases = (
        {},
        {"deflection": np.concatenate([-1e-3 * U3, [1e-4, -2e-4, 1e-4]])},
        {"wrench": np.concatenate([-1e3 * U3, np.zeros(3)])},
    )
    for kwargs in cases:
        res = ms.solve(**kwargs)
        assert res.converged and res.redundant == ()
        w, k_legs, dx = _legs_at(vm, res)
        k = ms.stiffness(res).stiffness
        assert np.linalg.norm(w - res.wrench) <= 1e-9 * max(np.linalg.norm(res.wrench), 1.0), kwargs
        assert _scaled_rel(k, k_legs, 0.3) < 1e-9, kwargs
        assert dx < 1e-8, kwargs


def test_leg_shorthand_loads_into_frames_and_closures():
    """Each leg gets a frame at its platform point, world-aligned at the reference; the task
    frame is the platform on the first leg; every other leg is held on it in the platform
    components; the leg joints are the path from the root."""
    xml = robot_urdf(2)
    vm = load_vjm(xml)
    assert vm.frame == "platform" and vm.task == tuple(range(6))
    assert [lg.name for lg in vm.legs] == ["leg1", "leg2", "leg3"]
    assert [(c.name, c.frame_a, c.frame_b, c.components) for c in vm.closures] == [
        (f"leg{i}", f"leg{i}__platform", "platform", ("x", "y", "z", "rx", "ry", "rz"))
        for i in (2, 3)
    ]
    data = vm.model.createData()
    pin.framesForwardKinematics(vm.model, data, vm.reference)
    p = data.oMf[vm.frame_id]
    for lg in vm.legs:
        m = data.oMf[vm.model.getFrameId(lg.platform_frame)]
        np.testing.assert_allclose(m.rotation, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(m.translation, [0.6, 0.2, 0.3], atol=1e-12)
        link = data.oMf[vm.model.getFrameId(lg.frame)]
        np.testing.assert_allclose(link.act(lg.offset), m.translation, atol=1e-14)
        assert lg.joints[0] == f"{lg.name}_act" and lg.joints[-1] == f"{lg.name}_pas0"
    np.testing.assert_allclose(p.rotation, np.eye(3), atol=1e-14)
    # a point platform (x y z): the legs meet at a point, closures in x y z
    cv = load_vjm(columns_xml())
    assert cv.frame == "p" and cv.task == (0, 1, 2)
    assert [c.components for c in cv.closures] == [("x", "y", "z")]


def test_bad_leg_models():
    xml = robot_urdf(0)
    with pytest.raises(FrameNotFound):
        load_vjm(xml.replace('frame="leg2_end"', 'frame="nowhere"'))
    i = xml.index('<vjm:leg name="leg3"')
    j = xml.index("/>", i)
    with pytest.raises(ModelError, match="leg3"):  # a wrong offset: the legs no longer meet
        load_vjm(xml[:i] + '<vjm:leg name="leg3" frame="leg3_end" offset="0 0 0"' + xml[j:])
    with pytest.raises(ModelError, match="vjm:task"):
        load_vjm(xml.replace("</robot>", '<vjm:task frame="leg1_end"/></robot>'))
    with pytest.raises(ModelError, match="two legs"):
        load_vjm(xml.replace('<vjm:leg name="leg2"', '<vjm:leg name="leg1"'))
    with pytest.raises(ModelError, match="without <vjm:leg"):
        load_vjm(xml[: xml.index("<vjm:leg")] + "</robot>")
    with pytest.raises(ModelError, match="already has a frame"):
        load_vjm(xml.replace('<vjm:platform name="platform"/>', '<vjm:platform name="leg1_end"/>'))
    # split_legs: no legs; a closure between two legs (a cross-link)
    serial = robot_urdf(0, n_legs=1).replace('<vjm:platform name="platform"/>', "")
    serial = serial[: serial.index("<vjm:leg")] + '<vjm:task frame="leg1_end"/></robot>'
    with pytest.raises(ModelError, match="no <vjm:leg"):
        split_legs(serial)
    cross = xml.replace(
        "</robot>",
        '<vjm:closure name="tie" frame_a="leg1__platform" frame_b="leg2__platform" components="x"/></robot>',
    )
    with pytest.raises(ModelError, match="cross-link"):
        split_legs(cross)


def _planar_legs(components: str) -> str:
    """Two planar legs (revolute springs about z, in the xy plane) meeting at a platform point."""
    lim = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    body, tags = ['<link name="base"/>'], []
    for name, base, a1, a2 in (("A", (0, 0, 0), 0.9, -0.4), ("B", (1.0, 0, 0), 2.2, 0.5)):
        body += [f'<link name="{name}{k}"/>' for k in (1, 2, 3)]
        body.append(
            f'<joint name="{name}_j1" type="revolute"><parent link="base"/><child link="{name}1"/>'
            f'<origin xyz="{base[0]} {base[1]} 0" rpy="0 0 {a1}"/><axis xyz="0 0 1"/>{lim}</joint>'
        )
        body.append(
            f'<joint name="{name}_j2" type="revolute"><parent link="{name}1"/><child link="{name}2"/>'
            f'<origin xyz="0.6 0 0" rpy="0 0 {a2}"/><axis xyz="0 0 1"/>{lim}</joint>'
        )
        body.append(
            f'<joint name="{name}_tip" type="fixed"><parent link="{name}2"/><child link="{name}3"/>'
            f'<origin xyz="0.5 0 0"/></joint>'
        )
        tags += [
            f'<vjm:joint name="{name}_j1" role="actuated" position="0" stiffness="200"/>',
            f'<vjm:joint name="{name}_j2" role="actuated" position="0" stiffness="150"/>',
        ]
    xml = (
        '<robot name="planar" xmlns:vjm="urn:vjm-pin:1">'
        + "".join(body)
        + "".join(tags)
        + "</robot>"
    )
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    pa = data.oMf[model.getFrameId("A3")]
    pb = data.oMf[model.getFrameId("B3")]
    off = pb.rotation.T @ (pa.translation - pb.translation)
    legs = (
        f'<vjm:platform name="platform" components="{components}"/>'
        '<vjm:leg name="A" frame="A3" offset="0 0 0"/>'
        f'<vjm:leg name="B" frame="B3" offset="{float(off[0])!r} {float(off[1])!r} {float(off[2])!r}"/>'
    )
    return xml.replace("</robot>", legs + "</robot>")


def test_redundant_leg_closure_rows_are_reported():
    """A planar mechanism whose platform is declared in all six components: the closure rows
    z, rx, ry are identically zero (redundant); the solver says so, gives them zero
    (minimum-norm) multipliers, and finds the equilibrium of the in-plane declaration."""
    w = [60.0, -40.0, 0.0, 0.0, 0.0, 10.0]
    six = MechanismSolver(load_vjm(_planar_legs("x y z rx ry rz")))
    three = MechanismSolver(load_vjm(_planar_legs("x y rz")))
    r6 = six.solve(wrench=w)
    r3 = three.solve(wrench=w)
    assert r6.converged and r3.converged
    assert r6.redundant == ("B.z", "B.rx", "B.ry") and r3.redundant == ()
    assert r6.multipliers_note and "3 redundant" in r6.multipliers_note
    labels = list(r6.closure_labels)
    for c in ("z", "rx", "ry"):
        assert r6.closure_multipliers[labels.index(f"B.{c}")] == 0.0
    for c in ("x", "y", "rz"):
        assert r6.closure_multipliers[labels.index(f"B.{c}")] == pytest.approx(
            r3.closure_multipliers[list(r3.closure_labels).index(f"B.{c}")], rel=1e-9
        )
    np.testing.assert_allclose(r6.x, r3.x, atol=1e-12)
    assert np.abs(r6.deflection).max() > 1e-3 and np.abs(r6.closure_multipliers).max() > 1.0
