"""The serial tracer's fused warm corrector (``vjm_pin.analysis.curve._Tracer._fused_step`` and
``EquilibriumSolver._corrector``) against the general path it replaces (``_solve_local`` then
``_Tracer.point``; private switch ``curve._fused_corrector``): the same curves, critical points and
verdicts, with the compiled kernels and with their numpy twins, and the fallbacks taken."""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.analysis import curve as curve_mod
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.equilibrium import EquilibriumSolver

#: (model, direction, max deflection, steps): Model C buckling (bifurcation and branch switch),
#: the Z postures (imperfect bifurcation of Model B, the knee of Model C), Model A.
CASES = [
    ("paper-c-s", [-1, 0, 0], 0.004, 40),
    ("paper-b-z", [-1, 0, 0], 0.1, 20),
    ("paper-c-z", [-1, 0, 0], 0.012, 20),
    ("paper-a-z", [-1, 0, 0], 0.2, 15),
]
REL = 1e-10


def _trace(vm, direction, md, steps, fused: bool):
    old = curve_mod._fused_corrector
    curve_mod._fused_corrector = fused
    try:
        return trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    finally:
        curve_mod._fused_corrector = old


def _close(a, b, rel=REL):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    assert np.array_equal(np.isfinite(a), np.isfinite(b))
    fin = np.isfinite(a)
    if fin.any():
        scale = max(float(np.abs(b[fin]).max()), 1e-300)
        assert float(np.abs(a[fin] - b[fin]).max()) <= rel * scale


def _assert_same_curve(c, g):
    assert len(c.points) == len(g.points)
    _close(c.deflections, g.deflections)
    _close(c.forces, g.forces)
    # mirror-image post-buckling branches are a rounding tie: compare |x|
    _close([np.abs(p.equilibrium.x) for p in c.points], [np.abs(p.equilibrium.x) for p in g.points])
    _close([p.stiffness for p in c.points], [p.stiffness for p in g.points])
    _close([p.force_control_margin for p in c.points], [p.force_control_margin for p in g.points])
    assert [p.stable for p in c.points] == [p.stable for p in g.points]
    assert [p.stable_end_held for p in c.points] == [p.stable_end_held for p in g.points]
    assert [q.kind for q in c.critical] == [q.kind for q in g.critical]
    for q, r in zip(c.critical, g.critical):
        _close([q.force, q.deflection, q.stiffness_before, q.stiffness_after, q.force_after],
               [r.force, r.deflection, r.stiffness_before, r.stiffness_after, r.force_after])
        assert q.index == r.index


@pytest.fixture(params=["0", "1"], ids=["numpy", "compiled"])
def jit(request, monkeypatch):
    if request.param == "1":
        pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", request.param)
    return request.param


@pytest.mark.parametrize("name,direction,md,steps", CASES, ids=[c[0] for c in CASES])
def test_fused_corrector_keeps_the_curve(jit, name, direction, md, steps):
    vm = resolve_model(name)
    fused = _trace(vm, direction, md, steps, True)
    general = _trace(vm, direction, md, steps, False)
    assert fused.critical, "each case has a critical point (the fused path must go through it)"
    _assert_same_curve(fused, general)


def _counting(monkeypatch):
    """Counts of the corrector's calls and of its converged answers."""
    calls = {"corrector": 0, "converged": 0}
    original = EquilibriumSolver._corrector

    def counted(self, *args, **kwargs):
        calls["corrector"] += 1
        out = original(self, *args, **kwargs)
        calls["converged"] += out is not None
        return out

    monkeypatch.setattr(EquilibriumSolver, "_corrector", counted)
    return calls


