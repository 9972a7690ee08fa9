"""The chain kernel's (vjm_pin.solver.chain_kernel) bit-identical shortcuts: the row-wise Hessian of Ψ
(eq. 16) against the dense kernel's, and the factorisation of eq. (28) that a converged iteration keeps
in a per-thread workspace for the curve's point (the tangent of eq. 29): kept and found only for the
same bits of the Jacobian, the wrench and the task rows, and a whole Model C curve (k = 4, 76 free
coordinates) bit for bit the same with and without it."""

import numpy as np
import pytest

from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import chain_kernel, kernel
from vjm_pin.solver.equilibrium import EquilibriumSolver

numba = pytest.importorskip("numba")

DIRECTION = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
MAX_DEFLECTION = 6e-4  # m: past the Euler load of Model C (tests/test_chain_kernel.py)


@pytest.fixture(autouse=True)
def _jit_on(monkeypatch):
    monkeypatch.setenv("VJM_PIN_JIT", "1")


@pytest.fixture(scope="module")
def compiled():
    assert kernel._load_compiled(), "numba is installed: the compiled kernel must load"
    assert chain_kernel._load() is not None
    return chain_kernel


def _same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_row_hessian_is_the_dense_kernels_bit_for_bit(compiled):
    """``_hessian_rows`` (compiled and interpreted) equals ``kernel._hessian`` in every bit, for
    random twists, wrenches with zero components and random support masks, and is the screw-form
    Hessian: ``a_i·ω_j`` on the support, ``ω_i·d_j`` off it."""
    rng = np.random.default_rng(3)
    for n in (1, 7, 60):
        jfree = rng.standard_normal((6, n))
        for f6 in (rng.standard_normal(6), np.array([-0.0, 0.0, 2.5, 0.0, -1.5, 0.0])):
            for mask in (rng.random((n, n)) < 0.5, np.tril(np.ones((n, n), bool))):
                ref = compiled._hessian(jfree, f6, mask, n)
                got = compiled._hessian_rows(jfree, f6, mask, n)
                assert _same_bits(got, ref)
                assert _same_bits(compiled._hessian_rows.py_func(jfree, f6, mask, n), ref)
                v, w = jfree[:3].T, jfree[3:].T
                d = np.cross(v, f6[:3])
                a = d + np.cross(w, f6[3:])
                want = np.where(mask, a @ w.T, w @ d.T)
                assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_workspace_round_trip_and_key(compiled):
    """What ``_ws_store`` keeps ``_ws_views`` gives back unchanged; ``_ws_match`` finds it only for
    the same bits of the key (a zero's sign, one ulp of the Jacobian or of the wrench, another task
    row or block width: not found); a workspace too short keeps nothing."""
    rng = np.random.default_rng(5)
    n, k, b = 11, 3, 5
    jz = rng.standard_normal((6, n))
    f6 = np.array([1.5, -0.0, 0.0, 2.0, -3.0, 0.25])
    task = np.array([0, 1, 2], np.int64)
    s = rng.random(n) + 0.5
    rho = 7.25
    bu, bq = rng.standard_normal((n + k, 3 + k)), rng.standard_normal((n + k, 3 + k))
    fx, fy = rng.standard_normal((n + k, 3 + k)), rng.standard_normal((n + k, 3 + k))
    pinv = rng.standard_normal((n + k, b))
    ws = np.zeros(compiled._ws_size(n, k, b))
    compiled._ws_store(ws, jz, f6, task, s, rho, bu, bq, pinv, fx, fy)
    assert compiled._ws_match(ws, jz, f6, task, b)
    got = compiled._ws_views(ws, n, k)
    for x, y in zip(got, (s, rho, bu, bq, fx, fy, pinv)):
        assert _same_bits(x, y)
    f_sign = f6.copy()
    f_sign[1] = 0.0
    jz_ulp = jz.copy()
    jz_ulp[4, 7] = np.nextafter(jz_ulp[4, 7], np.inf)
    f_ulp = f6.copy()
    f_ulp[3] = np.nextafter(f_ulp[3], 0.0)
    assert not compiled._ws_match(ws, jz, f_sign, task, b)
    assert not compiled._ws_match(ws, jz_ulp, f6, task, b)
    assert not compiled._ws_match(ws, jz, f_ulp, task, b)
    assert not compiled._ws_match(ws, jz, f6, np.array([0, 1, 3], np.int64), b)
    assert not compiled._ws_match(ws, jz, f6, task, b + 1)
    assert not compiled._ws_match(np.zeros(0), jz, f6, task, b)
    short = np.zeros(compiled._ws_size(n, k, b) // 4)
    compiled._ws_store(short, jz, f6, task, s, rho, bu, bq, pinv, fx, fy)
    assert not short.any() and not compiled._ws_match(short, jz, f6, task, b)


def test_k4_curve_is_bit_identical_with_and_without_the_kept_factorisation(compiled, monkeypatch):
    """A Model C compression curve through buckling (k = 4: the chain kernels run) gives the same
    bits whether the point reuses the converged iteration's factorisation of eq. (28) or makes its
    own: forces, deflections, every point's tangent stiffness, μ and dμ/ds; and the point does find
    it (the last iteration of the corrector is at the point's configuration and wrench)."""
    vm = load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=4))
    assert len(vm.theta_idx) + len(vm.q_idx) >= chain_kernel.POINT_MIN_N

    def run():
        return trace_curve(vm, DIRECTION, MAX_DEFLECTION, steps=24, solver=EquilibriumSolver(vm))

    hits = []
    fns = chain_kernel._load()
    real_point = fns[1]

    def spy(*a):
        jz, _ = chain_kernel._gather(a[0], a[1], a[3])
        hits.append(bool(chain_kernel._ws_match(a[-1], jz, a[11], a[3], max(a[8].shape[1], a[3].shape[0]))))
        return real_point(*a)

    monkeypatch.setattr(chain_kernel, "_COMPILED", [(fns[0], spy)])
    with_ws = run()
    assert len(hits) > 10 and sum(hits) >= 0.8 * len(hits)
    monkeypatch.setattr(chain_kernel, "_COMPILED", [fns])
    monkeypatch.setattr(chain_kernel, "_workspace", lambda lay, n: np.zeros(0))
    without = run()
    assert _same_bits(with_ws.forces, without.forces)
    assert _same_bits(with_ws.deflections, without.deflections)
    assert len(with_ws.points) == len(without.points)
    for p, q in zip(with_ws.points, without.points):
        assert p.stable == q.stable and p.stable_end_held == q.stable_end_held
        for name in ("deflection", "force", "wrench", "stiffness", "force_control_margin"):
            assert _same_bits(np.asarray(getattr(p, name), float), np.asarray(getattr(q, name), float)), name
    assert len(with_ws.critical) == len(without.critical)
    for c, d in zip(with_ws.critical, without.critical):
        assert _same_bits(c.force, d.force) and _same_bits(c.deflection, d.deflection)


