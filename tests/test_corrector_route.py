"""The corrector's straight route to the one-call compiled loop (``EquilibriumSolver._corrector`` with
``fresh`` inputs: ``_corrector_looped``) against the general route (``_fused_iterations`` then
``_fused_looped``; ``flushed`` :data:`~vjm_pin.solver.equilibrium.FRESH`): the same raw equilibria and the same caches, bit for bit; and the lean objects it
builds (``blocks.LazyBlocks``, ``SpectrumLater.stable_fields``) against the ones they replace."""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.kinematics.chain import flush_tiny
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.equilibrium import FRESH, EquilibriumSolver


def _same(u, v) -> bool:
    """Bit-for-bit equality of arrays, floats and the containers of a raw result or a cache."""
    if isinstance(u, np.ndarray):
        return (isinstance(v, np.ndarray) and u.dtype == v.dtype and u.shape == v.shape
                and u.tobytes() == v.tobytes())
    if isinstance(u, (tuple, list)):
        return type(u) is type(v) and len(u) == len(v) and all(_same(a, b) for a, b in zip(u, v))
    if isinstance(u, dict):
        return isinstance(v, dict) and list(u) == list(v) and all(_same(u[k], v[k]) for k in u)
    if isinstance(u, float):
        return isinstance(v, float) and np.float64(u).tobytes() == np.float64(v).tobytes()
    return u == v


def _state(st):
    return (st.position, st.rotation, st.jacobian, st.hessian)


def _verdict(stab):
    return (type(stab).__name__, stab.stable, stab.null_dim, stab.tolerance, stab.eigenvalues)



def _count_straight_route(monkeypatch) -> dict:
    """Count the calls of ``EquilibriumSolver._corrector_looped`` (the straight route): ``{"n": calls}``."""
    from vjm_pin.solver import equilibrium as eq_mod

    taken = {"n": 0}
    original = eq_mod.EquilibriumSolver._corrector_looped

    def counted(self, *args):
        taken["n"] += 1
        return original(self, *args)

    monkeypatch.setattr(eq_mod.EquilibriumSolver, "_corrector_looped", counted)
    return taken

@pytest.mark.parametrize("name", ["paper-c-s", "paper-b-z"])
def test_straight_route_is_the_general_route(name, monkeypatch):
    """A warm sequence of predicted starts (a curve's steps: each from the equilibrium before, moved):
    the straight route is taken and gives the general route's raw result (configuration, multiplier,
    iterations, state, factorisation, eigenvalues, residuals, verdict), the same ``_fast_its`` where it
    gives way, and leaves the same caches (``_fast_fact``, ``_fast_cache``, ``_fast_cond``, ``kin._last``
    and the kept Blocks, built)."""
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    from vjm_pin.solver.blocks import evaluate_blocks

    taken = _count_straight_route(monkeypatch)
    vm = resolve_model(name)
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    base = EquilibriumSolver(vm)
    a = base.solve(0.002 * d)
    fast = base._sibling(follow_stable=False, restarts=0)
    slow = base._sibling(follow_stable=False, restarts=0)
    cf, cs = fast._corrector_context(), slow._corrector_context()
    rng = np.random.default_rng(11)
    x_prev = a.x.copy()
    kinds = set()
    for i in range(12):
        s = 0.002 + 1e-5 * (i + 1)
        # moved starts: small (converges) and, every fourth step, large (gives way)
        scale = 0.5 if i % 4 == 3 else 1e-6
        x0 = x_prev.copy()
        x0[base.free] += scale * rng.standard_normal(len(base.free))
        x0 = flush_tiny(x0)
        pf, rf = fast._target_pose(s * d)
        ps, rs = slow._target_pose(s * d)
        assert pf.dtype == np.float64 and rf.flags.c_contiguous
        before = taken["n"]
        got = fast._corrector(cf, pf, rf, x0.copy(), FRESH)
        want = slow._corrector(cs, ps, rs, x0.copy(), True)
        assert fast._fast_its == slow._fast_its
        if i:  # (the first call sets the context's loop up: the general route)
            assert taken["n"] == before + 1
        if want is None:
            assert got is None
            kinds.add("gave way")
            continue
        kinds.add("converged")
        x, f, it, st, kf, ev, res, stab, wt = got
        wx, wf, wit, wst, wkf, wev, wres, wstab, wwt = want
        assert _same(x, wx) and _same(f, wf) and it == wit and _same(kf, wkf) and _same(res, wres)
        assert wt is not None and wt.shape == (len(base.free),) * 2 and (wwt is None or _same(wt, wwt))
        assert (ev is None) == (wev is None) and (ev is None or _same(ev, wev))
        assert _same(_state(st), _state(wst))
        assert _same(_verdict(stab), _verdict(wstab))
        # the caches
        assert _same(fast._fast_fact[0], slow._fast_fact[0]) and _same(_state(fast._fast_fact[2]), _state(wst))
        assert _same(fast._fast_fact[3:11], slow._fast_fact[3:11])
        assert _same(fast._fast_cache[0], slow._fast_cache[0]) and _same(fast._fast_cache[1], slow._fast_cache[1])
        assert _same(fast._fast_cond, slow._fast_cond)
        assert fast.kin._last[0] == slow.kin._last[0]
        assert _same(_state(fast.kin._last[1]), _state(slow.kin._last[1]))
        assert fast.kin._blocks_last[1] == slow.kin._blocks_last[1]
        w6 = kf[7]
        bf, bs = evaluate_blocks(vm, fast.kin, x, w6), evaluate_blocks(vm, slow.kin, wx, wkf[7])
        for attr in ("J_theta", "J_q", "H_tt", "H_tq", "H_qt", "H_qq", "K_theta"):
            assert _same(getattr(bf, attr), getattr(bs, attr)), attr
        assert evaluate_blocks(vm, fast.kin, x, w6) is bf  # built once, then kept
        x_prev = x.copy()
    assert kinds == {"gave way", "converged"}
    assert taken["n"] >= 10


