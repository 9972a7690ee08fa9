"""The compiled point kernel's own linear algebra (vjm_pin.analysis.point_kernel) against LAPACK.

- the tangent of eq. (29) (``_eq28_tangent``): the accept/decline decision against the generic
  regularity test (:func:`vjm_pin.solver.stiffness._inverse_if_regular`) wherever the bound is not
  within a factor 2 of the threshold, the accepted tangent against the generic inverse, and the
  decline (no exception) of an exactly singular or non-finite matrix;
- the null-space tangent on the corrector's QR (``_ns_tangent``) against eq. (28) solved in rational
  arithmetic, and its declines;
- ``Vᵀ sym(A) V`` by row operations only (``_q_both_sides``, ``_reduced``): the bits of the
  row-by-row reflection and the numbers of an explicit ``Q``;
- the largest eigenpair (``_top_eigpair``: row-oriented tridiagonalisation, Sturm bisection, inverse
  iteration) against ``np.linalg.eigh`` on random, clustered and multiple-top-eigenvalue matrices.

Every function is the compiled twin (numba); the tests skip only when numba is not importable.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.exact_eq28 import eq28_exact
from vjm_pin.analysis import point_kernel as pk
from vjm_pin.solver.stiffness import SINGULAR_RCOND, _inverse_if_regular, _ruiz

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def jit():
    """The module with its helpers compiled (compiled() replaces the globals by their njit twins)."""
    pytest.importorskip("numba")
    assert pk.compiled()
    for name in ("_eq28_tangent", "_abs_sums", "_top_eigpair", "_q_both_sides", "_reduced", "_ns_tangent"):
        assert hasattr(getattr(pk, name), "py_func"), name
    return pk


# --------------------------------------------------------------------------- eq. (28)'s tangent
def _eq28(jac, hz, kz, nt):
    """The matrix of eq. (28) in the order (F, q, θ) from ``J`` (m, n) and ``H − K`` in (θ, q) order
    (as stiffness.eq28_matrix builds it from the Blocks)."""
    m, n = jac.shape
    nq = n - nt
    perm = np.r_[m + nq + np.arange(nt), m + np.arange(nq)]
    a = np.zeros((m + n, m + n))
    a[:m, perm] = jac
    a[perm, :m] = jac.T
    a[np.ix_(perm, perm)] = hz - kz
    return a, perm


def _problem(rng, m, nt, nq, sing=0.0):
    """A random KKT problem: J (m, n), H (n, n, not symmetric), K (spring block), and ``sing`` pulls the
    matrix of eq. (28) towards singularity (H − K nearly singular on the null space of J)."""
    n = nt + nq
    jac = rng.standard_normal((m, n))
    hz = rng.standard_normal((n, n))
    kz = np.zeros((n, n))
    g = rng.standard_normal((nt, nt))
    kz[:nt, :nt] = g @ g.T + nt * np.eye(nt)
    if sing:
        # make H − K = Nᵀ diag N + (small) with one null direction z ⊥ rows of J nearly singular
        z = np.linalg.svd(jac)[2][-1]
        a = hz - kz
        a -= np.outer(a @ z, z) * (1.0 - sing)  # a z → sing · a z
        hz = a + kz
    return jac, hz, kz


def test_tangent_decision_matches_the_generic_regularity_test(jit):
    """``_eq28_tangent`` accepts exactly where :func:`_inverse_if_regular` does (cases whose bound is
    within a factor 2 of the threshold excluded: rounding may decide those either way), declines a
    singular matrix without raising, and its accepted tangent is the generic ``A⁻¹ [d_t; 0]``."""
    rng = np.random.default_rng(7)
    thr = 1.0 / (SINGULAR_RCOND * 10.0)
    seen = {True: 0, False: 0}
    for case in range(160):
        m, nt = (3, 18) if case % 2 else (int(rng.integers(1, 4)), int(rng.integers(1, 8)))
        nq = 2 if case % 2 else int(rng.integers(0, 5))
        sing = [0.0, 1e-6, 1e-9, 1e-11, 1e-12, 1e-13, 1e-14, 1e-16][case % 8]
        jac, hz, kz = _problem(rng, m, nt, nq, sing)
        if case % 5 == 0:  # badly scaled rows of J (units of force vs moment) and a stiff spring
            jac *= 10.0 ** rng.uniform(-4, 4, (m, 1))
            kz *= 1e6
        a, perm = _eq28(jac, hz, kz, nt)
        dt = rng.standard_normal(m)
        inv, regular = _inverse_if_regular(a)
        s, _ = _ruiz(a)
        with np.errstate(all="ignore"):
            try:
                si = np.linalg.inv(s)
                bound = np.sqrt(np.abs(s).sum(0).max() * np.abs(s).sum(1).max()) * np.sqrt(
                    np.abs(si).sum(0).max() * np.abs(si).sum(1).max())
            except np.linalg.LinAlgError:
                bound = np.inf
        xd = np.full(nt + nq, 7.0)
        fd = np.full(m, 7.0)
        ok, k = jit._eq28_tangent(np.ascontiguousarray(jac), hz, kz, dt, nt, SINGULAR_RCOND, xd, fd)
        if not ok:
            assert np.isnan(k) and (xd == 7.0).all() and (fd == 7.0).all()  # untouched
        if np.isfinite(bound) and 0.5 * thr < bound < 2.0 * thr:
            continue
        assert ok == regular, (case, bound / thr)
        seen[bool(ok)] += 1
        if ok:
            x = inv[:, :m] @ dt
            tol = 1e-14 * bound * np.abs(x).max()
            assert np.abs(fd - x[:m]).max() <= tol
            assert np.abs(xd - x[perm]).max() <= tol
            assert k == pytest.approx(dt @ x[:m], rel=1e-9, abs=tol * np.abs(dt).sum())
    assert seen[True] >= 40 and seen[False] >= 20, seen  # both decisions exercised


def test_abs_sums_are_the_one_and_infinity_norms(jit):
    """``_abs_sums``: ``(‖s‖₁, ‖s‖∞)`` of row- and column-major arrays (LAPACK's inverse is Fortran-ordered)."""
    rng = np.random.default_rng(13)
    for n in (1, 4, 23):
        s = rng.standard_normal((n, n)) * 10.0 ** rng.uniform(-5, 5, (n, 1))
        for a in (s, np.asfortranarray(s)):
            c1, ci = jit._abs_sums(a, np.empty(n))
            assert c1 == pytest.approx(np.abs(s).sum(axis=0).max(), rel=1e-14)
            assert ci == pytest.approx(np.abs(s).sum(axis=1).max(), rel=1e-14)


@pytest.mark.parametrize("kind", ["zero row of J", "zero column of J", "nan in H", "inf in K"])
def test_tangent_declines_a_singular_matrix_without_raising(jit, kind):
    """A matrix of eq. (28) with an exactly zero row, or with a non-finite entry: not ok, nothing written."""
    rng = np.random.default_rng(2)
    jac, hz, kz = _problem(rng, 3, 18, 2)
    if kind == "zero row of J":
        jac[1] = 0.0
    elif kind == "zero column of J":  # with H − K's row and column of that coordinate: a zero row
        jac[:, 19] = 0.0
        hz[19] = kz[19]
        hz[:, 19] = kz[:, 19]
    elif kind == "nan in H":
        hz[3, 5] = np.nan
    else:
        kz[2, 2] = np.inf
    xd, fd = np.zeros(20), np.zeros(3)
    ok, k = jit._eq28_tangent(jac, hz, kz, np.array([1.0, 0.0, 0.0]), 18, SINGULAR_RCOND, xd, fd)
    assert not ok and np.isnan(k)
    assert not xd.any() and not fd.any()


# --------------------------------------------------------------------------- the null-space tangent
@pytest.mark.parametrize("m,nt,nq,sing", [(3, 18, 2, 0.0), (1, 4, 1, 0.0), (6, 6, 3, 0.0), (3, 18, 2, 1e-6)])
def test_null_space_tangent_against_the_exact_solution(jit, m, nt, nq, sing):
    """``_ns_tangent`` on the Householder QR of ``Jᵀ`` (the corrector's ``_qr_t``) against eq. (28) solved in
    rational arithmetic: within the forward error bound of a backward-stable solve (``ε·cond``, the
    equilibrated unknowns), on random and nearly singular problems; ``wt`` is the corrector's
    ``(Qᵀ (K − H) Q)ᵀ``, and the result does not depend on the order (θ, q) of the columns."""
    from vjm_pin.solver.kernel import _qr_t

    rng = np.random.default_rng(11 + m + nt)
    for _ in range(8):
        jac, hz, kz = _problem(rng, m, nt, nq, sing)
        n = nt + nq
        dt = rng.standard_normal(m)
        hh = _qr_t(jac, m, n)
        xd, fd, wt = np.zeros(n), np.zeros(m), np.empty((n, n))
        ok, k = jit._ns_tangent(jac, hh, hz, kz, dt, xd, fd, wt)
        assert ok
        xe, fe = (np.array([float(v) for v in part]) for part in eq28_exact(jac, hz - kz, dt))
        big = np.block([[np.zeros((m, m)), jac], [jac.T, hz - kz]])
        s_eq, d = _ruiz(big)
        tol = 100.0 * EPS * np.linalg.cond(s_eq) * np.abs(np.r_[fe, xe] / d).max()
        assert np.abs((xd - xe) / d[m:]).max() <= tol
        assert np.abs((fd - fe) / d[:m]).max() <= tol
        assert abs(k - dt @ fe) <= tol * np.abs(dt * d[:m]).sum() + 4 * EPS * np.abs(dt * fe).sum()
        # wt: (Qᵀ W Q)ᵀ, W = K − H, with the explicit Q of the reflectors
        q = np.eye(n)
        for j in range(n):
            jit._q_vector(hh, q[:, j], m, n, False)
        assert np.abs(wt - (q.T @ (kz - hz) @ q).T).max() <= 1e-13 * np.abs(kz - hz).max() * n


def test_null_space_tangent_declines_what_it_cannot_solve(jit):
    """A singular ``ZᵀWZ`` (exactly: a zero pivot; numerically: the refinement's correction above
    :data:`~vjm_pin.analysis.point_kernel.REFINE_TOL`), a non-finite entry, a rank-deficient ``J``:
    declined (not ok, ``k`` NaN), never raised."""
    from vjm_pin.solver.kernel import _qr_t

    rng = np.random.default_rng(5)
    m, nt, nq = 3, 8, 2
    n = nt + nq
    dt = np.array([1.0, 0.5, -0.25])
    cases = []
    jac, hz, kz = _problem(rng, m, nt, nq)
    z = np.linalg.svd(jac)[2][m:]  # a basis of the null space of J
    w = (kz - hz)
    w_sing = w - (w @ z[0])[:, None] * z[0][None, :]  # W z₀ = 0: ZᵀWZ singular
    cases.append(("singular ZᵀWZ", jac, kz - w_sing, kz))
    cases.append(("nan in H", jac, np.where(np.eye(n, dtype=bool), np.nan, hz), kz))
    jr = jac.copy()
    jr[2] = jr[0]
    cases.append(("rank-deficient J", jr, hz, kz))
    for name, j_, h_, k_ in cases:
        hh = _qr_t(j_, m, n)
        ok, k = jit._ns_tangent(j_, hh, h_, k_, dt, np.zeros(n), np.zeros(m), np.empty((n, n)))
        assert not ok and np.isnan(k), name


# --------------------------------------------------------------------------- Vᵀ sym(A) V
@pytest.mark.parametrize("m,n", [(3, 20), (1, 5), (6, 9)])
def test_reduced_matrix_by_row_operations(jit, m, n):
    """``_reduced(_q_both_sides(…))`` against the row-by-row reflection it replaces (the same bits:
    each column of the transpose reflected with the operations of ``_q_vector``) and against
    ``Vᵀ sym(A) V`` with an explicit ``Q`` (numpy, to rounding)."""
    from vjm_pin.solver import kernel

    rng = np.random.default_rng(m * 100 + n)
    jac = rng.standard_normal((m, n))
    hh = kernel._qr_t(jac, m, n)
    a = rng.standard_normal((n, n))
    asym = 0.5 * (a + a.T) - np.diag(rng.uniform(1, 2, n))
    asym[0, 1] += 1e-3  # not exactly symmetric: the mirror identity must not rely on it
    # the previous formulation: Qᵀ a, then every row from the right
    c = asym.copy()
    kernel._reflect_rows(hh, c, m, n)
    for r in range(n):
        kernel._q_vector(hh, c[r], m, n, True)
    b = asym.copy()
    bt = jit._q_both_sides(hh, b, m, n)
    assert bt.T.tobytes() == c.tobytes()
    # numpy: V = [Z, y₀/‖y₀‖]
    q = np.linalg.qr(jac.T, mode="complete")[0]
    dt = rng.standard_normal(m)
    rmat = np.triu(hh[:m, :m].T)
    u = np.linalg.solve(rmat.T, dt)
    uh = u / np.linalg.norm(u)
    red = jit._reduced(bt, uh, m, n)
    y0 = jac.T @ np.linalg.solve(jac @ jac.T, dt)  # minimum-norm: J y₀ = d_t
    v = np.column_stack([q[:, m:], y0 / np.linalg.norm(y0)])
    want = v.T @ (0.5 * (asym + asym.T)) @ v
    # another basis of the null space of J (signs, rotation): compare the invariants
    assert red.shape == want.shape
    assert np.array_equal(red, red.T)
    assert np.allclose(np.linalg.eigvalsh(red), np.linalg.eigvalsh(want), rtol=0, atol=1e-12 * np.abs(asym).max())
    assert red[-1, -1] == pytest.approx(want[-1, -1], rel=1e-12, abs=1e-13 * np.abs(asym).max())


# --------------------------------------------------------------------------- the top eigenpair
def _symmetric(rng, ev):
    q, _ = np.linalg.qr(rng.standard_normal((len(ev), len(ev))))
    a = q @ np.diag(ev) @ q.T
    return 0.5 * (a + a.T)


def _eig_cases(rng):
    out = []
    for n in (1, 2, 3, 8, 18, 25):  # random
        a = rng.standard_normal((n, n))
        out.append((f"random{n}", a + a.T, 1))
    out.append(("scaled18", 1e6 * _symmetric(rng, rng.standard_normal(18)), 1))
    ev = np.r_[1.0 + 1e-9 * np.arange(5), rng.uniform(-3, 0.5, 13)]  # a cluster at the top
    out.append(("clustered", _symmetric(rng, ev), 1))
    ev = np.r_[2.0, 2.0, rng.uniform(-3, 1.5, 16)]  # a double top eigenvalue
    out.append(("double", _symmetric(rng, ev), 2))
    ev = np.r_[-1e-3, -1e-3, -1e-3, rng.uniform(-3, -0.5, 15)]  # triple, negative definite
    out.append(("triple", _symmetric(rng, ev), 3))
    ev = np.r_[5.0, 5.0 - 1e-13, rng.uniform(-5, 4, 16)]  # a top pair closer than the tolerance
    out.append(("near-double", _symmetric(rng, ev), 2))
    t = np.diag(rng.uniform(-1, 1, 12)) + np.diag(np.r_[1e-300, 0.5 * np.ones(10)], 1)
    out.append(("tridiagonal", t + np.triu(t, 1).T, 1))
    # a curve's margin matrix near buckling: the top eigenvalue ~0, alone, the rest spread over
    # −3000..−0.1 (Laguerre's method from far above the isolated top eigenvalue, then its rounding)
    for top in (-2e-6, 3e-9, 0.0, -4e-2):
        ev = np.r_[top, -np.geomspace(0.09, 3000.0, 17)]
        out.append((f"margin{top:g}", _symmetric(rng, ev), 1))
    ev = np.r_[1e-7, 1e-7 - 1e-12, -np.geomspace(0.09, 3000.0, 16)]  # a top pair 1e-12 apart, ‖a‖ 3000
    out.append(("margin-near-double", _symmetric(rng, ev), 2))
    return out


def test_top_eigenpair_matches_eigh(jit):
    """The largest eigenvalue to a few ``ε‖a‖``, the vector: unit, residual ``ε‖a‖``, and ``ε‖a‖/gap``
    from LAPACK's for a simple eigenvalue (in the eigenspace for a multiple one)."""
    rng = np.random.default_rng(23)
    for name, a, mult in _eig_cases(rng):
        n = a.shape[0]
        ev, u = np.linalg.eigh(a)
        scale = max(np.abs(ev).max(), 1e-300)
        lam, v = jit._top_eigpair(a.copy())
        assert abs(lam - ev[-1]) <= 4.0 * n * EPS * scale, (name, lam - ev[-1])
        assert abs(np.linalg.norm(v) - 1.0) <= 1e-13, name
        assert np.linalg.norm(a @ v - lam * v) <= 10.0 * n * EPS * scale, name
        top = u[:, n - mult:]
        if n > mult:
            gap = ev[-mult] - ev[-mult - 1]
            outside = np.linalg.norm(v - top @ (top.T @ v))
            assert outside <= 10.0 * n * EPS * scale / gap, (name, outside)
        # a predicted bracket (the tracer's, from the previous point): right, too narrow, wrong on
        # either side, around the second eigenvalue: the same eigenvalue to the same tolerance
        span = max(ev[-1] - ev[0], scale * 1e-3)
        for lo_, hi_ in ((ev[-1] - 1e-3 * span, ev[-1] + 1e-3 * span), (ev[-1] - 1e-15, ev[-1] + 1e-15),
                         (ev[-1] + 0.1 * span, ev[-1] + 0.2 * span), (ev[-1] - 0.2 * span, ev[-1] - 0.1 * span),
                         (ev[0] - 1.0, ev[-1] + 1.0), (ev[-2 if n > 1 else -1] - 1e-9 * span, ev[-1] - 1e-9 * span)):
            lam_h, v_h = jit._top_eigpair(a.copy(), lo_, hi_)
            assert abs(lam_h - ev[-1]) <= 4.0 * n * EPS * scale, (name, lo_, hi_, lam_h - ev[-1])
            assert np.linalg.norm(a @ v_h - lam_h * v_h) <= 10.0 * n * EPS * scale, name
        # the python function: the same numbers to rounding
        lam2, v2 = jit._top_eigpair.py_func(a.copy())
        assert abs(lam2 - lam) <= 4.0 * EPS * scale, name
        if mult == 1:
            assert np.abs(v2 - v).max() <= 10.0 * n * EPS * scale / max(ev[-1] - ev[-2] if n > 1 else scale,
                                                                       1e-300), name


def test_top_eigenpair_reads_the_lower_triangle(jit):
    """Only the lower triangle of ``a`` is read (the row-oriented tridiagonalisation mirrors it first):
    garbage above the diagonal changes no bit of the eigenpair."""
    rng = np.random.default_rng(31)
    for n in (2, 5, 18):
        a = rng.standard_normal((n, n))
        a = a + a.T
        lam, v = jit._top_eigpair(a.copy())
        b = a.copy()
        b[np.triu_indices(n, 1)] = rng.standard_normal(n * (n - 1) // 2) * 1e3
        lam2, v2 = jit._top_eigpair(b)
        assert lam2 == lam and v2.tobytes() == v.tobytes()
