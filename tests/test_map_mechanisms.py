"""Maps of closed mechanisms (issue 13): re-assembly at each actuator position, loaded
equilibria and K_C from MechanismSolver checked against independent solves, unreachable poses
reported, ``--load``, backends bit for bit, CLI errors."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from vjm_pin import load_vjm
from vjm_pin.analysis.assembly import Assembler
from vjm_pin.analysis.maps import assembled_model, run_map, stiffness_indices
from vjm_pin.cli import main
from vjm_pin.exceptions import FrameNotFound, InputError, RoleError
from vjm_pin.kinematics.closures import ClosureSet
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location(
    "make_closed_models", ROOT / "scripts" / "make_closed_models.py"
)
GEN = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(GEN)

W = np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0])
CRANKS = np.array(
    [-2.9, -1.2, -0.4, 0.7, 2.2]
)  # crank joint values (rad), both sides of the reference


@pytest.fixture(scope="module")
def four_bar():
    return resolve_model("four-bar")


def closed_form_model(vm, crank: float, params=None):
    """The four-bar at crank joint value ``crank`` assembled by the circle intersection of
    ``scripts/make_closed_models.py`` (independent of vjm_pin.analysis.assembly)."""
    p = dict(params or GEN.FOUR_BAR, crank_angle=-crank)  # joint value = −direction angle
    ab, bc, cd = GEN.four_bar_angles(p)
    return vm.with_positions({"crank": crank, "elbow": -(bc - ab), "knee": -(cd - bc)})


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def closure_residual(vm, x) -> float:
    return float(np.abs(ClosureSet(vm).evaluate(x, hessian=False).residual).max())


# ----------------------------------------------------------------------------- assembly
def test_assembly_follows_the_four_bar_geometry_all_round(four_bar):
    """A Grashof crank-rocker: every crank angle assembles, on the reference's branch."""
    asm = Assembler(four_bar, ["crank"])
    el, kn = four_bar.joint_index("elbow"), four_bar.joint_index("knee")
    for crank in np.linspace(-math.pi, math.pi, 37):
        a = asm.assemble([crank])
        assert a.ok, (crank, a.reason)
        ref = closed_form_model(four_bar, crank).reference
        assert np.abs(wrap(a.x[[el, kn]] - ref[[el, kn]])).max() < 1e-10, crank
        assert closure_residual(four_bar, a.x) <= 1e-12
        links = four_bar.theta_idx != four_bar.joint_index("crank")
        assert np.array_equal(
            a.x[four_bar.theta_idx[links]], four_bar.theta0[links]
        )  # springs at rest


def test_assembly_does_not_depend_on_the_order_of_the_poses(four_bar):
    values = np.linspace(-3.0, 3.0, 13)
    forward = [Assembler(four_bar, ["crank"]).assemble([v]).x for v in values]
    asm = Assembler(four_bar, ["crank"])
    backward = [asm.assemble([v]).x for v in values[::-1]][::-1]
    assert all(np.array_equal(f, b) for f, b in zip(forward, backward))


def test_assembly_refuses_passive_joints(four_bar):
    with pytest.raises(RoleError, match="passive"):
        Assembler(four_bar, ["elbow"])


# ----------------------------------------------------------------------------- the map
@pytest.fixture(scope="module")
def fb_map(four_bar):
    return run_map(four_bar, ["crank"], CRANKS[:, None], W, backend="serial")


def test_four_bar_map_equals_independent_equilibria_and_stiffness(four_bar, fb_map):
    """Each pose: the assembled model is the four-bar's geometry; the reported deflection is the
    one of an equilibrium re-solved independently (from the closed-form assembly, tighter
    tolerance), whose closure residual vanishes; k_along/k_min are those of
    MechanismSolver.stiffness at that equilibrium."""
    assert list(fb_map.status) == ["ok"] * len(CRANKS)
    for i, crank in enumerate(CRANKS):
        v_map = assembled_model(four_bar, ["crank"], [crank])
        v = closed_form_model(four_bar, crank)
        assert np.abs(wrap(v_map.reference - v.reference)).max() < 1e-10
        assert closure_residual(four_bar, v_map.reference) <= 1e-9
        solver = MechanismSolver(v, tol=1e-12)
        res = solver.solve(wrench=W)
        assert res.converged and closure_residual(four_bar, res.x) <= 1e-9
        assert fb_map.p0[i] == pytest.approx(solver.p0, abs=1e-12)
        assert fb_map.deflection[i] == pytest.approx(res.deflection, rel=1e-6, abs=1e-10)
        k = solver.stiffness(res).stiffness
        k_along, k_min = stiffness_indices(k, W, v.task)
        assert fb_map.k_along[i] == pytest.approx(k_along, rel=1e-6)
        assert fb_map.k_min[i] == pytest.approx(k_min, rel=1e-6)
        assert bool(fb_map.stable[i]) == bool(res.stable)