def test_straight_route_needs_fresh_inputs(monkeypatch):
    """Without ``FRESH`` (``flushed`` True or False) the corrector takes the general route; with the numpy
    kernel (``VJM_PIN_JIT=0``) there is no straight route at all."""
    taken = _count_straight_route(monkeypatch)
    monkeypatch.setenv("VJM_PIN_JIT", "0")
    vm = resolve_model("paper-c-s")
    d = np.array([-1.0, 0, 0, 0, 0, 0])
    base = EquilibriumSolver(vm)
    a = base.solve(0.002 * d)
    s = base._sibling(follow_stable=False, restarts=0)
    ctx = s._corrector_context()
    p, r = s._target_pose(0.00201 * d)
    for _ in range(3):
        assert s._corrector(ctx, p, r, a.x.copy(), FRESH) is not None
    assert taken["n"] == 0
    import importlib.util

    if importlib.util.find_spec("numba") is not None:
        monkeypatch.setenv("VJM_PIN_JIT", "1")
        s = base._sibling(follow_stable=False, restarts=0)
        ctx = s._corrector_context()
        for _ in range(3):
            assert s._corrector(ctx, p, r, a.x.copy(), True) is not None
            assert s._corrector(ctx, p, r, a.x.copy(), False) is not None
        assert taken["n"] == 0
        assert s._corrector(ctx, p, r, a.x.copy(), FRESH) is not None
        assert taken["n"] == 1


def test_lazy_blocks_are_the_builders_blocks():
    """``LazyBlocks((J, H, nθ, K_θ, state))`` builds the Blocks ``_blocks_builder`` builds (views of the
    same arrays, the same layout), and evaluate_blocks builds a kept one once."""
    from vjm_pin.solver.blocks import Blocks, LazyBlocks, evaluate_blocks
    from vjm_pin.solver.equilibrium import _blocks_builder

    vm = resolve_model("paper-c-s")
    s = EquilibriumSolver(vm)
    r = s.solve(np.array([-1e-4, 0, 0]))
    st = s.kin.evaluate(r.x, hessian=False)
    rng = np.random.default_rng(2)
    m, n, nt = len(s.task), len(s.free), s.nt
    jac, hz = rng.standard_normal((m, n)), rng.standard_normal((n, n))
    lazy = LazyBlocks((jac, hz, nt, vm.K_theta, st))
    got, want = lazy.build(), _blocks_builder(jac, hz, nt, vm.K_theta, st)()
    assert isinstance(got, Blocks) and callable(lazy.build)
    for attr in ("J_theta", "J_q", "H_tt", "H_tq", "H_qt", "H_qq"):
        a, b = getattr(got, attr), getattr(want, attr)
        assert a.shape == b.shape and np.array_equal(a, b) and np.shares_memory(a, jac if attr[0] == "J" else hz)
    assert got.K_theta is vm.K_theta and got.state is st and got.chain is None
    key = r.x.tobytes() + r.wrench.tobytes()
    s.kin._blocks_last = (vm, key, lazy)
    b = evaluate_blocks(vm, s.kin, r.x, r.wrench)
    assert isinstance(b, Blocks) and np.array_equal(b.H_qq, want.H_qq)
    assert evaluate_blocks(vm, s.kin, r.x, r.wrench) is b


def test_spectrum_later_template_is_stable_now():
    """An object from ``SpectrumLater.stable_fields`` (a template, the matrix set after) is the one
    ``stable_now`` builds: the same fields in the same order, the same eigenvalues when first read."""
    from vjm_pin.solver.stability import SpectrumLater

    rng = np.random.default_rng(5)
    a = rng.standard_normal((4, 4))
    sym = -(a @ a.T) - np.eye(4)
    tmpl = SpectrumLater.stable_fields(np.int64(4), np.float64(1e-9), np.linalg.eigvalsh)
    assert tmpl["_matrix"] is None
    got = object.__new__(SpectrumLater)
    got.__dict__.update(tmpl)
    got.__dict__["_matrix"] = sym.copy()
    want = SpectrumLater.stable_now(4, 1e-9, sym.copy(), np.linalg.eigvalsh)
    assert list(got.__dict__) == list(want.__dict__)
    assert {k: v for k, v in got.__dict__.items() if k != "_matrix"} == {
        k: v for k, v in want.__dict__.items() if k != "_matrix"}
    assert type(got.null_dim) is int and type(got.tolerance) is float
    np.testing.assert_array_equal(got.eigenvalues, want.eigenvalues)
    assert got._matrix is None and got.margin == want.margin and got.stable
    assert tmpl["_matrix"] is None  # the template itself is not written
