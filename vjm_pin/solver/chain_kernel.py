"""Compiled O(n) versions of the two hot per-point routines for long serial chains (issue 14).

The fused Newton iteration (:func:`vjm_pin.solver.kernel.iterate_compiled`) and the curve's
point kernel (:func:`vjm_pin.analysis.point_kernel._point_loops`) work on dense ``n × n``
matrices: ``QᵀWQ`` (``4mn²``), an LU of ``ZᵀWZ`` (``n³/3``), and at every equilibrium a full
symmetric eigenvalue decomposition of eq. (23)'s reduced matrix (and of the force-control
margin's). For a chain of 1-DoF joints ``W = K − H`` is block diagonal plus a rank-3
semiseparable matrix (:mod:`vjm_pin.solver.chain_algebra`), and every one of those steps has an
O(n) counterpart by elimination along the chain:

- the Newton step of eq. (28), ``W δx + Jᵀλ = −r``, ``J δx = e``: one factorisation of the
  bordered (scaled, augmented) KKT matrix and a refined solve;
- the ``follow_stable`` test (``½(ZᵀWZ + (ZᵀWZ)ᵀ) − shift·I ≻ 0``): Sylvester's count of the
  negative pivots of the symmetric bordered matrix shifted by ``shift`` (Haynsworth: the KKT
  inertia is the reduced one plus ``(m, m, 0)``);
- eq. (23)'s verdict and margin: only its *largest* eigenvalue (``−λ₁``, ``λ₁`` the smallest
  eigenvalue of ``Zᵀ W_s Z``) is used by the callers (``stable = max(ev) < −thr``, the tracer's
  ``λ`` and its zero crossings), found by inverse iteration on the bordered matrix shifted just
  below it, the shift certified by a Sturm count (no eigenvalue below it), then a second count
  just below the converged Rayleigh quotient certifies that it is the smallest eigenvalue;
  a previous eigenvector (the last point of a curve, the last solve) starts it, bisection on the
  Sturm count brackets it when there is none;
- the point kernel: the tangent of eq. (29) (the same KKT matrix, right-hand side ``d_t``), the
  force-control margin ``μ`` (the same eigenvalue problem with the held rows ``P J``) with its
  eigenvector, and ``dμ/ds`` of :meth:`~vjm_pin.analysis.point_kernel.PointKernel.margin_rate`
  with its sums over the support (``j ≤ i`` in chain order) as prefix and suffix sums.

The Householder QR of ``Jᵀ`` (O(n m²)), the multiplier, the residual, the convergence test and
the rank test are the dense kernel's arithmetic, unchanged (the same bits), so the factorisation
tuple ``fact`` can be handed between the two implementations (the chain kernel appends the six
Jacobian rows to the reflectors, rows the dense kernel never reads).

A converged iteration (the corrector's last) keeps its factorisation of eq. (28) in a per-thread
workspace of the layout (:func:`_workspace`); the curve's point at that equilibrium, which factorises
the same matrix for the tangent of eq. (29), uses it when its Jacobian, wrench and task rows are
bit for bit the iteration's (:func:`_ws_match`), so the point's numbers are the same bits either way.
The dense Hessian handed back in ``fact`` is :func:`_hessian_rows` (the dense kernel's entries, same
bits, without a branch in the inner loop).

Where the elimination is not trustworthy (a pivot with a reciprocal condition below
:data:`TRUST_RCOND`: next to a critical point; a solve residual above
:data:`~vjm_pin.solver.chain_algebra.SOLVE_RTOL`; an eigenvalue not certified) the routine says
so and the caller runs the dense routine, which decides exactly as before.

What the iteration reports at convergence changes with it: ``ev`` is the (1,) array of eq. (23)'s
largest eigenvalue, so :class:`~vjm_pin.solver.stability.StabilityResult` of a fused solve of a
long chain holds that eigenvalue only (``stable``, ``margin`` and the tracer's ``λ`` are
unchanged; :func:`~vjm_pin.solver.stability.check_stability` gives all of them).

Implementations: the loops below, compiled by numba (``njit(cache=True)``, loaded with the
solver's kernel: only on the compiled path, ``VJM_PIN_JIT`` not 0), and the same loops run by
the interpreter (the twin the tests compare with the compiled code; the independent reference
is the dense kernels). With ``VJM_PIN_JIT=0`` the dense numpy twins stay in use: interpreted,
these loops are slower than dense numpy at any size. The dispatch is by size,
:data:`ITERATE_MIN_N` and :data:`POINT_MIN_N` free coordinates (measured crossovers with the
dense compiled kernels on the Model C column: at n = 38 the chain's Newton step is slower, at
n = 56 every call is faster).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from vjm_pin.solver import chain_algebra as _algebra
from vjm_pin.solver import kernel as _kernel
from vjm_pin.solver.chain_algebra import PIVOT_RCOND, RHO_FACTOR, SOLVE_RTOL, _factor_loops, _inertia_small, _split
from vjm_pin.solver.chain_algebra import _inertia_pivots
from vjm_pin.solver.chain_algebra import _matvec_loops as _matvec
from vjm_pin.solver.chain_algebra import _solve_loops as _solve
from vjm_pin.solver.kernel import (
    _apply_qt,
    _back_substitute,
    _full_rank,
    _hessian,
    _moved_loops,
    _multiplier,
    _progress,
    _qr_t,
)

#: Free coordinates from which the compiled fused iteration uses the chain kernel.
ITERATE_MIN_N = 56
#: Free coordinates from which the compiled point kernel of a curve uses the chain kernel.
POINT_MIN_N = 56
#: Smallest pivot reciprocal condition for which a chain factorisation of eq. (28) is used (as
#: :data:`vjm_pin.solver.stiffness.CHAIN_TRUST_RCOND`): below it the dense routine decides.
TRUST_RCOND = 1e-8
#: Relative accuracy of the smallest eigenvalue (plus ``1e-13·max|K_θ|`` absolute).
EIG_RTOL = 1e-13
#: Inverse iterations before the result is declared unconverged (then the dense routine runs).
MAX_INVERSE = 40
#: Largest change of the unit eigenvector in the last inverse iteration: the verdict's (only
#: the next solve's start needs it) and the force-control margin's (``dμ/ds`` is linear in it).
VEC_TOL_VERDICT = 1e-8
VEC_TOL_MARGIN = 1e-11

NEED_DENSE = 9  #: status: the chain result is not trustworthy, run the dense routine
_CONTINUE, _POLISH, _CONVERGED = _kernel.CONTINUE, _kernel.POLISH, _kernel.CONVERGED
_FACTOR_FAIL, _STEP_FAIL, _RANK_FAIL = _kernel.FACTOR_FAIL, _kernel.STEP_FAIL, _kernel.RANK_FAIL


# =========================================================================== compiled pieces
def _w_gens(jz, f6, starts, kd, symmetric):
    """Generators of ``W = K − H`` (or its symmetric part) in chain order (chain_algebra's
    :func:`~vjm_pin.solver.chain_algebra.chain_matrix`): ``(diag, u, v, p, q)``."""
    n = jz.shape[1]
    b = kd.shape[1]
    f0, f1, f2, m0, m1, m2 = f6[0], f6[1], f6[2], f6[3], f6[4], f6[5]
    a = np.empty((n, 3))
    d = np.empty((n, 3))
    e = np.empty((n, 3))
    w = np.empty((n, 3))
    for i in range(n):
        v0, v1, v2 = jz[0, i], jz[1, i], jz[2, i]
        w0, w1, w2 = jz[3, i], jz[4, i], jz[5, i]
        d[i, 0] = v1 * f2 - v2 * f1
        d[i, 1] = v2 * f0 - v0 * f2
        d[i, 2] = v0 * f1 - v1 * f0
        e[i, 0] = w1 * m2 - w2 * m1
        e[i, 1] = w2 * m0 - w0 * m2
        e[i, 2] = w0 * m1 - w1 * m0
        for c in range(3):
            a[i, c] = d[i, c] + e[i, c]
        w[i, 0], w[i, 1], w[i, 2] = w0, w1, w2
    wd = np.zeros((n, b))
    for k in range(starts.shape[0] - 1):
        s0, s1 = starts[k], starts[k + 1]
        for i in range(s0, s1):
            for j in range(s0, s1):
                if j <= i:
                    hij = a[i, 0] * w[j, 0] + a[i, 1] * w[j, 1] + a[i, 2] * w[j, 2]
                else:
                    hij = w[i, 0] * d[j, 0] + w[i, 1] * d[j, 1] + w[i, 2] * d[j, 2]
                if symmetric:
                    if i <= j:
                        hji = a[j, 0] * w[i, 0] + a[j, 1] * w[i, 1] + a[j, 2] * w[i, 2]
                    else:
                        hji = w[j, 0] * d[i, 0] + w[j, 1] * d[i, 1] + w[j, 2] * d[i, 2]
                    hij = 0.5 * (hij + hji)
                wd[i, j - s0] = kd[i, j - s0] - hij
    if symmetric:
        uu = np.empty((n, 3))
        for i in range(n):
            for c in range(3):
                uu[i, c] = -(d[i, c] + 0.5 * e[i, c])
        return wd, uu, w, w, uu
    neg_a = -a
    neg_w = -w
    return wd, neg_a, w, neg_w, d


def _bordered(wd, wu, wv, wp, wq, starts, dpos, kp, cb):
    """The scaled, augmented bordered matrix ``[[S(W + ρCᵀC)S, SCᵀ], [CS, 0]]`` of
    :class:`~vjm_pin.solver.chain_algebra.ChainKKT` (shift 0): ``(bst, bd, bu, bv, bp, bq, s, ρ)``."""
    n, b = wd.shape
    k = cb.shape[0]
    r0 = wu.shape[1]
    s0_ = wq.shape[1]
    nb = starts.shape[0] - 1
    jn = np.zeros(n)
    for c in range(k):
        for i in range(n):
            jn[i] += cb[c, i] * cb[c, i]
    kref_sum = 0.0
    npos = 0
    for i in range(n):
        t = abs(wd[i, dpos[i]])
        if t != 0.0:
            kref_sum += t
            npos += 1
    kref = kref_sum / npos if npos else 1.0
    comp = 0.0
    tb = np.empty(b)  # a block's sums side by side (each in j order), then added to comp in i order
    for kb in range(nb):
        a0, a1 = starts[kb], starts[kb + 1]
        nk = a1 - a0
        for c in range(k):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    cj = cb[c, a0 + j]
                    t0 += kp[a0 + i, j] * cj
                    t1 += kp[a0 + i + 1, j] * cj
                    t2 += kp[a0 + i + 2, j] * cj
                tb[i] = t0
                tb[i + 1] = t1
                tb[i + 2] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    cj = cb[c, a0 + j]
                    t0 += kp[a0 + i, j] * cj
                    t1 += kp[a0 + i + 1, j] * cj
                tb[i] = t0
                tb[i + 1] = t1
                i += 2
            if i < nk:
                t0 = 0.0
                for j in range(nk):
                    cj = cb[c, a0 + j]
                    t0 += kp[a0 + i, j] * cj
                tb[i] = t0
                i += 1
            for i in range(nk):
                comp += cb[c, a0 + i] * tb[i]
    if k == 0:
        rho = 0.0
    elif comp > 0.0 and math.isfinite(comp):
        rho = RHO_FACTOR * k / comp
    else:
        mj = 0.0
        for i in range(n):
            mj += jn[i]
        rho = RHO_FACTOR * kref / max(mj / max(n, 1), 1e-300)
    s = np.empty(n)
    for i in range(n):
        dw = abs(wd[i, dpos[i]]) + rho * jn[i]
        s[i] = 1.0 / math.sqrt(dw) if dw > 0.0 else 1.0 / math.sqrt(kref)
    bsz = max(b, k)
    bd = np.zeros((n + k, bsz))
    for kb in range(nb):
        a0, a1 = starts[kb], starts[kb + 1]
        nk = a1 - a0
        for i in range(a0, a1):
            si = s[i]
            j = 0
            while j + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for c in range(k):
                    ci = cb[c, i]
                    t0 += ci * cb[c, a0 + j]
                    t1 += ci * cb[c, a0 + j + 1]
                    t2 += ci * cb[c, a0 + j + 2]
                bd[i, j] = (wd[i, j] + rho * t0) * si * s[a0 + j]
                bd[i, j + 1] = (wd[i, j + 1] + rho * t1) * si * s[a0 + j + 1]
                bd[i, j + 2] = (wd[i, j + 2] + rho * t2) * si * s[a0 + j + 2]
                j += 3
            if j + 1 < nk:
                t0, t1 = 0.0, 0.0
                for c in range(k):
                    ci = cb[c, i]
                    t0 += ci * cb[c, a0 + j]
                    t1 += ci * cb[c, a0 + j + 1]
                bd[i, j] = (wd[i, j] + rho * t0) * si * s[a0 + j]
                bd[i, j + 1] = (wd[i, j + 1] + rho * t1) * si * s[a0 + j + 1]
                j += 2
            if j < nk:
                t0 = 0.0
                for c in range(k):
                    ci = cb[c, i]
                    t0 += ci * cb[c, a0 + j]
                bd[i, j] = (wd[i, j] + rho * t0) * si * s[a0 + j]
                j += 1
    bu = np.zeros((n + k, r0 + k))
    bv = np.zeros((n + k, r0 + k))
    bp = np.zeros((n + k, s0_ + k))
    bq = np.zeros((n + k, s0_ + k))
    for i in range(n):
        si = s[i]
        for c in range(r0):
            bu[i, c] = wu[i, c] * si
            bv[i, c] = wv[i, c] * si
        for c in range(s0_):
            bp[i, c] = wp[i, c] * si
            bq[i, c] = wq[i, c] * si
        for c in range(k):
            js = si * cb[c, i]
            bu[i, r0 + c] = rho * js
            bv[i, r0 + c] = js
            bp[i, s0_ + c] = js
            bq[i, s0_ + c] = rho * js
    for c in range(k):
        bu[n + c, r0 + c] = 1.0
        bq[n + c, s0_ + c] = 1.0
    if k > 0:
        bst = np.empty(nb + 2, np.int64)
        bst[: nb + 1] = starts
        bst[nb + 1] = n + k
    else:
        bst = starts.copy()
    return bst, bd, bu, bv, bp, bq, s, rho


def _factor(starts, diag, u, v, p, q, symmetric):
    """Block LU of the quasiseparable matrix (chain_algebra's ``_factor_loops``, ``lean``: the
    inertia of the symmetric case by :func:`_inertia_small` per pivot block):
    ``(pinv, x, y, rcond_min, bad, npos, nneg, nzero)``."""
    pinv, x, y, info, counts = _factor_loops(starts, diag, u, v, p, q, symmetric, True)
    return pinv, x, y, info[0], info[4] != 0.0, counts[0], counts[1], counts[2]


def _shifted(bd, s, dpos, sigma):
    """``bd`` with the chain diagonal shifted by ``−σ`` (scaled: ``−σ s_i²``)."""
    out = bd.copy()
    for i in range(s.shape[0]):
        out[i, dpos[i]] -= sigma * s[i] * s[i]
    return out


def _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, c1, c2):
    """The bordered solve mapped back: ``(x, λ)`` of ``(W − σI)x + Cᵀλ = c1``, ``Cx = c2``."""
    n = s.shape[0]
    k, nc = c2.shape
    rhs = np.empty((n + k, nc))
    for i in range(n):
        for c in range(nc):
            rhs[i, c] = c1[i, c] * s[i]
    for i in range(k):
        for c in range(nc):
            rhs[n + i, c] = c2[i, c]
    z = _solve(bst, pinv, bu, fx, fy, bq, rhs)
    xs = np.empty((n, nc))
    lam = np.empty((k, nc))
    for i in range(n):
        for c in range(nc):
            xs[i, c] = z[i, c] * s[i]
    for i in range(k):
        for c in range(nc):
            lam[i, c] = z[n + i, c] + rho * c2[i, c]
    return xs, lam


def _kkt_solve(starts, wd, wu, wv, wp, wq, cb, sigma, bst, pinv, bu, fx, fy, bq, s, rho, b1, b2, refine):
    """:meth:`~vjm_pin.solver.chain_algebra.ChainKKT.solve`: ``(x, λ, relative residual)``."""
    n = s.shape[0]
    k, nc = b2.shape
    xs, lam = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, b1, b2)
    jsmax = 0.0
    for c in range(k):
        for i in range(n):
            jsmax = max(jsmax, abs(cb[c, i] * s[i]))
    bmax = 0.0
    for i in range(n):
        for c in range(nc):
            bmax = max(bmax, abs(b1[i, c] * s[i]))
    for i in range(k):
        for c in range(nc):
            bmax = max(bmax, abs(b2[i, c]))
    res = np.inf
    r1 = np.empty((n, nc))
    r2 = np.empty((k, nc))
    for it in range(refine + 1):
        wx = _matvec(starts, wd, wu, wv, wp, wq, xs)
        num = 0.0
        for i in range(n):
            for c in range(nc):
                t = wx[i, c] - sigma * xs[i, c]
                for j in range(k):
                    t += cb[j, i] * lam[j, c]
                r1[i, c] = b1[i, c] - t
                num = max(num, abs(r1[i, c] * s[i]))
        for c in range(nc):  # the k sums over the chain side by side (each in i order)
            j = 0
            while j + 2 < k:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(n):
                    xi = xs[i, c]
                    t0 += cb[j, i] * xi
                    t1 += cb[j + 1, i] * xi
                    t2 += cb[j + 2, i] * xi
                r2[j, c] = b2[j, c] - t0
                r2[j + 1, c] = b2[j + 1, c] - t1
                r2[j + 2, c] = b2[j + 2, c] - t2
                j += 3
            if j + 1 < k:
                t0, t1 = 0.0, 0.0
                for i in range(n):
                    xi = xs[i, c]
                    t0 += cb[j, i] * xi
                    t1 += cb[j + 1, i] * xi
                r2[j, c] = b2[j, c] - t0
                r2[j + 1, c] = b2[j + 1, c] - t1
                j += 2
            if j < k:
                t0 = 0.0
                for i in range(n):
                    xi = xs[i, c]
                    t0 += cb[j, i] * xi
                r2[j, c] = b2[j, c] - t0
                j += 1
        for j in range(k):
            for c in range(nc):
                num = max(num, abs(r2[j, c]))
        xm = 0.0
        for i in range(n):
            for c in range(nc):
                xm = max(xm, abs(xs[i, c] / s[i]))
        for j in range(k):
            for c in range(nc):
                xm = max(xm, abs(lam[j, c]))
        den = xm * max(1.0, jsmax) + bmax
        res = num / den if den > 0.0 else 0.0
        if not math.isfinite(res):
            res = np.inf
            break
        if it == refine or res < 1e-15:
            break
        dx, dl = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, r1, r2)
        xs += dx
        lam += dl
    return xs, lam, res


def _inertia_factor(starts, diag, u, v, p, q):
    """The symmetric ``lean`` block elimination of chain_algebra's ``_factor_loops`` for the inertia
    alone: ``(rcond_min, bad, npos, nneg, nzero)``, the same arithmetic in the same order (the same
    pivot blocks, reciprocal conditions and counts, bit for bit), without the factors a solve needs
    (no ``x``; this block's inverse and ``y`` kept only until ``G`` is updated): a Sturm count
    whose factorisation is not used (:func:`_count_only`)."""
    n, r = u.shape
    s = q.shape[1]
    bmax = diag.shape[1]
    g = np.zeros((r, s))
    ug = np.zeros((bmax, s))
    pi = np.zeros((bmax, bmax))
    work = np.zeros((bmax, 2 * bmax))
    vt = np.zeros((bmax, r))
    sm = np.zeros((bmax, bmax))
    pk = np.zeros((bmax, bmax))
    yk = np.zeros((bmax, s))
    tj = np.zeros(bmax)
    rows = np.empty(bmax, np.int64)
    rc_min = np.inf
    npos, nneg, nzero = 0, 0, 0
    for k in range(len(starts) - 1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for i in range(nk):
            ai = a + i
            c = 0
            while c + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for l in range(r):
                    ul = u[ai, l]
                    t0 += ul * g[l, c]
                    t1 += ul * g[l, c + 1]
                    t2 += ul * g[l, c + 2]
                ug[i, c] = t0
                ug[i, c + 1] = t1
                ug[i, c + 2] = t2
                c += 3
            if c + 1 < s:
                t0, t1 = 0.0, 0.0
                for l in range(r):
                    ul = u[ai, l]
                    t0 += ul * g[l, c]
                    t1 += ul * g[l, c + 1]
                ug[i, c] = t0
                ug[i, c + 1] = t1
                c += 2
            if c < s:
                t0 = 0.0
                for l in range(r):
                    ul = u[ai, l]
                    t0 += ul * g[l, c]
                ug[i, c] = t0
                c += 1
        ref_d, ref_c, ref_p = 0.0, 0.0, 0.0
        for i in range(nk):
            j = 0
            while j + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for c in range(s):
                    uc = ug[i, c]
                    t0 += uc * q[a + j, c]
                    t1 += uc * q[a + j + 1, c]
                    t2 += uc * q[a + j + 2, c]
                tj[j] = t0
                tj[j + 1] = t1
                tj[j + 2] = t2
                j += 3
            if j + 1 < nk:
                t0, t1 = 0.0, 0.0
                for c in range(s):
                    uc = ug[i, c]
                    t0 += uc * q[a + j, c]
                    t1 += uc * q[a + j + 1, c]
                tj[j] = t0
                tj[j + 1] = t1
                j += 2
            if j < nk:
                t0 = 0.0
                for c in range(s):
                    uc = ug[i, c]
                    t0 += uc * q[a + j, c]
                tj[j] = t0
                j += 1
            rd, rcr = 0.0, 0.0
            for j in range(nk):
                t = tj[j]
                pi[i, j] = diag[a + i, j] - t
                rd += abs(diag[a + i, j])
                rcr += abs(t)
            ref_d = max(ref_d, rd)
            ref_c = max(ref_c, rcr)
        for i in range(nk):
            for j in range(i + 1, nk):
                t = 0.5 * (pi[i, j] + pi[j, i])
                pi[i, j] = t
                pi[j, i] = t
        for i in range(nk):
            rp = 0.0
            for j in range(nk):
                rp += abs(pi[i, j])
            ref_p = max(ref_p, rp)
        ref = max(ref_d, max(ref_c, ref_p))
        # Gauss-Jordan inverse with partial pivoting: work = [pi | I]
        for i in range(nk):
            for j in range(nk):
                work[i, j] = pi[i, j]
                work[i, nk + j] = 1.0 if i == j else 0.0
        ok = True
        for col in range(nk):
            best, piv = -1.0, col
            for i in range(col, nk):
                if abs(work[i, col]) > best:
                    best, piv = abs(work[i, col]), i
            if not (best > 0.0) or not np.isfinite(best):
                ok = False
                break
            if piv != col:
                for j in range(2 * nk):
                    t = work[col, j]
                    work[col, j] = work[piv, j]
                    work[piv, j] = t
            dv = work[col, col]
            # (the columns left of col are never read again: from col on, the same operations)
            for j in range(col, 2 * nk):
                work[col, j] /= dv
            for i in range(nk):
                if i != col:
                    f = work[i, col]
                    if f != 0.0:
                        for j in range(col, 2 * nk):
                            work[i, j] -= f * work[col, j]
        inv_norm = 0.0
        for i in range(nk):
            ri = 0.0
            for j in range(nk):
                t = work[i, nk + j]
                pk[i, j] = t
                ri += abs(t)
            inv_norm = max(inv_norm, ri)
        if not ok or not np.isfinite(inv_norm):
            return 0.0, True, npos, nneg, nzero
        rc = 1.0 / (inv_norm * ref) if ref > 0.0 else 0.0
        if rc < rc_min:
            rc_min = rc
        for i in range(nk):
            for j in range(nk):
                sm[i, j] = pi[i, j]
        cp, cn, cz = _inertia_pivots(sm, nk, 1e-14 * nk * ref, rows)
        npos += cp
        nneg += cn
        nzero += cz
        for i in range(nk):
            ai = a + i
            l = 0
            while l + 2 < r:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for c in range(s):
                    qc = q[ai, c]
                    t0 += qc * g[l, c]
                    t1 += qc * g[l + 1, c]
                    t2 += qc * g[l + 2, c]
                vt[i, l] = v[ai, l] - t0
                vt[i, l + 1] = v[ai, l + 1] - t1
                vt[i, l + 2] = v[ai, l + 2] - t2
                l += 3
            if l + 1 < r:
                t0, t1 = 0.0, 0.0
                for c in range(s):
                    qc = q[ai, c]
                    t0 += qc * g[l, c]
                    t1 += qc * g[l + 1, c]
                vt[i, l] = v[ai, l] - t0
                vt[i, l + 1] = v[ai, l + 1] - t1
                l += 2
            if l < r:
                t0 = 0.0
                for c in range(s):
                    qc = q[ai, c]
                    t0 += qc * g[l, c]
                vt[i, l] = v[ai, l] - t0
                l += 1
        for i in range(nk):
            c = 0
            while c + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    pij = pk[i, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                    t1 += pij * (p[a + j, c + 1] - ug[j, c + 1])
                    t2 += pij * (p[a + j, c + 2] - ug[j, c + 2])
                yk[i, c] = t0
                yk[i, c + 1] = t1
                yk[i, c + 2] = t2
                c += 3
            if c + 1 < s:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    pij = pk[i, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                    t1 += pij * (p[a + j, c + 1] - ug[j, c + 1])
                yk[i, c] = t0
                yk[i, c + 1] = t1
                c += 2
            if c < s:
                t0 = 0.0
                for j in range(nk):
                    pij = pk[i, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                yk[i, c] = t0
                c += 1
        for l in range(r):
            c = 0
            while c + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * yk[i, c]
                    t1 += vl * yk[i, c + 1]
                    t2 += vl * yk[i, c + 2]
                g[l, c] += t0
                g[l, c + 1] += t1
                g[l, c + 2] += t2
                c += 3
            if c + 1 < s:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * yk[i, c]
                    t1 += vl * yk[i, c + 1]
                g[l, c] += t0
                g[l, c + 1] += t1
                c += 2
            if c < s:
                t0 = 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * yk[i, c]
                g[l, c] += t0
                c += 1
    return rc_min, False, npos, nneg, nzero


def _count_only(bst, bd, bu, bv, bp, bq, s, dpos, k, sigma):
    """:func:`_count` without the factorisation (:func:`_inertia_factor`): the same count."""
    sh = _shifted(bd, s, dpos, sigma)
    rc, bad, npos, nneg, nzero = _inertia_factor(bst, sh, bu, bv, bp, bq)
    if bad or not rc >= PIVOT_RCOND or npos < k or nneg < k or nzero > 0:
        return -1
    return nneg - k


def _count(bst, bd, bu, bv, bp, bq, s, dpos, k, sigma):
    """Sturm count: eigenvalues of ``Zᵀ W_s Z`` below ``σ`` (−1 when not reliable), and the
    factorisation at ``σ`` ``(pinv, x, y)``."""
    sh = _shifted(bd, s, dpos, sigma)
    pinv, fx, fy, rc, bad, npos, nneg, nzero = _factor(bst, sh, bu, bv, bp, bq, True)
    if bad or not rc >= PIVOT_RCOND or npos < k or nneg < k or nzero > 0:
        return -1, pinv, fx, fy
    return nneg - k, pinv, fx, fy


def _project(cb, v):
    """``v`` minus its component in the row space of ``cb`` (Gram–Schmidt twice on the rows)."""
    k, n = cb.shape
    qr = np.zeros((k, n))
    for c in range(k):
        for i in range(n):
            qr[c, i] = cb[c, i]
        for _ in range(2):
            for c2 in range(c):
                t = 0.0
                for i in range(n):
                    t += qr[c2, i] * qr[c, i]
                for i in range(n):
                    qr[c, i] -= t * qr[c2, i]
        nr = 0.0
        for i in range(n):
            nr += qr[c, i] * qr[c, i]
        nr = math.sqrt(nr)
        if nr > 0.0:
            for i in range(n):
                qr[c, i] /= nr
    out = v.copy()
    for _ in range(2):
        for c in range(k):
            t = 0.0
            for i in range(n):
                t += qr[c, i] * out[i]
            for i in range(n):
                out[i] -= t * qr[c, i]
    return out


def _rayleigh(starts, sd, su, sv, sp, sq, xv):
    """``xᵀ W_s x / xᵀx`` for the symmetric part's generators."""
    n = xv.shape[0]
    wx = _matvec(starts, sd, su, sv, sp, sq, xv.reshape(n, 1))
    num = 0.0
    den = 0.0
    for i in range(n):
        num += xv[i] * wx[i, 0]
        den += xv[i] * xv[i]
    return num / den


def _inverse(starts, sd, su, sv, sp, sq, bst, pinv, bu, fx, fy, bq, s, rho, k, lo, hi, start, atol, vtol):
    """Inverse iteration at the shift ``lo`` (no eigenvalue below it): ``(ok, value, vector)``;
    converged when the Rayleigh quotient has settled and the unit vector moves by at most
    ``vtol`` in one iteration (its error is then ~``vtol·ρ``, ``ρ = (λ₁ − lo)/(λ₂ − lo)``)."""
    n = s.shape[0]
    v = start.copy()
    nrm = math.sqrt(np.sum(v * v))
    if not nrm > 0.0:
        return False, 0.0, v
    v /= nrm
    prev = np.inf
    zero = np.zeros((k, 1))
    for _ in range(MAX_INVERSE):
        xs, _ = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, v.reshape(n, 1), zero)
        x1 = xs[:, 0].copy()
        nx = math.sqrt(np.sum(x1 * x1))
        if not math.isfinite(nx) or nx == 0.0:
            return False, 0.0, v
        x1 /= nx
        dot = 0.0
        for i in range(n):
            dot += x1[i] * v[i]
        sg = 1.0 if dot >= 0.0 else -1.0
        dv = 0.0
        for i in range(n):
            dv = max(dv, abs(x1[i] - sg * v[i]))
        rq = _rayleigh(starts, sd, su, sv, sp, sq, x1)
        if abs(rq - prev) <= 0.1 * (EIG_RTOL * abs(rq) + atol) and dv <= vtol:
            ok = lo - atol <= rq <= hi + EIG_RTOL * abs(hi) + atol
            return ok, rq, x1
        prev = rq
        v = x1
    return False, prev, v


