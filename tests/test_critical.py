"""The critical load along a direction, directly (vjm_pin/analysis/critical.py, vjm-pin critical).

Checked against code paths other than its own:
- ``trace_curve``'s first critical point (force, deflection, kind) on the paper models (Model C
  S with k = 1 and 2 sub-links per link, the Z and Π postures, Model A Z, Model B S and Z, the
  imperfect kind) and on a half von Mises truss (a limit point);
- closed forms: Model A S (rigid start, ``Kθ/L``, eq. 35) and the truss's force maximum
  ``F* = k (y*/ℓ* − y*)``, ``ℓ* = cos(φ₀)^(2/3)``;
- equilibria re-solved by the plain solver just before and after the critical deflection: the
  force-control margin (from the blocks with ``check_stability_held``) changes sign; the mode
  against an eigenvector computed here from SVD null spaces and ``reduced_matrix``;
- bad input, no critical point, a search budget too small (reported, not hidden); the CLI.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from vjm_pin.analysis.critical import critical_load
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError, NoCriticalPoint
from vjm_pin.model.format import load_vjm
from vjm_pin.model.registry import bundled_models, resolve_model
from vjm_pin.model.subdivide import subdivide_model
from vjm_pin.solver import EquilibriumSolver, MechanismSolver, blocks_at
from vjm_pin.solver.stability import check_stability_held, null_space, reduced_matrix

X = [-1.0, 0.0, 0.0]
RANGES = {"a": 1.0, "b": 0.5, "c": 0.5}  # the paper study (scripts/reproduce_paper.py)

PHI0, K_BAR = 0.3, 100.0  # the half truss: bar angle at rest (rad), axial spring (N/m)
TRUSS = f"""<robot xmlns:vjm="urn:vjm-pin:1" name="half-truss">
  <link name="base"/><link name="bar"/><link name="slider"/><link name="end"/>
  <joint name="phi" type="revolute"><parent link="base"/><child link="bar"/><axis xyz="0 0 1"/>
    <limit lower="-10" upper="10" effort="0" velocity="0"/></joint>
  <joint name="u" type="prismatic"><parent link="bar"/><child link="slider"/><axis xyz="1 0 0"/>
    <limit lower="-10" upper="10" effort="0" velocity="0"/></joint>
  <joint name="end_joint" type="fixed"><parent link="slider"/><child link="end"/><origin xyz="1 0 0"/></joint>
  <vjm:task frame="end" components="x y"/>
  <vjm:joint name="phi" role="passive" position="{PHI0}"/>
  <vjm:joint name="u" role="actuated" stiffness="{K_BAR}" position="0.0"/>