def test_four_bar_k_along_against_re_solved_equilibria(four_bar, fb_map):
    """k_along = 1/(f̂ᵀ C f̂): the stiffness an extra force along f̂ meets, by central differences
    of equilibria re-solved at W ± h f̂."""
    i = 3
    v = closed_form_model(four_bar, CRANKS[i])
    fh = W[:3] / np.linalg.norm(W[:3])
    h = 0.5
    pos = []
    for s in (1, -1):
        w2 = W.copy()
        w2[:3] += s * h * fh
        pos.append(MechanismSolver(v, tol=1e-12).solve(wrench=w2).position)
    k_fd = 2 * h / (fh @ (pos[0] - pos[1]))
    assert fb_map.k_along[i] == pytest.approx(k_fd, rel=1e-5)


def test_unreachable_poses_are_reported_with_a_status(tmp_path):
    """A non-Grashof four-bar (coupler = rocker = 0.5 m): the crank reaches |α| ≤ acos(0.2)
    (the distance from B to D is at most 1 m there); beyond, no assembly, every value NaN."""
    params = dict(GEN.FOUR_BAR, coupler=0.5, rocker=0.5)
    vm = load_vjm(GEN.four_bar_urdf(params, name="four-bar-short"))
    limit = math.acos(0.2)
    cranks = np.linspace(-math.pi, math.pi, 33)
    res = run_map(vm, ["crank"], cranks[:, None], np.array([0.0, 0.0, -5.0]), backend="serial")
    out = np.abs(cranks) > limit + 1e-3
    inside = np.abs(cranks) < limit - 0.15
    assert out.sum() > 5 and inside.sum() > 5
    assert np.all(res.status[out] == "no-assembly")
    assert np.all(np.isnan(res.deflection[out])) and np.all(np.isnan(res.p0[out]))
    assert np.all(np.isnan(res.k_along[out])) and not res.stable[out].any()
    assert np.all(res.status[inside] == "ok")
    for i in np.flatnonzero(inside)[::3]:  # the assembled poses are the geometry's
        v = closed_form_model(vm, cranks[i], params)
        assert res.p0[i] == pytest.approx(MechanismSolver(v).p0, abs=1e-10)


def test_load_option_acts_as_the_solver_says(four_bar):
    """A dead load at the task frame is the same as the end wrench; one at another frame gives the
    equilibrium MechanismSolver finds with that load."""
    crank = np.array([[0.7]])
    at_end = run_map(
        four_bar,
        ["crank"],
        crank,
        np.zeros(6),
        loads=[Load("coupler_point", W[:3])],
        backend="serial",
    )
    as_wrench = run_map(four_bar, ["crank"], crank, W, backend="serial")
    assert at_end.deflection[0] == pytest.approx(as_wrench.deflection[0], rel=1e-8, abs=1e-12)
    load = Load("rocker_link", [15.0, 0.0, -40.0])
    res = run_map(four_bar, ["crank"], crank, W, loads=[load], backend="serial")
    v = closed_form_model(four_bar, 0.7)
    solver = MechanismSolver(v, [load], tol=1e-12)
    eq = solver.solve(wrench=W)
    assert res.deflection[0] == pytest.approx(eq.deflection, rel=1e-6, abs=1e-10)
    assert np.abs(res.deflection[0] - as_wrench.deflection[0]).max() > 1e-4  # the load matters
    k_along, _ = stiffness_indices(solver.stiffness(eq).stiffness, W, v.task)
    assert res.k_along[0] == pytest.approx(k_along, rel=1e-6)


def test_map_input_errors(four_bar):
    with pytest.raises(RoleError, match="passive joint of a closed mechanism"):
        run_map(four_bar, ["elbow"], np.zeros((1, 1)), W, backend="serial")
    with pytest.raises(InputError, match="outside the task"):
        run_map(four_bar, ["crank"], np.zeros((1, 1)), [0.0, 10.0, 0.0], backend="serial")
    with pytest.raises(FrameNotFound):
        run_map(
            four_bar,
            ["crank"],
            np.zeros((1, 1)),
            W,
            loads=[Load("nope", [0, 0, 1])],
            backend="serial",
        )


