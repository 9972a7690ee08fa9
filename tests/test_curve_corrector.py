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


def _assert_same_curve(c, g, crit_rel=REL):
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
        _close([q.force, q.deflection, q.stiffness_before, q.force_after],
               [r.force, r.deflection, r.stiffness_before, r.force_after], rel=crit_rel)
        # the stiffness just past a bifurcation, on the branch switched to: a small difference of large
        # terms (paper-c-s: ~2e-5 of the stiffness before), and the switch amplifies the rounding of the
        # located point (paper-a-z: 3e-10 of stiffness_before between the two correctors with the
        # first-order predictor, 1.1e-9 with the second-order one; paper-c-s 9e-12 of it with μ's
        # predicted bracket; the forces equal to 1e-15): compared on the scale of the stiffness before
        scale_k = max(abs(r.stiffness_before), abs(r.stiffness_after))
        assert abs(q.stiffness_after - r.stiffness_after) <= max(1e-8, crit_rel) * scale_k
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
    # an imperfect point (paper-b-z) is the root of dμ/ds at a flat maximum of μ: it moves with the
    # rounding of μ (the two paths factor J differently), ~1e-7 (as tests/test_point_kernel.py says)
    _assert_same_curve(fused, general, crit_rel=1e-6 if name == "paper-b-z" else REL)


def _counting(monkeypatch):
    """Counts of the corrector's calls and of its converged answers (``_corrector``, and the merged
    step's ``_corrector_step`` where its corrector ran)."""
    calls = {"corrector": 0, "converged": 0}
    original = EquilibriumSolver._corrector

    def counted(self, *args, **kwargs):
        calls["corrector"] += 1
        out = original(self, *args, **kwargs)
        calls["converged"] += out is not None
        return out

    merged = EquilibriumSolver._corrector_step

    def counted_merged(self, *args, **kwargs):  # (the merged step's corrector: `(out, raw)`, raw None unless converged)
        out = merged(self, *args, **kwargs)
        if out is not None and out[0][0] != 0:  # (phase 0: rejected before the corrector ran)
            calls["corrector"] += 1
            calls["converged"] += out[1] is not None
        return out

    monkeypatch.setattr(EquilibriumSolver, "_corrector", counted)
    monkeypatch.setattr(EquilibriumSolver, "_corrector_step", counted_merged)
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


def _count_generic_points(monkeypatch) -> dict:
    """Count the calls of the generic point path (``_Tracer.point``)."""
    generic = {"n": 0}
    original_point = curve_mod._Tracer.point

    def point(self, eq, s):
        generic["n"] += 1
        return original_point(self, eq, s)

    monkeypatch.setattr(curve_mod._Tracer, "point", point)
    return generic


def test_point_kernel_declining_falls_back_to_the_generic_point(monkeypatch):
    """When the compiled point kernel declines (here: its rank test made impossible to pass), the fused
    step hands the point to ``_Tracer.point`` and the curve is still the general path's."""
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    vm = resolve_model("paper-c-s")
    general = _trace(vm, [-1, 0, 0], 0.004, 20, False)
    monkeypatch.setattr(curve_mod, "FAST_RANK", 2.0)  # sv.min() > 2·sv.max() never holds
    generic = _count_generic_points(monkeypatch)
    calls = _counting(monkeypatch)
    fused = _trace(vm, [-1, 0, 0], 0.004, 20, True)
    # every converged sub-step that passes the continuity check (nearly all) went to _Tracer.point
    assert calls["converged"] > 0 and generic["n"] >= 0.8 * calls["converged"]
    _assert_same_curve(fused, general)


