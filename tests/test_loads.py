"""Gravity and payload (eq. 5' and 28' of vjm_pin.loads) against finite differences and a closed form."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import brentq

from vjm_pin import EquilibriumSolver, load_vjm, loaded_stiffness
from vjm_pin.cli import main
from vjm_pin.loads import (
    STANDARD_GRAVITY,
    LinkLoads,
    LoadError,
    generalized_load,
    load_hessian,
    payload_wrench,
    potential_energy,
    solve_loaded,
    static_residual,
)
from vjm_pin.model.paper_models import paper_model_urdf
from vjm_pin.model.robots import build_robot

UR5_POSE = {
    "shoulder_pan_joint": 0.2,
    "shoulder_lift_joint": -1.1,
    "elbow_joint": 1.4,
    "wrist_1_joint": -0.9,
    "wrist_2_joint": 1.2,
    "wrist_3_joint": 0.3,
}
FOREARM = {
    "links": {
        "forearm_link": {
            "beam": {
                "section": "tube",
                "outer_diameter": 0.06,
                "wall": 0.003,
                "E": 7e10,
                "nu": 0.33,
            }
        },
        "upper_arm_link": {
            "beam": {
                "section": "tube",
                "outer_diameter": 0.07,
                "wall": 0.003,
                "E": 7e10,
                "nu": 0.33,
            }
        },
    }
}


def rel(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


@pytest.fixture(scope="module")
def ur5_flex():
    return build_robot("ur5", q=UR5_POSE, springs=FOREARM).vm


def test_generalized_load_is_minus_gradient_of_potential(ur5_flex):
    vm, loads = ur5_flex, LinkLoads.earth()
    rng = np.random.default_rng(0)
    x = vm.reference + rng.standard_normal(vm.model.nq) * 1e-3
    g = generalized_load(vm, loads, x)
    h = 1e-6
    fd = np.array(
        [
            -(potential_energy(vm, loads, x + h * e) - potential_energy(vm, loads, x - h * e))
            / (2 * h)
            for e in np.eye(vm.model.nq)
        ]
    )
    assert rel(g, fd) < 1e-7
    assert np.abs(g).max() > 1.0  # real weights, not a zero vector


def test_load_hessian_matches_finite_differences(ur5_flex):
    vm, loads = ur5_flex, LinkLoads.earth()
    x = vm.reference.copy()
    hg = load_hessian(vm, loads, x)
    h = 1e-6
    fd = np.column_stack(
        [
            (generalized_load(vm, loads, x + h * e) - generalized_load(vm, loads, x - h * e))
            / (2 * h)
            for e in np.eye(vm.model.nq)
        ]
    )
    assert rel(hg, fd) < 1e-6
    assert np.allclose(hg, hg.T, atol=1e-9 * np.abs(hg).max())  # gravity has a potential


def test_without_link_loads_equals_core_wrench_solve():
    vm = build_robot("ur5", q=UR5_POSE).vm
    f = np.array([20.0, -10.0, -150.0, 1.0, 2.0, -1.0])
    a = solve_loaded(vm, f)
    b = EquilibriumSolver(vm, tol=1e-12).solve_wrench(f)
    assert np.allclose(a.x, b.x, atol=1e-10)
    assert rel(a.stiffness.stiffness, loaded_stiffness(vm, b).stiffness) < 1e-8
    assert a.stable and b.stable


def test_gravity_equilibrium_and_loaded_stiffness_by_finite_differences(ur5_flex):
    """K_C of eq. (28') with H + H^G against δt of re-solved gravity-loaded equilibria."""
    vm, loads = ur5_flex, LinkLoads.earth()
    f = np.array([0.0, 30.0, -100.0, 0.0, 0.0, 0.0])
    eq = solve_loaded(vm, f, loads, tol=1e-12)
    assert np.abs(static_residual(vm, loads, eq.x, f)).max() < 1e-6
    assert eq.stable
    comp = np.linalg.inv(eq.stiffness.stiffness)
    h = 1.0  # N or N·m: the response is smooth, central differences
    fd = np.zeros((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        p = solve_loaded(vm, f + e, loads, tol=1e-12)
        m = solve_loaded(vm, f - e, loads, tol=1e-12)
        fd[:3, k] = (p.position - m.position) / (2 * h)
        fd[3:, k] = pin.log3(p.rotation @ m.rotation.T) / (2 * h)
    assert rel(comp, fd) < 1e-5, rel(comp, fd)
    # gravity changes both the deflection and the loaded stiffness: the H^G term is not a no-op
    no_g = solve_loaded(vm, f, tol=1e-12)
    assert np.linalg.norm(eq.deflection[:3] - no_g.deflection[:3]) > 1e-5
    assert rel(eq.stiffness.stiffness, no_g.stiffness.stiffness) > 1e-6


def test_pendulum_with_torsion_spring_closed_form(tmp_path):
    """A revolute joint about y, mass m at distance l along x, spring k: k θ = m g l cos θ.
    (A stiff roll joint about x comes first: gravity has no moment about x, so it stays at 0;
    it also keeps the chain at two joints.)"""
    m, l, k = 3.0, 0.5, 40.0
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
    vm = build_robot(p, springs={"actuators": {"j": k, "r": 1e4}}).vm
    eq = solve_loaded(vm, None, LinkLoads.earth(), tol=1e-13)
    theta = brentq(lambda t: k * t - m * STANDARD_GRAVITY * l * np.cos(t), -1.5, 1.5)
    th = dict(zip(vm.theta_names, eq.theta))
    assert th["j"] == pytest.approx(theta, rel=1e-9)
    assert abs(th["r"]) < 1e-12


def test_payload_is_an_end_force():
    assert np.allclose(payload_wrench(2.0), [0, 0, -2.0 * STANDARD_GRAVITY, 0, 0, 0])
    with pytest.raises(LoadError):
        payload_wrench(-1.0)
    vm = build_robot("ur5", q=UR5_POSE).vm
    a = solve_loaded(vm, payload_wrench(5.0))
    b = solve_loaded(vm, [0, 0, -5.0 * STANDARD_GRAVITY, 0, 0, 0])
    assert np.array_equal(a.x, b.x)


def test_passive_joints_and_bad_gravity_are_rejected():
    vm = load_vjm(paper_model_urdf("a", "s"))
    with pytest.raises(LoadError, match="passive"):
        solve_loaded(vm, None, LinkLoads.earth())
    with pytest.raises(Exception, match="gravity"):
        LinkLoads([0, 0, float("nan")])


def test_cli_gravity_payload(capsys):
    args = ["analyze", "ur5", "--payload", "3", "--gravity", "--json", "--q"] + [
        f"{a}={b}" for a, b in UR5_POSE.items()
    ]
    assert main(args) == 0
    import json

    out = json.loads(capsys.readouterr().out)
    vm = build_robot("ur5", q=UR5_POSE).vm
    eq = solve_loaded(vm, payload_wrench(3.0), LinkLoads.earth())
    assert np.allclose(out["deflection"], eq.deflection, atol=1e-12)
    assert out["gravity"] is True and out["stable"] is True
    assert main(["analyze", "ur5", "--payload", "-1"]) == 2
    assert main(["analyze", "paper-a-s", "--gravity"]) == 2