def test_workspaces_are_per_thread_and_layout(compiled):
    """``_workspace``: the same array for the same layout in one thread, another in another thread."""
    import threading

    lay = next(iter(chain_kernel._SHARED.values()), None)  # (the curve test above built one)
    if lay is None:
        pytest.skip("no chain layout built yet")
    a = chain_kernel._workspace(lay, lay.cols.shape[0])
    assert chain_kernel._workspace(lay, lay.cols.shape[0]) is a
    other = []
    t = threading.Thread(target=lambda: other.append(chain_kernel._workspace(lay, lay.cols.shape[0])))
    t.start()
    t.join()
    assert other[0] is not a and other[0].shape == a.shape
    n = lay.cols.shape[0]
    kept = chain_kernel._ws_rnd(a, n)
    assert _same_bits(kept, chain_kernel._rnd_start(n))
    assert chain_kernel._ws_rnd(a, n + 1).shape == (0,) and chain_kernel._ws_rnd(np.zeros(0), n).shape == (0,)


def test_count_without_factors_is_the_counts_bit_for_bit(compiled):
    """``_count_only`` (the Sturm count without the factors of a solve, :func:`_inertia_factor`) gives
    ``_count``'s count at every shift, and ``_inertia_factor`` chain_algebra's ``_factor_loops``
    reciprocal condition (same bits), failure flag and inertia, on the eq. (23) problems of a k = 4
    Model C column unloaded and under a compressive end force past buckling (negative counts, an
    unreliable shift at an eigenvalue included)."""
    vm = load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=4))
    s = EquilibriumSolver(vm)
    lay = chain_kernel._layout(s._kz, s._kz, s.free, s.nt, s.kin.support_mask(s.free))
    x = s.solve(np.zeros(6)).x  # the unloaded equilibrium
    j6 = np.ascontiguousarray(s.kin.evaluate(x, hessian=False).jacobian)
    task = np.asarray(vm.task, np.int64)
    jz, cb = compiled._gather(j6, lay.cols, task)
    factor_loops = chain_kernel._factor_loops
    seen = set()
    for fz in (0.0, -50.0, -400.0):
        f6 = np.array([fz, 0.0, 0.0, 0.0, 0.0, 0.0])
        for rows in (cb, cb[1:]):
            k = rows.shape[0]
            gens = compiled._w_gens(jz, f6, lay.starts, lay.kd, True)
            bst, bd, bu, bv, bp, bq, sc, _rho = compiled._bordered(*gens, lay.starts, lay.dpos, lay.kp, rows)
            shifts = [lay.kscale * t for t in (-1.0, -1e-3, 0.0, 1e-6, 1e-4, 1e-2, 0.3)]
            lam = compiled._smallest(lay.starts, lay.dpos, lay.kp, jz, f6, lay.kd, rows, lay.kscale, False,
                                     np.zeros(jz.shape[1]), 1e-8)
            if lam[0]:
                shifts.append(lam[1])  # at an eigenvalue: typically unreliable (−1)
            for sig in shifts:
                c = compiled._count_only(bst, bd, bu, bv, bp, bq, sc, lay.dpos, k, sig)
                assert c == compiled._count(bst, bd, bu, bv, bp, bq, sc, lay.dpos, k, sig)[0]
                seen.add(c > 0)
                sh = compiled._shifted(bd, sc, lay.dpos, sig)
                rc, bad, npos, nneg, nzero = compiled._inertia_factor(bst, sh, bu, bv, bp, bq)
                _p, _x, _y, info, counts = factor_loops(bst, sh, bu, bv, bp, bq, True, True)
                assert _same_bits(rc, info[0]) and bad == (info[4] != 0.0)
                if not bad:
                    assert (npos, nneg, nzero) == tuple(int(t) for t in counts)
    assert seen == {False, True}