@pytest.mark.parametrize("merged", [True, False], ids=["merged", "three-calls"])
def test_point_kernel_raising_falls_back_to_the_generic_point(merged, monkeypatch):
    """numba's ``np.linalg`` raises ``LinAlgError`` on an exactly singular matrix: a point kernel that
    raises (here: every call) hands the point to ``_Tracer.point``, merged or not, and the curve is
    still the general path's."""
    from vjm_pin.analysis import point_kernel as pk

    pytest.importorskip("numba")
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    vm = resolve_model("paper-c-s")
    general = _trace(vm, [-1, 0, 0], 0.004, 20, False)
    raised = {"n": 0}

    def raising(*args):
        raised["n"] += 1
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setattr(pk, "_reuse", raising)  # the unmerged step's point on the corrector's QR
    monkeypatch.setattr(pk, "_step", raising if merged else False)  # the merged step (False: not used)
    monkeypatch.setattr(curve_mod, "_merged", merged)
    generic = _count_generic_points(monkeypatch)
    fused = _trace(vm, [-1, 0, 0], 0.004, 20, True)
    assert raised["n"] >= 20 and generic["n"] >= 20
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


def test_compiled_step_helpers_are_the_numpy_expressions():
    """The fused step's compiled helpers (point_kernel.fused) give the numbers of the numpy expressions
    they replace, bit for bit: the tangent prediction ``flush_tiny(x + ds·ẋ)`` (and its second-order
    form) and its scaled move, the
    corrector's continuity check, and the point kernel's numbers with the tangent laid out in (nq,)/(6,)."""
    pytest.importorskip("numba")
    from vjm_pin.analysis import point_kernel as pk
    from vjm_pin.kinematics.chain import flush_tiny

    predict, fused_point, _, predict2 = pk.fused()
    rng = np.random.default_rng(7)
    nq = 9
    free = np.array([0, 2, 3, 5, 6, 8])
    vscale = np.array([1.0, 1.0, 0.37, 1.0, 2.5, 1.0])
    for trial in range(20):
        ax = rng.standard_normal(nq) * 10.0 ** rng.integers(-3, 1, nq)
        xd = rng.standard_normal(nq)
        ds = float(rng.uniform(-1e-3, 1e-3))
        if trial % 4 == 0:  # entries the flush sets to zero (and one it must leave)
            ax[1], xd[1] = 3e-151, 0.0
            ax[4], xd[4] = -2e-152, 1e-300
            ax[7], xd[7] = 2e-150, 0.0
        xp = np.empty(nq)
        move = predict(ax, xd, ds, free, vscale, True, xp)
        want = flush_tiny(ax + ds * xd)
        assert xp.tobytes() == want.tobytes()
        assert move == float(np.abs((want - ax)[free] / vscale).max())
        raw = np.empty(nq)
        predict(ax, xd, ds, free, vscale, False, raw)  # the flush switched off
        assert raw.tobytes() == (ax + ds * xd).tobytes()
        # the second-order prediction (_Tracer.step: dx = ds·ẋ + c·(ẋ − ẋ_back))
        hx = xd + 1e-3 * rng.standard_normal(nq)
        c = float(rng.uniform(-2e-3, 2e-3))
        xp2 = np.empty(nq)
        move2 = predict2(ax, xd, hx, ds, c, free, vscale, True, xp2)
        want2 = flush_tiny(ax + (ds * xd + c * (xd - hx)))
        assert xp2.tobytes() == want2.tobytes()
        assert move2 == float(np.abs((want2 - ax)[free] / vscale).max())
    xd[free[2]] = np.nan
    assert np.isnan(predict(ax, xd, ds, free, vscale, True, np.empty(nq)))

    # the continuity check and the point of a real equilibrium of Model C
    vm = resolve_model("paper-c-s")
    solver = EquilibriumSolver(vm)
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    eq = solver.solve(0.002 * d)
    tr = curve_mod._Tracer(vm, d, 0.004, solver, 1e-4)
    kern = tr.kernel
    b = tr.blocks(eq.x, eq.wrench)
    hz = kern.hessian(b)
    j6 = np.ascontiguousarray(b.state.jacobian)
    args = (kern.kz, kern.task, kern.dt, tr.mask, np.asarray(eq.wrench, float), kern.nt, True, pk.FAST_RANK,
            curve_mod.SINGULAR_RCOND)
    want = pk.compiled()(np.ascontiguousarray(j6.take(tr.free, axis=1)), hz, *args)
    assert want[0] == 0
    x_pred = eq.x.copy()
    x_pred[tr.free] += 1e-4 * _scaled_pattern(tr)
    corr = float(np.abs((eq.x - x_pred)[tr.free] / tr.var_scale).max())
    x_dot, w_dot = np.full(vm.model.nq, np.nan), np.full(6, np.nan)
    got = fused_point(eq.x, x_pred, corr * (1 - 1e-12), tr.free, tr.var_scale, j6, hz, *args, x_dot, w_dot)
    assert got[0] == -1 and np.isnan(x_dot).all()  # strayed: nothing else done
    got = fused_point(eq.x, x_pred, corr, tr.free, tr.var_scale, j6, hz, *args, x_dot, w_dot)
    assert got[0] == 0
    _, k, xd_w, fd_w, mu, rate = want
    assert (got[1], got[2], got[3]) == (k, mu, rate)
    lay_x, lay_w = np.zeros(vm.model.nq), np.zeros(6)
    lay_x[tr.free] = xd_w
    lay_w[tr.task] = fd_w
    assert x_dot.tobytes() == lay_x.tobytes() and w_dot.tobytes() == lay_w.tobytes()


