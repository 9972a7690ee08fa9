"""Zero load on a chain that is rigid along a task direction (a straight chain of rigid links).

At the unloaded straight configuration the end frame cannot move along the chain to first order
(the x row of J is zero), so every axial force balances there: the held problem leaves the
force indeterminate. ``analyze`` (and ``EquilibriumSolver.solve`` at a zero deflection) answers
with the unloaded reference under zero wrench (the minimum-norm one), its eq. (23) verdict, and
a K_C that is infinite along the rigid direction and finite along the others; a deflection that
stretches the chain finds no equilibrium (exit 3, the contract of tests/test_interfaces.py for
"a deflection the chain cannot reach") with one line naming the requested deflection and why.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess

import numpy as np
import pytest

from vjm_pin import EquilibriumSolver, generate_vjm, load_vjm
from vjm_pin.cli import main
from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
from vjm_pin.model.paper_models import paper_spec, rigid_chain_urdf
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import blocks_at, loaded_stiffness
from vjm_pin.solver.stiffness import eq28_matrix, rigid_directions, stiffness_from_blocks, stiffness_rigid

ZERO_LOADS = (
    [],
    ["--deflection", "0", "0", "0"],
    ["--deflection", "0", "0", "0", "0", "0", "0"],
    ["--wrench", "0", "0", "0"],
)
#: Spring constants of the column without a passive joint (N·m/rad): base, middle, top.
SPRINGS = {"base_z": 2.0, "qa1": 1.0, "qa2": 1.5}


def column_urdf(angle: float = 0.0, task=("x", "y", "rz")) -> str:
    """Model A S's straight column of three rigid 1 m links with every joint a spring (no passive
    base pin, so that the directions across the column have a finite non-zero stiffness), turned
    by ``angle`` about z: rigid along the column at its reference."""
    spec = paper_spec("a", "s")
    spec.update(
        name="column",
        passive=[],
        actuators=dict(SPRINGS),
        positions={"base_z": angle, "qa1": 0.0, "qa2": 0.0},
        task=list(task),
    )
    return generate_vjm(rigid_chain_urdf(planar=True), spec)


@pytest.fixture(params=[(0.0, ("x", "y", "rz")), (math.pi / 4, ("x", "y", "rz")), (math.pi / 4, ("x", "y"))],
                ids=["along-x", "at-45deg", "at-45deg-xy"])
def column(request, tmp_path):
    angle, task = request.param
    path = tmp_path / "column.urdf"
    path.write_text(column_urdf(angle, task))
    return str(path), load_vjm(str(path)), angle


def _analyze(capsys, argv):
    code = main(["analyze", *argv, "--json"])
    cap = capsys.readouterr()
    return code, cap


def _limit_stiffness(b, eps_rel=1e-9):
    """K_C of eq. (28) with a small compliance ``ε`` added on the task rows (the top-left block
    ``−εI``: a soft element in series, which makes the matrix regular), for ``ε → 0``: the
    finite part of the stiffness of a rigid direction, by another route than the projection of
    :func:`stiffness_rigid`. Returns ``(K_ε, ε)``."""
    a = eq28_matrix(b)
    m = b.J_theta.shape[0]
    eps = eps_rel / max(np.abs(b.K_theta).max(), 1e-300)
    a[:m, :m] -= eps * np.eye(m)
    rhs = np.zeros((a.shape[0], m))
    rhs[:m] = np.eye(m)
    return np.linalg.solve(a, rhs)[:m], eps


def _check_rigid_stiffness(k6, vm, rigid_task):
    """``k6`` (6, 6, None for infinite entries as in --json): infinite where the projector on the
    rigid direction is non-zero, and equal to the limit of the regularised eq. (28) on the other
    task directions."""
    t = list(vm.task)
    k = np.array([[np.inf if v is None else v for v in row] for row in k6], float)
    kt = k[np.ix_(t, t)]
    proj = np.outer(rigid_task, rigid_task)
    assert np.array_equal(~np.isfinite(kt), np.abs(proj) > 1e-12)
    b = blocks_at(vm, vm.reference, np.zeros(6))
    k_eps, _ = _limit_stiffness(b)
    v = np.linalg.svd(np.eye(len(t)) - proj)[0][:, : len(t) - 1]  # the other task directions
    # on the other directions the regularised stiffness converges to the reported one
    fin = np.isfinite(kt)
    assert fin.any() or len(t) == 2
    ref = v @ (v.T @ k_eps @ v) @ v.T
    scale = np.abs(ref).max()
    assert scale > 0
    assert np.allclose(kt[fin], ref[fin], rtol=1e-6, atol=1e-6 * scale)
    return ref


# --------------------------------------------------------------------------- the bundled Model A S
@pytest.mark.parametrize("argv", ZERO_LOADS, ids=["none", "deflection3", "deflection6", "wrench"])
def test_zero_load_on_model_a_s_is_the_unloaded_state(capsys, argv):
    code, cap = _analyze(capsys, ["paper-a-s", *argv])
    assert code == 0, cap.err
    assert "Infinity" not in cap.out and "NaN" not in cap.out  # valid JSON
    out = json.loads(cap.out)
    assert out["converged"] is True
    assert out["wrench"] == [0.0] * 6
    assert np.abs(out["deflection"]).max() <= 1e-12
    assert out["stable_end_held"] is True
    assert out["checks"]["ok"] is True
    vm = resolve_model("paper-a-s")
    assert np.allclose(list(out["theta"].values()), vm.reference[vm.theta_idx], atol=1e-12)
    # K_C: infinite (null) along x, the rigid direction, and the note names it
    k = out["stiffness"]
    assert k is not None and k[0][0] is None
    assert all(v is not None for i, row in enumerate(k) for j, v in enumerate(row) if (i, j) != (0, 0))
    assert "[-1.0, 0.0]" in out["stiffness_note"] and "infinite" in out["stiffness_note"]
    # along y the passive base pin turns the unloaded column freely: zero, as the limit of eq. (28)
    b = blocks_at(vm, vm.reference, np.zeros(6))
    k_eps, _ = _limit_stiffness(b)
    assert k[1][1] == pytest.approx(k_eps[1, 1], abs=1e-9)
    # the unloaded stiffness is reported as before (eq. 28 singular: null with the same direction)
    assert out["stiffness_unloaded"] is None and "[-1.0, 0.0]" in out["stiffness_unloaded_note"]
    assert out["weakest"]["direction"][1] == pytest.approx(1.0)


def test_zero_load_text_output_names_the_rigid_direction(capsys):
    assert main(["analyze", "paper-a-s"]) == 0
    text = capsys.readouterr().out
    assert "equilibrium: reference, 0 iterations" in text
    assert "inf" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("loaded stiffness K_C:"))
    assert "task direction [-1.0, 0.0]" in line and "infinite" in line


def test_solver_at_zero_deflection_returns_the_reference_with_zero_wrench():
    vm = resolve_model("paper-a-s")
    solver = EquilibriumSolver(vm)
    for d in ([0, 0, 0], np.zeros(6), [0.0, 0.0]):
        res = solver.solve(d)
        assert res.converged and res.path == "reference" and res.iterations == 0
        assert np.array_equal(res.wrench, np.zeros(6))
        assert np.array_equal(res.x, vm.reference)
        assert res.stable is True and res.stable_end_held is True
        assert max(res.residuals.values()) == 0.0
    checked = solver.verify(solver.solve([0, 0, 0]))
    assert checked.checks["ok"] and checked.checks["stiffness_checked"] is False
    # the eq. (23) verdict is that of the reference under zero wrench, computed afresh
    from vjm_pin.solver.stability import check_stability

    fresh = check_stability(blocks_at(vm, vm.reference, np.zeros(6)))
    assert np.allclose(np.sort(res.stability.eigenvalues), np.sort(fresh.eigenvalues), rtol=1e-12, atol=1e-14)
    # eq. (28) is singular there; stiffness_rigid gives the finite rest
    with pytest.raises(SingularStiffness, match="rigid direction"):
        loaded_stiffness(vm, res)


def test_a_warm_start_or_a_start_wrench_keeps_the_iteration():
    """Only the default start at a zero deflection is answered by the reference: a given start
    (curve tracing, the checks' re-solves) runs the iteration as before."""
    vm = resolve_model("paper-a-s")
    solver = EquilibriumSolver(vm)
    res = solver.solve([0, 0, 0], wrench0=np.array([-0.5, 0, 0, 0, 0, 0]))
    assert res.path != "reference"


# --------------------------------------------------------------------------- a column with springs only
@pytest.mark.parametrize("argv", ZERO_LOADS[:2] + ZERO_LOADS[3:], ids=["none", "deflection", "wrench"])
def test_zero_load_stiffness_is_finite_across_the_column(capsys, column, argv):
    path, vm, angle = column
    code, cap = _analyze(capsys, [path, *argv])
    assert code == 0, cap.err
    out = json.loads(cap.out)
    assert out["wrench"] == [0.0] * 6
    assert out["stable_end_held"] is True
    t = list(vm.task)
    rigid_task = np.array([math.cos(angle), math.sin(angle)] + [0.0] * (len(t) - 2))
    ref = _check_rigid_stiffness(out["stiffness"], vm, rigid_task)
    # the compliance across the column by hand: springs k_i at distances 3, 2, 1 m from the end
    c_side = sum(dist**2 / k for dist, k in zip((3.0, 2.0, 1.0), SPRINGS.values()))
    side = np.array([-math.sin(angle), math.cos(angle)] + [0.0] * (len(t) - 2))
    if len(t) == 2:  # (x, y): the stiffness across the column is 1 / its compliance
        assert side @ ref @ side == pytest.approx(1.0 / c_side, rel=1e-6)
    # the weakest translational stiffness (end free to rotate) is across the column, 1/c_side
    wk = out["weakest"]
    assert wk["stiffness_along"] == pytest.approx(1.0 / c_side, rel=1e-5)
    assert abs(np.dot(wk["direction"][:2], side[:2])) == pytest.approx(1.0, abs=1e-9)
    # the note names the rigid direction (and, off the task axes, gives the finite part)
    note = out["stiffness_note"]
    assert "infinite" in note
    named = np.array(json.loads(note.split("task direction ")[1].split("]")[0] + "]"))
    assert abs(named @ rigid_task) == pytest.approx(1.0, abs=2e-3)


def test_zero_load_stiffness_matches_mixed_control_finite_differences():
    """Physically: hold the end at ±h along y (free along x, zero force there) and read the
    reaction: its slope is the stiffness along y with x free, 1 / C_yy (C the compliance, zero
    along the rigid direction), which the rigid K_C's finite part gives; the column at 45°."""
    angle = math.pi / 4
    vm = load_vjm(column_urdf(angle, ("x", "y")))
    b = blocks_at(vm, vm.reference, np.zeros(6))
    kres = stiffness_rigid(b, vm.task)
    side6 = np.array([-math.sin(angle), math.cos(angle), 0, 0, 0, 0])
    solver = EquilibriumSolver(vm)
    h = 1e-6
    # hold y, load x with zero force: the end moves freely along the column
    forces = []
    for s in (1.0, -1.0):
        res = solver.solve_mixed(deflection=[0.0, s * h], held=("y",))
        assert res.converged
        forces.append(res.wrench[:2])
    # the y reaction per y displacement with x free: 1 / C_yy, C the compliance (zero along the column)
    kfd = (forces[0][1] - forces[1][1]) / (2 * h)
    fin = kres.finite_part[:2, :2]
    c = np.linalg.pinv(fin, rcond=1e-10)
    assert kfd == pytest.approx(1.0 / c[1, 1], rel=1e-4)
    c_side = sum(dist**2 / k for dist, k in zip((3.0, 2.0, 1.0), SPRINGS.values()))
    assert side6[:2] @ fin @ side6[:2] == pytest.approx(1.0 / c_side, rel=1e-9)


def test_stiffness_rigid_api():
    vm = load_vjm(column_urdf(0.0))
    b = blocks_at(vm, vm.reference, np.zeros(6))
    r = rigid_directions(b)
    assert r.shape == (1, 3) and abs(r[0, 0]) == pytest.approx(1.0)
    with pytest.raises(SingularStiffness, match="rigid direction"):
        stiffness_from_blocks(b, vm.task)
    for method in ("eq30", "eq32", "eq33"):
        kres = stiffness_rigid(b, vm.task, method)
        assert np.isinf(kres.stiffness[0, 0]) and np.isfinite(kres.stiffness[1:, 1:]).all()
        assert np.allclose(kres.rigid[0, :3], r[0]) and kres.is_symmetric()
        assert np.allclose(kres.finite_part[1:, 1:], kres.stiffness[1:, 1:])
        assert np.all(kres.finite_part[0] == 0) or np.abs(kres.finite_part[0]).max() < 1e-12
    # a regular chain has no rigid direction
    bz = blocks_at(resolve_model("paper-a-z"), resolve_model("paper-a-z").reference, np.zeros(6))
    assert rigid_directions(bz).shape[0] == 0
    with pytest.raises(SingularStiffness, match="no rigid direction"):
        stiffness_rigid(bz, (0, 1))


# --------------------------------------------------------------------------- loaded: unchanged
@pytest.mark.parametrize(
    "model,d", [("paper-a-s", [-0.001, 0, 0]), ("paper-a-s", [-0.2, 0, 0]), ("paper-a-z", [-0.001, 0, 0])]
)
def test_compression_is_the_equilibrium_it_was(capsys, model, d):
    """A compressive deflection still buckles the column: the CLI reports the equilibrium the
    solver finds on its own (not the reference) and its eq. (30) K_C, all finite."""
    code, cap = _analyze(capsys, [model, "--deflection", *map(str, d)])
    assert code == 0, cap.err
    out = json.loads(cap.out)
    vm = resolve_model(model)
    res = EquilibriumSolver(vm).solve(d)
    assert res.path != "reference" and out["path"] == res.path
    assert np.allclose(out["wrench"], res.wrench, rtol=1e-9, atol=1e-12)
    assert np.allclose(out["deflection"], res.deflection, rtol=1e-9, atol=1e-12)
    k = np.array(out["stiffness"], float)
    assert np.isfinite(k).all()
    assert np.allclose(k, loaded_stiffness(vm, res).stiffness, rtol=1e-8, atol=1e-12)
    assert out["stiffness_note"] is None


def test_a_regular_model_at_zero_load_is_unchanged(capsys):
    """paper-a-z can move in every task direction: the usual iteration (0 iterations at the
    reference) and its regular eq. (30) K_C, equal to the unloaded one."""
    code, cap = _analyze(capsys, ["paper-a-z"])
    assert code == 0
    out = json.loads(cap.out)
    vm = resolve_model("paper-a-z")
    res = EquilibriumSolver(vm).solve([0, 0, 0])
    assert res.path != "reference" and out["path"] == res.path
    assert np.allclose(out["stiffness"], out["stiffness_unloaded"], rtol=1e-9, atol=1e-12)
    assert out["stiffness_note"] is None


# --------------------------------------------------------------------------- out of reach
@pytest.mark.parametrize(
    "model,d,asked",
    [("paper-a-s", ["0.001", "0", "0"], "[0.001, 0.0, 0.0"), ("paper-a-s", ["0", "0.001", "0"], "[0.0, 0.001, 0.0")],
    ids=["stretch", "sideways-at-full-length"],
)
def test_a_deflection_beyond_the_rigid_reach_is_one_line_exit_3(capsys, model, d, asked):
    assert main(["analyze", model, "--deflection", *d]) == 3
    cap = capsys.readouterr()
    assert cap.out == ""
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vjm-pin: error: ")
    assert "Traceback" not in cap.err
    assert asked in lines[0] and "out of reach" in lines[0] and "rigid direction" in lines[0]
    assert "no equilibrium" in lines[0]


def test_the_stretch_on_a_spring_column_is_refused_too(capsys, tmp_path):
    path = tmp_path / "column.urdf"
    path.write_text(column_urdf(0.0))
    assert main(["analyze", str(path), "--deflection", "0.002", "0", "0"]) == 3
    err = capsys.readouterr().err
    assert "[0.002, 0.0, 0.0, 0.0, 0.0, 0.0]" in err and "out of reach" in err


@pytest.mark.skipif(shutil.which("vjm-pin") is None, reason="the console script is not installed")
def test_stretch_exit_status_from_the_shell(tmp_path):
    r = subprocess.run(["vjm-pin", "analyze", "paper-a-s", "--deflection", "0.001", "0", "0"],
                       capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 3 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "[0.001, 0.0, 0.0" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run(["vjm-pin", "analyze", "paper-a-s"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr


def test_no_equilibrium_names_the_requested_deflection():
    """The solver's own error names the deflection asked for, then where its last iterate ended."""
    vm = resolve_model("paper-a-s")
    with pytest.raises(NoEquilibrium) as e:
        EquilibriumSolver(vm, restarts=1).solve([0.001, 0, 0])
    msg = str(e.value)
    assert msg.startswith("no equilibrium found for deflection [0.001, 0.0, 0.0, 0.0, 0.0, 0.0]")
    assert "last iterate" in msg


def test_rigid_reach_is_a_second_order_test():
    """checks.rigid_reach on the straight column: stretching is beyond reach, compressing is not;
    sideways the end must come closer by about h²/(2L)."""
    from vjm_pin.solver.checks import rigid_reach

    vm = resolve_model("paper-a-s")
    b = blocks_at(vm, vm.reference, np.zeros(6))
    jac = np.hstack([b.J_theta, b.J_q])
    rig = rigid_directions(b)

    def hess(rho):
        w = np.zeros(6)
        w[list(vm.task)] = rho
        h = blocks_at(vm, vm.reference, w)
        return np.block([[h.H_tt, h.H_tq], [h.H_qt, h.H_qq]])

    got = rigid_reach(jac, rig, hess, np.array([1e-3, 0.0]))
    assert got is not None and got[0][0] == pytest.approx(1.0) and got[2] == pytest.approx(0.0, abs=1e-15)
    assert rigid_reach(jac, rig, hess, np.array([-1e-3, 0.0])) is None
    h = 1e-3
    got = rigid_reach(jac, rig, hess, np.array([0.0, h]))
    assert got is not None and got[2] == pytest.approx(-h * h / (2 * 3.0), rel=1e-6)
    # shortened by more than that, the sideways move is within reach
    assert rigid_reach(jac, rig, hess, np.array([-h * h, h])) is None