def _rnd_start(n):
    """The fixed pseudo-random start of :func:`_smallest` (length ``n``, before its projection)."""
    rnd = np.empty(n)
    for i in range(n):
        rnd[i] = math.sin(1.0 + 0.7 * i) + 0.3 * math.cos(2.3 * i)
    return rnd


def _smallest(starts, dpos, kp, jz, f6, kd, cb, scale, has_guess, gvec, vtol, rnd0=None):
    """Smallest eigenvalue ``λ₁`` of ``Zᵀ W_s Z`` (``Z``: null space of ``cb``) and a unit
    eigenvector (chain order): ``(ok, λ₁, vector)`` (module docstring). ``gvec``: a previous
    eigenvector (length n; used when ``has_guess``); when the attempt from it fails (a mode
    switch, no convergence, no certificate) the bracket is made from scratch. ``rnd0``:
    :func:`_rnd_start` of length n when given (a workspace's copy), else it is computed."""
    sd, su, sv, sp, sq = _w_gens(jz, f6, starts, kd, True)
    return _smallest_w(starts, dpos, kp, sd, su, sv, sp, sq, cb, scale, has_guess, gvec, vtol, rnd0)


def _smallest_w(starts, dpos, kp, sd, su, sv, sp, sq, cb, scale, has_guess, gvec, vtol, rnd0):
    """:func:`_smallest` from the generators of ``W_s`` (:func:`_w_gens`, ``symmetric``), which the
    caller keeps (the point's ``dμ/ds`` multiplies by the same matrix)."""
    n = sd.shape[0]
    k = cb.shape[0]
    atol = 1e-13 * scale
    bst, bd, bu, bv, bp, bq, s, rho = _bordered(sd, su, sv, sp, sq, starts, dpos, kp, cb)
    empty = np.zeros(n)
    # a fixed pseudo-random start (the bisection path, a mixed-in component)
    if rnd0 is None:
        raw = _rnd_start(n)
    else:
        raw = rnd0 if rnd0.shape[0] == n else _rnd_start(n)
    rnd = _project(cb, raw)
    nr = math.sqrt(np.sum(rnd * rnd))
    for attempt in range(2):
        if attempt == 0 and not has_guess:
            continue
        lo, hi = 0.0, 0.0
        have_lo = False
        pinv_lo, fx_lo, fy_lo = bd, bu, bq  # placeholders (typed), replaced with the factor at lo
        start = rnd.copy()
        if attempt == 0:
            g = _project(cb, gvec)
            ng = math.sqrt(np.sum(g * g))
            if not (ng > 0.0 and math.isfinite(ng) and nr > 0.0):
                continue
            g /= ng
            hi = _rayleigh(starts, sd, su, sv, sp, sq, g)  # ≥ λ₁ (Courant–Fischer)
            if not math.isfinite(hi):
                continue
            for i in range(n):
                start[i] = g[i] + 1e-3 * rnd[i] / nr
            delta = 0.02 * abs(hi) + 1e3 * atol
            for _ in range(12):
                sig = hi - delta
                c, pinv_, fx_, fy_ = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, sig)
                if c == 0:
                    lo, have_lo = sig, True
                    pinv_lo, fx_lo, fy_lo = pinv_, fx_, fy_
                    break
                delta *= 4.0 if c > 0 else 1.001
            if not have_lo:
                continue
        else:  # bracket from scratch and bisect to two digits
            hi = scale
            step = scale
            found = False
            for _ in range(64):
                c = _count_only(bst, bd, bu, bv, bp, bq, s, dpos, k, hi)
                if c >= 1:
                    found = True
                    break
                hi, step = (hi + step, 4.0 * step) if c == 0 else (hi + 1e-3 * step, step)
            if not found:
                return False, 0.0, empty
            lo = -scale
            step = -scale
            found = False
            for _ in range(64):
                c, pinv_, fx_, fy_ = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, lo)
                if c == 0:
                    found = True
                    pinv_lo, fx_lo, fy_lo = pinv_, fx_, fy_
                    break
                lo, step = (lo + step, 4.0 * step) if c > 0 else (lo + 1e-3 * step, step)
            if not found:
                return False, 0.0, empty
            while hi - lo > 1e-2 * max(abs(lo), abs(hi)) + atol:
                c = -1
                mid = lo
                for frac in (0.5, 0.375, 0.625, 0.25, 0.75):
                    mid = _split(lo, hi, frac, atol)
                    c, pinv_, fx_, fy_ = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, mid)
                    if c >= 0:
                        break
                if c < 0:
                    return False, 0.0, empty
                if c >= 1:
                    hi = mid
                else:
                    lo = mid
                    pinv_lo, fx_lo, fy_lo = pinv_, fx_, fy_
        ok, val, vec = _inverse(starts, sd, su, sv, sp, sq, bst, pinv_lo, bu, fx_lo, fy_lo, bq, s, rho, k, lo, hi,
                                start, atol, vtol)
        if not ok:
            continue
        # certify: no eigenvalue below the converged value (less its accuracy)
        margin = 1e-9 * abs(val) + 1e2 * atol
        for _ in range(6):
            c = _count_only(bst, bd, bu, bv, bp, bq, s, dpos, k, val - margin)
            if c == 0:
                return True, val, vec
            if c > 0:
                break
            margin *= 10.0
    return False, 0.0, empty


