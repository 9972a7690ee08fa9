"""The fused Newton iteration (vjm_pin.solver.kernel): the compiled kernel against its numpy twin and
both against the solver's unfused path (``_fast_factor`` / ``_fast_descent_step`` / ``_fast_step``),
whole solves and a short curve with the compiled kernel on and off, the numpy fallback without
numba, and the import policy (a one-shot run never imports numba).

The first test that needs the compiled kernel compiles it (numba, cached on disk next to the
module; later runs load it)."""

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import equilibrium as eqmod
from vjm_pin.solver import kernel
from vjm_pin.solver.blocks import evaluate_blocks
from vjm_pin.solver.equilibrium import EquilibriumSolver
from vjm_pin.solver.stability import check_stability

from .chains import random_vjm, ur5_link_springs

numba = pytest.importorskip("numba")


def rel(a, b, scale=None):
    s = max(np.abs(b).max() if scale is None else scale, 1e-300)
    return np.abs(np.asarray(a) - np.asarray(b)).max() / s


@pytest.fixture(scope="module")
def compiled():
    fn = kernel._load_compiled()
    assert fn, "numba is installed: the compiled kernel must load"
    return fn


CASES = {
    "model-c": lambda: resolve_model("paper-c-s"),
    "model-c-k2": lambda: load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=2)),
    "ur5-link-springs": ur5_link_springs,
    "prismatic-6row": lambda: random_vjm(3, n_joints=6, n_passive=1, link_springs=2),
    "prismatic-3row": lambda: random_vjm(4, n_joints=5, n_passive=2, link_springs=2, task=("x", "y", "z")),
}


def _points(vm, rng, s):
    """(x, target position, target rotation) triples: near the reference (not converged: a descent
    step) and an equilibrium under a small load with its own end pose (converged)."""
    kin = s.kin
    out = []
    for amp in (1e-3, 2e-2):
        x = vm.reference + rng.uniform(-amp, amp, vm.model.nq)
        p, r = kin.placement(vm.reference + rng.uniform(-amp, amp, vm.model.nq))
        out.append((x, p, r))
    return out


def _kernel_inputs(s, x, p_t, r_t):
    st = Kinematics(s.vm.model, s.vm.frame_id).evaluate(x, hessian=False)
    erot = pin.log3(r_t @ st.rotation.T) if s._ir.size else np.zeros(3)
    consts, _ = s._kernel_consts()
    return np.ascontiguousarray(st.jacobian), st.position.copy(), erot, kernel.with_target(consts, p_t)


def _unfused(s, x, p_t, r_t):
    """The solver's unfused quantities at x: (f, r, tau, hz, R, e, descent step, polish step, ev)."""
    m, n = len(s.task), len(s.free)
    big = n > eqmod.SCIPY_LAPACK_MAX_N
    f6 = np.zeros(6)
    st, jac, qf, rr, f, r, tau, hz = s._fast_factor(x, f6, np.zeros((n, n), order="F"), big)
    y, z = qf[:, :m], qf[:, m:]
    e, ep, er = s._fast_error(st, p_t, r_t)
    s._ref_errors = (jac, e, ep, er)
    dx = s._fast_descent_step(hz, y, z, rr, e, r, big)
    step, red = s._fast_step(s._kz, hz, z, y, rr, e, r, big)
    neg = -red
    ev = np.linalg.eigvalsh(0.5 * (neg + neg.T))
    return f, r, tau, hz, np.triu(rr[:, :m]), dx, step, ev, np.linalg.cond(red)


def step_tol(cond):
    """Rounding differences of a step solved with ZᵀWZ grow with its condition number: 1e-12
    relative, or 1e-15·cond(ZᵀWZ) at the (random, ill-conditioned) points where that is larger."""
    return max(1e-12, 1e-15 * cond)


