"""``vjm-pin view`` on mechanisms (loop closures, the Orthoglide's legs, dead loads): the load
path, the unstable parts, the compliance ellipsoid and the continued branch of a curve, each
against closed forms or re-solved equilibria. The browser pictures are in test_viewer.py."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from vjm_pin.kinematics.dead_loads import Load

from .portal_frame import CORNER_SIGNS, d2potential
from .roller_column import CRITICAL_DEFLECTION, CRITICAL_FORCE, roller_column

CORNERS = ("corner_bl", "corner_tl", "corner_tr", "corner_br")


def _portal():
    from vjm_pin.model.registry import resolve_model

    vm = resolve_model("portal-frame")
    k = float(vm.K_theta[0, 0])
    h = float(np.linalg.norm(vm.model.jointPlacements[vm.model.getJointId("corner_tl")].translation))
    return vm, k, h


def _page_setup(text: str) -> dict:
    return json.loads(re.search(r"var setup = (\{.*?\});\n", text, re.DOTALL).group(1))


# ----------------------------------------------------------------------------- load path
def test_portal_load_path_turns_unstable_at_the_sway_buckling_load():
    """Vertical dead loads P on both column tops, the top free: the straight frame is an
    equilibrium at every P and is stable under the loads iff P < 2k/h (closed form); past it
    the unstable mode is the sway (corner turns ∝ (1, −1, 1, −1)) with the curvature of the
    total potential, V''(0)·dφ², for the mode's unit norm."""
    from vjm_pin.cli.view import mechanism_load_path
    from vjm_pin.solver import MechanismSolver

    vm, k, h = _portal()
    p_max = 1.5 * 2 * k / h
    loads = [Load("top_left", [0, 0, -p_max]), Load("top_right", [0, 0, -p_max])]
    path = mechanism_load_path(vm, "loads", None, loads, n=8)
    idx = [vm.joint_index(c) for c in CORNERS]
    for f in path:
        p = f.load_factor * p_max
        res = f.result
        assert res.converged
        np.testing.assert_allclose(res.x[idx], 0.0, atol=1e-9)  # the straight frame
        assert res.stable is (p < 2 * k / h), (p, res.stable)
        assert res.stable_end_held is True  # the top held: nothing can sway
        # re-solved from the unloaded frame, independently of the warm-started path
        cold = MechanismSolver(vm, [Load(ld.frame, f.load_factor * ld.wrench) for ld in loads],
                               follow_stable=False).solve(wrench=np.zeros(6))
        np.testing.assert_allclose(cold.x, res.x, atol=1e-9)
        if res.stable:
            assert f.modes.shape[1] == 0
            continue
        assert f.modes.shape[1] == 1
        v = f.modes[:, 0]
        np.testing.assert_allclose(v[idx] / v[idx[0]], CORNER_SIGNS, atol=1e-9)
        ev, _ = MechanismSolver(vm, [Load(ld.frame, f.load_factor * ld.wrench) for ld in loads]).unstable_modes(res)
        dphi = abs(v[idx[0]])
        assert ev[0] == pytest.approx(-d2potential(0.0, k, h, P=p) * dphi**2, rel=1e-8)


def test_orthoglide_q3_past_the_critical_force_the_most_loaded_leg_is_red():
    """Q3 under a dead force along −u beyond its critical force (3.46 kN, docs/orthoglide.md):
    the path continued from below is unstable and its unstable mode is carried by one leg —
    the leg that transmits the largest force (statics from the closure reactions; at Q3 the
    leg forces per unit force are 0.19, 0.19 and 0.82)."""
    from vjm_pin.cli.view import mechanism_load_path, unstable_legs
    from vjm_pin.model.registry import resolve_model

    vm = resolve_model("orthoglide-q3")
    w = np.array([-2300.0, -2300.0, -2300.0, 0.0, 0.0, 0.0])  # |F| = 3.98 kN
    path = mechanism_load_path(vm, "wrench", w, n=6)
    assert all(f.result.stable for f in path[:-1])  # up to 3.19 kN
    last = path[-1].result
    assert last.converged and last.stable is False
    np.testing.assert_allclose(last.wrench, w, atol=1e-6)
    # leg forces: the closures carry legs 2 and 3 into the platform; leg 1 holds the rest
    on_platform = {name: np.asarray(wb[:3]) for name, (_, wb) in last.reaction_wrenches.items()}
    forces = {name: float(np.linalg.norm(f)) for name, f in on_platform.items()}
    forces["leg1"] = float(np.linalg.norm(w[:3] + sum(on_platform.values())))
    most = max(forces, key=forces.get)
    assert forces[most] > 2.5 * min(forces.values()), forces
    assert unstable_legs(vm, path[-1].modes) == [most]
    assert unstable_legs(vm, path[-2].modes) == []