def _gather(jsrc, idx, task):
    """The Jacobian columns ``idx`` of ``jsrc`` (6 rows) in chain order, and their task rows:
    ``(jz, cb)``."""
    n = idx.shape[0]
    m = task.shape[0]
    jz = np.empty((6, n))
    for c in range(n):
        for a_ in range(6):
            jz[a_, c] = jsrc[a_, idx[c]]
    cb = np.empty((m, n))
    for i in range(m):
        for c in range(n):
            cb[i, c] = jz[task[i], c]
    return jz, cb


def _held_rows(rows, cb):
    """The held rows ``P J`` (k, n): ``rows`` (k, m) times the task rows ``cb`` (m, n), each sum in
    the order of the task rows (as the point kernel forms them)."""
    k = rows.shape[0]
    m, n = cb.shape
    ch = np.zeros((k, n))
    for a_ in range(k):
        for i in range(m):
            pa = rows[a_, i]
            for c in range(n):
                ch[a_, c] += pa * cb[i, c]
    return ch


def _qr_rank(cb, m, n, ratio):
    """The Householder QR of ``cbᵀ`` (:func:`~vjm_pin.solver.kernel._qr_t`; ``cb`` (m, n), m ≤ n),
    its ``R`` and the rank test: ``(ok, hh, R)``, ok when ``R`` is finite and its singular values
    (those of ``cb``) have a ratio above ``ratio``."""
    hh = _qr_t(cb, m, n)
    rmat = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            rmat[i, j] = hh[j, i]
            if not math.isfinite(hh[j, i]):
                return False, hh, rmat
    sv = np.linalg.svd(rmat)[1]
    return sv[m - 1] > ratio * sv[0], hh, rmat


