"""The reorganised compiled helpers of the dense kernel (vjm_pin/solver/kernel.py) give the numbers of the
loops they replace, bit for bit: ``_step_t`` (the step on the transposed ``QᵀWQ``) against the former step
on ``QᵀWQ`` itself, the branch-free ``_hessian``, the column-oriented Cholesky tests (``_shifted_cholesky``,
``_certified_stable``) and the four-row ``_spring_gradient``. References: plain Python transcriptions of the
former entry-by-entry loops (IEEE double arithmetic, the same operations in the same order; the compiled
kernels do not contract products and sums into FMAs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from vjm_pin.solver import kernel  # noqa: E402


@pytest.fixture(scope="module")
def k():
    if not kernel._load_compiled():
        pytest.skip("numba kernel not available")
    return kernel


def _bits(a):
    return np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes()


def _cases(seed, count):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(2, 26))
        m = int(rng.integers(1, min(6, n - 1) + 1))
        scale = 10.0 ** rng.integers(-3, 4)
        yield rng, n, m, scale


def _former_step(k, wq, hh, rr, e, r, n, m):
    """The step of kernel.py before ``_step_t`` (on ``wq`` = ``QᵀWQ``, its reduced matrix copied row by
    row), transcribed; the QR and LU helpers are the kernel's compiled ones, as there."""
    nz = n - m
    py = np.zeros(m)
    for i in range(m):
        if rr[i, i] == 0.0:
            return False, np.zeros(0)
    for i in range(m):
        s = e[i]
        for j in range(i):
            s -= rr[j, i] * py[j]
        py[i] = s / rr[i, i]
    qr_ = k._apply_qt(hh, r, m, n)
    rhs = np.zeros(nz)
    for j in range(nz):
        s = qr_[m + j]
        for i in range(m):
            s += wq[m + j, i] * py[i]
        rhs[j] = s
    lu = np.ascontiguousarray(wq[m:, m:])
    if not k._lu_eliminate(lu, rhs, nz):
        return False, np.zeros(0)
    pz = k._back_substitute(lu, rhs, nz)
    dx = np.concatenate([py, -pz])
    for kk in range(m - 1, -1, -1):
        t = hh[m, kk]
        if t == 0.0:
            continue
        s = dx[kk]
        for i in range(kk + 1, n):
            s += hh[kk, i] * dx[i]
        s *= t
        dx[kk] -= s
        for i in range(kk + 1, n):
            dx[i] -= s * hh[kk, i]
    return True, dx


def test_step_on_transpose_matches_the_former_step(k):
    for rng, n, m, scale in _cases(1, 150):
        jac = rng.standard_normal((m, n)) * scale
        hh = k._qr_t(jac, m, n)
        task = rng.permutation(6)[:m].astype(np.int64)
        tau = rng.standard_normal(n) * scale
        ok, rr, f, r, f6 = k._multiplier(jac, hh, tau, task, m, n)
        assert ok
        w = rng.standard_normal((n, n)) * scale
        wq = w.copy()
        k._reflect_rows(hh, wq, m, n)
        wt = np.ascontiguousarray(wq.T)
        k._reflect_rows(hh, wt, m, n)  # (Qᵀ W Q)ᵀ
        wq = np.ascontiguousarray(wt.T)
        e = rng.standard_normal(m) * 1e-3
        ok1, dx1 = _former_step(k, wq, hh, rr, e, r, n, m)
        ok2, dx2 = k._step_t(wt, hh, rr, e, r, n, m)
        assert ok1 == ok2
        if ok1:
            assert _bits(dx1) == _bits(dx2)
    # an exactly singular reduced matrix: both decline
    n, m = 6, 2
    rng = np.random.default_rng(9)
    jac = rng.standard_normal((m, n))
    hh = k._qr_t(jac, m, n)
    ok, rr, f, r, f6 = k._multiplier(jac, hh, rng.standard_normal(n), np.arange(m, dtype=np.int64), m, n)
    wt = np.zeros((n, n))
    assert not k._step_t(wt, hh, rr, np.ones(m), r, n, m)[0]
    assert not _former_step(k, np.zeros((n, n)), hh, rr, np.ones(m), r, n, m)[0]


def test_spring_gradient_matches_row_sums(k):
    for rng, n, _, scale in _cases(5, 80):
        nt = int(rng.integers(0, n + 1))
        kz = rng.standard_normal((n, n)) * scale * 1e3
        theta_idx = rng.permutation(n + 3)[:nt].astype(np.int64)
        x = rng.standard_normal(n + 3)
        theta0 = rng.standard_normal(nt) * 1e-2
        ref = np.zeros(n)
        kl, xl, t0 = kz.tolist(), x.tolist(), theta0.tolist()
        for i in range(nt):
            s = 0.0
            for j in range(nt):
                s += kl[i][j] * (xl[theta_idx[j]] - t0[j])
            ref[i] = s
        tau = np.zeros(n)
        k._spring_gradient(kz, x, theta_idx, theta0, nt, tau)
        assert _bits(tau) == _bits(ref)