def test_shared_workspace_gives_the_numbers_of_a_fresh_solver(four_bar):
    """One MechanismSolver per process re-based at each pose (issue 14): the same numbers, bit
    for bit, as a new solver per pose and as the pose evaluated alone."""
    from vjm_pin.analysis import maps

    maps._SOLVER_CACHE.clear()
    rows = [maps.evaluate_pose(four_bar, ["crank"], [c], W) for c in CRANKS]
    maps._SOLVER_CACHE.clear()
    alone = maps.evaluate_pose(four_bar, ["crank"], [CRANKS[-1]], W)
    v = assembled_model(four_bar, ["crank"], [CRANKS[-1]])
    fresh = MechanismSolver(v)
    res = fresh.solve(wrench=W, x0=v.reference)
    assert len({id(h[1]) for h in maps._SOLVER_CACHE.values()}) == 1
    for key in ("p0", "deflection", "k_along", "k_min"):
        assert np.array_equal(rows[-1][key], alone[key]), key
    assert np.array_equal(rows[-1]["deflection"], res.deflection)
    assert np.array_equal(rows[-1]["p0"], fresh.p0)


def test_at_reference_refuses_another_mechanism(four_bar):
    solver = MechanismSolver(four_bar)
    with pytest.raises(InputError, match="another reference"):
        solver.at_reference(resolve_model("portal-frame"))
    moved = assembled_model(four_bar, ["crank"], [0.3])
    assert solver.at_reference(moved).p0 == pytest.approx(MechanismSolver(moved).p0, abs=0)


def test_local_pool_and_dask_agree_bit_for_bit_on_a_closed_mechanism(four_bar):
    poses = np.linspace(-3.0, 3.0, 9)[:, None]
    serial = run_map(four_bar, ["crank"], poses, W, backend="serial")
    local = run_map(four_bar, ["crank"], poses, W, backend="local", workers=2, chunk=2)
    dask = run_map(four_bar, ["crank"], poses, W, backend="dask", workers=2, chunk=3)
    for r in (local, dask):
        for f in ("deflection", "k_along", "k_min", "p0", "stable", "status"):
            assert np.array_equal(
                getattr(r, f), getattr(serial, f), equal_nan=f not in ("stable", "status")
            ), f


def test_orthoglide_map_reassembles_at_its_actuator_positions():
    """``map orthoglide-q0``: the three actuators sampled, the legs re-assembled (closures hold,
    springs at rest), the loaded platform equilibrium that of MechanismSolver solved anew."""
    from vjm_pin.analysis.maps import mapped_joints

    vm = resolve_model("orthoglide-q0")
    names = mapped_joints(vm)
    act = [vm.joint_index(n) for n in names]
    assert len(names) == 3 and all(vm.roles[n] == "actuated" for n in names)
    poses = vm.reference[act] + np.array([[0.03, -0.02, 0.01], [-0.05, 0.0, 0.04]])
    w = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    res = run_map(vm, names, poses, w, backend="serial")
    assert list(res.status) == ["ok", "ok"]
    springs = [i for i in vm.theta_idx if i not in act]
    rest = {i: t for i, t in zip(vm.theta_idx, vm.theta0)}
    for i, pose in enumerate(poses):
        v = assembled_model(vm, names, pose)
        assert np.array_equal(v.reference[act], pose)
        assert np.array_equal(v.reference[springs], [rest[j] for j in springs])
        assert closure_residual(vm, v.reference) <= 1e-9
        assert np.abs(v.reference[vm.q_idx] - vm.reference[vm.q_idx]).max() > 1e-3  # the legs moved
        solver = MechanismSolver(v, tol=1e-12)
        eq = solver.solve(wrench=w)
        assert closure_residual(vm, eq.x) <= 1e-9
        assert res.p0[i] == pytest.approx(solver.p0, abs=1e-12)
        assert res.deflection[i] == pytest.approx(eq.deflection, rel=1e-6, abs=1e-11)
        k_along, _ = stiffness_indices(solver.stiffness(eq).stiffness, w, v.task)
        assert res.k_along[i] == pytest.approx(k_along, rel=1e-6)