def _twists(jz):
    """The columns of a (6, n) Jacobian as rows: ``(v, ω)``, each (n, 3)."""
    n = jz.shape[1]
    om = np.empty((n, 3))
    li = np.empty((n, 3))
    for c in range(n):
        for a3 in range(3):
            li[c, a3] = jz[a3, c]
            om[c, a3] = jz[3 + a3, c]
    return li, om


def _twist_rate_row(i, o0, o1, o2, p0, p1, p2, li, om, dli, dom):
    """Row ``i`` of the twists' rates along a motion: ``δω_i = o × ω_i`` and
    ``δv_i = o × v_i + ω_i × p`` (``o``: the summed angular rates of the joints before ``i``,
    ``p``: the summed linear rates of those after it), written into ``dom`` and ``dli``."""
    dom[i, 0] = o1 * om[i, 2] - o2 * om[i, 1]
    dom[i, 1] = o2 * om[i, 0] - o0 * om[i, 2]
    dom[i, 2] = o0 * om[i, 1] - o1 * om[i, 0]
    dli[i, 0] = o1 * li[i, 2] - o2 * li[i, 1] + om[i, 1] * p2 - om[i, 2] * p1
    dli[i, 1] = o2 * li[i, 0] - o0 * li[i, 2] + om[i, 2] * p0 - om[i, 0] * p2
    dli[i, 2] = o0 * li[i, 1] - o1 * li[i, 0] + om[i, 0] * p1 - om[i, 1] * p0