def _scaled_pattern(tr):
    """A displacement pattern of the free coordinates, scaled as the tracer scales them."""
    return tr.var_scale * np.linspace(-1.0, 1.0, len(tr.free))


def test_corrector_result_reads_as_the_general_result(jit):
    """``_corrector_result`` computes q, θ, the deflection, the end placement and the energy when first
    read (DeferredResult): every field equals the general path's (``_solve_local``) bit for bit, read in
    any order, and it behaves as an EquilibriumResult (replace, frozen, copy and pickle: plain results)."""
    import copy
    import dataclasses
    import pickle

    from vjm_pin.solver.equilibrium import EquilibriumResult

    vm = resolve_model("paper-c-s")
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    base = EquilibriumSolver(vm)
    a = base.solve(0.002 * d)
    x0 = a.x.copy()
    x0[base.free] += 1e-5
    s_vec = 0.0021 * d
    want = base._sibling(follow_stable=False, restarts=0)._solve_local(s_vec, x0)
    new = base._sibling(follow_stable=False, restarts=0)
    p_t, r_t = new._target_pose(s_vec)
    ctx = new._corrector_context()
    names = [f.name for f in dataclasses.fields(EquilibriumResult)]

    def same(u, v):
        if isinstance(u, np.ndarray):
            return isinstance(v, np.ndarray) and u.shape == v.shape and u.tobytes() == v.tobytes()
        if isinstance(u, float):
            return isinstance(v, float) and np.float64(u).tobytes() == np.float64(v).tobytes()
        if isinstance(u, (bool, int, str, tuple, dict)):
            return u == v
        return (u is None) == (v is None)

    for order in (names, names[::-1]):
        got = new._corrector_result(new._corrector(ctx, p_t, r_t, x0), p_t, r_t)
        assert isinstance(got, EquilibriumResult)
        for k in order:
            assert same(getattr(got, k), getattr(want, k)), k
        assert got.q is got.q and not np.shares_memory(got.q, got.x)  # kept, and its own array
        got.x[:] = 0.0  # the result's arrays are the caller's: the derived fields do not depend on them
    got = new._corrector_result(new._corrector(ctx, p_t, r_t, x0), p_t, r_t)
    got.x[:] = np.nan
    assert same(got.theta, want.theta) and same(got.energy, want.energy)
    with pytest.raises(dataclasses.FrozenInstanceError):
        got.energy = 1.0
    moved = dataclasses.replace(got, path="x")
    assert moved.path == "x" and same(moved.deflection, want.deflection) and same(moved.energy, want.energy)
    fresh = new._corrector_result(new._corrector(ctx, p_t, r_t, x0), p_t, r_t)
    for back in (pickle.loads(pickle.dumps(fresh)), copy.copy(fresh), copy.deepcopy(fresh)):
        assert type(back) is EquilibriumResult and list(vars(back)) == names
        assert all(same(getattr(back, k), getattr(want, k)) for k in names)