@pytest.mark.parametrize("case", sorted(CASES))
def test_fused_iteration_matches_unfused_path(case, compiled):
    """One iteration: multiplier, residual, ∇E, screw Hessian, R, descent / polish steps, new
    iterate and the eigenvalues of eq. (23): compiled = numpy twin = unfused path (1e-12 relative)."""
    vm = CASES[case]()
    rng = np.random.default_rng(sum(map(ord, case)))
    for follow in (True, False):
        s = EquilibriumSolver(vm, follow_stable=follow)
        for x, p_t, r_t in _points(vm, rng, s):
            f, r, tau, hz, rr, dx_ref, _, _, cond = _unfused(s, x, p_t, r_t)
            jac_ref, e_ref, ep_ref, er_ref = s._ref_errors
            kkt_ref = np.linalg.norm(e_ref / s._err_scale) + np.linalg.norm(r) / s.kscale
            j6, pos, erot, consts = _kernel_inputs(s, x, p_t, r_t)
            dummy = eqmod._KERNEL_DUMMY[:8]
            outs = {}
            for name, fn in (("numpy", kernel.iterate_numpy), ("compiled", compiled)):
                outs[name] = (fn(j6, pos, erot, x, True, False, True, True, dummy, consts),
                              fn(j6, pos, erot, x, True, True, True, True, dummy, consts))
            tscale = max(np.abs(tau).max(), 1e-6 * s.kscale)
            for name, (a, _) in outs.items():
                status, kkt, ep, er, rs, fact, dx, xn, _ = a
                jac, _, rk, fk, rk_res, tauk, hzk, f6 = fact
                np.testing.assert_array_equal(jac, jac_ref)
                assert ep == ep_ref and er == er_ref, (name, "task error")
                assert abs(rs - np.abs(r).max()) <= 1e-12 * tscale, (name, "max residual")
                assert abs(kkt - kkt_ref) <= 1e-12 * kkt_ref, (name, "KKT norm")
                assert rel(fk, f) < 1e-12, (name, "multiplier")
                assert rel(rk_res, r, tscale) < 1e-12, (name, "residual")
                assert rel(tauk, tau, tscale) < 1e-12, (name, "grad E")
                assert rel(hzk, hz) < 1e-12, (name, "screw Hessian")
                assert rel(np.triu(rk), rr) < 1e-12, (name, "R")
                np.testing.assert_array_equal(f6[s.task], fk)
                assert status in (kernel.CONTINUE, kernel.STEP_FAIL), (name, status)  # none converged
                if dx_ref is None:
                    assert status == kernel.STEP_FAIL, name
                else:
                    assert status == kernel.CONTINUE, name
                    assert rel(dx, dx_ref) < step_tol(cond), (name, "descent step")
                    moved = x.copy()
                    moved[s.free] += dx
                    np.testing.assert_array_equal(xn, moved)  # nothing tiny to flush here
            # the same iteration with the numpy fallback and compiled: same verdicts
            assert outs["numpy"][0][0] == outs["compiled"][0][0]
            assert abs(outs["numpy"][0][1] - outs["compiled"][0][1]) <= 1e-12 * outs["numpy"][0][1]
            # polish flag without convergence: still the descent step
            assert outs["compiled"][1][0] == outs["compiled"][0][0]
            # at its own end pose with a loose residual test the point counts as converged: the
            # unmodified (polish) step and, without polish, eq. (23)
            st = Kinematics(vm.model, vm.frame_id).evaluate(x, hessian=False)
            loose = s._sibling(tol=1e-4, follow_stable=follow)
            loose.kscale = s.kscale * 1e12
            _, _, _, _, _, _, step_c, ev_c, cond_c = _unfused(loose, x, st.position, st.rotation)
            j6c, posc, erotc, cc = _kernel_inputs(loose, x, st.position, st.rotation)
            for fn in (kernel.iterate_numpy, compiled):
                a = fn(j6c, posc, erotc, x, True, False, True, False, dummy, cc)
                assert a[0] in (kernel.CONVERGED, kernel.RANK_FAIL)
                if a[0] == kernel.CONVERGED:
                    assert rel(a[8], ev_c) < 1e-12, "eq. (23) eigenvalues"
                b = fn(j6c, posc, erotc, x, True, True, True, True, dummy, cc)
                if step_c is not None and np.abs(step_c / s.var_scale).max() > eqmod.POLISH_STEP:
                    assert b[0] == kernel.POLISH
                    assert rel(b[6], step_c) < step_tol(cond_c), "polish step"