def _rate_terms(li, om, dli, dom, wrench, fd, task):
    """Per column of ``dμ/ds`` (:meth:`~vjm_pin.analysis.point_kernel.PointKernel.margin_rate`;
    also :func:`~vjm_pin.analysis.point_kernel._point_loops`), with the wrench ``F = (f, m)`` and
    its rate ``δF`` (task rows): ``a = v×f + ω×m``, ``da = δv×f + v×δf + δω×m + ω×δm``,
    ``b = v×f``, ``db = δv×f + v×δf``: ``(a, da, b, db)``, each (n, 3)."""
    n = li.shape[0]
    wdot = np.zeros(6)
    for i in range(task.shape[0]):
        wdot[task[i]] = fd[i]
    f0, f1, f2, m0, m1, m2 = wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5]
    g0, g1, g2, n0, n1, n2 = wdot[0], wdot[1], wdot[2], wdot[3], wdot[4], wdot[5]
    aa = np.empty((n, 3))
    da = np.empty((n, 3))
    bb = np.empty((n, 3))
    db = np.empty((n, 3))
    for c in range(n):
        v0, v1, v2 = li[c, 0], li[c, 1], li[c, 2]
        w0_, w1_, w2_ = om[c, 0], om[c, 1], om[c, 2]
        dv0, dv1, dv2 = dli[c, 0], dli[c, 1], dli[c, 2]
        dw0, dw1, dw2 = dom[c, 0], dom[c, 1], dom[c, 2]
        b0 = v1 * f2 - v2 * f1
        b1_ = v2 * f0 - v0 * f2
        b2_ = v0 * f1 - v1 * f0
        bb[c, 0], bb[c, 1], bb[c, 2] = b0, b1_, b2_
        aa[c, 0] = b0 + w1_ * m2 - w2_ * m1
        aa[c, 1] = b1_ + w2_ * m0 - w0_ * m2
        aa[c, 2] = b2_ + w0_ * m1 - w1_ * m0
        e0 = dv1 * f2 - dv2 * f1 + v1 * g2 - v2 * g1
        e1 = dv2 * f0 - dv0 * f2 + v2 * g0 - v0 * g2
        e2 = dv0 * f1 - dv1 * f0 + v0 * g1 - v1 * g0
        db[c, 0], db[c, 1], db[c, 2] = e0, e1, e2
        da[c, 0] = e0 + dw1 * m2 - dw2 * m1 + w1_ * n2 - w2_ * n1
        da[c, 1] = e1 + dw2 * m0 - dw0 * m2 + w2_ * n0 - w0_ * n2
        da[c, 2] = e2 + dw0 * m1 - dw1 * m0 + w0_ * n1 - w1_ * n0
    return aa, da, bb, db


def _rate_lin(dli, dom, w, g, task):
    """``gᵀ (J' w)`` on the task rows (the second term of ``dμ/ds``)."""
    jw = np.zeros(6)
    for c in range(dli.shape[0]):
        for a3 in range(3):
            jw[a3] += dli[c, a3] * w[c]
            jw[3 + a3] += dom[c, a3] * w[c]
    lin = 0.0
    for i in range(task.shape[0]):
        lin += g[i] * jw[task[i]]
    return lin


def _hessian_rows(jfree, f6, mask, n):
    """:func:`vjm_pin.solver.kernel._hessian` (the (θ, q)-ordered Hessian of Ψ, eq. 16, in screw
    form), every entry the same expression evaluated in the same order (so the same bits), written
    row by row with both cases of the support mask computed and one selected: no branch in the inner
    loop (~7x faster at n = 146)."""
    fx, fy, fz, mx, my, mz = f6[0], f6[1], f6[2], f6[3], f6[4], f6[5]
    d0 = np.empty(n)
    d1 = np.empty(n)
    d2 = np.empty(n)
    e0 = np.empty(n)
    e1 = np.empty(n)
    e2 = np.empty(n)
    w0 = np.empty(n)
    w1 = np.empty(n)
    w2 = np.empty(n)
    for b in range(n):
        v0, v1, v2 = jfree[0, b], jfree[1, b], jfree[2, b]
        a0, a1, a2 = jfree[3, b], jfree[4, b], jfree[5, b]
        d0[b] = fz * v1 - fy * v2
        d1[b] = -fz * v0 + fx * v2
        d2[b] = fy * v0 - fx * v1
        e0[b] = mz * a1 - my * a2
        e1[b] = -mz * a0 + mx * a2
        e2[b] = my * a0 - mx * a1
        w0[b], w1[b], w2[b] = a0, a1, a2
    hz = np.empty((n, n))
    for i in range(n):
        di0, di1, di2 = d0[i], d1[i], d2[i]
        ei0, ei1, ei2 = e0[i], e1[i], e2[i]
        wi0, wi1, wi2 = w0[i], w1[i], w2[i]
        row = hz[i]
        mrow = mask[i]
        for j in range(n):
            ta = w0[j] * di0 + w1[j] * di1 + w2[j] * di2 + (ei0 * w0[j] + ei1 * w1[j] + ei2 * w2[j])
            tb = wi0 * d0[j] + wi1 * d1[j] + wi2 * d2[j]
            row[j] = ta if mrow[j] else tb
    return hz


#: Header of a factorisation workspace (:func:`_ws_store`): valid flag, n, k, block width, r, s, ρ,
#: and the length of the :func:`_rnd_start` vector kept after it (:func:`_workspace`; 0: none).
_WS_HEAD = 8


def _ws_size(n, k, b):
    """Length of a workspace for ``n`` chain coordinates, ``k ≤ 6`` border rows and ``K_θ`` blocks
    of width ``b`` (:func:`_ws_store`; generators of ``W`` with 3 columns)."""
    kk = max(k, 6)
    r = 3 + kk
    return _WS_HEAD + n + 6 * n + 6 + kk + n + (n + kk) * (4 * r + max(b, kk))


def _bits_equal(a, b):
    """``a`` and ``b`` are the same float64 (the sign of a zero included; NaN never)."""
    return a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))


def _ws_store(ws, jz, f6, task, s, rho, bu, bq, pinv, fx, fy):
    """Keep the factorisation of eq. (28)'s bordered matrix (:func:`_bordered`, :func:`_factor`) of
    the Jacobian columns ``jz`` (chain order), the wrench ``f6`` and the task rows ``task`` in the
    workspace ``ws`` (1-D, :func:`_ws_size`; nothing kept when it is too short), for
    :func:`_ws_match` / :func:`_ws_views`: the curve's point at a converged equilibrium factorises
    the same matrix (the tangent of eq. 29)."""
    n = jz.shape[1]
    k = task.shape[0]
    nk, r = bu.shape
    sc = bq.shape[1]
    bsz = pinv.shape[1]
    need = _WS_HEAD + n + 6 * n + 6 + k + n + nk * (2 * r + 2 * sc + bsz)
    if ws.shape[0] < need:
        return
    ws[0] = 0.0
    ws[1], ws[2], ws[3], ws[4], ws[5], ws[6] = n, k, bsz, r, sc, rho
    o = _WS_HEAD + n
    for a_ in range(6):
        for i in range(n):
            ws[o] = jz[a_, i]
            o += 1
    for a_ in range(6):
        ws[o] = f6[a_]
        o += 1
    for i in range(k):
        ws[o] = task[i]
        o += 1
    for i in range(n):
        ws[o] = s[i]
        o += 1
    for arr in (bu, bq, fx, fy, pinv):
        for i in range(nk):
            for c in range(arr.shape[1]):
                ws[o] = arr[i, c]
                o += 1
    ws[0] = 1.0


def _ws_match(ws, jz, f6, task, bsz):
    """The workspace holds the factorisation of this problem (:func:`_ws_store`): the same bits of
    ``jz`` and ``f6``, the same task rows and block width."""
    n = jz.shape[1]
    k = task.shape[0]
    if ws.shape[0] < _WS_HEAD or ws[0] != 1.0 or ws[1] != n or ws[2] != k or ws[3] != bsz:
        return False
    o = _WS_HEAD + n
    for a_ in range(6):
        for i in range(n):
            if not _bits_equal(ws[o], jz[a_, i]):
                return False
            o += 1
    for a_ in range(6):
        if not _bits_equal(ws[o], f6[a_]):
            return False
        o += 1
    for i in range(k):
        if ws[o] != task[i]:
            return False
        o += 1
    return True


def _ws_views(ws, n, k):
    """The kept factorisation (:func:`_ws_match` true): ``(s, ρ, bu, bq, fx, fy, pinv)``, views of ``ws``."""
    bsz, r, sc, rho = int(ws[3]), int(ws[4]), int(ws[5]), ws[6]
    nk = n + k
    o = _WS_HEAD + n + 6 * n + 6 + k
    s = ws[o:o + n]
    o += n
    bu = ws[o:o + nk * r].reshape(nk, r)
    o += nk * r
    bq = ws[o:o + nk * sc].reshape(nk, sc)
    o += nk * sc
    fx = ws[o:o + nk * r].reshape(nk, r)
    o += nk * r
    fy = ws[o:o + nk * sc].reshape(nk, sc)
    o += nk * sc
    pinv = ws[o:o + nk * bsz].reshape(nk, bsz)
    return s, rho, bu, bq, fx, fy, pinv


def _ws_rnd(ws, n):
    """The :func:`_rnd_start` vector kept in the workspace (a view), or an empty view when none."""
    if ws.shape[0] >= _WS_HEAD + n and ws[7] == n:
        return ws[_WS_HEAD:_WS_HEAD + n]
    return ws[:0]