def test_payload_and_gravity_maps_of_a_serial_robot_take_the_mechanism_solver(capsys):
    """``--payload`` is a dead load at the end frame (MechanismSolver, as ``analyze``): the same
    deflection as that weight given as the end wrench to the serial solver; ``--gravity`` maps a
    chain with passive joints (link weights) and equals MechanismSolver at the pose."""
    from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY
    from vjm_pin.model.robots import build_robot

    vm = build_robot("ur5").vm
    names = ["shoulder_lift_joint", "elbow_joint"]
    poses = np.array([[-1.2, 1.0], [-0.6, 1.8]])
    weight = np.array([0.0, 0.0, -5.0 * STANDARD_GRAVITY, 0.0, 0.0, 0.0])
    as_load = run_map(
        vm, names, poses, np.zeros(6), loads=[Load.weight(vm.frame, 5.0)], backend="serial"
    )
    as_wrench = run_map(vm, names, poses, weight, backend="serial")
    assert list(as_load.status) == list(as_wrench.status) == ["ok", "ok"]
    np.testing.assert_allclose(as_load.deflection, as_wrench.deflection, rtol=1e-7, atol=1e-12)
    pc = resolve_model("paper-c-s")  # passive joints
    g = np.array([0.0, 0.0, -STANDARD_GRAVITY])
    qa = [n for n in pc.joint_names if pc.roles[n] == "actuated"]
    pose = pc.reference[[pc.joint_index(n) for n in qa]][None, :] + 0.1
    res = run_map(pc, qa, pose, np.array([-50.0, 0.0, 0.0]), gravity=g, backend="serial")
    v = pc.with_positions(dict(zip(qa, pose[0])))
    eq = MechanismSolver(v, gravity=g, tol=1e-12).solve(wrench=np.array([-50.0, 0.0, 0.0]))
    assert res.status[0] == "ok"
    assert res.deflection[0] == pytest.approx(eq.deflection, rel=1e-6, abs=1e-11)


# ----------------------------------------------------------------------------- CLI
def test_cli_map_of_a_closed_mechanism_with_a_load(tmp_path, capsys):
    import jsonschema

    from vjm_pin.cli.schema import load_schema

    out = tmp_path / "fb.npz"
    argv = [
        "map",
        "four-bar",
        "--grid",
        "crank=-1:1:3",
        "--backend",
        "serial",
        "--no-progress",
        "--wrench",
        "0",
        "0",
        "-60",
        "--load",
        "rocker_link",
        "15",
        "0",
        "-40",
        "--json",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    jsonschema.validate(s, load_schema("map"))
    assert s["joints"] == ["crank"] and s["status"] == {"ok": 3}
    assert s["loads"][0]["frame"] == "rocker_link" and s["loads"][0]["wrench"][2] == -40.0
    z = np.load(out)
    res = run_map(
        resolve_model("four-bar"),
        ["crank"],
        z["poses"],
        W,
        loads=[Load("rocker_link", [15, 0, -40])],
        backend="serial",
    )
    assert np.array_equal(z["deflection"], res.deflection)
    assert list(z["load_frames"]) == ["rocker_link"] and np.array_equal(
        z["load_wrenches"], [[15, 0, -40, 0, 0, 0]]
    )


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["four-bar", "--grid", "elbow=0:1:3"], "passive joint of a closed mechanism"),
        (["four-bar", "--samples", "2", "--load", "nope", "0", "0", "1"], "nope"),
        (["four-bar", "--samples", "2", "--load", "coupler_point", "1", "2"], "load"),
        (["four-bar", "--samples", "2", "--load", "coupler_point", "a", "2", "3"], "load"),
        (["four-bar", "--samples", "2", "--wrench", "0", "100", "0"], "outside the task"),
        (["portal-frame", "--samples", "2"], "no actuated joint"),
    ],
)
def test_cli_map_errors_are_one_line(args, fragment, capsys):
    rc = main(["map", *args, "--backend", "serial", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("vjm-pin: error: ") and fragment in err, err


def test_orthoglide_samples_its_actuator_stroke_and_every_sample_assembles():
    """The bundled Orthoglide's actuator limits are its stroke over the 200 mm workspace cube
    (scripts/make_orthoglide.py), so sampled poses lie in the workspace and assemble."""
    from vjm_pin.analysis.maps import mapped_joints, sample_poses

    vm = resolve_model("orthoglide-q0")
    names, poses = sample_poses(vm, 6, seed=3)
    assert list(names) == list(mapped_joints(vm))
    lo, hi = vm.model.lowerPositionLimit, vm.model.upperPositionLimit
    idx = [vm.joint_index(n) for n in names]
    assert np.all(hi[idx] - lo[idx] < 0.3)  # a real stroke, not a placeholder
    res = run_map(vm, names, poses, np.array([0.0, 0.0, -100.0, 0, 0, 0]), backend="serial")
    assert list(res.status) == ["ok"] * 6