</robot>"""


def _model(name):
    if name == "c-s-k2":
        return subdivide_model(bundled_models()["paper-c-s"], 2), 0.5
    if name == "truss":
        return load_vjm(TRUSS), 0.6
    if name == "c-s+x":  # pulled: the S posture buckles too (trace_curve agrees)
        return resolve_model("paper-c-s"), 1e-3
    return resolve_model(f"paper-{name}"), RANGES[name[0]]


def _direction(name):
    return {"truss": [0.0, -1.0, 0.0], "c-s+x": [1.0, 0.0, 0.0]}.get(name, X)


def _margin(vm, eq, d) -> float:
    """μ: the largest eigenvalue with the task rows orthogonal to ``d`` held (check_stability_held)."""
    dt = np.asarray(d, float)[list(vm.task)]
    dt = dt / np.linalg.norm(dt)
    held = np.linalg.svd(dt.reshape(-1, 1))[0][:, 1:].T
    return float(check_stability_held(blocks_at(vm, eq.x, eq.wrench), held).eigenvalues.max())


@pytest.mark.parametrize(
    "name", ["c-s", "c-s-k2", "c-s+x", "c-z", "c-pi", "a-z", "b-s", "b-z", "truss"]
)
def test_agrees_with_the_first_critical_point_of_trace_curve(name):
    vm, rng = _model(name)
    d = _direction(name)
    r = critical_load(vm, d)
    cp = trace_curve(vm, d, rng, steps=5).critical[0]
    assert r.converged and r.check(1e-6), r
    assert r.kind == cp.kind
    assert r.force == pytest.approx(cp.force, rel=1e-6), "force (N)"
    assert r.deflection == pytest.approx(cp.deflection, rel=1e-5), "deflection (m)"
    assert r.force == pytest.approx(float(np.asarray(r.direction[:3]) @ r.wrench[:3]), rel=1e-12)
    assert r.equilibrium.converged and np.array_equal(r.x, r.equilibrium.x)


def test_model_a_s_rigid_start_closed_form():
    """A straight chain of rigid links with rotational springs Kθ = 1 N·m/rad, links L = 1 m:
    P_cr = Kθ/L (eq. 35) at deflection 0, as trace_curve reports it."""
    r = critical_load(resolve_model("paper-a-s"), X)
    assert r.force == pytest.approx(1.0, rel=1e-9), "Kθ/L (N)"
    assert r.deflection == 0.0 and r.kind == "bifurcation" and r.converged
    # the mode bends the chain: it moves the spring coordinates, not only the passive joint
    vm = resolve_model("paper-a-s")
    assert np.linalg.norm(r.mode[vm.theta_idx]) > 0.1


def test_limit_point_of_the_half_truss_closed_form():
    """The half von Mises truss (bar through a pinned base, axial spring k, end held in x):
    F(y) = k (y/ℓ − y), ℓ = √(c² + y²), c = cos φ₀; its maximum at ℓ* = c^(2/3) (snap-through)."""
    vm = load_vjm(TRUSS)
    r = critical_load(vm, [0.0, -1.0, 0.0])
    c = np.cos(PHI0)
    ell = c ** (2.0 / 3.0)
    y = np.sqrt(ell * ell - c * c)
    assert r.kind == "limit"
    assert r.force == pytest.approx(K_BAR * (y / ell - y), rel=1e-9), "F* (N)"
    assert r.deflection == pytest.approx(np.sin(PHI0) - y, rel=1e-7), "deflection (m)"
    assert abs(r.stiffness) < 1e-5 * K_BAR  # dF/ds = 0 at a limit point
    # the mode of a limit point: the motion along the path with x held (dφ/ds, du/ds)
    # = (−c/ℓ², −y/ℓ) (φ = atan2(y, c), u = ℓ − 1, y = sin φ₀ − s), normalised
    t = np.zeros(vm.model.nq)
    t[vm.q_idx] = -c / ell**2
    t[vm.theta_idx] = -y / ell
    assert abs(float(r.mode @ t)) / np.linalg.norm(t) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("name", ["c-s", "truss"])
def test_re_solved_equilibria_are_singular_there(name):
    """Equilibria re-solved by the plain solver, warm-started along the branch from the
    unloaded state: the margin μ changes sign across the critical deflection and is ~0 at it;
    the mode is the critical eigenvector computed here from SVD null spaces."""
    vm, _ = _model(name)
    d = np.concatenate([_direction(name), np.zeros(3)])
    r = critical_load(vm, d)
    sol = EquilibriumSolver(vm, follow_stable=False, restarts=0)
    eq = sol.solve(0.0 * d)
    for s in np.linspace(0.0, r.deflection, 21)[1:]:
        eq = sol.solve(s * d, x0=eq.x, wrench0=eq.wrench)
        assert eq.converged
    assert float(d @ eq.wrench) == pytest.approx(r.force, rel=1e-7)
    delta = 1e-3 * r.deflection
    before = sol.solve((r.deflection - delta) * d, x0=eq.x, wrench0=eq.wrench)
    after = sol.solve((r.deflection + delta) * d, x0=eq.x, wrench0=eq.wrench)
    m0, mb, ma = _margin(vm, eq, d), _margin(vm, before, d), _margin(vm, after, d)
    assert mb < 0 < ma
    assert abs(m0) < 0.01 * min(-mb, ma)
    # the mode: the critical eigenvector of eq. (23) at a bifurcation, of the force-control
    # matrix at a limit point (computed here with SVD bases)
    b = blocks_at(vm, r.x, r.wrench)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    if r.kind == "bifurcation":
        z = null_space(b.J_theta, b.J_q)
    else:
        dt = d[list(vm.task)]
        p = np.linalg.svd(dt.reshape(-1, 1))[0][:, 1:].T
        z = null_space(p @ b.J_theta, p @ b.J_q)
    ev, u = np.linalg.eigh(reduced_matrix(b, z))
    assert abs(ev[-1]) < 1e-6 * np.linalg.norm(vm.K_theta, 2)  # singular there
    if ev.size > 1:
        assert ev[-2] < -1e3 * abs(ev[-1])  # a simple critical eigenvalue: the mode is defined
    w = z @ u[:, -1]
    assert abs(float(w @ r.mode[free])) == pytest.approx(1.0, abs=1e-8)
    assert np.all(r.mode[np.setdiff1d(np.arange(vm.model.nq), free)] == 0)


def test_mode_is_a_zero_energy_direction_by_finite_differences():
    """Model C S at its critical point: the second difference of the total potential
    ``½θᵀKθ − Fᵀ(p − p₀)`` (the critical force kept fixed) along the buckling mode, a motion that
    keeps the end fixed to first order, vanishes (neutral equilibrium: the reduced matrix of
    eq. 23 is singular along it), while along the other such motions it is positive (stable)."""
    vm = resolve_model("paper-c-s")
    r = critical_load(vm, X)
    b = blocks_at(vm, r.x, r.wrench)
    z = null_space(b.J_theta, b.J_q)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    sol = EquilibriumSolver(vm)
    assert not np.any(r.wrench[3:])  # a pure force: its potential is −Fᵀp

    def potential(x):
        th = x[vm.theta_idx] - vm.theta0
        p, _ = sol.kin.placement(x)
        return 0.5 * th @ vm.K_theta @ th - r.wrench[:3] @ (p - sol.p0)

    def second(v, h=1e-4):
        xp, xm = r.x.copy(), r.x.copy()
        xp[free] += h * v
        xm[free] -= h * v
        return (potential(xp) - 2 * potential(r.x) + potential(xm)) / h**2

    mode = r.mode[free]
    others = [z[:, j] - (z[:, j] @ mode) * mode for j in range(z.shape[1])]
    others = [v / np.linalg.norm(v) for v in others if np.linalg.norm(v) > 0.5]
    stiff = min(second(v) for v in others)
    assert stiff > 0
    assert abs(second(mode)) < 1e-4 * stiff


def test_no_critical_point_and_bad_input():
    vm = resolve_model("paper-c-s")
    for name in ("paper-a-pi", "paper-b-pi"):  # paper §6.1: no sudden buckling in the Π posture
        with pytest.raises(NoCriticalPoint, match="stays stable"):
            critical_load(resolve_model(name), X, max_deflection=RANGES[name[6]])
    for bad, match in (
        ([0.0, 0.0, 0.0], "must not be zero"),
        ([1.0, 0.0], "3 or 6"),
        ([np.nan, 0.0, 0.0], "finite|NaN"),
        ([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], "outside the task"),
    ):
        with pytest.raises(InputError, match=match):
            critical_load(vm, bad)
    with pytest.raises(InputError, match="outside the task"):
        critical_load(resolve_model("paper-a-s"), [0.0, 0.0, 1.0])
    for kw, match in (
        ({"rtol": 0.0}, "rtol"),
        ({"max_iter": 0}, "max_iter"),
        ({"max_deflection": -1.0}, "max_deflection"),
    ):
        with pytest.raises(InputError, match=match):
            critical_load(vm, X, **kw)
    with pytest.raises(InputError, match="another model"):
        critical_load(vm, X, solver=EquilibriumSolver(resolve_model("paper-c-z")))
    fb = resolve_model("four-bar")
    with pytest.raises(InputError, match="serial chains"):
        critical_load(fb, X)
    with pytest.raises(InputError, match="EquilibriumSolver"):
        critical_load(vm, X, solver=MechanismSolver(vm))


def test_search_budget_too_small_is_reported_not_hidden():
    vm = resolve_model("paper-a-z")
    full = critical_load(vm, X)
    short = critical_load(vm, X, max_iter=2)
    assert full.converged and full.check()
    assert not short.converged and not short.check() and short.message
    assert short.iterations <= 2
    assert abs(short.force / full.force - 1) > 1e-6  # the point reached, not the answer


def test_a_given_solver_and_range_give_the_same_point():
    vm = resolve_model("paper-c-z")
    a = critical_load(vm, X)
    b = critical_load(vm, X, solver=EquilibriumSolver(vm), max_deflection=0.5, rtol=1e-10)
    assert b.force == pytest.approx(a.force, rel=1e-7)
    assert b.residuals["location"] <= 1e-10


def test_cli_json_and_text(capsys):
    assert main(["critical", "paper-c-s", "--direction", "-1", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)  # validated against the schema by conftest
    r = critical_load(resolve_model("paper-c-s"), X)
    assert out["command"] == "critical" and out["kind"] == "bifurcation" and out["converged"]
    assert out["force"] == pytest.approx(r.force, rel=1e-12)
    assert out["deflection"] == pytest.approx(r.deflection, rel=1e-12)
    assert out["units"]["force"].startswith("N")
    assert main(["critical", "paper-c-s", "--direction", "-1", "0", "0"]) == 0
    text = capsys.readouterr().out
    assert "mN" in text and "mm" in text and "bifurcation" in text
    value = float(text.split("critical load ")[1].split(" mN")[0])
    assert value == pytest.approx(1e3 * r.force, rel=1e-7)


@pytest.mark.parametrize(
    "argv, status, needle",
    [
        (["critical", "paper-c-s", "--direction", "0", "0", "0"], 2, "must not be zero"),
        (["critical", "paper-c-s", "--direction", "-1", "0", "0", "--rtol", "1"], 2, "--rtol"),
        (["critical", "no-such-model", "--direction", "-1", "0", "0"], 2, "unknown model"),
        (["critical", "four-bar", "--direction", "-1", "0", "0"], 2, "serial chains"),
        (["critical", "paper-a-pi", "--direction", "-1", "0", "0"], 3, "no critical point"),
    ],
)
def test_cli_errors_are_one_line(argv, status, needle, capsys):
    assert main(argv) == status
    err = capsys.readouterr().err.strip()
    assert err.startswith("vjm-pin: error:") and len(err.splitlines()) == 1 and needle in err