# --------------------------------------------------------------------------- the iteration
def _iterate_chain(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, ci, cf, kz, mask, theta0, vscale,
                   escale, cols, order, starts, dpos, kd, kp, kscale, klo, khi, has_guess, gvec, ws=None):
    """:func:`vjm_pin.solver.kernel._iterate_loops` with the O(n) chain algebra (module
    docstring). Extra results: ``vec`` (the eigenvector of the verdict, chain order, status
    CONVERGED; the input ``gvec`` otherwise, unused). Status :data:`NEED_DENSE`: run the dense
    kernel instead. ``ws``: a workspace (:func:`_ws_size`) in which a converged iteration keeps
    its factorisation of eq. (28) for the curve's point (:func:`_point_chain`), or None."""
    if ws is None:
        wsa = np.zeros(0)
    else:
        wsa = ws
    n, nt, m, nip, nir = ci[0], ci[1], ci[2], ci[3], ci[4]
    free = ci[6:6 + n]
    theta_idx = ci[6 + n:6 + n + nt]
    task = ci[6 + n + nt:6 + n + nt + m]
    ip = ci[6 + n + nt + m:6 + n + nt + m + nip]
    ir = ci[6 + n + nt + m + nip:6 + n + nt + m + nip + nir]
    shift, max_step = cf[4], cf[5]
    follow, polish_step, rank_tol = cf[6] != 0.0, cf[7], cf[8]
    fact_in = fact
    empty = fact_in[3]
    novec = gvec  # (an input array: returned without boxing a new one)
    if refactor:
        hh = np.zeros((m + 7, n))
        for a_ in range(6):
            for b in range(n):
                hh[m + 1 + a_, b] = J6[a_, free[b]]
        jfree = hh[m + 1:, :]
        jac = np.empty((m, n))
        for i in range(m):
            jac[i, :] = jfree[task[i], :]
        tau = np.zeros(n)
        for i in range(nt):
            s = 0.0
            for j in range(klo[i], khi[i]):
                s += kz[i, j] * (x[theta_idx[j]] - theta0[j])
            tau[i] = s
        hh[:m + 1, :] = _qr_t(jac, m, n)
        ok, rr, f, r, f6 = _multiplier(jac, hh, tau, task, m, n)
        if not ok:
            return _FACTOR_FAIL, 0.0, 0.0, 0.0, 0.0, fact, empty, empty, empty, novec
        hz = _hessian_rows(jfree, f6, mask, n) if keep else fact_in[6]
        fact = (jac, hh, rr, f, r, tau, hz, f6)
    jac, hh, rr, f, r, tau, hz, f6 = fact
    if hh.shape[0] != m + 7:  # a factorisation by the dense kernel: no Jacobian rows here
        return NEED_DENSE, 0.0, 0.0, 0.0, 0.0, fact_in, empty, empty, empty, novec
    jfree = hh[m + 1:, :]
    e, ep, er, rs, kkt, converged = _progress(pos, erot, ip, ir, task, cf, escale, r, tau)
    jz, cb = _gather(jfree, order, task)  # chain order: Jacobian columns, task rows
    if not converged or polish_left:
        wd, wu, wv, wp, wq = _w_gens(jz, f6, starts, kd, False)
        bst, bd, bu, bv, bp, bq, s_, rho = _bordered(wd, wu, wv, wp, wq, starts, dpos, kp, cb)
        pinv, fx, fy, rc, bad, _a, _b, _c = _factor(bst, bd, bu, bv, bp, bq, False)
        if bad or not rc >= TRUST_RCOND:
            return NEED_DENSE, kkt, ep, er, rs, fact_in, empty, empty, empty, novec
        b1 = np.empty((n, 1))
        for c in range(n):
            b1[c, 0] = -r[order[c]]
        b2 = np.empty((m, 1))
        for i in range(m):
            b2[i, 0] = e[i]
        xs, _lam, res = _kkt_solve(starts, wd, wu, wv, wp, wq, cb, 0.0, bst, pinv, bu, fx, fy, bq, s_, rho, b1, b2, 2)
        if not res <= SOLVE_RTOL:
            return NEED_DENSE, kkt, ep, er, rs, fact_in, empty, empty, empty, novec
        dx = np.empty(n)
        for c in range(n):
            dx[order[c]] = xs[c, 0]
        if converged:  # the point of a curve at this equilibrium factorises the same matrix
            _ws_store(wsa, jz, f6, task, s_, rho, bu, bq, pinv, fx, fy)
        if not converged:
            if follow:  # ½(ZᵀWZ + (ZᵀWZ)ᵀ) − shift·I ≻ 0: no eigenvalue of Zᵀ W_s Z at or below shift
                sd, su, sv, sp, sq = _w_gens(jz, f6, starts, kd, True)
                bst2, bd2, bu2, bv2, bp2, bq2, s2, _rho2 = _bordered(sd, su, sv, sp, sq, starts, dpos, kp, cb)
                cnt = _count_only(bst2, bd2, bu2, bv2, bp2, bq2, s2, dpos, m, shift)
                if cnt < 0:
                    return NEED_DENSE, kkt, ep, er, rs, fact_in, empty, empty, empty, novec
                if cnt > 0:
                    return _STEP_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty, novec
            smax = 0.0
            for c in range(n):
                v = abs(dx[c] / vscale[c])
                if not v <= smax:
                    smax = v
            if not smax <= max_step:
                return _STEP_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty, novec
            return (_CONTINUE, kkt, ep, er, rs, fact if keep else fact_in, dx if keep else empty,
                    _moved_loops(x, free, dx, flush), empty, novec)
        finite = True
        smax = 0.0
        for c in range(n):
            if not math.isfinite(dx[c]):
                finite = False
            smax = max(smax, abs(dx[c] / vscale[c]))
        if finite and smax > polish_step:
            return (_POLISH, kkt, ep, er, rs, fact if keep else fact_in, dx if keep else empty,
                    _moved_loops(x, free, dx, flush), empty, novec)
    if not _full_rank(rr, m, rank_tol):
        return _RANK_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty, novec
    ok, lam1, vec = _smallest(starts, dpos, kp, jz, f6, kd, cb, kscale, has_guess, gvec, VEC_TOL_VERDICT,
                              _ws_rnd(wsa, n))
    if not ok:
        return NEED_DENSE, kkt, ep, er, rs, fact_in, empty, empty, empty, novec
    ev = np.empty(1)
    ev[0] = -lam1
    if refactor and not keep:
        fact = (jac, hh, rr, f, r, tau, _hessian_rows(jfree, f6, mask, n), f6)
    return _CONVERGED, kkt, ep, er, rs, fact, empty, empty, ev, vec


# --------------------------------------------------------------------------- the point
def _point_chain(J6, cols, order, task, dt, prow, starts, dpos, kd, kp, kscale, wrench, use_rate, fast_rank,
                 has_guess, gvec, ws=None):
    """:func:`vjm_pin.analysis.point_kernel._point_loops` with the O(n) chain algebra:
    ``(status, k, δx ((θ, q) order), δF, μ, dμ/ds, eigenvector (chain order))``; status
    :data:`NEED_DENSE`: run the dense kernel (which decides, as before). ``ws``: the workspace of
    the iterations (:func:`_iterate_chain`) or None: the factorisation of eq. (28) a converged
    iteration kept there is this point's when its Jacobian, wrench and task rows are bit for bit
    this point's (the last iteration of the corrector), and is then used as it is."""
    n = cols.shape[0]
    m = task.shape[0]
    nan = np.nan
    xd = np.zeros(n)
    fd = np.zeros(m)
    novec = gvec  # (an input array: returned without boxing a new one; status not 0)
    if ws is None:
        wsa = np.zeros(0)
    else:
        wsa = ws
    if m < 2 or m > n:
        return NEED_DENSE, nan, xd, fd, nan, nan, novec
    jz, cb = _gather(J6, cols, task)
    # rank test of J (FAST_RANK) and its QR for the multiplier g
    ok, hh, rmat = _qr_rank(cb, m, n, fast_rank)
    if not ok:
        return NEED_DENSE, nan, xd, fd, nan, nan, novec
    # tangent of eq. (29): W δx − Jᵀ δF = 0, J δx = d_t
    wd, wu, wv, wp, wq = _w_gens(jz, wrench, starts, kd, False)
    if _ws_match(wsa, jz, wrench, task, max(kd.shape[1], m)):
        # the converged iteration's factorisation of this matrix (it passed the same test)
        s_, rho, bu, bq, fx, fy, pinv = _ws_views(wsa, n, m)
        bst = np.empty(starts.shape[0] + 1, np.int64)
        bst[: starts.shape[0]] = starts
        bst[starts.shape[0]] = n + m
    else:
        bst, bd, bu, bv, bp, bq, s_, rho = _bordered(wd, wu, wv, wp, wq, starts, dpos, kp, cb)
        pinv, fx, fy, rc, bad, _a, _b, _c = _factor(bst, bd, bu, bv, bp, bq, False)
        if bad or not rc >= TRUST_RCOND:
            return NEED_DENSE, nan, xd, fd, nan, nan, novec
    b1 = np.zeros((n, 1))
    b2 = np.empty((m, 1))
    for i in range(m):
        b2[i, 0] = dt[i]
    xs, lam, res = _kkt_solve(starts, wd, wu, wv, wp, wq, cb, 0.0, bst, pinv, bu, fx, fy, bq, s_, rho, b1, b2, 2)
    if not res <= SOLVE_RTOL:
        return NEED_DENSE, nan, xd, fd, nan, nan, novec
    k = 0.0
    for i in range(m):
        fd[i] = -lam[i, 0]
        k += dt[i] * fd[i]
    for c in range(n):
        xd[order[c]] = xs[c, 0]
        if not math.isfinite(xs[c, 0]):
            return NEED_DENSE, nan, xd, fd, nan, nan, novec
    # μ: the largest eigenvalue of Vᵀ sym(H − K) V, V the null space of P J: −λ₁
    ch = _held_rows(prow, cb)
    sd, su, svv, sp, sq = _w_gens(jz, wrench, starts, kd, True)  # (dμ/ds below uses them too)
    ok, lam1, w = _smallest_w(starts, dpos, kp, sd, su, svv, sp, sq, ch, kscale, has_guess, gvec, VEC_TOL_MARGIN,
                              _ws_rnd(wsa, n))
    if not ok:
        return NEED_DENSE, nan, xd, fd, nan, nan, novec
    mu = -lam1
    if not use_rate:
        return 0, k, xd, fd, mu, nan, w
    # dμ/ds = wᵀH'w − 2 gᵀJ'w (PointKernel.margin_rate), chain order, O(n)
    wsw = _matvec(starts, sd, su, svv, sp, sq, w.reshape(n, 1))
    resv = np.empty(n)
    for c in range(n):
        resv[c] = -(wsw[c, 0] - lam1 * w[c])  # sym(H − K) w − μ w
    yr = _apply_qt(hh, resv, m, n)
    g = _back_substitute(rmat, yr, m)
    xc = np.empty(n)
    for c in range(n):
        xc[c] = xs[c, 0]
    li, om = _twists(jz)
    dom = np.empty((n, 3))
    dli = np.empty((n, 3))
    # Ω_i = Σ_{j≤i} δx_j ω_j (prefix), P_i = Σ_{j>i} δx_j v_j (suffix)
    pre = np.zeros((n, 3))
    o0, o1, o2 = 0.0, 0.0, 0.0
    for i in range(n):
        o0 += xc[i] * om[i, 0]
        o1 += xc[i] * om[i, 1]
        o2 += xc[i] * om[i, 2]
        pre[i, 0], pre[i, 1], pre[i, 2] = o0, o1, o2
    p0, p1, p2 = 0.0, 0.0, 0.0
    for i in range(n - 1, -1, -1):
        o0, o1, o2 = pre[i, 0], pre[i, 1], pre[i, 2]
        _twist_rate_row(i, o0, o1, o2, p0, p1, p2, li, om, dli, dom)
        p0 += xc[i] * li[i, 0]
        p1 += xc[i] * li[i, 1]
        p2 += xc[i] * li[i, 2]
    aa, da, bb, db = _rate_terms(li, om, dli, dom, wrench, fd, task)
    # quad = Σ_i w_i [Σ_{j≤i} (dom_j·aa_i + om_j·da_i) w_j + Σ_{j>i} (dom_i·bb_j + om_i·db_j) w_j]
    quad = 0.0
    s1 = np.zeros(3)
    s2 = np.zeros(3)
    for i in range(n):
        for a3 in range(3):
            s1[a3] += w[i] * dom[i, a3]
            s2[a3] += w[i] * om[i, a3]
        quad += w[i] * (aa[i, 0] * s1[0] + aa[i, 1] * s1[1] + aa[i, 2] * s1[2]
                        + da[i, 0] * s2[0] + da[i, 1] * s2[1] + da[i, 2] * s2[2])
    t1 = np.zeros(3)
    t2 = np.zeros(3)
    for i in range(n - 1, -1, -1):
        quad += w[i] * (dom[i, 0] * t1[0] + dom[i, 1] * t1[1] + dom[i, 2] * t1[2]
                        + om[i, 0] * t2[0] + om[i, 1] * t2[1] + om[i, 2] * t2[2])
        for a3 in range(3):
            t1[a3] += w[i] * bb[i, a3]
            t2[a3] += w[i] * db[i, a3]
    return 0, k, xd, fd, mu, quad - 2.0 * _rate_lin(dli, dom, w, g, task), w