def _deferred_trace(vm, direction, md, steps, defer: bool):
    """:func:`trace_curve` with the corrector's lazy eq. (23) verdict on or off (the private switch
    ``equilibrium._corrector_defer``): the points and the stability results of their equilibria."""
    from vjm_pin.solver import equilibrium as eq_mod

    old = eq_mod._corrector_defer
    eq_mod._corrector_defer = defer
    try:
        return trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    finally:
        eq_mod._corrector_defer = old


@pytest.mark.parametrize("name,direction,md,steps", CASES[:3], ids=[c[0] for c in CASES[:3]])
def test_lazy_corrector_verdict_keeps_the_curve(name, direction, md, steps, monkeypatch):
    """With the compiled kernel the corrector certifies "stable" without the eigenvalues of eq. (23)
    (SpectrumLater, the tracer's ``_LateBP``): the curve, its critical points and every point's
    eigenvalues, read afterwards, are those of the eager verdict (the same LAPACK call: bit for bit),
    and the tracer itself never asks for them on those points."""
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    from vjm_pin.solver.stability import SpectrumLater

    vm = resolve_model(name)
    computed = {"n": 0}
    spectrum = SpectrumLater.eigenvalues.fget

    def counted(self):
        computed["n"] += self._spectrum is None
        return spectrum(self)

    monkeypatch.setattr(SpectrumLater, "eigenvalues", property(counted))
    lazy = _deferred_trace(vm, direction, md, steps, True)
    during = computed["n"]
    late = [p for p in lazy.points if type(p.equilibrium.stability) is SpectrumLater]
    eager = _deferred_trace(vm, direction, md, steps, False)
    assert len(late) >= len(lazy.points) // 2  # the common point of a stable stretch
    assert during <= len(lazy.points) - len(late)  # (only the few the tracer's switch reads)
    _assert_same_curve(lazy, eager)
    for p, q in zip(lazy.points, eager.points):
        a, b = p.equilibrium.stability, q.equilibrium.stability
        assert a.stable == b.stable and a.null_dim == b.null_dim and a.tolerance == b.tolerance
        assert np.array_equal(a.eigenvalues, b.eigenvalues)
        assert a.margin == b.margin
    assert all(p.stable for p in late)


def test_late_point_answers_from_the_certificate():
    """``_LateBP``: below/above the tracer's threshold answered from the certified verdict without
    the spectrum while that threshold is not above the solver's; beyond it, and for ``lam`` itself,
    the largest eigenvalue of the kept matrix, read once."""
    from vjm_pin.solver.stability import SpectrumLater

    sym = np.array([[-3.0, 0.5], [0.5, -2.0]])
    calls = {"n": 0}

    def spectrum(m):
        calls["n"] += 1
        return np.linalg.eigvalsh(m)

    largest = float(np.linalg.eigvalsh(sym)[-1])

    def point():
        st = SpectrumLater(True, 2, 1e-3, sym.copy(), spectrum)
        return curve_mod._LateBP(0.0, None, 1.0, 5.0, -1.0, st)

    p = point()
    assert p.below(1e-3) and not p.above(1e-3) and p.below(1e-6) and calls["n"] == 0
    assert p.below(1.0) and calls["n"] == 1  # a threshold above the certificate's: the spectrum
    assert p.lam == largest and calls["n"] == 1
    assert not p.below(2.0) and p.above(2.0)  # (λ_max ≈ −1.79 ≥ −2: from the value now)
    q = point()
    assert q.lam == largest and calls["n"] == 2 and q.below(1e-3) and q.above(-largest)
    plain = curve_mod._BP(0.0, None, 1.0, 5.0, None, -1.0, largest)
    for thr in (1e-3, 1.0, 1.6, 2.0, 3.0):
        assert point().below(thr) == plain.below(thr) == (largest < -thr)
        assert point().above(thr) == plain.above(thr) == (largest >= -thr)
