"""Three shortcuts probed beyond the one case each was written for.

1. The escape's hand-off to plain Newton steps (``EquilibriumSolver._relaxed_local``, used inside
   ``_escape``): warm-started sweeps through buckling (Model C subdivided, postures Π and Z, a
   lateral imperfection of either sign, Model B) reach the same equilibria (same branch, same
   energy, same stability) with the hand-off switched off, under the numpy twin and the compiled
   kernel; the branch is kept along the sweep and the choice is deterministic.
2. The mechanism tracer's short-step Newton give-up (``mechanism_curve.SHORT_STEP_RADIUS``): a
   curve that hits it (the two-column parallel robot through its buckling) is the same curve
   (points, end, critical points) as with the radius unbounded (the behaviour before it).
3. ``critical_load``'s refined first point (``critical._refined_start``, the compiled chain path):
   the force meets ``rtol`` against a re-location at ``rtol = 1e-10`` and agrees with
   ``trace_curve``'s critical point to the sum of both tolerances, on cases beyond the straight
   Model C column (oblique directions, subdivisions, other postures and models).
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.analysis import critical as critical_mod
from vjm_pin.analysis import mechanism_curve
from vjm_pin.analysis.critical import critical_load
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver
from vjm_pin.solver.mechanism import MechanismSolver

from .columns import max_deflection


def _model_c(posture: str = "s", k: int = 1):
    if k == 1:
        return resolve_model(f"paper-c-{posture}")
    return load_vjm(paper_model_urdf("c", posture, beam=PAPER_BEAM, subdivide=k))


def _dir6(v) -> np.ndarray:
    v = np.asarray(v, float)
    return np.concatenate([v / np.linalg.norm(v), np.zeros(3)])


def _jit(monkeypatch, jit: str) -> None:
    if jit == "1":
        pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", jit)


# --------------------------------------------------------------------------- 1. escape hand-off
def _sweep(vm, d, top, steps, handoff: bool, monkeypatch):
    """Warm-started solves along ``d`` to ``top`` (each from the previous equilibrium); the number
    of hand-offs that returned an equilibrium."""
    inner = EquilibriumSolver._relaxed_local
    used = []

    def spy(self, *a):
        out = inner(self, *a) if handoff else None
        used.append(out is not None)
        return out

    with monkeypatch.context() as m:
        m.setattr(EquilibriumSolver, "_relaxed_local", spy)
        s = EquilibriumSolver(vm)
        out = [s.solve(top / steps * d)]
        for t in np.linspace(top / steps, top, steps)[1:]:
            out.append(s.solve(t * d, x0=out[-1].x, wrench0=out[-1].wrench))
    return out, sum(used)


C_TOP = max_deflection()
SWEEPS = {
    "c-s-k2": (lambda: _model_c("s", 2), _dir6([-1, 0, 0]), C_TOP, 24),
    "c-s-k4": (lambda: _model_c("s", 4), _dir6([-1, 0, 0]), C_TOP, 24),
    "c-s-k4-coarse": (lambda: _model_c("s", 4), _dir6([-1, 0, 0]), C_TOP, 4),  # escape at the first solve
    "c-s-imperfect+z": (lambda: _model_c("s"), _dir6([-1, 0, 1e-4]), C_TOP, 24),
    "c-s-imperfect-z": (lambda: _model_c("s"), _dir6([-1, 0, -1e-4]), C_TOP, 24),
    "c-s-k2-imperfect+y": (lambda: _model_c("s", 2), _dir6([-1, 1e-4, 0]), C_TOP, 24),
    "c-pi": (lambda: _model_c("pi"), _dir6([-1, 0, 0]), 0.3, 30),
    "c-z": (lambda: _model_c("z"), _dir6([-1, 0, 0]), 0.3, 30),
    "b-s": (lambda: resolve_model("paper-b-s"), _dir6([-1, 0, 0]), 0.3, 30),
}


@pytest.mark.parametrize("jit", ["0", "1"])
@pytest.mark.parametrize("case", sorted(SWEEPS))
def test_escape_hand_off_keeps_the_branch_of_the_safeguarded_escape(case, jit, monkeypatch):
    _jit(monkeypatch, jit)
    make, d, top, steps = SWEEPS[case]
    vm = make()
    fast, used = _sweep(vm, d, top, steps, True, monkeypatch)
    slow, _ = _sweep(vm, d, top, steps, False, monkeypatch)
    assert used >= 1  # the hand-off returned the escape's equilibrium at least once
    assert any("escape" in r.path for r in fast)
    for a, b in zip(fast, slow, strict=True):  # the same equilibrium: branch, side, energy, verdict
        assert a.converged and b.converged and a.stable and b.stable
        assert np.abs(a.x - b.x).max() <= 1e-9
        assert np.abs(a.wrench - b.wrench).max() <= 1e-9 * np.abs(b.wrench).max()
        assert a.energy == pytest.approx(b.energy, rel=1e-9)
    # along the sweep one branch: the buckled coordinate keeps its sign once it has left zero
    x_ref = EquilibriumSolver(vm).solve(0.0 * d).x  # the unloaded (straight) configuration
    i = int(np.argmax(np.abs(fast[-1].x - x_ref)))
    side = np.sign(fast[-1].x[i] - x_ref[i])
    k = next(j for j, r in enumerate(fast) if "escape" in r.path)
    assert side != 0 and all(np.sign(r.x[i] - x_ref[i]) == side for r in fast[k:])
    # and the choice is deterministic: the same sweep again gives the same equilibria
    again, _ = _sweep(vm, d, top, steps, True, monkeypatch)
    for a, b in zip(fast, again, strict=True):
        np.testing.assert_array_equal(a.x, b.x)


def test_mirror_imperfections_buckle_at_one_energy(monkeypatch):
    """The symmetric column with a lateral imperfection of either sign (and none): the buckled
    equilibria at the end of the sweep have one energy (mirror images or the same branch)."""
    vm = _model_c("s")
    ends = []
    for sz in (1e-4, -1e-4, 0.0):
        for handoff in (True, False):
            out, _ = _sweep(vm, _dir6([-1, 0, sz]), C_TOP, 24, handoff, monkeypatch)
            ends.append(out[-1].energy)
    assert np.ptp(ends) <= 1e-7 * abs(ends[0])


# --------------------------------------------------------------------------- 2. mechanism give-up
def _columns():
    from .parallel_models import columns_xml

    return load_vjm(columns_xml(1.0, 100.0, 1e5))


def _mechanism_curve(vm, d, top, steps, radius, monkeypatch, **kw):
    inner = MechanismSolver._newton
    calls = []

    def spy(self, *a, radius=None, **k):
        out = inner(self, *a, radius=radius, **k)
        if radius is not None:
            calls.append(bool(out[2]))
        return out

    with monkeypatch.context() as m:
        m.setattr(mechanism_curve, "SHORT_STEP_RADIUS", radius)
        m.setattr(MechanismSolver, "_newton", spy)
        c = trace_curve(vm, d, top, steps, **kw)
    return c, calls


def test_short_step_give_up_gives_the_curve_of_the_unbounded_newton(monkeypatch):
    """The two-column robot pushed through its in-plane buckling: the short-step Newton gives up
    (radius) where the unbounded one would wander, and the curve is the same."""
    vm = _columns()
    a, hits = _mechanism_curve(vm, [-1, 0, 0], 7e-3, 7, mechanism_curve.SHORT_STEP_RADIUS, monkeypatch)
    b, _ = _mechanism_curve(vm, [-1, 0, 0], 7e-3, 7, 1e300, monkeypatch)
    assert hits and not all(hits)  # the bounded Newton ran and gave up at least once
    assert len(a.points) == len(b.points) and a.points[-1].deflection == pytest.approx(7e-3, rel=1e-12)
    np.testing.assert_allclose(a.deflections, b.deflections, rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.forces, b.forces, rtol=1e-9, atol=1e-12 * np.abs(b.forces).max())
    assert [p.stable for p in a.points] == [p.stable for p in b.points]
    assert len(a.critical) == len(b.critical) >= 1
    for ca, cb in zip(a.critical, b.critical):
        assert ca.kind == cb.kind
        assert ca.force == pytest.approx(cb.force, rel=1e-7)
        assert ca.deflection == pytest.approx(cb.deflection, rel=1e-6, abs=1e-12)


# --------------------------------------------------------------------------- 3. critical_load
RTOL = 1e-7  # critical_load's default rtol (and trace_curve's 1e-3·refine_tol)


def _refined_spy(monkeypatch):
    inner = critical_mod._refined_start
    starts = []

    def spy(*a, **k):
        out = inner(*a, **k)
        starts.append(out)
        return out

    monkeypatch.setattr(critical_mod, "_refined_start", spy)
    return starts


CRITICAL = {
    # the compiled chain path (VJM_PIN_JIT=1, long chains): where _refined_start applies
    "c-s-k4": ("1", lambda: _model_c("s", 4), [-1, 0, 0]),
    "c-s-k8": ("1", lambda: _model_c("s", 8), [-1, 0, 0]),
    "c-s-k4-oblique": ("1", lambda: _model_c("s", 4), [-1, 0.3, 0.2]),
    "c-s-k4-oblique-worst": ("1", lambda: _model_c("s", 4), [-1, 0.24, 0.27]),  # largest error seen
    "c-s-k8-oblique": ("1", lambda: _model_c("s", 8), [-1, -0.4, 0.3]),
    "c-z-k8": ("1", lambda: _model_c("z", 8), [-1, 0.2, -0.1]),
    # the dense path
    "c-s": ("0", lambda: _model_c("s"), [-1, 0, 0]),
    "c-s-k2": ("0", lambda: _model_c("s", 2), [-1, 0, 0]),
    "c-s-oblique": ("0", lambda: _model_c("s"), [-1, 0.3, 0.2]),
    "c-pi": ("0", lambda: _model_c("pi"), [-1, 0, 0]),
    "a-z": ("0", lambda: resolve_model("paper-a-z"), [-1, 0.3, 0]),
    "b-s": ("0", lambda: resolve_model("paper-b-s"), [-1, 0, 0]),
    "b-pi": ("0", lambda: resolve_model("paper-b-pi"), [-1, 0, 0]),
}


@pytest.mark.parametrize("case", sorted(CRITICAL))
def test_critical_load_meets_its_rtol(case, monkeypatch):
    jit, make, d = CRITICAL[case]
    _jit(monkeypatch, jit)
    vm = make()
    d = np.asarray(d, float) / np.linalg.norm(d)
    starts = _refined_spy(monkeypatch)
    r = critical_load(vm, d)
    if jit == "1" and case.startswith("c-s"):
        assert starts and starts[0] is not None  # the refined first point was taken
    ref = critical_load(vm, d, rtol=1e-10)
    assert r.converged and ref.converged and r.kind == ref.kind
    assert abs(r.force - ref.force) <= RTOL * abs(ref.force) + 1e-10 * abs(ref.force)
    assert r.residuals["location"] <= RTOL
    # trace_curve's critical point (its own tolerance 1e-7): within the sum of both
    cp = trace_curve(vm, d, 1.5 * ref.deflection if ref.deflection > 0 else 1e-3, steps=4).critical[0]
    assert cp.kind == r.kind
    assert abs(r.force - cp.force) <= 2 * RTOL * abs(cp.force)