def test_fused_path_is_the_common_step(jit, monkeypatch):
    """Nearly every sub-step of a buckling curve takes the fused corrector (a curve through a
    bifurcation); with the switch off it is never called."""
    vm = resolve_model("paper-c-s")
    calls = _counting(monkeypatch)
    steps = {"n": 0}
    original_step = curve_mod._Tracer.step

    def step(self, *args):
        steps["n"] += 1
        return original_step(self, *args)

    monkeypatch.setattr(curve_mod._Tracer, "step", step)
    c = _trace(vm, [-1, 0, 0], 0.004, 40, True)
    assert c.critical and c.critical[0].kind == "bifurcation"
    assert calls["converged"] >= 0.8 * steps["n"]
    calls["corrector"] = 0
    _trace(vm, [-1, 0, 0], 0.004, 40, False)
    assert calls["corrector"] == 0


def test_point_kernel_declining_falls_back_to_the_generic_point(monkeypatch):
    """When the compiled point kernel declines (here: its rank test made impossible to pass), the fused
    step hands the point to ``_Tracer.point`` and the curve is still the general path's."""
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    vm = resolve_model("paper-c-s")
    general = _trace(vm, [-1, 0, 0], 0.004, 20, False)
    monkeypatch.setattr(curve_mod, "FAST_RANK", 2.0)  # sv.min() > 2·sv.max() never holds
    generic = {"n": 0}
    original_point = curve_mod._Tracer.point

    def point(self, eq, s):
        generic["n"] += 1
        return original_point(self, eq, s)

    monkeypatch.setattr(curve_mod._Tracer, "point", point)
    calls = _counting(monkeypatch)
    fused = _trace(vm, [-1, 0, 0], 0.004, 20, True)
    # every converged sub-step that passes the continuity check (nearly all) went to _Tracer.point
    assert calls["converged"] > 0 and generic["n"] >= 0.8 * calls["converged"]
    _assert_same_curve(fused, general)


@pytest.mark.parametrize("name", ["paper-c-s", "paper-b-z"])
def test_corrector_is_the_local_solve(jit, name):
    """``EquilibriumSolver._corrector`` from predicted starts: the equilibrium, iterations, residuals
    and verdict of ``_solve_local`` (the general path), and None exactly where it gives way."""
    vm = resolve_model(name)
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    base = EquilibriumSolver(vm)
    a = base.solve(0.002 * d)
    rng = np.random.default_rng(3)
    kinds = set()
    for scale in (1e-6, 1e-4, 1e-2, 0.3, 1.0):
        x0 = a.x.copy()
        x0[base.free] += scale * rng.standard_normal(len(base.free))
        s_vec = 0.0021 * d
        ref = base._sibling(follow_stable=False, restarts=0)
        new = base._sibling(follow_stable=False, restarts=0)
        want = ref._solve_local(s_vec, x0)
        ctx = new._corrector_context()
        assert ctx is not None
        p_t, r_t = new._target_pose(s_vec)
        raw = new._corrector(ctx, p_t, r_t, x0)
        assert new._fast_its == ref._fast_its
        if want is None:
            assert raw is None
            kinds.add("gave way")
            continue
        kinds.add("converged")
        got = new._corrector_result(raw, p_t, r_t)
        np.testing.assert_array_equal(got.x, want.x)
        np.testing.assert_array_equal(got.wrench, want.wrench)
        np.testing.assert_array_equal(got.deflection, want.deflection)
        assert got.iterations == want.iterations and got.path == want.path
        assert got.residuals == want.residuals and got.energy == want.energy
        assert got.stable == want.stable
        np.testing.assert_array_equal(got.stability.eigenvalues, want.stability.eigenvalues)
        # the caches the general path leaves (the next warm start and the point's Blocks)
        from vjm_pin.solver.blocks import evaluate_blocks

        bg = evaluate_blocks(vm, new.kin, got.x, got.wrench)
        bw = evaluate_blocks(vm, ref.kin, want.x, want.wrench)
        np.testing.assert_array_equal(bg.H_tt, bw.H_tt)
        np.testing.assert_array_equal(bg.J_theta, bw.J_theta)
    assert kinds == {"gave way", "converged"}
