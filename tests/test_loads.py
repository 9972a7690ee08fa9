"""Gravity, payload and dead loads through the one mechanism solver (MechanismSolver with
``loads=`` and ``gravity=``), against finite differences, re-solved equilibria, independent
statics and closed forms. (Formerly the separate ``vjm_pin.loads.solve_loaded`` path; the
values it was checked against are recomputed here from their definitions.)"""

import json

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import brentq

from vjm_pin import EquilibriumSolver, loaded_stiffness
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError
from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY, DeadLoads, Load
from vjm_pin.model.robots import build_robot
from vjm_pin.solver import MechanismSolver

EARTH = (0.0, 0.0, -STANDARD_GRAVITY)
UR5_POSE = {
    "shoulder_pan_joint": 0.2,
    "shoulder_lift_joint": -1.1,
    "elbow_joint": 1.4,
    "wrist_1_joint": -0.9,
    "wrist_2_joint": 1.2,
    "wrist_3_joint": 0.3,
}
TUBE = {"section": "tube", "wall": 0.003, "E": 7e10, "nu": 0.33}
FOREARM = {
    "links": {
        "forearm_link": {"beam": {**TUBE, "outer_diameter": 0.06}},
        "upper_arm_link": {"beam": {**TUBE, "outer_diameter": 0.07}},
    }
}


def rel(a, b):
    return np.linalg.norm(np.asarray(a) - b) / max(np.linalg.norm(b), 1e-300)


@pytest.fixture(scope="module")
def ur5_flex():
    return build_robot("ur5", q=UR5_POSE, springs=FOREARM).vm


def gravity_force(vm, x):
    """``G(x) = −g(x)`` (n,) of Pinocchio's generalised gravity on a copy of the model carrying
    standard gravity: independent of :class:`DeadLoads`."""
    m = vm.model.copy()
    m.gravity.linear = np.array(EARTH)
    return -np.asarray(pin.computeGeneralizedGravity(m, m.createData(), np.asarray(x, float)))


def statics_residual(vm, res, end_load=np.zeros(6)):
    """Eq. (5) with link weights, over the spring and passive coordinates, from Pinocchio alone:
    ``K(θ−θ₀) − Jᵀw − G`` on springs, ``−Jᵀw − G`` on passive joints (w: the reported task wrench
    plus ``end_load``, a dead load at the end frame)."""
    x = np.asarray(res.x, float)
    d = vm.model.createData()
    j = pin.computeFrameJacobian(vm.model, d, x, vm.frame_id, pin.LOCAL_WORLD_ALIGNED)
    gen = j.T @ (res.wrench + end_load) + gravity_force(vm, x)
    r = -gen
    r[vm.theta_idx] += vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    return r[np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)]


def test_link_weights_are_minus_the_gradient_of_their_potential(ur5_flex):
    vm = ur5_flex
    dl = DeadLoads(vm, (), EARTH)
    rng = np.random.default_rng(0)
    x = vm.reference + rng.standard_normal(vm.model.nq) * 1e-3
    st = dl.evaluate(x)
    h = 1e-6
    fd = np.array(
        [-(dl.evaluate(x + h * e).potential - dl.evaluate(x - h * e).potential) / (2 * h) for e in np.eye(vm.model.nq)]
    )
    assert rel(st.force, fd) < 1e-7
    assert rel(st.force, gravity_force(vm, x)) < 1e-12
    assert np.abs(st.force).max() > 1.0  # real weights, not a zero vector


def test_link_weight_derivative_matches_finite_differences(ur5_flex):
    vm = ur5_flex
    dl = DeadLoads(vm, (), EARTH)
    x = vm.reference.copy()
    hg = dl.evaluate(x).derivative
    h = 1e-6
    fd = np.column_stack(
        [(dl.evaluate(x + h * e).force - dl.evaluate(x - h * e).force) / (2 * h) for e in np.eye(vm.model.nq)]
    )
    assert rel(hg, fd) < 1e-6
    assert np.allclose(hg, hg.T, atol=1e-9 * np.abs(hg).max())  # gravity has a potential


def test_without_dead_loads_the_mechanism_solver_is_the_serial_wrench_solve():
    vm = build_robot("ur5", q=UR5_POSE).vm
    f = np.array([20.0, -10.0, -150.0, 1.0, 2.0, -1.0])
    ms = MechanismSolver(vm, tol=1e-12)
    a = ms.solve(wrench=f)
    b = EquilibriumSolver(vm, tol=1e-12).solve_wrench(f)
    assert np.abs(a.x - b.x).max() < 1e-10
    assert rel(ms.stiffness(a).stiffness, loaded_stiffness(vm, b).stiffness) < 1e-8
    assert a.stable and b.stable