def _hessian_reference(jfree, f6, mask, n):
    """The entry-by-entry loop with the support mask as a branch (the former ``_hessian``)."""
    fx, fy, fz, mx, my, mz = (float(v) for v in f6)
    d = np.empty((3, n))
    em = np.empty((3, n))
    for b in range(n):
        v0, v1, v2 = (float(jfree[a, b]) for a in range(3))
        w0, w1, w2 = (float(jfree[a, b]) for a in range(3, 6))
        d[0, b] = fz * v1 - fy * v2
        d[1, b] = -fz * v0 + fx * v2
        d[2, b] = fy * v0 - fx * v1
        em[0, b] = mz * w1 - my * w2
        em[1, b] = -mz * w0 + mx * w2
        em[2, b] = my * w0 - mx * w1
    j = jfree.tolist()
    dl = d.tolist()
    el = em.tolist()
    hz = np.empty((n, n))
    for i in range(n):
        for c in range(n):
            if mask[i, c]:
                hz[i, c] = (j[3][c] * dl[0][i] + j[4][c] * dl[1][i] + j[5][c] * dl[2][i]
                            + (el[0][i] * j[3][c] + el[1][i] * j[4][c] + el[2][i] * j[5][c]))
            else:
                hz[i, c] = j[3][i] * dl[0][c] + j[4][i] * dl[1][c] + j[5][i] * dl[2][c]
    return hz


def test_hessian_branch_free_matches_reference(k):
    for rng, n, _, scale in _cases(2, 60):
        jfree = rng.standard_normal((6, n)) * scale
        f6 = rng.standard_normal(6) * 100.0
        mask = np.tril(np.ones((n, n), bool)) if rng.random() < 0.5 else rng.random((n, n)) < 0.5
        ref = _hessian_reference(jfree, f6, mask, n)
        assert _bits(k._hessian(jfree, f6, mask, n)) == _bits(ref)


def _chol_reference(diag_of, off_of, nz):
    """Row-oriented Cholesky (the former loops): True when every pivot is positive."""
    lo = [[0.0] * nz for _ in range(nz)]
    for j in range(nz):
        s = diag_of(j)
        for kk in range(j):
            s -= lo[j][kk] * lo[j][kk]
        if not s > 0.0:
            return False, lo
        dj = math.sqrt(s)
        lo[j][j] = dj
        for i in range(j + 1, nz):
            s = off_of(i, j)
            for kk in range(j):
                s -= lo[i][kk] * lo[j][kk]
            lo[i][j] = s / dj
    return True, lo


def test_cholesky_tests_match_row_oriented(k):
    if kernel.lean() is None:
        pytest.skip("numba kernel not available")
    for rng, n, m, scale in _cases(3, 120):
        nz = n - m
        a = rng.standard_normal((n, n)) * scale
        wt = a @ a.T / n + rng.standard_normal((n, n)) * scale * 1e-3
        # a shift around the smallest eigenvalue: both verdicts occur
        red = wt[m:, m:] + wt[m:, m:].T
        shift = 0.5 * float(np.linalg.eigvalsh(red)[0]) * rng.uniform(0.5, 1.5)
        w = wt.tolist()
        ok_ref, _ = _chol_reference(lambda j: w[m + j][m + j] + w[m + j][m + j] - 2.0 * shift,
                                    lambda i, j: w[m + j][m + i] + w[m + i][m + j], nz)
        got = k._shifted_cholesky(wt, m, nz, shift, np.empty((nz, nz)), np.empty(nz))
        assert got == ok_ref
        sym = np.empty((nz, nz))
        for i in range(nz):
            for j in range(nz):
                sym[i, j] = 0.5 * (-w[m + j][m + i] + -w[m + i][m + j])
        thr = float(-np.linalg.eigvalsh(sym)[-1]) * rng.uniform(0.5, 1.5)
        s = sym.tolist()
        fro = 0.0
        for i in range(nz):
            for j in range(nz):
                fro += s[i][j] * s[i][j]
        sh = thr + kernel.CERT_MARGIN * (math.sqrt(fro) + thr)
        ok_ref, _ = _chol_reference(lambda j: -s[j][j] - sh, lambda i, j: -s[i][j], nz)
        assert kernel._certified_stable(sym, nz, thr) == ok_ref
