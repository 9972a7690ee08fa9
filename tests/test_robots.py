"""Real robots by name or file: defaults, Salisbury's closed form, finite differences, errors."""

import json

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin import EquilibriumSolver, loaded_stiffness, unloaded_stiffness
from vjm_pin.cli import main
from vjm_pin.exceptions import FrameNotFound, InputError, JointNotFound, ModelError, SpecError
from vjm_pin.kinematics.chain import displace
from vjm_pin.model.registry import resolve, resolve_model
from vjm_pin.model.robots import (
    DEFAULT_REVOLUTE_STIFFNESS,
    AmbiguousFrame,
    UnknownRobot,
    beam_length,
    build_robot,
    default_frame,
    frame_candidates,
    robot_names,
    robot_source,
    urdf_tree,
)

from .chains import random_chain_urdf

UR5_POSE = {
    "shoulder_pan_joint": 0.2,
    "shoulder_lift_joint": -1.1,
    "elbow_joint": 1.4,
    "wrist_1_joint": -0.9,
    "wrist_2_joint": 1.2,
    "wrist_3_joint": 0.3,
}


def rel(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


def rigid_jacobian(urdf_path, frame, pose):
    """Jacobian of ``frame`` straight from Pinocchio on the rigid URDF (independent of vjm_pin)."""
    model = pin.buildModelFromUrdf(str(urdf_path))
    data = model.createData()
    x = pin.neutral(model)
    for name, v in pose.items():
        x[model.joints[model.getJointId(name)].idx_q] = v
    pin.computeJointJacobians(model, data, x)
    pin.updateFramePlacements(model, data)
    return pin.getFrameJacobian(model, data, model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED)


# --------------------------------------------------------------------------- Salisbury
def test_ur5_actuator_springs_unloaded_equals_salisbury():
    """K_C = J⁻ᵀ K_θ J⁻¹ (Salisbury 1980) for a 6-joint arm with actuator springs only."""
    rm = build_robot("ur5", q=UR5_POSE)
    vm = rm.vm
    assert vm.n_q == 0 and vm.n_theta == 6 and vm.frame == "tool0"
    jac = rigid_jacobian(rm.source.urdf, "tool0", UR5_POSE)
    ji = np.linalg.inv(jac)
    k_sal = ji.T @ (DEFAULT_REVOLUTE_STIFFNESS * np.eye(6)) @ ji
    for method in ("eq30", "eq32", "eq33"):
        k = unloaded_stiffness(vm, method).stiffness
        assert rel(k, k_sal) < 1e-9, (method, rel(k, k_sal))


def test_panda_redundant_unloaded_equals_compliance_form():
    """7 joints: K_C = (J K_θ⁻¹ Jᵀ)⁻¹ with per-joint stiffnesses from a spec."""
    ks = [3e5, 2e5, 1.5e5, 1e5, 5e4, 4e4, 3e4]
    names = [f"panda_joint{i}" for i in range(1, 8)]
    rm = build_robot("panda", springs={"actuators": dict(zip(names, ks))})
    assert rm.pose_name == "default" and rm.vm.frame == "panda_hand_tcp"
    jac = rigid_jacobian(rm.source.urdf, "panda_hand_tcp", rm.pose)
    model = pin.buildModelFromUrdf(str(rm.source.urdf))
    jac7 = jac[:, [model.joints[model.getJointId(n)].idx_v for n in names]]  # fingers excluded
    k_ref = np.linalg.inv(jac7 @ np.diag(1 / np.array(ks)) @ jac7.T)
    assert rel(unloaded_stiffness(rm.vm).stiffness, k_ref) < 1e-9


# --------------------------------------------------------------------------- loaded
def test_ur5_loaded_stiffness_matches_finite_differences_of_resolved_equilibria():
    vm = build_robot("ur5", q=UR5_POSE).vm
    solver = EquilibriumSolver(vm, tol=1e-13)
    f = np.array([30.0, -20.0, -100.0, 2.0, -1.0, 3.0])
    res = solver.solve_wrench(f)
    assert res.converged and res.stable
    assert rel(res.wrench, f) < 1e-8
    kc = loaded_stiffness(vm, res).stiffness
    h = 1e-6
    fd = np.zeros((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        rp = solver.solve(
            target=displace(res.position, res.rotation, e), x0=res.x, wrench0=res.wrench
        )
        rm = solver.solve(
            target=displace(res.position, res.rotation, -e), x0=res.x, wrench0=res.wrench
        )
        fd[:, k] = (rp.wrench - rm.wrench) / (2 * h)
    assert rel(kc, fd) < 1e-5, rel(kc, fd)
    # the loaded stiffness differs from the unloaded one by the H term (eq. 28): not a no-op
    k0 = unloaded_stiffness(vm).stiffness
    assert rel(kc, k0) > 1e-5
    # deflection-driven solve at the wrench-driven deflection gives the wrench back
    back = solver.solve(res.deflection)
    assert rel(back.wrench, f) < 1e-6
    assert np.allclose(back.x, res.x, atol=1e-9)


# --------------------------------------------------------------------------- every robot
def _pick_frame(name):
    """Default frame, or None with the reason when the tree is branched."""
    src = robot_source(name)
    text = src.urdf.read_text()
    try:
        return default_frame(text, src.srdf), src, None
    except AmbiguousFrame as e:
        assert e.candidates and set(e.candidates) <= set(urdf_tree(text).links)
        return None, src, e


NO_URDF = {"cassie"}  # example-robot-data ships an SDF only
NO_JOINTS = {"hector", "iris"}  # drones: no movable joint in the URDF


@pytest.mark.parametrize("name", robot_names())
def test_every_example_robot_data_robot_loads_and_analyses(name):
    """Every fixed-base robot analyses at its reference pose with the defaults; a branched
    fixed-base tree (two arms, hands, mobile bases) with the deepest leaf as --frame; branched
    free-flyer trees (legged robots and humanoids) need --frame and are skipped here."""
    if name in NO_URDF:
        with pytest.raises(ModelError, match="no URDF"):
            build_robot(name)
        pytest.skip(f"{name}: SDF only")
    if name in NO_JOINTS:
        with pytest.raises(ModelError, match="no movable joint"):
            build_robot(name)
        pytest.skip(f"{name}: no movable joint")
    frame, src, err = _pick_frame(name)
    if frame is None:
        if src.free_flyer:
            pytest.skip(f"{name}: legged/humanoid tree without --frame ({err.link} branches)")
        tree = urdf_tree(src.urdf.read_text())
        frame = max(
            frame_candidates(tree),
            key=lambda ln: sum(tree.joints[j][0] != "fixed" for j in tree.path_joints(ln)),
        )
    rm = build_robot(name, frame=frame)
    vm = rm.vm
    assert vm.n_theta >= 1 and vm.n_q == 0
    k0 = unloaded_stiffness(vm).stiffness
    t = list(vm.task)
    kt = k0[np.ix_(t, t)]
    assert np.all(np.isfinite(kt)) and np.linalg.eigvalsh(0.5 * (kt + kt.T)).min() > 0
    res = EquilibriumSolver(vm).solve_wrench(np.zeros(6))
    assert res.converged and res.stable
    assert np.abs(res.deflection).max() < 1e-12


# --------------------------------------------------------------------------- defaults, helpers
def test_default_frames_and_tasks():
    assert build_robot("ur5").vm.frame == "tool0"
    dp = build_robot("double_pendulum").vm
    assert dp.n_theta == 2 and len(dp.task) == 2  # 2 joints: a 2-D task
    assert 1 in dp.task  # hanging along z: y and the rotation about x move the tip
    with pytest.raises(AmbiguousFrame, match="choose the end frame") as e:
        build_robot("baxter")
    assert "left_hand" in " ".join(e.value.candidates) or e.value.candidates
    assert isinstance(e.value, FrameNotFound)


def test_default_pose_moves_off_singularity_but_explicit_pose_is_kept():
    rm = build_robot("ur5")  # no SRDF state: zeros is the stretched (singular) arm
    assert "singular" in rm.pose_name
    zero = {n: 0.0 for n in UR5_POSE}
    vm = build_robot("ur5", q=zero).vm
    assert np.allclose(vm.reference, 0.0)


def test_beam_length_from_joint_origins_and_link_springs(tmp_path):
    src = robot_source("ur5")
    tree = urdf_tree(src.urdf.read_text())
    length = beam_length(src.urdf, "forearm_link")
    assert length == pytest.approx(np.linalg.norm(tree.origins["wrist_1_joint"]))
    assert length > 0.3
    spec = tmp_path / "springs.yaml"
    spec.write_text(
        "links:\n  forearm_link:\n    beam: {section: tube, outer_diameter: 0.08, wall: 0.004, E: 7.0e10, nu: 0.33}\n"
    )
    rm = build_robot("ur5", q=UR5_POSE, springs=str(spec))
    grp = [g for g in rm.vm.springs if g.link == "forearm_link"]
    assert len(grp) == 1 and grp[0].beam["length"] == pytest.approx(length)
    # a flexible link lowers the stiffness in every direction (K_link is in series)
    k_rigid = unloaded_stiffness(build_robot("ur5", q=UR5_POSE).vm).stiffness
    k_flex = unloaded_stiffness(rm.vm).stiffness
    assert np.linalg.eigvalsh(k_rigid - k_flex).min() > -1e-6 * np.abs(k_rigid).max()
    assert np.linalg.eigvalsh(k_rigid - k_flex).max() > 0


def test_plain_urdf_file(tmp_path):
    p = tmp_path / "arm.urdf"
    p.write_text(random_chain_urdf(np.random.default_rng(3), n_joints=6, prismatic_prob=0.0))
    vm, robot = resolve(str(p), q={"j2": 0.4, "j3": -0.7})
    assert robot is not None and vm.frame == "tool" and vm.n_theta == 6
    assert np.isclose(vm.reference[vm.joint_index("j3")], -0.7)


# --------------------------------------------------------------------------- errors
def test_clear_errors():
    with pytest.raises(UnknownRobot, match="did you mean ur5"):
        resolve_model("ur5x")
    with pytest.raises(FrameNotFound, match="nope"):
        build_robot("ur5", frame="nope")
    with pytest.raises(JointNotFound, match="foo"):
        build_robot("ur5", q={"foo": 1.0})
    with pytest.raises(InputError, match="outside its limits"):
        build_robot("ur5", q={"elbow_joint": 9.0})
    with pytest.raises(InputError, match="finite"):
        build_robot("ur5", q={"elbow_joint": float("nan")})
    with pytest.raises(InputError, match="no named pose 'ready'"):
        build_robot("panda", pose_name="ready")
    with pytest.raises(ModelError, match="VJM model"):
        resolve("paper-a-s", frame="end")
    with pytest.raises(SpecError):
        build_robot("ur5", springs={"links": {"forearm_link": {"beam": {"section": "hexagon"}}}})
    assert main(["analyze", "ur5", "--q", "elbow_joint=abc"]) == 2
    assert main(["analyze", "nosuchrobot"]) == 2


# --------------------------------------------------------------------------- CLI
def test_cli_analyze_robot_json_and_human(capsys):
    args = ["analyze", "ur5", "--wrench", "0", "0", "-100", "0", "0", "0"]
    args += ["--q"] + [f"{k}={v}" for k, v in UR5_POSE.items()]
    assert main(args + ["--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    vm = build_robot("ur5", q=UR5_POSE).vm
    res = EquilibriumSolver(vm).solve_wrench([0, 0, -100.0, 0, 0, 0])
    assert np.allclose(out["deflection"], res.deflection, atol=1e-12)
    assert out["stable"] is True
    w = out["weakest"]
    k6 = np.asarray(out["stiffness"])
    d = np.asarray(w["direction"])
    # the end free to rotate: the stiffness a force along d meets, 1 / (dᵀ C_tt d)
    assert 1.0 / (d @ np.linalg.inv(k6)[:3, :3] @ d) == pytest.approx(w["stiffness_along"], rel=1e-8)
    assert w["stiffness_along"] < w["stiffness_along_rotations_held"] <= d @ k6[:3, :3] @ d
    assert main(args) == 0
    text = capsys.readouterr().out
    dz = res.deflection[2] * 1e3
    assert (
        "mm" in text
        and "mrad" in text
        and "stable" in text
        and "weakest translational stiffness (end free to rotate)" in text
    )
    assert f"{dz:.4g}"[:5] in text


def test_models_robots_lists_names(capsys):
    assert main(["models", "--robots", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["robots"]
    assert "ur5" in rows and rows["ur5"]["urdf"].endswith("ur5_robot.urdf")


def test_spec_file_sets_frame_and_actuator_stiffness(tmp_path, capsys):
    spec = tmp_path / "s.yaml"
    spec.write_text("frame: forearm_link\nactuators: {default: 2.0e4, elbow_joint: 5.0e4}\n")
    vm = build_robot("ur5", springs=str(spec)).vm
    assert vm.frame == "forearm_link" and vm.n_theta == 3  # joints beyond the frame are locked
    k = dict(zip(vm.theta_names, np.diag(vm.K_theta)))
    assert k == {"shoulder_pan_joint": 2.0e4, "shoulder_lift_joint": 2.0e4, "elbow_joint": 5.0e4}
    assert main(["analyze", "ur5", "--springs", str(spec), "--frame", "tool0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frame"] == "tool0" and len(out["theta"]) == 6