def test_gravity_equilibrium_and_loaded_stiffness_by_finite_differences(ur5_flex):
    """K_C with the weights' Hessian against δt of re-solved gravity-loaded equilibria."""
    vm = ur5_flex
    ms = MechanismSolver(vm, (), EARTH, tol=1e-12)
    f = np.array([0.0, 30.0, -100.0, 0.0, 0.0, 0.0])
    eq = ms.solve(wrench=f)
    tau = np.abs(vm.K_theta @ (eq.theta - vm.theta0)).max()
    assert np.abs(statics_residual(vm, eq)).max() < 1e-9 * tau
    assert eq.stable and eq.stable_end_held
    comp = np.linalg.inv(ms.stiffness(eq).stiffness)
    h = 1.0  # N or N·m: the response is smooth, central differences
    fd = np.zeros((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        p = ms.solve(wrench=f + e, x0=eq.x)
        m = ms.solve(wrench=f - e, x0=eq.x)
        fd[:3, k] = (p.position - m.position) / (2 * h)
        fd[3:, k] = pin.log3(p.rotation @ m.rotation.T) / (2 * h)
    assert rel(comp, fd) < 1e-5, rel(comp, fd)
    # gravity changes both the deflection and the loaded stiffness: the weights are not a no-op
    bare = MechanismSolver(vm, tol=1e-12)
    no_g = bare.solve(wrench=f)
    assert np.linalg.norm(eq.deflection[:3] - no_g.deflection[:3]) > 1e-5
    assert rel(ms.stiffness(eq).stiffness, bare.stiffness(no_g).stiffness) > 1e-6


def _pendulum(tmp_path, m, l, passive=False):
    """A revolute joint ``j`` about y, mass m at distance l along x, tip at 2l (end frame). A stiff
    roll joint ``r`` about x comes first: gravity has no moment about x, so it stays at 0."""
    urdf = f"""<robot name="pend">
  <link name="base"/>
  <link name="arm"><inertial><origin xyz="{l} 0 0"/><mass value="{m}"/>
    <inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tip"/>
  <link name="roll"/>
  <joint name="r" type="revolute"><parent link="base"/><child link="roll"/><axis xyz="1 0 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j" type="revolute"><parent link="roll"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="{2 * l} 0 0"/></joint>
</robot>"""
    p = tmp_path / "pend.urdf"
    p.write_text(urdf)
    return p


def test_pendulum_with_torsion_spring_closed_form(tmp_path):
    """Spring k on j, end free: k θ = m g l cos θ (θ about +y tips the arm down)."""
    m, l, k = 3.0, 0.5, 40.0
    vm = build_robot(_pendulum(tmp_path, m, l), springs={"actuators": {"j": k, "r": 1e4}}).vm
    eq = MechanismSolver(vm, (), EARTH, tol=1e-13).solve(wrench=np.zeros(6))
    theta = brentq(lambda t: k * t - m * STANDARD_GRAVITY * l * np.cos(t), -1.5, 1.5)
    th = dict(zip(vm.theta_names, eq.theta))
    assert th["j"] == pytest.approx(theta, rel=1e-9)
    assert abs(th["r"]) < 1e-12
    # the same weight as a dead load at the centre of mass instead of gravity: the same answer
    com = tmp_path / "pend_com.urdf"
    com.write_text(
        _pendulum(tmp_path, m, l).read_text().replace(
            '<link name="tip"/>', '<link name="tip"/><link name="com"/>'
        ).replace(
            "</robot>",
            f'<joint name="c" type="fixed"><parent link="arm"/><child link="com"/><origin xyz="{l} 0 0"/></joint></robot>',
        )
    )
    vm2 = build_robot(com, springs={"actuators": {"j": k, "r": 1e4}}).vm
    eq2 = MechanismSolver(vm2, [Load.weight("com", m)], tol=1e-13).solve(wrench=np.zeros(6))
    assert dict(zip(vm2.theta_names, eq2.theta))["j"] == pytest.approx(theta, rel=1e-9)


def test_passive_joint_under_gravity_with_the_end_held(tmp_path):
    """Passive joints under link weights need the end held (the old gravity path refused them):
    with j passive and the tip held at its reference, nothing moves and the tip reaction balances
    the arm's weight about j (the rest by the statics of eq. 5)."""
    m, l = 3.0, 0.5
    vm = build_robot(_pendulum(tmp_path, m, l), springs={"actuators": {"r": 1e4}, "passive": ["j"]}).vm
    assert vm.q_names == ["j"]
    res = MechanismSolver(vm, (), EARTH, tol=1e-12).solve(deflection=np.zeros(6))
    assert np.abs(res.x - vm.reference).max() < 1e-12
    assert np.abs(statics_residual(vm, res)).max() < 1e-9 * m * STANDARD_GRAVITY * l
    # about the axis of j (through the origin, +y) the reaction's moment (r × F + M) cancels the
    # weight's, (l, 0, 0) × (0, 0, −m g) = (0, m g l, 0)
    moment_j = np.cross(res.position, res.wrench[:3])[1] + res.wrench[4]
    assert moment_j == pytest.approx(-m * STANDARD_GRAVITY * l, rel=1e-9)
    assert res.stable_end_held


def test_payload_is_a_weight_at_the_end_frame():
    assert np.allclose(Load.weight("tool0", 2.0).wrench, [0, 0, -2.0 * STANDARD_GRAVITY, 0, 0, 0])
    with pytest.raises(InputError, match="mass"):
        Load.weight("tool0", -1.0)
    vm = build_robot("ur5", q=UR5_POSE).vm
    a = MechanismSolver(vm, [Load.weight(vm.frame, 5.0)]).solve(wrench=np.zeros(6))
    b = MechanismSolver(vm).solve(wrench=[0, 0, -5.0 * STANDARD_GRAVITY, 0, 0, 0])
    assert np.abs(a.x - b.x).max() < 1e-12
    assert np.allclose(a.wrench, 0) and np.allclose(b.wrench[:3], [0, 0, -5.0 * STANDARD_GRAVITY])


def test_bad_gravity_is_rejected():
    vm = build_robot("ur5", q=UR5_POSE).vm
    with pytest.raises(InputError, match="gravity"):
        MechanismSolver(vm, (), [0, 0, float("nan")])


def test_cli_gravity_payload_agree_with_the_mechanism_solver(capsys):
    args = ["analyze", "ur5", "--payload", "3", "--gravity", "--json", "--q"] + [f"{a}={b}" for a, b in UR5_POSE.items()]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    vm = build_robot("ur5", q=UR5_POSE).vm
    ms = MechanismSolver(vm, [Load.weight(vm.frame, 3.0)], EARTH)
    eq = ms.solve(wrench=np.zeros(6))
    assert np.allclose(out["deflection"], eq.deflection, atol=1e-12)
    assert np.allclose(out["stiffness"], ms.stiffness(eq).stiffness, rtol=1e-8, atol=1e-6)
    # the payload is the weight of 3 kg at the end frame, listed with the dead loads
    assert out["loads"] == [{"frame": "tool0", "wrench": [0.0, 0.0, -3 * STANDARD_GRAVITY, 0.0, 0.0, 0.0],
                             "source": "payload"}]
    payload = Load.weight(vm.frame, 3.0).wrench
    tau = np.abs(vm.K_theta @ (eq.theta - vm.theta0)).max()
    assert np.abs(statics_residual(vm, eq, payload)).max() < 1e-9 * tau  # weights: G of Pinocchio
    assert out["gravity"] is True and out["stable"] is True and out["payload"] == 3.0
    assert out["path"].startswith("mechanism:")
    assert main(["analyze", "ur5", "--payload", "-1"]) == 2
    assert "--payload" in capsys.readouterr().err


def test_cli_curve_with_gravity_holds_the_weight(capsys):
    """`curve --gravity`: the link weights stay on along the curve; every point is the mechanism
    solver's held equilibrium under them (at s = 0 the end reaction carries the arm's weight)."""
    from vjm_pin.model.registry import resolve_model

    assert main(["curve", "ur5", "--direction", "0", "0", "-1", "--max-deflection", "1e-4", "--steps", "1",
                 "--gravity", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["gravity"] is True and out["loads"] == []
    vm = resolve_model("ur5")
    ms = MechanismSolver(vm, (), EARTH)
    for p in out["points"]:
        res = ms.solve(deflection=[0, 0, -p["deflection"], 0, 0, 0])
        assert np.allclose(p["wrench"], res.wrench, rtol=1e-7, atol=1e-7)
        assert np.abs(statics_residual(vm, res)).max() < 1e-8 * np.abs(res.wrench).max()
    assert np.linalg.norm(out["points"][0]["wrench"][:3]) > 10.0  # the weight (N), not a zero load