def test_compliance_ellipsoid_is_the_displacement_under_unit_forces():
    """Four-bar under a dead force at the coupler point: along each principal axis of the
    ellipsoid, a small extra force moves the coupler point by (semi-axis × force) along that
    axis (central differences of re-solved equilibria); no semi-axis outside the task (y)."""
    from vjm_pin.cli.view import compliance_ellipsoid
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import MechanismSolver

    vm = resolve_model("four-bar")
    solver = MechanismSolver(vm)
    w0 = np.array([20.0, 0.0, -50.0])
    res = solver.solve(wrench=w0)
    axes_len, axes = compliance_ellipsoid(solver.stiffness(res).stiffness, vm.task)
    assert axes_len[0] > axes_len[1] > 0 and axes_len[2] == 0
    np.testing.assert_allclose(axes.T @ axes, np.eye(3), atol=1e-12)
    assert abs(axes[1, 2]) == pytest.approx(1.0)  # the zero axis is y (not in the task)
    eps = 1e-2  # N
    for i in range(2):
        e = axes[:, i]
        plus = solver.solve(wrench=w0 + eps * e, x0=res.x)
        minus = solver.solve(wrench=w0 - eps * e, x0=res.x)
        dp = (plus.position - minus.position) / (2 * eps)
        np.testing.assert_allclose(dp, axes_len[i] * e, rtol=0, atol=1e-5 * axes_len[0])