# =========================================================================== loading, layout
_COMPILED: list = []  # [(iterate, point)] once loaded, [None] when numba is unavailable
_HELPERS = ("_hessian_rows", "_bits_equal", "_ws_store", "_ws_match", "_ws_views", "_ws_rnd", "_rnd_start",
            "_w_gens", "_bordered", "_factor", "_shifted", "_raw_solve", "_kkt_solve", "_inertia_factor",
            "_count_only", "_count", "_project", "_rayleigh", "_inverse", "_split", "_smallest_w", "_smallest", "_gather",
            "_held_rows", "_qr_rank", "_twists", "_twist_rate_row", "_rate_terms", "_rate_lin")
#: The ones :func:`vjm_pin.analysis.point_kernel._point_loops` calls too.
RATE_HELPERS = ("_back_substitute", "_twists", "_twist_rate_row", "_rate_terms", "_rate_lin")
#: The dense kernel's helpers (vjm_pin.solver.kernel) this kernel calls, compiled there once (the block
#: elimination loops are chain_algebra's, compiled by its ``_kernels``). numba's on-disk cache is
#: invalidated by changes to this file only: after editing those, clear ``__pycache__``.
_DENSE_HELPERS = ("_qr_t", "_apply_qt", "_back_substitute", "_multiplier", "_hessian", "_progress", "_full_rank",
                  "_moved_loops")


def _load():
    """``(iterate, point)`` compiled by numba (cached on disk), or None without numba."""
    if _COMPILED:
        return _COMPILED[0]
    try:
        import numba
    except Exception:  # noqa: BLE001 - any import failure: the dense kernels stay in use
        _COMPILED.append(None)
        return None
    if not _kernel._load_compiled() or _algebra._kernels() is None:
        _COMPILED.append(None)
        return None
    opts = {"cache": True, "nogil": True}
    g = globals()
    for name in _DENSE_HELPERS:
        g[name] = getattr(_kernel, name)
    g["_factor_loops"], g["_solve"], g["_matvec"] = _algebra._kernels()
    g["_inertia_small"] = _algebra._inertia_small  # compiled by _kernels (tests call it here)
    g["_inertia_pivots"] = _algebra._inertia_pivots  # (compiled by _kernels too)
    for name in _HELPERS:
        g[name] = numba.njit(**opts)(g[name])
    _COMPILED.append((numba.njit(**opts)(_iterate_chain), numba.njit(**opts)(_point_chain)))
    return _COMPILED[0]


class _Layout:
    """Per-model constants in chain order (from ``K_θ`` in (θ, q) order and the free columns)."""

    # (key: the _ContentKey it is kept under in _SHARED, set by _layout)
    __slots__ = ("cols", "dpos", "kd", "khi", "key", "klo", "kp", "kscale", "ok", "order", "starts")

    def __init__(self, kz, free, nt, mask):
        from vjm_pin.solver.chain_algebra import chain_layout

        free = np.asarray(free, np.int64)
        lay = chain_layout(np.ascontiguousarray(kz[:nt, :nt]), free[:nt], free[nt:])
        self.cols = np.ascontiguousarray(lay.cols, np.int64)
        self.order = np.ascontiguousarray(lay.order, np.int64)
        self.starts = np.ascontiguousarray(lay.starts, np.int64)
        self.kd = np.ascontiguousarray(lay.k_diag, float)
        self.kp = np.ascontiguousarray(lay._k_pinv, float)
        blk = lay.block_ids()
        self.dpos = np.ascontiguousarray(np.arange(lay.n) - lay.starts[blk], np.int64)
        self.kscale = float(np.abs(lay.k_diag).max(initial=0.0)) or 1.0
        n = len(free)
        nzr = kz[:nt, :nt] != 0
        any_ = nzr.any(axis=1)
        self.klo = np.where(any_, np.argmax(nzr, axis=1), 0).astype(np.int64)
        self.khi = np.where(any_, nt - np.argmax(nzr[:, ::-1], axis=1), 0).astype(np.int64)
        # the chain form needs the support of every free column to be its predecessors in chain order
        if mask is None:
            self.ok = True
        else:
            mc = np.asarray(mask, bool)[np.ix_(self.order, self.order)]
            self.ok = bool(np.array_equal(mc, np.tril(np.ones((n, n), bool))))


_LAYOUTS: dict = {}  # id(key object) -> (key object, kz, mask, layout): the per-solver fast path
_SHARED: dict = {}  # content key (_content_key) -> layout, least recently used first
_LOCK = threading.Lock()
#: Bounds of the content-keyed layout cache: entries, and the bytes of their keys (the newest
#: entry is always kept).
SHARED_MAX = 8
SHARED_MAX_BYTES = 1 << 26


#: :class:`_ContentKey` hashes every this-many-th row and column of ``K_θ`` and of the support mask.
KEY_SAMPLE_STEP = 7


def _bits(a: np.ndarray) -> np.ndarray:
    """``a`` (float or bool) as unsigned integers of its own width (a view): compared bit for bit
    (``-0.0 != 0.0``, a NaN equal to itself), as bytes would be."""
    return a.view(np.uint64 if a.dtype.itemsize == 8 else np.uint8)


class _ContentKey:
    """A :func:`_content_key`: ``K_θ``, the free coordinates and the support mask of a layout,
    equal to another only when every bit of the three is (compared in place, no copies), hashed
    from their shapes, the free coordinates and a sample of the two square arrays (every
    :data:`KEY_SAMPLE_STEP`-th row and column). A probe key holds views of its caller's arrays; a
    key kept in the cache holds copies (:meth:`kept`). Copying and hashing the whole ~0.2 MB of
    bytes took ~50–200 µs per fresh solver at n = 144 (a page-faulting copy); keys that share
    the hash only cost the comparison."""

    __slots__ = ("shape", "kt", "free", "mask", "_hash")

    def __init__(self, shape, kt, free, mask):
        self.shape, self.kt, self.free, self.mask = shape, kt, free, mask
        st = KEY_SAMPLE_STEP
        self._hash = hash((
            shape, free.tobytes(), kt[::st, ::st].tobytes(), b"" if mask is None else mask[::st, ::st].tobytes()
        ))

    def __hash__(self):
        return self._hash

    def __eq__(self, other):
        if not isinstance(other, _ContentKey):
            return NotImplemented
        return (
            self._hash == other._hash
            and self.shape == other.shape
            and np.array_equal(self.free, other.free)
            and np.array_equal(_bits(self.kt), _bits(other.kt))
            and (self.mask is None or np.array_equal(self.mask, other.mask))
        )

    @property
    def nbytes(self) -> int:
        return self.kt.nbytes + self.free.nbytes + (0 if self.mask is None else self.mask.nbytes)

    def kept(self) -> "_ContentKey":
        """This key with its own copies of the arrays (for the cache: the caller's may change)."""
        k = object.__new__(_ContentKey)
        k.shape, k._hash = self.shape, self._hash
        k.kt, k.free = self.kt.copy(), self.free.copy()
        k.mask = None if self.mask is None else self.mask.copy()
        return k