def _column_solves(vm, direction, span, n):
    s = EquilibriumSolver(vm)
    prev, out = None, []
    for t in np.linspace(span / n, span, n):
        r = s.solve(t * direction, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
        out.append(r)
        prev = r
    return s, out


def _with_jit(monkeypatch, value, fn):
    monkeypatch.setenv("VJM_PIN_JIT", value)
    try:
        return fn()
    finally:
        monkeypatch.delenv("VJM_PIN_JIT")


@pytest.mark.parametrize("case", ["model-c", "ur5-link-springs", "prismatic-6row"])
def test_whole_solves_agree_with_and_without_jit_and_unfused(case, compiled, monkeypatch):
    """Warm-started solves (Model C past buckling): compiled, numpy twin and the unfused path give the
    same equilibria, wrenches, paths and verdicts (1e-10); the Blocks the solver remembers are
    those evaluated afresh."""
    vm = CASES[case]()
    if case == "model-c":
        direction, span = np.array([-1.0, 0, 0, 0, 0, 0]), 6e-5
    elif case == "ur5-link-springs":
        direction, span = np.array([0, 0, -1.0, 0, 0, 0]), 1e-3
    else:
        direction, span = np.array([1.0, -0.5, 0.3, 0, 0, 0]) * 1e-2, 1.0
    runs = {
        "compiled": lambda: _with_jit(monkeypatch, "1", lambda: _column_solves(vm, direction, span, 10)),
        "numpy": lambda: _with_jit(monkeypatch, "0", lambda: _column_solves(vm, direction, span, 10)),
    }
    got = {k: f() for k, f in runs.items()}
    monkeypatch.setattr(eqmod, "_fused_enabled", False)
    got["unfused"] = _column_solves(vm, direction, span, 10)
    monkeypatch.setattr(eqmod, "_fused_enabled", True)
    ref = got["unfused"][1]
    for name in ("compiled", "numpy"):
        s, res = got[name]
        for a, b in zip(res, ref):
            assert a.converged and b.converged and a.stable == b.stable and a.path == b.path, name
            assert a.iterations == b.iterations, name
            assert rel(a.wrench, b.wrench) < 1e-10, name
            assert np.abs(a.x - b.x).max() < 1e-10, name
            assert rel(a.stability.eigenvalues, b.stability.eigenvalues) < 1e-10, name
            for k in ("position", "orientation", "statics"):
                assert abs(a.residuals[k] - b.residuals[k]) <= 1e-10 * max(abs(b.residuals[k]), 1e-300) or (
                    abs(a.residuals[k] - b.residuals[k]) < 1e-15 * max(s.kscale, 1.0)), (name, k)
        # the remembered Blocks and verdict at the last point = fresh ones (a new Kinematics)
        last = res[-1]
        cached = evaluate_blocks(vm, s.kin, last.x, last.wrench)
        fresh = evaluate_blocks(vm, Kinematics(vm.model, vm.frame_id), last.x, last.wrench)
        for attr in ("J_theta", "J_q", "H_tt", "H_tq", "H_qt", "H_qq"):
            if getattr(fresh, attr).size:
                assert rel(getattr(cached, attr), getattr(fresh, attr)) < 1e-12, (name, attr)
        assert rel(check_stability(fresh).eigenvalues, last.stability.eigenvalues) < 1e-10, name


def test_short_curve_agrees_with_and_without_jit(compiled, monkeypatch):
    from vjm_pin.analysis.curve import trace_curve

    vm = resolve_model("paper-c-s")
    direction = np.array([-1.0, 0, 0, 0, 0, 0])

    def curve():
        return trace_curve(vm, direction, 8e-5, steps=12)

    a = _with_jit(monkeypatch, "1", curve)
    b = _with_jit(monkeypatch, "0", curve)
    fa, fb = np.array([p.force for p in a.points]), np.array([p.force for p in b.points])
    assert fa.shape == fb.shape and len(fa) >= 12
    assert rel(fa, fb) < 1e-10
    assert [p.stable for p in a.points] == [p.stable for p in b.points]
    assert len(a.critical) == len(b.critical)
    for ca, cb in zip(a.critical, b.critical):
        assert abs(ca.force - cb.force) <= 1e-10 * abs(cb.force)


def test_fallback_without_numba(monkeypatch):
    """numba not importable: the kernel is the numpy twin even when asked for, and solves run."""
    monkeypatch.setattr(kernel, "_compiled", None)
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba -> ImportError
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    assert kernel.get() is kernel.iterate_numpy
    assert kernel.load() is False
    vm = resolve_model("paper-c-s")
    r = EquilibriumSolver(vm).solve(np.array([-2e-5, 0, 0, 0, 0, 0]))
    assert r.converged and r.stable
    assert r.residuals["statics"] <= 1e-10 * np.abs(r.wrench).max() * 10


def test_import_policy(compiled, monkeypatch):
    """VJM_PIN_JIT=0 always numpy; auto: numpy until JIT_AFTER_ITERATIONS numpy iterations ran, or
    once loaded; =1 compiled."""
    monkeypatch.setenv("VJM_PIN_JIT", "0")
    assert kernel.get() is kernel.iterate_numpy
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    assert kernel.get() is compiled
    monkeypatch.delenv("VJM_PIN_JIT")
    monkeypatch.setattr(kernel, "_compiled", None)
    monkeypatch.setattr(kernel, "_numpy_iterations", 0)
    assert kernel.get() is kernel.iterate_numpy
    monkeypatch.setattr(kernel, "_numpy_iterations", kernel.JIT_AFTER_ITERATIONS)
    assert kernel.get() not in (None, kernel.iterate_numpy)  # loads it (from numba's cache)
    assert kernel.loaded()


def test_one_shot_run_does_not_import_numba():
    code = (
        "import sys\n"
        "from vjm_pin.cli import main\n"
        "rc = main(['analyze', 'paper-c-s', '--deflection', '-0.00002', '0', '0'])\n"
        "assert rc == 0, rc\n"
        "assert 'numba' not in sys.modules, 'numba imported by a one-shot analyze'\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "VJM_PIN_JIT"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env, check=False)
    assert out.returncode == 0, out.stderr[-2000:]


def test_lean_verdict_certificate_agrees_with_the_eigenvalues(compiled):
    """``_certified_stable`` (Cholesky past ``thr + δ``) certifies only matrices whose computed largest
    eigenvalue is below ``−thr``, and every one clearly below; undecided near the threshold (the caller
    then computes the eigenvalues). ``_cond_bound`` bounds ``σ_max/σ_min`` from above (inf when
    singular or not finite)."""
    assert kernel.lean() is not None
    rng = np.random.default_rng(7)
    thr = 1e-3
    for nz in (1, 2, 5, 17):
        for gap in (1e-2, 1e-6, 1e-9, 1e-13, 0.0, -1e-13, -1e-9, -1e-3):
            qm, _ = np.linalg.qr(rng.standard_normal((nz, nz)))
            lam = -thr - np.abs(rng.standard_normal(nz)) * 5.0 - gap
            lam[0] = -thr - gap  # the largest: gap below −thr (above it when negative)
            sym = np.ascontiguousarray((qm * lam) @ qm.T)
            sym = 0.5 * (sym + sym.T)
            ev = kernel.spectrum(sym)
            cert = kernel._certified_stable(sym, nz, thr)
            assert cert == kernel._certified_stable.py_func(sym, nz, thr)
            if cert:
                assert ev[-1] < -thr
            if gap >= 1e-6:
                assert cert
            if gap <= 0.0:
                assert not cert
    for m in (1, 3, 6):
        for scale in (1.0, 1e-6, 1e-12):
            rr = np.triu(rng.standard_normal((m, m)))
            rr[m - 1, m - 1] *= scale
            sv = np.linalg.svd(rr, compute_uv=False)
            c = kernel._cond_bound(rr, m)
            assert sv[0] / sv[-1] <= c * (1 + 1e-12) and c == kernel._cond_bound.py_func(rr, m)
        sing = np.triu(rng.standard_normal((m, m)))
        sing[m - 1, m - 1] = 0.0
        assert kernel._cond_bound(sing, m) == np.inf
        sing[0, 0] = np.nan
        assert not 1e-10 * kernel._cond_bound(sing, m) < 0.5


@pytest.mark.parametrize("case", ["model-c", "ur5-link-springs", "prismatic-6row"])
def test_compiled_restoration_matches_the_numpy_one(case, compiled, monkeypatch):
    """``_restore`` with the compiled step (``kernel._restore_step``, in the whole compiled restoration
    ``kernel._restore_into`` with the compiled kinematics) against its numpy loop from configurations
    pushed off an equilibrium (the escape's starts) and from a far, damped start: the same steps to
    rounding, the same number of kinematics evaluations and the same verdict."""
    vm = CASES[case]()
    s = eqmod.EquilibriumSolver(vm)
    d = np.zeros(6)
    d[s.task[0]] = -1e-4
    r = s.solve(d)
    p_t, r_t = s._target_pose(d * 1.05)
    rng = np.random.default_rng(3)
    assert kernel.restorer() is not None
    for amp in (1e-3, 3e-2, 1.0):
        x0 = r.x.copy()
        x0[s.free] += amp * rng.standard_normal(len(s.free))
        got = {}
        for jit in ("0", "1"):
            monkeypatch.setenv("VJM_PIN_JIT", jit)
            steps = []
            inner = s.kin.evaluate

            def evaluate(x, hessian=True, inner=inner, steps=steps):
                steps.append(1)
                return inner(x, hessian)

            monkeypatch.setattr(s.kin, "evaluate", evaluate)
            loop = kernel.restore_looped()
            if loop is not None:  # the compiled restoration: its count of evaluations

                def counted(*a, loop=loop, steps=steps):
                    status, evals = loop(*a)
                    steps.extend([1] * evals)
                    return status, evals

                monkeypatch.setattr(kernel, "_restore_looped", counted)
            s.kin._last = None
            x, _st, ok = s._restore(x0.copy(), None, p_t, r_t)
            monkeypatch.undo()
            got[jit] = (x, ok, len(steps))
        (xa, oka, na), (xb, okb, nb) = got["0"], got["1"]
        assert (oka, na) == (okb, nb)
        # (rounding, amplified by the conditioning of the damped steps from the far start)
        assert rel(xb, xa, scale=np.abs(xa).max()) < (1e-12 if amp < 1.0 else 1e-10), amp


def test_lu_elimination_is_a_solve_with_dgesv_failures(compiled):
    """``_lu_eliminate`` (the partially pivoted LU of ``_step_t`` and ``_restore_step``) then
    ``_back_substitute`` solve ``A x = b`` as ``numpy.linalg.solve`` does (to rounding), compiled and
    as plain Python alike (bit for bit); an exactly zero pivot — a zero column, a zero matrix — fails,
    and a pivot chosen by the largest magnitude solves a matrix whose leading entry is zero."""
    assert kernel._load_compiled()
    rng = np.random.default_rng(11)
    for k in (1, 2, 3, 6, 17):
        for trial in range(4):
            a = rng.standard_normal((k, k))
            if trial == 1 and k > 1:
                a[0, 0] = 0.0  # (needs the row swap)
            b = rng.standard_normal(k)
            want = np.linalg.solve(a, b)
            outs = []
            for fn in (kernel._lu_eliminate, kernel._lu_eliminate.py_func):
                lu, y = a.copy(), b.copy()
                assert fn(lu, y, k)
                outs.append(kernel._back_substitute(lu, y, k))
            assert outs[0].tobytes() == outs[1].tobytes()
            assert np.allclose(outs[0], want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
        for bad in (np.zeros((k, k)), np.hstack([rng.standard_normal((k, k - 1)), np.zeros((k, 1))])):
            for fn in (kernel._lu_eliminate, kernel._lu_eliminate.py_func):
                assert not fn(bad.copy(), np.ones(k), k)


def test_mode_follows_every_change_of_the_environment(monkeypatch):
    """``mode()`` keeps the parse of the last ``VJM_PIN_JIT`` value it read and reads the variable at
    every call: each change (set, changed, unset, set back) gives the mode of the new value."""
    for raw, want in (("1", "1"), (" Off ", "0"), ("off", "0"), ("YES", "1"), (None, "auto"), ("0", "0"),
                      ("maybe", "auto"), ("1", "1"), ("1", "1"), (None, "auto"), ("false", "0")):
        if raw is None:
            monkeypatch.delenv("VJM_PIN_JIT", raising=False)
        else:
            monkeypatch.setenv("VJM_PIN_JIT", raw)
        assert kernel.mode() == want, raw


@pytest.mark.parametrize("certified", [False, True])
def test_workspace_after_a_convergence_is_fresh_but_for_the_read_buffers(certified):
    """``workspace_after`` lays its buffers out as ``workspace`` does (shapes, dtypes, C-contiguous,
    writable) and shares with the converged workspace only ``info``, the corrector's ``(QᵀWQ)ᵀ`` (read
    at once by the curve's point) and, for a certified verdict (eigenvalues not written), the eigenvalue
    buffer: across more calls than a block holds, no buffer a result or a cache keeps overlaps any other
    handed out."""
    ci = np.array([9, 0, 4], dtype=np.int64)  # (n, _, m: what workspace reads)
    _, ws = kernel.workspace(ci, 11)
    _, want = kernel.workspace(ci, 11)
    pool = []
    kept = []
    for _ in range(kernel.WORKSPACE_BLOCK + 3):
        new = kernel.workspace_after(ws, certified, pool)
        assert [(a.shape, a.dtype, a.flags.c_contiguous, a.flags.writeable) for a in new] == [
            (a.shape, a.dtype, True, True) for a in want]
        shared = [i for i, (a, b) in enumerate(zip(new, ws)) if np.shares_memory(a, b)]
        assert shared == ([8, 10, 11] if certified else [10, 11])
        kept.extend(a for i, a in enumerate(new) if i not in shared)
        ws = new
    assert not any(np.shares_memory(a, b) for i, a in enumerate(kept) for b in kept[:i])