def test_view_four_bar_json_page_and_schema(tmp_path, capsys):
    """The CLI on a closed loop with a dead load: the JSON (validated by conftest) names the
    closure and the load, its last frame is the equilibrium under the full loads (re-solved
    here), its ellipsoid that of this equilibrium; the page has a load arrow per dead load and
    the legend names the closure marker and the ellipsoid with its scale."""
    from vjm_pin.cli import main
    from vjm_pin.cli.view import compliance_ellipsoid
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import MechanismSolver

    page = tmp_path / "fb.html"
    argv = ["view", "four-bar", "--wrench", "20", "-50", "--load", "coupler_point", "0", "0", "-30",
            "--ellipsoid", "--html", str(page), "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "wrench" and out["closures"] == ["rocker_pivot"]
    assert out["loads"][0]["frame"] == "coupler_point"
    vm = resolve_model("four-bar")
    solver = MechanismSolver(vm, [Load("coupler_point", [0, 0, -30])])
    ref = solver.solve(wrench=[20.0, 0.0, -50.0])
    last = out["frames"][-1]
    np.testing.assert_allclose(last["deflection"], ref.deflection, atol=1e-9)
    assert last["stable"] is True and last["unstable_modes"] == 0
    ell = out["ellipsoid"]["frames"][-1]
    lengths, axes = compliance_ellipsoid(solver.stiffness(ref).stiffness, vm.task)
    np.testing.assert_allclose(ell["compliance_eigenvalues"], lengths, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(np.abs(np.asarray(ell["axes"])), np.abs(axes.T), atol=1e-6)
    setup = _page_setup(page.read_text(encoding="utf-8"))
    legend = " | ".join(e["text"] for e in setup["legend"])
    assert "loop closure" in legend and "dead loads" in legend
    assert f"{out['ellipsoid']['force']:.3g} N" in legend
    loads = [a for a in setup["anchors"] if a["cls"] == "load"]
    assert len(loads) == 1 and loads[0]["text"][-1] == "coupler_point: 30 N"


def test_view_bad_load_and_nothing_to_show(tmp_path, capsys):
    from vjm_pin.cli import main

    out = tmp_path / "x.html"
    for argv, words in (
        (["view", "four-bar", "--load", "nope", "0", "0", "-1", "--html", str(out)], "nope"),
        (["view", "four-bar", "--html", str(out)], "--load"),
        (["view", "four-bar", "--wrench", "1", "2", "3", "4", "--html", str(out)], "--wrench"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("vjm-pin: error:") and words in err and err.count("\n") == 1, err
        assert not out.exists()


# ----------------------------------------------------------------------------- curves
@pytest.fixture(scope="module")
def roller(tmp_path_factory):
    from vjm_pin.analysis.curve import trace_curve
    from vjm_pin.model.registry import resolve_model

    path = roller_column(tmp_path_factory.mktemp("roller"))
    vm = resolve_model(str(path))
    curve = trace_curve(vm, [-1.0, 0, 0], 0.3, 12)
    return path, vm, curve


def test_roller_column_curve_page_shows_the_continued_branch_unstable(roller):
    """The closed loop buckles at the closed-form load; the page's critical frame is there and
    the branch it leaves (the straight column) is drawn past it: its states are unstable
    equilibria (re-solved) and straight, distinct from the followed bent branch."""
    import pinocchio as pin

    from vjm_pin.cli.view import curve_animation
    from vjm_pin.solver import MechanismSolver

    _, vm, curve = roller
    assert len(curve.critical) == 1
    c = curve.critical[0]
    assert abs(c.force) == pytest.approx(CRITICAL_FORCE, rel=1e-4)
    assert c.deflection == pytest.approx(CRITICAL_DEFLECTION, rel=1e-3)
    _, _, _, kw = curve_animation(vm, curve, n_frames=31, all_branches=True)
    frames, k = kw["_frames"], kw["critical_index"]
    assert frames[k].kind == "critical" and frames[k].deflection == pytest.approx(c.deflection, rel=1e-3)
    assert len(kw["branches"]) == 1 and kw["closures"] == [("roller", "end", "anchor")]
    (branch,) = kw["branches"]
    shown = [i for i, q in enumerate(branch.frames) if q is not None]
    assert shown and min(shown) > k and len(shown) > len(frames) // 3
    solver = MechanismSolver(vm, follow_stable=False)
    data = vm.model.createData()
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    for i in shown[:: max(1, len(shown) // 4)]:
        x_shown = branch.frames[i]  # magnified by the page's scale (1 here: shown as computed)
        eq = solver.solve(deflection=frames[i].deflection * d, x0=x_shown)
        assert eq.converged and eq.stable is False and not branch.stable[i]
        np.testing.assert_allclose(eq.x, x_shown, atol=1e-7)
        pin.forwardKinematics(vm.model, data, eq.x)
        assert max(abs(m.translation[1]) for m in data.oMi[1:]) < 1e-9  # straight
        assert np.linalg.norm(frames[i].x - eq.x) > 1e-3  # not the followed (bent) branch
    assert kw.get("modes") is not None and all(m is None for m in kw["modes"])  # followed: stable


def test_view_curve_on_a_closed_loop_cli(roller, tmp_path, capsys):
    from vjm_pin.cli import main

    path, _, _ = roller
    page = tmp_path / "r.html"
    argv = ["view", str(path), "--curve", "--direction", "-1", "0", "0", "--max-deflection", "0.3",
            "--steps", "12", "--all-branches", "--ellipsoid", "--html", str(page), "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    k = out["critical_frame"]
    assert out["branches"] == 1 and out["closures"] == ["roller"]
    assert out["frames"][k]["kind"] == "critical"
    assert abs(out["critical"][0]["force"]) == pytest.approx(CRITICAL_FORCE, rel=1e-4)
    # the compliance along x before buckling is the base spring's, 1/k_a (m/N)
    ell = out["ellipsoid"]["frames"]
    assert ell[1]["compliance_eigenvalues"][0] == pytest.approx(1e-3, rel=1e-6)
    setup = _page_setup(page.read_text(encoding="utf-8"))
    assert any("unstable" in e["text"] for e in setup["legend"])


def test_view_portal_loads_only_json(tmp_path, capsys):
    """``--load`` alone: the top free (mode ``loads``, no end force); the JSON frames carry
    both verdicts and the unstable-mode count, turning unstable past 2k/h."""
    from vjm_pin.cli import main

    _, k, h = _portal()
    page = tmp_path / "p.html"
    argv = ["view", "portal-frame", "--load", "top_left", "0", "0", "-300", "--load", "top_right", "0", "0",
            "-300", "--html", str(page), "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "loads" and out["parallel"] is False and len(out["loads"]) == 2
    for f in out["frames"]:
        unstable = f["load_factor"] * 300 > 2 * k / h
        assert f["stable"] is not unstable and f["unstable_modes"] == int(unstable)
        assert f["stable_end_held"] is True and f["unstable_legs"] == []
        np.testing.assert_allclose(f["wrench"], 0.0, atol=1e-9)  # nothing on the free top
    setup = _page_setup(page.read_text(encoding="utf-8"))
    assert not any(a["cls"] == "force" for a in setup["anchors"])  # no end-force arrow
    assert sum(a["cls"] == "load" for a in setup["anchors"]) == 2