def _content_key(kz, free, nt, mask) -> _ContentKey:
    """Everything a :class:`_Layout` is computed from: ``K_θ = kz[:nt, :nt]``, the free
    coordinates and the support mask (their shapes and element types fixed by the conversions),
    so equal models share a layout and models that differ in any bit do not (a
    :class:`_ContentKey` of views where no conversion is needed)."""
    kt = np.asarray(kz, float)[:nt, :nt]
    fr = np.ascontiguousarray(free, np.int64)
    mk = None if mask is None else np.asarray(mask, np.bool_)
    shape = (int(nt), fr.shape[0], kt.shape, None if mask is None else mk.shape)
    return _ContentKey(shape, kt, fr, mk)


def _layout(key_obj, kz, free, nt, mask) -> _Layout:
    """The :class:`_Layout` of ``(kz, free, nt, mask)``: by the identity of ``key_obj`` (an
    array owned by one solver or point kernel, with the same ``kz`` and ``mask`` objects), else
    by content (:func:`_content_key`): a fresh solver of a model seen before reuses its layout
    (building one costs ~10 ms at n = 144, the pseudo-inverses of the ``K_θ`` blocks)."""
    hit = _LAYOUTS.get(id(key_obj))
    if hit is not None and hit[0] is key_obj and hit[1] is kz and hit[2] is mask:
        return hit[3]
    key = _content_key(kz, free, nt, mask)
    with _LOCK:
        lay = _SHARED.pop(key, None)  # (one comparison with the kept key on a hit)
        if lay is not None:
            _SHARED[lay.key] = lay  # reinserted last: the most recently used
    if lay is None:
        built = _Layout(kz, free, nt, mask)  # outside the lock: ~10 ms at n = 144
        with _LOCK:  # threads (a map's workers) share the caches
            lay = _SHARED.pop(key, None)  # another thread's equal layout, if it was first
            if lay is None:
                lay = built
                lay.key = key.kept()  # (its own copies: the caller's arrays may change)
            _SHARED[lay.key] = lay
            size = sum(k.nbytes for k in _SHARED)
            while len(_SHARED) > 1 and (len(_SHARED) > SHARED_MAX or size > SHARED_MAX_BYTES):
                k = next(iter(_SHARED))
                size -= k.nbytes
                del _SHARED[k]
    with _LOCK:
        if len(_LAYOUTS) >= 32:
            _LAYOUTS.pop(next(iter(_LAYOUTS)))
        _LAYOUTS[id(key_obj)] = (key_obj, kz, mask, lay)
    return lay


# =========================================================================== entry points
_PROWS: dict = {}  # d_t (bytes, length) -> (m − 1, m) rows spanning its complement
_GUESS: dict = {}  # id(key object) -> (key object, previous eigenvector in chain order)


_TLS = threading.local()  # .ws: id(layout) -> (layout, workspace) of this thread (_workspace)
#: Workspaces kept per thread (the most recent layouts).
WS_MAX = 8


def _workspace(lay, n):
    """This thread's factorisation workspace for the layout ``lay`` (:func:`_ws_size`): the
    iterations of a solve keep their converged factorisation of eq. (28) there, the curve's
    point reads it (:func:`_point_chain`); per thread, so that a map's workers never share one."""
    d = getattr(_TLS, "ws", None)
    if d is None:
        d = _TLS.ws = {}
    hit = d.get(id(lay))
    if hit is not None and hit[0] is lay:
        return hit[1]
    ws = np.zeros(_ws_size(n, 6, lay.kd.shape[1]))
    ws[_WS_HEAD:_WS_HEAD + n] = _rnd_start(n)  # (compiled: the bits _smallest would compute)
    ws[7] = n
    if len(d) >= WS_MAX:
        d.pop(next(iter(d)))
    d[id(lay)] = (lay, ws)
    return ws


def _guess(key_obj, n):
    hit = _GUESS.get(id(key_obj))
    if hit is not None and hit[0] is key_obj and hit[1].shape[0] == n:
        return True, hit[1]
    return False, np.zeros(n)


def _remember(key_obj, vec):
    with _LOCK:
        if len(_GUESS) >= 64:
            _GUESS.pop(next(iter(_GUESS)))
        _GUESS[id(key_obj)] = (key_obj, vec)


#: id(kernel constants ``ci``) -> (ci, layout, its problem: Jacobian rows in chain order (6, n),
#: task rows, wrench; λ₁, unit eigenvector): the certified eq. (23) verdict of the last converged
#: chain iteration with those constants (:func:`last_verdict`).
_VERDICT: dict = {}


def _record_verdict(ci, lay, out):
    """Keep the converged iteration's eq. (23) problem (copies) and its certified eigenpair."""
    fct = out[5]
    n, nt, m = int(ci[0]), int(ci[1]), int(ci[2])
    hh = fct[1]
    if hh.shape[0] != m + 7 or out[9].shape[0] != n:
        return
    jz = hh[m + 1:, :][:, lay.order]  # (a copy: fancy indexing)
    task = ci[6 + n + nt:6 + n + nt + m].copy()
    rec = (ci, lay, jz, task, np.array(fct[7], float), float(-out[8][0]), out[9])
    with _LOCK:
        if len(_VERDICT) >= 64:
            _VERDICT.pop(next(iter(_VERDICT)), None)
        _VERDICT[id(ci)] = rec


def last_verdict(key_obj, lay, jz, task, wrench):
    """``(λ₁, y)`` of the last converged chain iteration with the kernel constants ``key_obj``: the
    smallest eigenvalue of ``Zᵀ sym(K − H) Z`` (eq. 23, every task row held) certified by its Sturm
    count, and its unit eigenvector (chain order, converged to :data:`VEC_TOL_VERDICT` per step),
    when that problem is bit for bit the one given (layout ``lay``, Jacobian rows ``jz`` in chain
    order, task rows ``task``, ``wrench``); else None."""
    rec = _VERDICT.get(id(key_obj))
    if rec is None or rec[0] is not key_obj or rec[1] is not lay:
        return None
    _, _, rjz, rtask, rw, lam, vec = rec
    w = np.asarray(wrench, float)
    t = np.asarray(task)
    if (
        rjz.shape != jz.shape
        or rw.shape != w.shape
        or rtask.shape != t.shape
        or rjz.tobytes() != np.ascontiguousarray(jz, float).tobytes()
        or rw.tobytes() != w.tobytes()
        or not np.array_equal(rtask, t)
    ):
        return None
    return lam, vec


def iterate(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts, dense):
    """One fused iteration (the contract of :func:`vjm_pin.solver.kernel.iterate_numpy`) by the
    compiled chain kernel; ``dense`` (the dense kernel, same signature without ``dense``) where
    the chain result is not trustworthy or the model is not a plain chain. At status CONVERGED
    ``ev`` holds the largest eigenvalue of eq. (23) only (the one the verdict and the curve's
    ``λ`` use), not all of them."""
    fns = _load()
    ci, cf, kz, mask, theta0, vscale, escale = consts
    n, nt = int(ci[0]), int(ci[1])
    lay = _layout(ci, kz, ci[6:6 + n], nt, mask)
    if fns is None or not lay.ok:
        return dense(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts)
    has, gvec = _guess(ci, n)
    out = fns[0](J6, pos, erot, x, refactor, polish_left, flush, keep, fact, ci, cf, kz, mask, theta0, vscale,
                 escale, lay.cols, lay.order, lay.starts, lay.dpos, lay.kd, lay.kp, lay.kscale, lay.klo, lay.khi,
                 has, gvec, _workspace(lay, n))
    if out[0] == NEED_DENSE:
        return dense(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts)
    if out[0] == _kernel.CONVERGED:
        _remember(ci, out[9])
        _record_verdict(ci, lay, out)
    return out[:9]


def point(pk, b, mask, wrench, fast_rank):
    """The compiled :meth:`~vjm_pin.analysis.point_kernel.PointKernel.point` by the chain
    kernel: ``(k, δx, δF, μ, dμ/ds or None)``, or None where the dense kernel must decide (not a
    plain chain, a near-critical factorisation, an eigenvalue not certified)."""
    fns = _load()
    if fns is None or pk.m < 2:
        return None
    lay = _layout(pk.kz, pk.kz, pk.free, pk.nt, mask)
    if not lay.ok:
        return None
    dt = np.ascontiguousarray(pk.dt, float)
    pkey = (dt.shape, dt.tobytes())
    prow = _PROWS.get(pkey)
    if prow is None:
        # rows spanning the complement of d_t (a function of d_t only: shared by equal directions)
        u = np.linalg.svd(dt.reshape(-1, 1) / np.linalg.norm(dt), full_matrices=True)[0]
        prow = np.ascontiguousarray(u[:, 1:].T)
        with _LOCK:
            if len(_PROWS) >= 32:
                _PROWS.pop(next(iter(_PROWS)))
            _PROWS[pkey] = prow
    rate_wanted = mask is not None
    n = lay.cols.shape[0]
    has, gvec = _guess(pk, n)
    st, k, xd, fd, mu, rate, vec = fns[1](
        np.ascontiguousarray(b.state.jacobian, dtype=float), lay.cols, lay.order, pk.task.astype(np.int64), pk.dt,
        prow, lay.starts, lay.dpos, lay.kd, lay.kp, lay.kscale,
        np.asarray(wrench if wrench is not None else np.zeros(6), dtype=float), rate_wanted, float(fast_rank), has,
        gvec, _workspace(lay, n),
    )
    if st != 0:
        return None
    _remember(pk, vec)
    return k, xd, fd, mu, (rate if rate_wanted else None)
