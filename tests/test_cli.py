"""The CLI in process: analyze --json has the documented keys and agrees with the library."""

import json

import numpy as np
import pytest

from vjm_pin import EquilibriumSolver, loaded_stiffness
from vjm_pin.cli import main
from vjm_pin.model.registry import resolve_model

KEYS = {"converged", "iterations", "wrench", "deflection", "stable", "stability_eigenvalues", "stiffness",
        "stiffness_unloaded", "q", "theta", "residual"}


def test_analyze_json_model_a(capsys):
    assert main(["analyze", "paper-a-s", "--deflection", "-0.2", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    phi = np.arccos(1 - 0.2 / 2)
    assert -out["wrench"][0] == pytest.approx(phi / np.sin(phi), rel=1e-6)
    assert out["converged"] and out["stable"]
    assert set(out["q"]) == {"base_z"} and set(out["theta"]) == {"qa1", "qa2"}
    k = np.array(out["stiffness"])
    assert k.shape == (6, 6) and np.all(k[2:] == 0) and np.all(k[:, 2:] == 0)
    vm = resolve_model("paper-a-s")
    res = EquilibriumSolver(vm).solve([-0.2, 0, 0])
    assert np.allclose(k, loaded_stiffness(vm, res).stiffness, rtol=1e-8, atol=1e-12)
    # rigid straight chain: unloaded stiffness is infinite along x, and the output says so
    assert out["stiffness_unloaded"] is None and "infinite" in out["stiffness_unloaded_note"]


def test_analyze_human_output(capsys):
    assert main(["analyze", "paper-c-s", "--deflection", "-0.001", "0", "0"]) == 0
    out = capsys.readouterr().out
    assert "stable" in out and "loaded stiffness" in out and "N/m" in out


def test_models_lists_bundled(capsys):
    assert main(["models", "--json"]) == 0
    names = json.loads(capsys.readouterr().out)["models"]
    assert "paper-a-s" in names and "paper-c-s" in names


def test_help_on_every_command(capsys):
    from vjm_pin.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in sub.choices:
        with pytest.raises(SystemExit) as e:
            main([name, "--help"])
        assert e.value.code == 0
        assert "usage" in capsys.readouterr().out


def test_curve_matrices_match_analyze_on_the_traced_state(capsys):
    """The loaded K_C at a curve point (curve --matrices) is the one of the traced equilibrium."""
    from vjm_pin.analysis.curve import trace_curve

    assert main(["curve", "paper-c-s", "--direction", "-1", "0", "0", "--max-deflection", "0.002", "--steps", "4",
                 "--matrices", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    vm = resolve_model("paper-c-s")
    curve = trace_curve(vm, [-1, 0, 0], 0.002, 4)
    last = curve.points[-1]
    k_cli = np.array(out["points"][-1]["stiffness"])
    assert np.allclose(k_cli, loaded_stiffness(vm, last.equilibrium).stiffness, rtol=1e-8, atol=1e-12)
    # the directional stiffness reported for the point is dᵀ K_C d
    assert out["points"][-1]["stiffness_along"] == pytest.approx(k_cli[0, 0], rel=1e-8)


def test_analyze_subdivide_refines_the_model(capsys):
    assert main(["analyze", "paper-c-s", "--deflection", "-0.0001", "0", "0", "--subdivide", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["theta"]) == 36  # 3 links × 2 sub-links × 6 springs
    assert main(["analyze", "paper-c-s", "--deflection", "0", "0", "0", "--subdivide", "0"]) == 2


# ----------------------------------------------------------------------------- dead loads, closures
from . import portal_frame as pf  # noqa: E402


def _portal_constants():
    """The corner spring k (N·m/rad) and the column height h (m), read from the bundled model."""
    import pinocchio as pin

    vm = resolve_model("portal-frame")
    k = float(vm.K_theta[0, 0])
    assert np.allclose(vm.K_theta, k * np.eye(4))
    d = vm.model.createData()
    pin.framesForwardKinematics(vm.model, d, vm.reference)
    z = {f: d.oMf[vm.model.getFrameId(f)].translation[2] for f in ("top_left", "base")}
    return k, float(z["top_left"] - z["base"])


def _analyze(capsys, *argv):
    assert main(["analyze", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("model", ["portal-frame", "portal-frame-6"])
@pytest.mark.parametrize("H_force,P_ratio", [(60.0, 0.5), (-35.0, 0.9), (20.0, 0.0)])
def test_analyze_portal_frame_with_loads_matches_the_closed_form(capsys, model, H_force, P_ratio):
    """--wrench H at the top, --load P on both column tops: the sway, K_C and the closure reaction
    of the closed form (tests/portal_frame.py); the same with the closure in six components
    (three redundant rows: minimum-norm multipliers, zero on them)."""
    k, h = _portal_constants()
    P = P_ratio * pf.critical_load(k, h)
    out = _analyze(capsys, model, "--wrench", str(H_force), "0", "0",
                   "--load", "top_left", "0", "0", str(-P), "--load", "top_right", "0", "0", str(-P))
    phi = pf.sway(H_force, k, h, P)
    assert out["deflection"][0] == pytest.approx(pf.deflection(phi, h), rel=1e-8)
    assert out["deflection"][2] == pytest.approx(-h * (1 - np.cos(phi)), rel=1e-8, abs=1e-14)
    assert out["stiffness"][0][0] == pytest.approx(pf.stiffness(phi, k, h, P), rel=1e-6)
    assert out["wrench"][0] == pytest.approx(H_force, rel=1e-12)
    assert out["stable"] is True and out["stable_end_held"] is True and out["parallel"] is True
    assert out["control"] == {"held": [], "loaded": ["x"]}
    assert [ld["frame"] for ld in out["loads"]] == ["top_left", "top_right"]
    assert all(ld["wrench"] == [0.0, 0.0, -P, 0.0, 0.0, 0.0] and ld["source"] == "load" for ld in out["loads"])
    (c,) = out["closures"]
    assert (c["name"], c["frame_a"], c["frame_b"]) == ("right_foot", "foot", "anchor")
    # the closure holds the foot against the corner spring below it (turned by −φ): moment −kφ
    assert c["wrench_a"][4] == pytest.approx(-k * phi, rel=1e-8, abs=1e-9)
    assert np.allclose(np.add(c["wrench_a"][:3], c["wrench_b"][:3]), 0, atol=1e-9)  # action and reaction
    if model == "portal-frame-6":
        assert sorted(out["redundant"]) == ["right_foot.rx", "right_foot.rz", "right_foot.y"]
        assert "minimum-norm" in out["multipliers_note"]
        assert all(abs(c["multipliers"][comp]) < 1e-9 for comp in ("y", "rx", "rz"))
    else:
        assert out["redundant"] == [] and out["multipliers_note"] is None
        assert set(c["multipliers"]) == {"x", "z", "ry"}


def test_portal_frame_sway_buckling_load_is_2k_over_h(capsys):
    """Above P = 2k/h per column the unswayed frame is unstable under force control (the top free)
    and stable with the top held; below it, stable both ways. K_C = (4k − 2Ph)/h² there."""
    k, h = _portal_constants()
    pc = pf.critical_load(k, h)
    for ratio, stable in ((0.9, True), (1.1, False)):
        loads = ["--load", "top_left", "0", "0", str(-ratio * pc), "--load", "top_right", "0", "0", str(-ratio * pc)]
        free = _analyze(capsys, "portal-frame", "--wrench", "0", "0", "0", *loads)
        held = _analyze(capsys, "portal-frame", "--deflection", "0", "0", "0", *loads)
        assert free["stable"] is stable and free["stable_end_held"] is True
        assert held["stable"] is True and held["stable_end_held"] is True
        for out in (free, held):
            assert abs(out["deflection"][0]) < 1e-12
            assert out["stiffness"][0][0] == pytest.approx(pf.stiffness(0.0, k, h, ratio * pc), rel=1e-8)


def test_analyze_a_dead_load_at_the_end_frame_is_the_end_wrench(capsys):
    """`--load END F` (mechanism solver, the end free under a dead load) and `--wrench F` (serial
    solver) are the same physical problem: the same equilibrium and K_C."""
    vm = resolve_model("paper-c-s")
    a = _analyze(capsys, "paper-c-s", "--load", vm.frame, "-0.05", "0.01", "0")
    b = _analyze(capsys, "paper-c-s", "--wrench", "-0.05", "0.01", "0")
    assert a["path"].startswith("mechanism:") and not b["path"].startswith("mechanism:")
    assert np.allclose(a["deflection"], b["deflection"], rtol=1e-8, atol=1e-12)
    assert np.allclose(a["stiffness"], b["stiffness"], rtol=1e-6, atol=1e-9)
    assert a["wrench"] == [0.0] * 6 and a["loads"][0]["wrench"][:3] == [-0.05, 0.01, 0.0]
    assert a["stable"] == b["stable"] and a["stable_end_held"] == b["stable_end_held"]


def test_analyze_serial_chain_with_loads_on_links(capsys):
    """A UR5 with dead loads on two links and the end held at a deflection: the CLI's equilibrium
    is the MechanismSolver's, and the statics of eq. (5) hold with the loads' own Jacobians."""
    import pinocchio as pin

    from vjm_pin.kinematics.dead_loads import Load
    from vjm_pin.model.robots import build_robot
    from vjm_pin.solver import MechanismSolver

    q = {"shoulder_lift_joint": -1.0, "elbow_joint": 1.2}
    argv = ["ur5", "--q", *[f"{n}={v}" for n, v in q.items()], "--deflection", "0.0005", "0", "-0.001",
            "--load", "forearm_link", "10", "0", "-80", "--load", "wrist_2_link", "0", "5", "-20", "0.5", "0", "0"]
    out = _analyze(capsys, *argv)
    vm = build_robot("ur5", q=q).vm
    loads = [Load("forearm_link", [10, 0, -80]), Load("wrist_2_link", [0, 5, -20, 0.5, 0, 0])]
    ms = MechanismSolver(vm, loads)
    res = ms.solve(deflection=[0.0005, 0, -0.001, 0, 0, 0])
    assert np.allclose(out["deflection"], res.deflection, atol=1e-12)
    assert np.allclose(out["wrench"], res.wrench, rtol=1e-8, atol=1e-8)
    assert np.allclose(out["stiffness"], ms.stiffness(res).stiffness, rtol=1e-8, atol=1e-6)
    assert out["control"]["loaded"] == [] and out["closures"] is None and out["parallel"] is False
    # statics, from Pinocchio alone: K(θ−θ₀) = Jᵀw + Σ J_lᵀ w_l
    x = res.x
    d = vm.model.createData()
    gen = pin.computeFrameJacobian(vm.model, d, x, vm.frame_id, pin.LOCAL_WORLD_ALIGNED).T @ res.wrench
    for ld in loads:
        fid = vm.model.getFrameId(ld.frame)
        gen = gen + pin.computeFrameJacobian(vm.model, d, x, fid, pin.LOCAL_WORLD_ALIGNED).T @ ld.wrench
    tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    assert np.abs(tau - gen[vm.theta_idx]).max() < 1e-8 * np.abs(tau).max()
    # the loads matter: without them the held end needs another reaction
    bare = _analyze(capsys, *argv[: argv.index("--load")])
    assert np.linalg.norm(np.subtract(bare["wrench"], out["wrench"])) > 1.0


def test_analyze_orthoglide_q0_through_the_one_path(capsys):
    """The Orthoglide (legs loaded as closures onto the platform) through the mechanism solver:
    the asked wrench, both verdicts, closure reactions, K_C against re-solved equilibria (the
    platform held at neighbouring deflections), and the robot's symmetry at Q0 (x, y, z alike)."""
    from vjm_pin.solver import MechanismSolver

    f = -1000.0 / np.sqrt(3.0)
    out = _analyze(capsys, "orthoglide-q0", "--wrench", str(f), str(f), str(f))
    assert out["parallel"] is True and out["path"].startswith("mechanism:")
    assert np.allclose(out["wrench"], [f, f, f, 0, 0, 0], rtol=1e-12, atol=1e-9)
    assert out["stable"] is True and out["stable_end_held"] is True
    assert out["closures"] and all(len(c["wrench_a"]) == 6 for c in out["closures"])
    k = np.array(out["stiffness"])
    assert np.allclose(np.diag(k)[:3], k[0, 0], rtol=1e-9)  # Q0: the three axes are alike
    vm = resolve_model("orthoglide-q0")
    ms = MechanismSolver(vm)
    d0 = np.array(out["deflection"])
    h = 1e-7  # m
    for j in range(3):
        e = np.zeros(6)
        e[j] = h
        wp = ms.solve(deflection=d0 + e).wrench
        wm = ms.solve(deflection=d0 - e).wrench
        col = (wp - wm) / (2 * h)
        assert np.abs(col[:3] - k[:3, j]).max() < 1e-5 * k[0, 0], j
    # the deflection integrates the compliance from no load to this load: the trapezoid rule
    # ½(C(0) + C(F))F within its error (C changes by ~0.2 % over this range)
    k0 = np.array(out["stiffness_unloaded"])[:3, :3]
    fv = np.array([f, f, f])
    trapezoid = 0.5 * (np.linalg.solve(k[:3, :3], fv) + np.linalg.solve(k0, fv))
    assert np.allclose(d0[:3], trapezoid, rtol=2e-5)
    assert not np.allclose(d0[:3], np.linalg.solve(k0, fv), rtol=2e-5)  # the load matters


def _curve(capsys, *argv):
    assert main(["curve", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_curve_portal_frame_with_loads_matches_the_closed_form(capsys):
    """`curve --load` on the closed portal frame: force, tangent stiffness and K_C of every point
    against the closed form H(φ), K_C(φ) at Δ = h sin φ with P on both column tops."""
    k, h = _portal_constants()
    P = 0.5 * pf.critical_load(k, h)
    loads = ["--load", "top_left", "0", "0", str(-P), "--load", "top_right", "0", "0", str(-P)]
    out = _curve(capsys, "portal-frame", "--direction", "1", "0", "0", "--max-deflection", "0.3", "--steps", "3",
                 "--matrices", *loads)
    assert out["parallel"] is True and out["free"] is False and out["gravity"] is False
    assert [ld["frame"] for ld in out["loads"]] == ["top_left", "top_right"]
    assert len(out["points"]) == 4 and out["critical"] == []
    for p in out["points"]:
        phi = np.arcsin(p["deflection"] / h)
        assert p["force"] == pytest.approx(pf.force(phi, k, h, P), rel=1e-8, abs=1e-9)
        assert p["stiffness_along"] == pytest.approx(pf.stiffness(phi, k, h, P), rel=1e-6)
        assert p["stiffness"][0][0] == pytest.approx(p["stiffness_along"], rel=1e-9)
        assert p["stable"] is True and p["force_control_margin"] > 0


@pytest.mark.parametrize("free", [False, True])
def test_curve_serial_chain_with_a_load_against_the_mechanism_solver(capsys, free):
    """`curve --load` on an open chain: every point is the MechanismSolver's equilibrium under the
    dead load with the end held at the point's deflection: in every task component, or (--free)
    only along the direction (x here), the other components free with no load on them. (Below the
    chain's buckling deflection, 1.6e-4 m: one stable equilibrium per point.)"""
    from vjm_pin.kinematics.dead_loads import Load
    from vjm_pin.solver import MechanismSolver

    argv = ["paper-c-s", "--direction", "-1", "0", "0", "--max-deflection", "1e-4", "--steps", "2",
            "--load", "end", "0", "-0.01", "0"] + (["--free"] if free else [])
    out = _curve(capsys, *argv)
    assert out["free"] is free and out["parallel"] is False
    vm = resolve_model("paper-c-s")
    ms = MechanismSolver(vm, [Load("end", [0, -0.01, 0])])
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    for p in out["points"]:
        res = ms.solve(deflection=p["deflection"] * d, held=("x",) if free else None)
        assert np.allclose(p["wrench"], res.wrench, rtol=1e-7, atol=1e-9)
        assert p["force"] == pytest.approx(d @ res.wrench, rel=1e-7, abs=1e-9)
        assert p["stable"] is True and res.stable is True
        if free:
            assert np.allclose(p["wrench"][1:], 0.0, atol=1e-12)  # nothing holds the end across d
    # the load matters: without it the chain is straight and nothing pushes back at zero deflection
    bare = _curve(capsys, *argv[: argv.index("--load")])
    assert bare["points"][0]["force"] == pytest.approx(0.0, abs=1e-12)
    assert np.abs(np.subtract(out["points"][-1]["wrench"], bare["points"][-1]["wrench"])).max() > 1e-3
