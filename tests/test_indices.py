"""Weakest translational stiffness (vjm_pin.analysis.indices): against a closed form, against finite
differences of re-solved equilibria (force-driven with the end free, deflection-driven with the
rotations held), at a singular pose and at a mechanism."""

import json

import numpy as np
import pytest

from vjm_pin import EquilibriumSolver, generate_vjm, load_vjm, loaded_stiffness, unloaded_stiffness
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError
from vjm_pin.analysis.indices import lost_directions, name_direction, weakest_translation
from vjm_pin.kinematics.chain import Kinematics, displace
from vjm_pin.model.format import COMPONENTS
from vjm_pin.model.registry import resolve_model

UR5_ZERO = {
    n: 0.0
    for n in (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
}


def planar_urdf(lengths, last_passive_axis=None) -> str:
    """A chain of revolute joints about z, links along x of the given lengths, end frame 'tool'.
    ``last_passive_axis``: add a joint 'jp' of that type ("prismatic x" or "revolute z") at the tool."""
    parts = ['<robot name="planar">', '<link name="base"/>']
    parent, x = "base", 0.0
    for i, length in enumerate(lengths):
        parts.append(f'<link name="l{i + 1}"/>')
        parts.append(
            f'<joint name="j{i + 1}" type="revolute"><parent link="{parent}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{x!r} 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        parent, x = f"l{i + 1}", float(length)
    if last_passive_axis is not None:
        jt, ax = last_passive_axis.split()
        axis = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}[ax]
        parts.append('<link name="lp"/>')
        parts.append(
            f'<joint name="jp" type="{jt}"><parent link="{parent}"/><child link="lp"/><origin xyz="{x!r} 0 0"/>'
            f'<axis xyz="{axis}"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        parent, x = "lp", 0.0
    parts.append('<link name="tool"/>')
    parts.append(
        f'<joint name="tj" type="fixed"><parent link="{parent}"/><child link="tool"/><origin xyz="{x!r} 0 0"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)


def planar_model(lengths, k, q, task, passive=None):
    spec = {
        "frame": "tool",
        "task": task,
        "actuators": {f"j{i + 1}": float(ki) for i, ki in enumerate(k)},
        "positions": {f"j{i + 1}": float(qi) for i, qi in enumerate(q)},
        "passive": ["jp"] if passive else [],
    }
    return load_vjm(generate_vjm(planar_urdf(lengths, passive), spec))


def planar_jacobian(lengths, q) -> np.ndarray:
    """(3, n) closed-form Jacobian of (x, y, rz) of a planar chain of revolute joints."""
    phi = np.cumsum(q)
    lengths = np.asarray(lengths, float)
    j = np.zeros((3, len(q)))
    for c in range(len(q)):
        j[0, c] = -np.sum(lengths[c:] * np.sin(phi[c:]))
        j[1, c] = np.sum(lengths[c:] * np.cos(phi[c:]))
        j[2, c] = 1.0
    return j


LENGTHS, K3, Q3 = (0.5, 0.4, 0.3), (2.0e4, 5.0e3, 1.0e3), (0.3, 0.9, -0.7)


def test_closed_form_planar_3r():
    """Unloaded 3R arm: C = J K⁻¹ Jᵀ on (x, y, rz); the end free to rotate, k = 1/λ_max(C_xy)."""
    vm = planar_model(LENGTHS, K3, Q3, ["x", "y", "rz"])
    j = planar_jacobian(LENGTHS, Q3)
    c = j @ np.diag(1.0 / np.array(K3)) @ j.T
    ev, vec = np.linalg.eigh(c[:2, :2])
    w = weakest_translation(unloaded_stiffness(vm).task_stiffness, vm.task)
    assert w.kind == "compliance" and w.components == ("x", "y")
    assert w.stiffness == pytest.approx(1.0 / ev[-1], rel=1e-9)
    assert abs(abs(w.direction[:2] @ vec[:, -1]) - 1.0) < 1e-9 and w.direction[2] == 0.0
    held = np.linalg.inv(c)[:2, :2]  # K_C's translational block: rz held
    assert w.stiffness_rotations_held == pytest.approx(np.linalg.eigvalsh(held)[0], rel=1e-9)
    assert w.stiffness < w.stiffness_rotations_held
    # without rz in the task the end is free to rotate anyway: the same number
    vm2 = planar_model(LENGTHS, K3, Q3, ["x", "y"])
    w2 = weakest_translation(unloaded_stiffness(vm2).task_stiffness, vm2.task)
    assert w2.stiffness == pytest.approx(w.stiffness, rel=1e-9)


def fd_free_stiffness(vm, w0, u, h):
    """1 / (uᵀ δp / δf): a dead force ±h u added to the end wrench w0 (the end free), re-solved."""
    dw = np.concatenate([u * h, np.zeros(3)])
    s = EquilibriumSolver(vm, tol=1e-12)
    pp = s.solve_wrench(w0 + dw).position
    pm = s.solve_wrench(w0 - dw).position
    return 2 * h / (u @ (pp - pm))


def fd_held_translational(vm, eq, h):
    """(3, 3) δF/δp of re-solved deflection-driven equilibria around ``eq``, the rotations held."""
    s = EquilibriumSolver(vm, tol=1e-13)
    k = np.zeros((3, 3))
    for j in range(3):
        dt = np.zeros(6)
        dt[j] = h
        fp = s.solve(target=displace(eq.position, eq.rotation, dt), x0=eq.x).wrench
        fm = s.solve(target=displace(eq.position, eq.rotation, -dt), x0=eq.x).wrench
        k[:, j] = (fp[:3] - fm[:3]) / (2 * h)
    return k


@pytest.fixture(scope="module")
def ur5():
    return resolve_model("ur5")


@pytest.mark.parametrize(
    "w0",
    [np.zeros(6), np.array([30.0, -20.0, -100.0, 4.0, -6.0, 3.0])],
    ids=["unloaded", "force+moment"],
)
def test_ur5_free_and_held_by_finite_differences(ur5, w0):
    """The reported direction and number are what a force along it meets with the end free
    (re-solved force-driven equilibria); no sampled direction is weaker; the rotations-held
    number is the smallest eigenvalue of re-solved deflection-driven δF/δp. With a moment K_C
    is not symmetric: the definition uses the symmetric part of C_tt."""
    eq = EquilibriumSolver(ur5, tol=1e-12).solve_wrench(w0)
    k6 = loaded_stiffness(ur5, eq).stiffness
    if np.any(w0[3:]):
        assert (
            np.abs(k6 - k6.T).max() > 0.1 * np.abs(w0[3:]).max()
        )  # really non-symmetric (N·m/rad)
    w = weakest_translation(k6, (0, 1, 2, 3, 4, 5))
    assert w.kind == "compliance"
    h = 5.0  # N: the displacement is ~40 µm, far above the solver tolerance, nonlinearity O(h²)
    k_fd = fd_free_stiffness(ur5, w0, w.direction, h)
    assert k_fd == pytest.approx(w.stiffness, rel=1e-5)
    rng = np.random.default_rng(3)
    for _ in range(4):
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        assert fd_free_stiffness(ur5, w0, u, h) >= w.stiffness * (1 - 1e-5)
    kh = fd_held_translational(ur5, eq, 1e-5)
    held_fd = np.linalg.eigvalsh(0.5 * (kh + kh.T))[0]
    assert held_fd == pytest.approx(w.stiffness_rotations_held, rel=1e-5)
    # freeing the rotations softens the ur5 a lot (Schur complement): 124 vs 247 N/mm unloaded
    assert k_fd < 0.75 * held_fd


def test_negative_directional_stiffness_by_inverted_finite_differences():
    """paper-a-s (pinned chain) compressed by a prescribed deflection: the lateral stiffness is
    negative. K_C from central differences of re-solved equilibria, inverted numerically, gives
    the same negative number and direction."""
    vm = resolve_model("paper-a-s")
    s = EquilibriumSolver(vm, tol=1e-13)
    eq = s.solve([-1e-3, 0, 0])
    m = len(vm.task)
    h = 1e-6
    k_fd = np.zeros((m, m))
    for jj, c in enumerate(vm.task):
        dt = np.zeros(6)
        dt[c] = h
        fp = s.solve(target=displace(eq.position, eq.rotation, dt), x0=eq.x).wrench
        fm = s.solve(target=displace(eq.position, eq.rotation, -dt), x0=eq.x).wrench
        k_fd[:, jj] = ((fp - fm) / (2 * h))[list(vm.task)]
    w = weakest_translation(loaded_stiffness(vm, eq).task_stiffness, vm.task)
    c = np.linalg.inv(k_fd)
    ev, vec = np.linalg.eigh(0.5 * (c + c.T))
    assert ev[0] < 0 and w.kind == "negative" and w.stiffness < 0
    assert w.stiffness == pytest.approx(1.0 / ev[0], rel=1e-4)
    assert abs(abs(vec[:, 0] @ w.direction[list(vm.task)]) - 1) < 1e-6


def test_singular_pose_names_the_lost_direction(ur5, capsys):
    """The stretched ur5 (all joints 0): the task drops one component; lost_directions names
    it (a left-null vector of the end Jacobian there, not at a nearby pose) and the CLI warns."""
    vm = resolve_model("ur5", q=UR5_ZERO)
    dropped = [c for c in COMPONENTS if c not in vm.task_names]
    assert dropped  # the default task left something out at this pose
    lost = lost_directions(vm)
    assert len(lost) == len(dropped)
    free = np.concatenate([vm.theta_idx, vm.q_idx])
    jac = Kinematics(vm.model, vm.frame_id).evaluate(vm.reference, hessian=False).jacobian[:, free]
    smax = np.linalg.norm(jac, 2)
    for v in lost:
        assert np.linalg.norm(v @ jac) <= 1e-9 * smax
    assert sorted(name_direction(v, COMPONENTS) for v in lost) == sorted(dropped)
    assert lost_directions(ur5) == ()  # the default (nudged) pose is regular
    args = ["analyze", "ur5", "--q"] + [f"{k}=0" for k in UR5_ZERO]
    assert main(args + ["--json"]) == 0
    wk = json.loads(capsys.readouterr().out)["weakest"]
    assert wk["lost_directions"] == sorted(dropped) and wk["stiffness_along"] > 0
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "warning: singular pose" in text and f"along {dropped[0]}" in text


def test_translational_mechanism_gives_zero_along_the_passive_motion():
    """A passive prismatic joint at the end, unloaded: K_C is singular, the end slides along the
    joint axis without force: weakest 0 along the axis, the free direction named. (Under a load
    the same motion meets the geometric stiffness of the load, ~|F|/L, of either sign.)"""
    vm = planar_model(LENGTHS[:2], K3[:2], Q3[:2], ["x", "y"], passive="prismatic x")
    w = weakest_translation(unloaded_stiffness(vm).task_stiffness, vm.task)
    jq = (
        Kinematics(vm.model, vm.frame_id)
        .evaluate(vm.reference, hessian=False)
        .jacobian[:3, vm.q_idx[0]]
    )
    assert w.kind == "free" and w.stiffness == 0.0 and len(w.free) == 1
    assert abs(abs(w.direction @ jq) / np.linalg.norm(jq) - 1) < 1e-8


def test_rotational_mechanism_does_not_change_the_translational_index():
    """A passive revolute joint at the end point: K_C singular in rz only; the end is free to
    rotate anyway, so the index equals that of the same arm without the joint and rz."""
    vm = planar_model(LENGTHS, K3, Q3, ["x", "y", "rz"], passive="revolute z")
    w = weakest_translation(unloaded_stiffness(vm).task_stiffness, vm.task)
    assert w.kind == "compliance" and w.free == ("rz",)
    ref = planar_model(LENGTHS, K3, Q3, ["x", "y"])
    w_ref = weakest_translation(unloaded_stiffness(ref).task_stiffness, ref.task)
    assert w.stiffness == pytest.approx(w_ref.stiffness, rel=1e-8)


def test_bad_input_is_refused():
    with pytest.raises(InputError, match="no translational"):
        weakest_translation(np.eye(2), (3, 5))
    with pytest.raises(InputError, match="NaN"):
        weakest_translation(np.full((2, 2), np.nan), (0, 1))
    with pytest.raises(InputError, match=r"\(3, 3\)"):
        weakest_translation(np.eye(2), (0, 1, 2))
