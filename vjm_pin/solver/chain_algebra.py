"""Linear algebra of long serial chains in O(n): recursive block elimination along the chain.

For a chain of 1-DoF joints the Hessian of ``Ψ`` (eq. 16) in screw form
(:mod:`vjm_pin.kinematics.screw`) is a rank-3 *semiseparable* matrix in the chain order
(Pinocchio's: a parent before its children): with the twists ``J[:, i] = (v_i, ω_i)``, the end
wrench ``F = (f, m)``, ``d_i = v_i × f`` and ``a_i = d_i + ω_i × m``::

    H[i, j] = a_i · ω_j   (j ≤ i),        H[i, j] = ω_i · d_j   (j > i).

``K_θ`` is block diagonal (1-D actuator springs, coupled 3×3 or 6×6 link springs on consecutive
joints; passive joints interleaved with zero stiffness). So ``W = K − H``, the matrix of the
Newton step, of the stability test (eq. 23) and of the loaded stiffness (eq. 28–30), is::

    W[i, j] = D_k[i, j]         (i, j in the same diagonal block k),
    W[i, j] = u_i · v_j          (block of i after block of j),
    W[i, j] = p_i · q_j          (block of i before block of j),

with n × r generators (:class:`QuasiMatrix`). Gaussian elimination from the base to the end of
the chain keeps that form: after the blocks ``1..k−1`` the pivot of block ``k`` is
``Π_k = D_k − U_k G_k Q_kᵀ`` and ``G_{k+1} = G_k + (V_k − Q_k G_kᵀ)ᵀ Π_k⁻¹ (P_k − U_k G_k)``
(``G_1 = 0``, r × s), which is a block LU ``W = L Π R`` with ``L[i, k] = u_i X_kᵀ``,
``R[k, j] = Y_k q_jᵀ``: O(n r²) work and memory (:func:`factor`). For a symmetric matrix the
pivots are symmetric and Sylvester's law of inertia gives ``In(W) = Σ_k In(Π_k)``.

The task rows ``J`` (m = 3 or 6) border ``W`` as the last block of the KKT matrix of eq. (28),
``[[W, Jᵀ], [J, 0]]``; its columns are further generators. ``W`` itself may be singular where
the KKT matrix is not (passive joints of zero stiffness, unloaded; a compressed column beyond the
buckling load of its free end but held at the end), so the elimination runs on the congruent
``[[W + ρJᵀJ, Jᵀ], [J, 0]]`` (augmented Lagrangian: the same inertia, the same ``δx``, the
multiplier shifted by ``ρ δt``), with a diagonal scaling of the coordinates, and solves are
refined against the un-augmented matrix (:class:`ChainKKT`). Haynsworth's inertia formula then
gives the stability count of eq. (23): ``In(KKT) = In(Zᵀ W Z) + (m, m, 0)`` for a full-rank
``J``, with ``Z`` an orthonormal basis of its null space, and shifting ``W`` by ``σ I`` counts the
eigenvalues of ``Zᵀ W Z`` below ``σ`` (a Sturm count: :func:`count_below`;
:func:`smallest_reduced_eigenpair` by bisection and inverse iteration). The border may also be
any set of held combinations of the six Jacobian rows (mixed control, the curve tracer's margin).

Elimination without pivoting across blocks is exact in exact arithmetic whenever the leading
block minors are regular; every pivot is checked (reciprocal condition relative to the size of
the terms it was computed from) and a factorisation with a near-singular pivot says so
(``reliable`` False) instead of returning a wrong number: callers use the dense path then.

The loops run compiled by numba (``@njit(cache=True)``, imported on first use only: a one-shot
``vjm-pin analyze`` of a short chain never imports it); :data:`BACKEND` ``"numpy"`` or the
solver's switch ``VJM_PIN_JIT=0`` (read at import, :mod:`vjm_pin.solver.kernel`) select the pure-numpy version of
the same recursion, which the tests compare with the compiled one and with dense numpy.

Use: :func:`chain_layout` once per model; per configuration (Jacobian ``J6`` of all joints, end
wrench ``F``): ``ChainKKT(layout, J6, F, task).stiffness()`` (eq. 30),
``.solve_free(-r, -e)`` (a Newton step in the solver's (θ, q) order),
:func:`chain_stability` (eq. 23's verdict), :func:`smallest_reduced_eigenpair` (its margin
and mode). :func:`vjm_pin.solver.blocks.evaluate_blocks` attaches what these need to
:class:`~vjm_pin.solver.blocks.Blocks` for chains of ``CHAIN_MIN_N`` free coordinates or more;
:func:`~vjm_pin.solver.stiffness.stiffness_eq30` and
:func:`~vjm_pin.solver.stability.stability_verdict` then use it.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from vjm_pin.solver.kernel import mode as _jit_mode  # numpy only: numba stays lazy

#: ``"auto"`` (numba when importable), ``"numba"`` or ``"numpy"``.
BACKEND = "auto"
#: A pivot block whose reciprocal condition number, relative to the terms it was formed from, is
#: below this makes the factorisation unreliable (near-singular leading minor).
PIVOT_RCOND = 1e-13
#: Weight of the augmentation ``ρ JᵀJ`` relative to the end stiffness of the unloaded chain
#: (``m / trace(J K⁺ Jᵀ)``).
RHO_FACTOR = 1.0
#: Relative residual above which a refined KKT solve is reported unreliable.
SOLVE_RTOL = 1e-9


# --------------------------------------------------------------------------- the matrix
@dataclass(frozen=True)
class QuasiMatrix:
    """``M = blockdiag(D_k) + (strict block-lower part of U Vᵀ) + (strict block-upper part of P Qᵀ)``.

    Attributes:
        starts: (N+1,) int block boundaries (block k is rows ``starts[k]:starts[k+1]``).
        diag: (n, b) row i holds ``M[i, starts[k] : starts[k+1]]`` (block k of row i), zero padded.
        u, v: (n, r) lower generators: ``M[i, j] = u_i·v_j`` when block(i) > block(j).
        p, q: (n, s) upper generators: ``M[i, j] = p_i·q_j`` when block(i) < block(j).
    """

    starts: np.ndarray
    diag: np.ndarray
    u: np.ndarray
    v: np.ndarray
    p: np.ndarray
    q: np.ndarray

    @property
    def n(self) -> int:
        return self.u.shape[0]

    def block_ids(self) -> np.ndarray:
        """(n,) block index of each row."""
        return self._blk

    @cached_property
    def _blk(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.starts) - 1), np.diff(self.starts))

    def dense(self) -> np.ndarray:
        """The (n, n) dense matrix (tests and small sizes only: O(n²))."""
        blk = self.block_ids()
        a = np.where(blk[:, None] > blk[None, :], self.u @ self.v.T, 0.0)
        a += np.where(blk[:, None] < blk[None, :], self.p @ self.q.T, 0.0)
        for k in range(len(self.starts) - 1):
            s0, s1 = self.starts[k], self.starts[k + 1]
            a[s0:s1, s0:s1] = self.diag[s0:s1, : s1 - s0]
        return a

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``M x`` for x (n,) or (n, c), O(n (r + s + b) c)."""
        x = np.asarray(x, float)
        one = x.ndim == 1
        x2 = x.reshape(self.n, -1)
        if _use_numba():
            args = (np.ascontiguousarray(self.starts, dtype=np.int64),) + tuple(
                np.ascontiguousarray(t, dtype=float) for t in (self.diag, self.u, self.v, self.p, self.q, x2)
            )
            y = _kernels()[2](*args)
            return y[:, 0] if one else y
        st = self.starts
        blk = self.block_ids()
        # block-diagonal part
        y = np.zeros_like(x2)
        for w in range(self.diag.shape[1]):
            col = st[blk] + w
            ok = col < st[blk + 1]
            y[ok] += self.diag[ok, w, None] * x2[col[ok]]
        # lower: row i gets u_i · Σ_{j in earlier blocks} v_j x_j
        vx = np.cumsum(self.v[:, :, None] * x2[:, None, :], axis=0)
        pre = np.concatenate([np.zeros((1,) + vx.shape[1:]), vx])[st[blk]]
        y += np.einsum("ir,irc->ic", self.u, pre)
        # upper: row i gets p_i · Σ_{j in later blocks} q_j x_j
        qx = np.cumsum((self.q[:, :, None] * x2[:, None, :])[::-1], axis=0)[::-1]
        post = np.concatenate([qx, np.zeros((1,) + qx.shape[1:])])[st[blk + 1]]
        y += np.einsum("is,isc->ic", self.p, post)
        return y[:, 0] if one else y


@dataclass(frozen=True)
class Factor:
    """Block LU ``M = L Π R`` of a :class:`QuasiMatrix` (module docstring).

    Attributes:
        matrix: the factorised :class:`QuasiMatrix`.
        pinv: (n, b) inverses of the pivot blocks, laid out as :attr:`QuasiMatrix.diag`.
        x, y: (n, r), (n, s) factor generators (``L[i, k] = u_i X_kᵀ``, ``R[k, j] = Y_k q_jᵀ``).
        inertia: ``(positive, negative, zero)`` eigenvalue counts (symmetric matrices; else None).
        logabsdet: ``log|det M|`` (−inf when singular).
        sign: sign of ``det M`` (0 when singular).
        rcond: smallest relative reciprocal condition number of a pivot block.
        worst: block index of that pivot.
        reliable: every pivot regular (``rcond ≥ PIVOT_RCOND``) and finite.
    """

    matrix: QuasiMatrix
    pinv: np.ndarray
    x: np.ndarray
    y: np.ndarray
    inertia: tuple[int, int, int] | None
    logabsdet: float
    sign: float
    rcond: float
    worst: int
    reliable: bool

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``M⁻¹ b`` for b (n,) or (n, c) (forward and back substitution, O(n (r + s) c))."""
        b = np.asarray(b, float)
        one = b.ndim == 1
        b2 = np.ascontiguousarray(b.reshape(self.matrix.n, -1))
        m = self.matrix
        if _use_numba():
            out = _kernels()[1](m.starts, self.pinv, m.u, self.x, self.y, m.q, b2)
        else:
            out = _solve_numpy(m.starts, self.pinv, m.u, self.x, self.y, m.q, b2)
        return out[:, 0] if one else out


#: ``VJM_PIN_JIT=0`` (the solver's switch) in the environment at import: the numpy recursion.
_NO_NUMBA = _jit_mode() == "0"


def _use_numba() -> bool:
    if BACKEND == "numpy" or _NO_NUMBA:
        return False
    if BACKEND == "numba":
        return True
    return compiled_available() and _kernels() is not None


def compiled_available() -> bool:
    """Whether the compiled recursion runs now, without importing numba: not switched off
    (:data:`BACKEND`, ``VJM_PIN_JIT=0``) and, in ``auto`` mode, numba already imported in this
    process (e.g. by the solver's kernel after its iteration threshold) or ``VJM_PIN_JIT=1``: the
    package's one rule, so a one-shot run never pays numba's import (~1-2 s)."""
    if BACKEND == "numpy" or _NO_NUMBA:
        return False
    if _KERNELS:
        return _KERNELS[0] is not None
    wanted = _jit_mode() == "1"
    if BACKEND == "numba" or wanted or "numba" in sys.modules:
        import importlib.util

        return importlib.util.find_spec("numba") is not None
    return False


def factor(m: QuasiMatrix, symmetric: bool = False) -> Factor:
    """Block LU of ``m`` by elimination from the first block to the last (module docstring).

    ``symmetric``: ``m`` is symmetric (``p = v``, ``q = u``, symmetric diagonal blocks): the
    inertia is counted from the pivots (Sylvester). A near-singular or non-finite pivot gives
    ``reliable = False`` (the factors are then not to be used)."""
    starts = np.ascontiguousarray(m.starts, dtype=np.int64)
    args = tuple(np.ascontiguousarray(a, dtype=float) for a in (m.diag, m.u, m.v, m.p, m.q))
    if _use_numba():
        pinv, x, y, info, counts = _kernels()[0](starts, *args, bool(symmetric))
    else:
        pinv, x, y, info, counts = _factor_numpy(starts, *args, bool(symmetric))
    rc, logdet, sgn, worst, bad = float(info[0]), float(info[1]), float(info[2]), int(info[3]), bool(info[4])
    reliable = not bad and rc >= PIVOT_RCOND and np.isfinite(logdet)
    inertia = (int(counts[0]), int(counts[1]), int(counts[2])) if symmetric else None
    if bad:
        logdet, sgn = -np.inf, 0.0
    return Factor(m, pinv, x, y, inertia, logdet, sgn, rc, worst, reliable)


# --------------------------------------------------------------------------- numpy recursion
def _factor_numpy(starts, diag, u, v, p, q, symmetric):
    n, r = u.shape
    s = q.shape[1]
    pinv = np.zeros_like(diag)
    x = np.zeros((n, r))
    y = np.zeros((n, s))
    g = np.zeros((r, s))
    rc_min, logdet, sign, worst, bad = np.inf, 0.0, 1.0, -1, 0.0
    counts = np.zeros(3, np.int64)
    for k in range(len(starts) - 1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        ug = u[a:e] @ g
        corr = ug @ q[a:e].T
        d = diag[a:e, :nk]
        pi = d - corr
        if symmetric:
            pi = 0.5 * (pi + pi.T)
        ref = max(np.abs(d).sum(axis=1).max(), np.abs(corr).sum(axis=1).max(), np.abs(pi).sum(axis=1).max())
        try:
            inv = np.linalg.inv(pi)
        except np.linalg.LinAlgError:
            inv = None
        if inv is None or not np.isfinite(inv).all() or not np.isfinite(pi).all():
            return pinv, x, y, np.array([0.0, -np.inf, 0.0, k, 1.0]), counts
        rc = 1.0 / (np.abs(inv).sum(axis=1).max() * ref) if ref > 0 else 0.0
        if rc < rc_min:
            rc_min, worst = rc, k
        sgn_k, ld = np.linalg.slogdet(pi)
        logdet += ld
        sign *= sgn_k
        if symmetric:
            ev = np.linalg.eigvalsh(pi)
            tiny = 1e-14 * nk * ref
            counts[0] += int(np.sum(ev > tiny))
            counts[1] += int(np.sum(ev < -tiny))
            counts[2] += int(np.sum(np.abs(ev) <= tiny))
        pinv[a:e, :nk] = inv
        vt = v[a:e] - q[a:e] @ g.T
        pt = p[a:e] - ug
        x[a:e] = inv.T @ vt
        yk = inv @ pt
        y[a:e] = yk
        g = g + vt.T @ yk
    return pinv, x, y, np.array([rc_min, logdet, sign, worst, bad]), counts


def _solve_numpy(starts, pinv, u, x, y, q, b):
    n, c = b.shape
    r, s = u.shape[1], q.shape[1]
    z = np.empty((n, c))
    acc = np.zeros((r, c))
    nb = len(starts) - 1
    for k in range(nb):
        a, e = starts[k], starts[k + 1]
        zk = b[a:e] - u[a:e] @ acc
        acc += x[a:e].T @ zk
        z[a:e] = pinv[a:e, : e - a] @ zk
    out = np.empty((n, c))
    acc = np.zeros((s, c))
    for k in range(nb - 1, -1, -1):
        a, e = starts[k], starts[k + 1]
        xk = z[a:e] - y[a:e] @ acc
        acc += q[a:e].T @ xk
        out[a:e] = xk
    return out


# --------------------------------------------------------------------------- compiled recursion
_KERNELS: list = []


def _kernels():
    """``(factor, solve)`` compiled by numba on first use, or None when numba is missing."""
    if _KERNELS:
        return _KERNELS[0]
    try:
        from numba import njit
    except ImportError:  # pragma: no cover - numba is a dependency; the numpy path stays
        _KERNELS.append(None)
        return None
    global _inertia_small, _inertia_pivots
    _inertia_pivots = njit(cache=True)(_inertia_pivots)  # called by _factor_loops: compiled first
    _inertia_small = njit(cache=True)(_inertia_small)
    _KERNELS.append(
        (njit(cache=True)(_factor_loops), njit(cache=True)(_solve_loops), njit(cache=True)(_matvec_loops))
    )
    return _KERNELS[0]


def _inertia_small(a, nk, tiny):
    """``(positive, negative, zero)`` of the symmetric ``a[:nk, :nk]`` (destroyed) by symmetric
    elimination with Bunch–Parlett pivoting (1×1 or 2×2 pivots; Sylvester's law of inertia)."""
    return _inertia_pivots(a, nk, tiny, np.empty(nk, np.int64))


def _inertia_pivots(a, nk, tiny, idx):
    """:func:`_inertia_small` with the caller's integer work array ``idx`` (length ≥ ``nk``,
    overwritten: the rows not yet eliminated, ascending): the block eliminations call it once per
    pivot block without an allocation. The same pivots, the same operations in the same order as
    scanning all ``nk`` rows and skipping the eliminated ones (no update reads a row or column it
    writes), so the same counts."""
    alpha = (1.0 + math.sqrt(17.0)) / 8.0
    for i in range(nk):
        idx[i] = i
    npos, nneg, nzero = 0, 0, 0
    left = nk
    while left > 0:
        gd, idd = -1.0, -1
        go, io, jo = 0.0, -1, -1
        for ii in range(left):
            i = idx[ii]
            if abs(a[i, i]) > gd:
                gd, idd = abs(a[i, i]), i
            for jj in range(ii + 1, left):
                j = idx[jj]
                if abs(a[i, j]) > go:
                    go, io, jo = abs(a[i, j]), i, j
        if gd >= alpha * go or left == 1:
            piv = a[idd, idd]
            if piv > tiny:
                npos += 1
            elif piv < -tiny:
                nneg += 1
            else:
                nzero += 1
            w = 0
            for ii in range(left):
                if idx[ii] != idd:
                    idx[w] = idx[ii]
                    w += 1
            left = w
            if piv != 0.0:
                for ii in range(left):
                    i = idx[ii]
                    f = a[i, idd] / piv
                    for jj in range(left):
                        j = idx[jj]
                        a[i, j] -= f * a[idd, j]
        else:
            p11, p12, p22 = a[io, io], a[io, jo], a[jo, jo]
            det = p11 * p22 - p12 * p12
            if det < 0.0:
                npos += 1
                nneg += 1
            elif det > 0.0:
                if p11 + p22 > 0.0:
                    npos += 2
                else:
                    nneg += 2
            else:
                nzero += 1
                if p11 + p22 > 0.0:
                    npos += 1
                else:
                    nneg += 1
            w = 0
            for ii in range(left):
                if idx[ii] != io and idx[ii] != jo:
                    idx[w] = idx[ii]
                    w += 1
            left = w
            if det != 0.0:
                i11, i12, i22 = p22 / det, -p12 / det, p11 / det
                for ii in range(left):
                    i = idx[ii]
                    c1 = a[i, io] * i11 + a[i, jo] * i12
                    c2 = a[i, io] * i12 + a[i, jo] * i22
                    for jj in range(left):
                        j = idx[jj]
                        a[i, j] -= c1 * a[io, j] + c2 * a[jo, j]
    return npos, nneg, nzero


# The compiled loops below compute every sum of a block (a row of ``u g``, of the pivot block's
# correction, of ``x``, ``y``, ``G``, ``z``, ...) as a plain left-to-right sum, as numpy's recursion
# defines it, but three independent sums at a time (the sums side by side, each in its own order):
# the latency of one chain of additions no longer bounds the loop (~1.3-1.5x faster at the Model C
# column's sizes, blocks of 1 and 5 rows, 6 generator columns), and every result is the same bits
# as one sum after the other (tests/test_chain_trim_loops.py keeps the loops as they were).
def _factor_loops(starts, diag, u, v, p, q, symmetric, lean=False):  # pragma: no cover - compiled by numba
    """The block LU of :func:`factor`: ``(pinv, x, y, info, counts)``. ``lean`` (the compiled
    chain kernel, :mod:`vjm_pin.solver.chain_kernel`): the inertia of a symmetric pivot block by
    :func:`_inertia_small` instead of its eigenvalues, and no determinant (``info[1:3]`` stay 0, 1)."""
    n, r = u.shape
    s = q.shape[1]
    bmax = diag.shape[1]
    pinv = np.zeros_like(diag)
    x = np.zeros((n, r))
    y = np.zeros((n, s))
    g = np.zeros((r, s))
    ug = np.zeros((bmax, s))
    pi = np.zeros((bmax, bmax))
    work = np.zeros((bmax, 2 * bmax))
    vt = np.zeros((bmax, r))
    sm = np.zeros((bmax, bmax))
    rows = np.empty(bmax, np.int64)
    tj = np.zeros(bmax)
    info = np.zeros(5)
    counts = np.zeros(3, np.int64)
    rc_min, logdet, sign, worst = np.inf, 0.0, 1.0, -1
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
        if symmetric:
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
                if not lean:
                    sign = -sign
            dv = work[col, col]
            if not lean:
                if dv < 0.0:
                    sign = -sign
                logdet += np.log(abs(dv))
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
                pinv[a + i, j] = t
                ri += abs(t)
            inv_norm = max(inv_norm, ri)
        if not ok or not np.isfinite(inv_norm):
            info[0], info[1], info[2], info[3], info[4] = 0.0, -np.inf, 0.0, k, 1.0
            return pinv, x, y, info, counts
        rc = 1.0 / (inv_norm * ref) if ref > 0.0 else 0.0
        if rc < rc_min:
            rc_min, worst = rc, k
        if symmetric and lean:
            for i in range(nk):
                for j in range(nk):
                    sm[i, j] = pi[i, j]
            cp, cn, cz = _inertia_pivots(sm, nk, 1e-14 * nk * ref, rows)
            counts[0] += cp
            counts[1] += cn
            counts[2] += cz
        elif symmetric:
            if nk == 1:
                ev = np.array([pi[0, 0]])
            else:
                ev = np.linalg.eigvalsh(pi[:nk, :nk].copy())
            tiny = 1e-14 * nk * ref
            for i in range(nk):
                if ev[i] > tiny:
                    counts[0] += 1
                elif ev[i] < -tiny:
                    counts[1] += 1
                else:
                    counts[2] += 1
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
            ai = a + i
            l = 0
            while l + 2 < r:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    pji = pinv[a + j, i]
                    t0 += pji * vt[j, l]
                    t1 += pji * vt[j, l + 1]
                    t2 += pji * vt[j, l + 2]
                x[ai, l] = t0
                x[ai, l + 1] = t1
                x[ai, l + 2] = t2
                l += 3
            if l + 1 < r:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    pji = pinv[a + j, i]
                    t0 += pji * vt[j, l]
                    t1 += pji * vt[j, l + 1]
                x[ai, l] = t0
                x[ai, l + 1] = t1
                l += 2
            if l < r:
                t0 = 0.0
                for j in range(nk):
                    pji = pinv[a + j, i]
                    t0 += pji * vt[j, l]
                x[ai, l] = t0
                l += 1
            c = 0
            while c + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    pij = pinv[ai, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                    t1 += pij * (p[a + j, c + 1] - ug[j, c + 1])
                    t2 += pij * (p[a + j, c + 2] - ug[j, c + 2])
                y[ai, c] = t0
                y[ai, c + 1] = t1
                y[ai, c + 2] = t2
                c += 3
            if c + 1 < s:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    pij = pinv[ai, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                    t1 += pij * (p[a + j, c + 1] - ug[j, c + 1])
                y[ai, c] = t0
                y[ai, c + 1] = t1
                c += 2
            if c < s:
                t0 = 0.0
                for j in range(nk):
                    pij = pinv[ai, j]
                    t0 += pij * (p[a + j, c] - ug[j, c])
                y[ai, c] = t0
                c += 1
        for l in range(r):
            c = 0
            while c + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * y[a + i, c]
                    t1 += vl * y[a + i, c + 1]
                    t2 += vl * y[a + i, c + 2]
                g[l, c] += t0
                g[l, c + 1] += t1
                g[l, c + 2] += t2
                c += 3
            if c + 1 < s:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * y[a + i, c]
                    t1 += vl * y[a + i, c + 1]
                g[l, c] += t0
                g[l, c + 1] += t1
                c += 2
            if c < s:
                t0 = 0.0
                for i in range(nk):
                    vl = vt[i, l]
                    t0 += vl * y[a + i, c]
                g[l, c] += t0
                c += 1
    info[0], info[1], info[2], info[3], info[4] = rc_min, logdet, sign, worst, 0.0
    return pinv, x, y, info, counts


def _solve_loops(starts, pinv, u, x, y, q, b):  # pragma: no cover - compiled by numba
    n, nc = b.shape
    r, s = u.shape[1], q.shape[1]
    bmax = pinv.shape[1]
    z = np.empty((n, nc))
    zk = np.empty((bmax, nc))
    acc = np.zeros((r, nc))
    nb = len(starts) - 1
    for k in range(nb):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for c in range(nc):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = b[a + i, c], b[a + i + 1, c], b[a + i + 2, c]
                for l in range(r):
                    al = acc[l, c]
                    t0 -= u[a + i, l] * al
                    t1 -= u[a + i + 1, l] * al
                    t2 -= u[a + i + 2, l] * al
                zk[i, c] = t0
                zk[i + 1, c] = t1
                zk[i + 2, c] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = b[a + i, c], b[a + i + 1, c]
                for l in range(r):
                    al = acc[l, c]
                    t0 -= u[a + i, l] * al
                    t1 -= u[a + i + 1, l] * al
                zk[i, c] = t0
                zk[i + 1, c] = t1
                i += 2
            if i < nk:
                t0 = b[a + i, c]
                for l in range(r):
                    al = acc[l, c]
                    t0 -= u[a + i, l] * al
                zk[i, c] = t0
                i += 1
        for c in range(nc):
            l = 0
            while l + 2 < r:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    zi = zk[i, c]
                    t0 += x[a + i, l] * zi
                    t1 += x[a + i, l + 1] * zi
                    t2 += x[a + i, l + 2] * zi
                acc[l, c] += t0
                acc[l + 1, c] += t1
                acc[l + 2, c] += t2
                l += 3
            if l + 1 < r:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    zi = zk[i, c]
                    t0 += x[a + i, l] * zi
                    t1 += x[a + i, l + 1] * zi
                acc[l, c] += t0
                acc[l + 1, c] += t1
                l += 2
            if l < r:
                t0 = 0.0
                for i in range(nk):
                    zi = zk[i, c]
                    t0 += x[a + i, l] * zi
                acc[l, c] += t0
                l += 1
        for c in range(nc):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    zj = zk[j, c]
                    t0 += pinv[a + i, j] * zj
                    t1 += pinv[a + i + 1, j] * zj
                    t2 += pinv[a + i + 2, j] * zj
                z[a + i, c] = t0
                z[a + i + 1, c] = t1
                z[a + i + 2, c] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    zj = zk[j, c]
                    t0 += pinv[a + i, j] * zj
                    t1 += pinv[a + i + 1, j] * zj
                z[a + i, c] = t0
                z[a + i + 1, c] = t1
                i += 2
            if i < nk:
                t0 = 0.0
                for j in range(nk):
                    zj = zk[j, c]
                    t0 += pinv[a + i, j] * zj
                z[a + i, c] = t0
                i += 1
    out = np.empty((n, nc))
    acc2 = np.zeros((s, nc))
    for k in range(nb - 1, -1, -1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for c in range(nc):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = z[a + i, c], z[a + i + 1, c], z[a + i + 2, c]
                for l in range(s):
                    al = acc2[l, c]
                    t0 -= y[a + i, l] * al
                    t1 -= y[a + i + 1, l] * al
                    t2 -= y[a + i + 2, l] * al
                out[a + i, c] = t0
                out[a + i + 1, c] = t1
                out[a + i + 2, c] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = z[a + i, c], z[a + i + 1, c]
                for l in range(s):
                    al = acc2[l, c]
                    t0 -= y[a + i, l] * al
                    t1 -= y[a + i + 1, l] * al
                out[a + i, c] = t0
                out[a + i + 1, c] = t1
                i += 2
            if i < nk:
                t0 = z[a + i, c]
                for l in range(s):
                    al = acc2[l, c]
                    t0 -= y[a + i, l] * al
                out[a + i, c] = t0
                i += 1
        for c in range(nc):
            l = 0
            while l + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    oi = out[a + i, c]
                    t0 += q[a + i, l] * oi
                    t1 += q[a + i, l + 1] * oi
                    t2 += q[a + i, l + 2] * oi
                acc2[l, c] += t0
                acc2[l + 1, c] += t1
                acc2[l + 2, c] += t2
                l += 3
            if l + 1 < s:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    oi = out[a + i, c]
                    t0 += q[a + i, l] * oi
                    t1 += q[a + i, l + 1] * oi
                acc2[l, c] += t0
                acc2[l + 1, c] += t1
                l += 2
            if l < s:
                t0 = 0.0
                for i in range(nk):
                    oi = out[a + i, c]
                    t0 += q[a + i, l] * oi
                acc2[l, c] += t0
                l += 1
    return out


def _matvec_loops(starts, diag, u, v, p, q, x):  # pragma: no cover - compiled by numba
    n, nc = x.shape
    r, s = u.shape[1], q.shape[1]
    y = np.zeros((n, nc))
    acc = np.zeros((r, nc))
    tmp = np.empty(diag.shape[1])
    nb = len(starts) - 1
    for k in range(nb):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for c in range(nc):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for j in range(nk):
                    xj = x[a + j, c]
                    t0 += diag[a + i, j] * xj
                    t1 += diag[a + i + 1, j] * xj
                    t2 += diag[a + i + 2, j] * xj
                tmp[i] = t0
                tmp[i + 1] = t1
                tmp[i + 2] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = 0.0, 0.0
                for j in range(nk):
                    xj = x[a + j, c]
                    t0 += diag[a + i, j] * xj
                    t1 += diag[a + i + 1, j] * xj
                tmp[i] = t0
                tmp[i + 1] = t1
                i += 2
            if i < nk:
                t0 = 0.0
                for j in range(nk):
                    xj = x[a + j, c]
                    t0 += diag[a + i, j] * xj
                tmp[i] = t0
                i += 1
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = tmp[i], tmp[i + 1], tmp[i + 2]
                for l in range(r):
                    al = acc[l, c]
                    t0 += u[a + i, l] * al
                    t1 += u[a + i + 1, l] * al
                    t2 += u[a + i + 2, l] * al
                y[a + i, c] = t0
                y[a + i + 1, c] = t1
                y[a + i + 2, c] = t2
                i += 3
            if i + 1 < nk:
                t0, t1 = tmp[i], tmp[i + 1]
                for l in range(r):
                    al = acc[l, c]
                    t0 += u[a + i, l] * al
                    t1 += u[a + i + 1, l] * al
                y[a + i, c] = t0
                y[a + i + 1, c] = t1
                i += 2
            if i < nk:
                t0 = tmp[i]
                for l in range(r):
                    al = acc[l, c]
                    t0 += u[a + i, l] * al
                y[a + i, c] = t0
                i += 1
        for c in range(nc):
            l = 0
            while l + 2 < r:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += v[a + i, l] * xi
                    t1 += v[a + i, l + 1] * xi
                    t2 += v[a + i, l + 2] * xi
                acc[l, c] += t0
                acc[l + 1, c] += t1
                acc[l + 2, c] += t2
                l += 3
            if l + 1 < r:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += v[a + i, l] * xi
                    t1 += v[a + i, l + 1] * xi
                acc[l, c] += t0
                acc[l + 1, c] += t1
                l += 2
            if l < r:
                t0 = 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += v[a + i, l] * xi
                acc[l, c] += t0
                l += 1
    acc2 = np.zeros((s, nc))
    for k in range(nb - 1, -1, -1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for c in range(nc):
            i = 0
            while i + 2 < nk:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for l in range(s):
                    al = acc2[l, c]
                    t0 += p[a + i, l] * al
                    t1 += p[a + i + 1, l] * al
                    t2 += p[a + i + 2, l] * al
                y[a + i, c] += t0
                y[a + i + 1, c] += t1
                y[a + i + 2, c] += t2
                i += 3
            if i + 1 < nk:
                t0, t1 = 0.0, 0.0
                for l in range(s):
                    al = acc2[l, c]
                    t0 += p[a + i, l] * al
                    t1 += p[a + i + 1, l] * al
                y[a + i, c] += t0
                y[a + i + 1, c] += t1
                i += 2
            if i < nk:
                t0 = 0.0
                for l in range(s):
                    al = acc2[l, c]
                    t0 += p[a + i, l] * al
                y[a + i, c] += t0
                i += 1
        for c in range(nc):
            l = 0
            while l + 2 < s:
                t0, t1, t2 = 0.0, 0.0, 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += q[a + i, l] * xi
                    t1 += q[a + i, l + 1] * xi
                    t2 += q[a + i, l + 2] * xi
                acc2[l, c] += t0
                acc2[l + 1, c] += t1
                acc2[l + 2, c] += t2
                l += 3
            if l + 1 < s:
                t0, t1 = 0.0, 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += q[a + i, l] * xi
                    t1 += q[a + i, l + 1] * xi
                acc2[l, c] += t0
                acc2[l + 1, c] += t1
                l += 2
            if l < s:
                t0 = 0.0
                for i in range(nk):
                    xi = x[a + i, c]
                    t0 += q[a + i, l] * xi
                acc2[l, c] += t0
                l += 1
    return y


# --------------------------------------------------------------------------- the chain
@dataclass(frozen=True)
class ChainLayout:
    """The solver's free coordinates of one model in chain order, and ``K_θ``'s blocks there.

    Attributes:
        cols: (n,) velocity indices of the free coordinates (θ and q), ascending (chain order).
        order: (n,) position of each chain coordinate in the solver's (θ, q) order
            (``concatenate([theta_idx, q_idx])[order] == cols``).
        starts: (N+1,) diagonal-block boundaries in chain order: the finest partition into
            consecutive coordinates that ``K_θ`` does not couple across.
        k_diag: (n, b) the stiffness rows inside their blocks (N·m/rad, N/m, …), chain order.
    """

    cols: np.ndarray
    order: np.ndarray
    starts: np.ndarray
    k_diag: np.ndarray

    @property
    def n(self) -> int:
        return len(self.cols)

    def block_ids(self) -> np.ndarray:
        return self._in_blocks[0]

    def k_norm2(self) -> float:
        """``‖K_θ‖₂`` (largest singular value) from the diagonal blocks: O(n), once."""
        return self._k_norm2

    def k_pinv_apply(self, a: np.ndarray) -> np.ndarray:
        """``K⁺ a`` for a (n, c) in chain order (``K⁺`` the block-wise inverse, zero on the
        zero-stiffness blocks of passive joints): O(n b c)."""
        blk, j = self._in_blocks
        inside = j < self.starts[blk + 1][:, None]
        jj = np.minimum(j, self.n - 1)
        return np.einsum("ib,ibc->ic", np.where(inside, self._k_pinv, 0.0), a[jj])

    @cached_property
    def _k_pinv(self) -> np.ndarray:
        """The blocks' pseudo-inverses (a zero block: zero), one stacked ``np.linalg.pinv`` per
        block size (the same numbers as block by block, ~8× faster at n = 146)."""
        out = np.zeros_like(self.k_diag)
        sizes = np.diff(self.starts)
        for size in np.unique(sizes):
            rows = self.starts[:-1][sizes == size][:, None] + np.arange(size)  # (blocks, size)
            blks = self.k_diag[rows, :size]
            keep = blks.any(axis=(1, 2))
            if keep.any():
                out[rows[keep], :size] = np.linalg.pinv(blks[keep])
        return out

    @cached_property
    def _k_norm2(self) -> float:
        best = 0.0
        for k in range(len(self.starts) - 1):
            a, e = self.starts[k], self.starts[k + 1]
            blk = self.k_diag[a:e, : e - a]
            if blk.any():
                best = max(best, float(np.linalg.norm(blk, 2)) if e - a > 1 else abs(float(blk[0, 0])))
        return best

    def in_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """``(block, cols)``: (n,) block of each row, (n, b) column index of each block entry of
        the row (chain order; padding entries are ``≥ starts[block + 1]``: mask them)."""
        return self._in_blocks

    @cached_property
    def _in_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        blk = np.repeat(np.arange(len(self.starts) - 1), np.diff(self.starts))
        j = self.starts[blk][:, None] + np.arange(self.k_diag.shape[1])[None, :]
        return blk, j


_LAYOUTS: dict[tuple, tuple] = {}


def chain_layout(k_theta: np.ndarray, theta_idx: np.ndarray, q_idx: np.ndarray) -> ChainLayout:
    """:class:`ChainLayout` of a model (``vm.K_theta``, ``vm.theta_idx``, ``vm.q_idx``), kept per
    ``K_θ`` array (treated as immutable, like everywhere in the solver): O(n²) once, not per point."""
    theta_idx = np.asarray(theta_idx, np.int64)
    q_idx = np.asarray(q_idx, np.int64)
    key = (id(k_theta), theta_idx.tobytes(), q_idx.tobytes())
    hit = _LAYOUTS.get(key)
    if hit is not None and hit[0] is k_theta:
        return hit[1]
    free = np.concatenate([theta_idx, q_idx])
    order = np.argsort(free, kind="stable")
    n, nt = len(free), len(theta_idx)
    kf = np.zeros((n, n))
    kf[:nt, :nt] = k_theta
    kc = kf[np.ix_(order, order)]
    nz = (kc != 0) | (kc.T != 0)
    reach = np.where(nz.any(axis=1), n - 1 - np.argmax(nz[:, ::-1], axis=1), np.arange(n))
    reach = np.maximum.accumulate(np.maximum(reach, np.arange(n)))
    ends = np.flatnonzero(reach == np.arange(n)) + 1
    starts = np.concatenate([[0], ends]).astype(np.int64)
    b = int(np.diff(starts).max()) if n else 1
    blk = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    j = starts[blk][:, None] + np.arange(b)[None, :]
    inside = j < starts[blk + 1][:, None]
    k_diag = np.where(inside, kc[np.arange(n)[:, None], np.minimum(j, n - 1)], 0.0)
    lay = ChainLayout(free[order], order, starts, k_diag)
    if len(_LAYOUTS) >= 32:
        _LAYOUTS.pop(next(iter(_LAYOUTS)))
    _LAYOUTS[key] = (k_theta, lay)
    return lay


def _skew_rows(vec3: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Rows ``vec_i × f`` of an (n, 3) array (``vec @ [f]×``, ``[f]×`` the cross-product matrix)."""
    fx, fy, fz = f.tolist()
    return vec3 @ np.array([[0.0, -fz, fy], [fz, 0.0, -fx], [-fy, fx, 0.0]])


def chain_matrix(layout: ChainLayout, jacobian: np.ndarray, wrench: np.ndarray, symmetric: bool = False) -> QuasiMatrix:
    """``W = K − H`` (eq. 16: ``H`` the Hessian of ``Ψ``, in screw form) in chain order as a
    :class:`QuasiMatrix`; ``symmetric``: its symmetric part (the matrix of eq. 23).

    Args:
        layout: :func:`chain_layout` of the model.
        jacobian: (6, nv) ``LOCAL_WORLD_ALIGNED`` frame Jacobian of the end frame (all joints).
        wrench: (6,) end wrench ``(f, m)`` (N, N·m), world axes.
    """
    jz = np.asarray(jacobian, float)[:, layout.cols]
    wrench = np.asarray(wrench, float)
    v, w = jz[:3].T, jz[3:].T
    d = _skew_rows(v, wrench[:3])
    e = _skew_rows(w, wrench[3:])
    a = d + e
    n = layout.n
    blk, j = layout.in_blocks()
    inside = j < layout.starts[blk + 1][:, None]
    jj = np.minimum(j, n - 1)
    i = np.arange(n)[:, None]
    lower_h = np.einsum("ik,ibk->ib", a, w[jj])  # a_i·ω_j
    upper_h = np.einsum("ik,ibk->ib", w, d[jj])  # ω_i·d_j
    h = np.where(jj <= i, lower_h, upper_h)
    diag = np.where(inside, layout.k_diag - h, 0.0)
    if symmetric:
        hsym = 0.5 * (h + _h_transposed(a, d, w, jj, i))
        diag = np.where(inside, layout.k_diag - hsym, 0.0)
        uu = -(d + 0.5 * e)
        return QuasiMatrix(layout.starts, diag, uu, w, w, uu)
    return QuasiMatrix(layout.starts, diag, -a, w, -w, d)


def _h_transposed(a, d, w, jj, i):
    """``H[j, i]`` for the block entries ``(i, j)`` (``j = jj``)."""
    # H[j, i] = a_j·ω_i when i ≤ j, ω_j·d_i when i > j
    return np.where(i <= jj, np.einsum("ibk,ik->ib", a[jj], w), np.einsum("ibk,ik->ib", w[jj], d))



class ChainKKT:
    """The bordered matrix ``[[W − σI, J_tᵀ], [J_t, 0]]`` of one chain configuration, factorised in
    O(n): ``W = K − H`` (or its symmetric part), ``J_t`` the task rows of the Jacobian.

    Eq. (28) is this matrix with ``σ = 0`` (``δF`` the negative multiplier), eq. (23)'s reduced
    matrix is ``Zᵀ W Z`` on its null space. The elimination runs on the scaled, augmented
    ``[[S (W − σI + ρJᵀJ) S, S Jᵀ], [J S, 0]]`` (module docstring): congruent, so the inertia is
    the KKT matrix's; solves are mapped back and refined against the original matrix.

    Args:
        layout: :func:`chain_layout` of the model.
        jacobian: (6, nv) end-frame Jacobian (``LOCAL_WORLD_ALIGNED``), all joints.
        wrench: (6,) total end wrench (N, N·m).
        task: constrained task components (indices into x y z rx ry rz), or a (k, 6) matrix
            of held combinations of the six Jacobian rows (mixed control: ``held @ I[task]``;
            k = 0 is pure force control, the matrix is ``W`` itself).
        symmetric: use the symmetric part of ``W`` (stability, eq. 23); else ``W`` itself (eq. 28,
            the Newton step).
        shift: ``σ`` (same units as ``W``).

    Attributes:
        factor: the :class:`Factor` of the scaled augmented matrix (chain blocks, then the m
            multipliers as the last block).
        reliable: every pivot regular (else use the dense path).
    """

    def __init__(self, layout: ChainLayout, jacobian, wrench, task, symmetric: bool = False, shift: float = 0.0):
        self.layout = layout
        rows = np.asarray(task, dtype=float)
        self.task = None if rows.ndim == 2 else tuple(int(t) for t in task)
        self.symmetric = bool(symmetric)
        self.shift = float(shift)
        jac = np.asarray(jacobian, float)
        self.w = chain_matrix(layout, jac, wrench, symmetric)
        if self.task is None:  # held combinations of the Jacobian rows
            jc = (rows.reshape(-1, 6) @ jac[:, layout.cols]).T  # (n, k)
        else:
            jc = jac[np.ix_(list(self.task), layout.cols)].T  # (n, m)
        self.jc = jc
        n, m = jc.shape
        self.m = m
        st = layout.starts
        blk, j = layout.in_blocks()
        inside = j < st[blk + 1][:, None]
        jj = np.minimum(j, n - 1)
        diag_w = self.w.diag[np.arange(n), np.arange(n) - st[blk]] - self.shift
        jn = np.einsum("ik,ik->i", jc, jc)
        absd = np.abs(diag_w)
        npos = int(np.count_nonzero(absd))
        kref = float(absd.sum()) / npos if npos else 1.0  # the typical diagonal entry
        # ρ ~ the stiffness of the chain at the end (m / trace of the unloaded compliance
        # J K⁺ Jᵀ): the multiplier λ = μ + ρ b₂ then loses few digits to the cancellation
        comp = float(np.einsum("ic,ic->", jc, layout.k_pinv_apply(jc))) if n and m else 0.0
        if m == 0:
            rho = 0.0
        elif comp > 0 and np.isfinite(comp):
            rho = RHO_FACTOR * m / comp
        else:
            rho = RHO_FACTOR * kref / max(float(jn.sum()) / max(n, 1), 1e-300)
        dw = np.abs(diag_w) + rho * jn
        s = np.where(dw > 0, 1.0 / np.sqrt(np.where(dw > 0, dw, 1.0)), 1.0 / np.sqrt(kref))
        self.rho, self.scale = rho, s
        js = jc * s[:, None]
        d = (self.w.diag - np.where(jj == np.arange(n)[:, None], self.shift, 0.0)) * s[:, None] * s[jj]
        d = d + rho * np.einsum("ik,ibk->ib", js, js[jj])
        d = np.where(inside, d, 0.0)
        b = max(self.w.diag.shape[1], m)
        diag = np.zeros((n + m, b))
        diag[:n, : d.shape[1]] = d

        def gen(g, jpart):
            out = np.zeros((n + m, g.shape[1] + m))
            out[:n, : g.shape[1]] = g * s[:, None]
            out[:n, g.shape[1] :] = jpart
            return out

        u = gen(self.w.u, rho * js)
        v = gen(self.w.v, js)
        p = gen(self.w.p, js)
        q = gen(self.w.q, rho * js)
        r0 = self.w.u.shape[1]
        u[n:, r0:] = np.eye(m)
        q[n:, self.w.q.shape[1] :] = np.eye(m)
        self.matrix = QuasiMatrix(np.append(st, n + m) if m else st, diag, u, v, p, q)
        self.factor = factor(self.matrix, self.symmetric)
        self.reliable = self.factor.reliable

    def with_shift(self, shift: float) -> ChainKKT:
        """The same matrix shifted to ``σ = shift``: the generators and the scaling are reused
        (any positive scaling keeps the inertia), only the diagonal and the factorisation change."""
        new = object.__new__(ChainKKT)
        new.__dict__.update(self.__dict__)
        new.shift = float(shift)
        n = self.layout.n
        diag = self.matrix.diag.copy()
        blk = self.layout.block_ids()
        rows = np.arange(n)
        diag[rows, rows - self.layout.starts[blk]] -= (new.shift - self.shift) * self.scale**2
        m = self.matrix
        new.matrix = QuasiMatrix(m.starts, diag, m.u, m.v, m.p, m.q)
        new.matrix.__dict__["_blk"] = m.block_ids()
        new.factor = factor(new.matrix, self.symmetric)
        new.reliable = new.factor.reliable
        return new

    def count_below(self, sigma: float) -> int | None:
        """:func:`count_below` at ``sigma`` for this configuration (one factorisation)."""
        ine = self.with_shift(sigma).reduced_inertia()
        return None if ine is None else ine[1]

    # -- inertia / stability -------------------------------------------------------------------
    @property
    def inertia(self) -> tuple[int, int, int] | None:
        """``(positive, negative, zero)`` of the KKT matrix (symmetric only)."""
        return self.factor.inertia

    def reduced_inertia(self) -> tuple[int, int, int] | None:
        """Inertia of ``Zᵀ (W − σI) Z`` (Haynsworth: the KKT inertia minus ``(m, m, 0)``); None
        when not symmetric, unreliable, or ``J_t`` is not of full row rank (counts below m)."""
        ine = self.factor.inertia
        if ine is None or not self.reliable or ine[0] < self.m or ine[1] < self.m or ine[2]:
            return None
        return ine[0] - self.m, ine[1] - self.m, 0

    # -- solves ----------------------------------------------------------------------------------
    def _kkt_matvec(self, x, lam):
        """The original (unscaled, un-augmented) KKT matrix times ``(x, λ)``."""
        r1 = self.w.matvec(x) - self.shift * x + self.jc @ lam
        return r1, self.jc.T @ x

    def solve(self, b1: np.ndarray, b2: np.ndarray, refine: int = 2) -> tuple[np.ndarray, np.ndarray, float]:
        """``(x, λ, residual)`` with ``(W − σI) x + J_tᵀ λ = b1``, ``J_t x = b2`` (chain order;
        b1 (n, c), b2 (m, c)); ``residual`` is the relative residual (scaled) after refinement."""
        s, rho, n = self.scale, self.rho, self.layout.n
        b1 = np.asarray(b1, float).reshape(n, -1)
        b2 = np.asarray(b2, float).reshape(self.m, b1.shape[1])

        def raw(c1, c2):
            z = self.factor.solve(np.vstack([c1 * s[:, None], c2]))
            return z[:n] * s[:, None], z[n:] + rho * c2

        x, lam = raw(b1, b2)
        res = np.inf
        for it in range(refine + 1):
            r1, r2 = self._kkt_matvec(x, lam)
            r1, r2 = b1 - r1, b2 - r2
            num = max(np.abs(r1 * s[:, None]).max(initial=0.0), np.abs(r2).max(initial=0.0))
            den = max(np.abs(x / s[:, None]).max(initial=0.0), np.abs(lam).max(initial=0.0)) * max(
                1.0, np.abs(self.jc * s[:, None]).max(initial=0.0)
            ) + max(np.abs(b1 * s[:, None]).max(initial=0.0), np.abs(b2).max(initial=0.0))
            res = num / den if den > 0 else 0.0
            if it == refine or res < 1e-15:
                break
            dx, dl = raw(r1, r2)
            x, lam = x + dx, lam + dl
        if not np.isfinite(res):
            res = np.inf
        return x, lam, float(res)

    def solve_free(self, b1: np.ndarray, b2: np.ndarray, refine: int = 2) -> tuple[np.ndarray, np.ndarray, float]:
        """:meth:`solve` with ``b1`` and ``x`` in the solver's (θ, q) order (``concatenate([theta_idx,
        q_idx])``, as :class:`~vjm_pin.solver.blocks.Blocks`): the Newton step of eq. (24)–(26)
        (``b1`` the negative static residual, ``b2`` the negative task error)."""
        order = self.layout.order
        x, lam, res = self.solve(np.asarray(b1, float)[order], b2, refine)
        out = np.empty_like(x)
        out[order] = x
        if np.ndim(b1) == 1:
            out = out[:, 0]
        return out, (lam[:, 0] if np.ndim(b2) == 1 else lam), res

    def stiffness(self) -> tuple[np.ndarray, np.ndarray, float]:
        """``(K_C, dx/dt, residual)`` of eq. (28)–(30): ``K_C`` (m, m) for the task rows,
        ``dx/dt`` (n, m) in the solver's (θ, q) order."""
        n, m = self.layout.n, self.m
        x, lam, res = self.solve(np.zeros((n, m)), np.eye(m))
        out = np.empty_like(x)
        out[self.layout.order] = x
        return -lam, out, res


def count_below(layout: ChainLayout, jacobian, wrench, task, sigma: float) -> int | None:
    """Number of eigenvalues of ``Zᵀ W_s Z`` below ``sigma`` (``W_s`` the symmetric part of
    ``K − H``, ``Z`` an orthonormal basis of the null space of the task rows): eq. (23)'s matrix
    is ``−Zᵀ W_s Z``. None when the factorisation is unreliable (``σ`` at an eigenvalue, a
    rank-deficient ``J``)."""
    kkt = ChainKKT(layout, jacobian, wrench, task, symmetric=True, shift=sigma)
    ine = kkt.reduced_inertia()
    return None if ine is None else ine[1]


def smallest_reduced_eigenvalue(
    layout: ChainLayout, jacobian, wrench, task, rtol: float = 1e-12, scale: float | None = None,
    guess: float | None = None,
) -> float | None:
    """Smallest eigenvalue of ``Zᵀ W_s Z`` (:func:`smallest_reduced_eigenpair`)."""
    pair = smallest_reduced_eigenpair(layout, jacobian, wrench, task, rtol, scale, guess)
    return None if pair is None else pair[0]


def smallest_reduced_eigenpair(
    layout: ChainLayout, jacobian, wrench, task, rtol: float = 1e-12, scale: float | None = None,
    guess: float | None = None,
) -> tuple[float, np.ndarray] | None:
    """Smallest eigenvalue of ``Zᵀ W_s Z`` and a unit eigenvector ``x = Z y`` (joint
    displacements that keep the end fixed, in the solver's (θ, q) order): eq. (23)'s reduced
    matrix is ``−Zᵀ W_s Z`` (stable iff the eigenvalue is positive; at a critical point ``x``
    is the buckling mode).

    Bisection on the Sturm count (:func:`count_below`) to two digits brackets the eigenvalue
    from below by ``σ``; inverse iteration with the KKT solve at that shift (for ``v`` in the null
    space, ``[[W_s − σI, Jᵀ], [J, 0]]⁻¹ [v; 0] = Z (Zᵀ W_s Z − σI)⁻¹ Zᵀ v``) and the Rayleigh
    quotient then converge to the smallest eigenvalue; bisection to ``rtol`` takes over if they
    do not. Accuracy ``rtol`` relative to the eigenvalue plus ``1e-13 · scale`` (default
    ``scale``: the largest diagonal entry of ``K_θ``). Each count or shift is one O(n)
    factorisation (about 15 from scratch; a ``guess`` near the eigenvalue, e.g. the previous
    point of a curve, brackets it in a few). None when no count is reliable or the reduced space
    is empty."""
    if scale is None:
        scale = float(np.abs(layout.k_diag).max(initial=0.0)) or 1.0
    atol = 1e-13 * scale
    base = ChainKKT(layout, jacobian, wrench, task, symmetric=True)

    def cnt(sig):
        return base.count_below(sig)

    def bracket(start, step, want_some):
        sig = start
        for _ in range(64):
            c = cnt(sig)
            if c is not None and (c >= 1) == want_some:
                return sig
            sig, step = (sig + step, 4.0 * step) if c is not None else (sig + 1e-3 * step, step)
        return None

    def bisect(lo, hi, tol):
        while hi - lo > tol * max(abs(lo), abs(hi)) + atol:
            for frac in (0.5, 0.375, 0.625, 0.25, 0.75):  # off an eigenvalue if mid is on one
                mid = _split(lo, hi, frac, atol)
                c = cnt(mid)
                if c is not None:
                    break
            else:
                return lo, hi, True  # every trial on an eigenvalue: within the pivot precision
            if c >= 1:
                hi = mid
            else:
                lo = mid
        return lo, hi, False

    if guess is not None and np.isfinite(guess):
        delta = 0.05 * abs(guess) + 1e3 * atol
        hi = bracket(guess + delta, 3.0 * delta, True)
        lo = bracket(guess - delta, -3.0 * delta, False)
    else:
        hi = bracket(scale, scale, True)
        lo = bracket(-scale, -scale, False)
    if hi is None or lo is None:
        return None
    lo, hi, stuck = bisect(lo, hi, max(rtol, 1e-2))
    vec = _inverse_iteration(base.with_shift(lo), lo, hi, rtol, atol) if not stuck else None
    if vec is not None:
        return vec
    lo, hi, _ = bisect(lo, hi, rtol)
    value = 0.5 * (lo + hi)
    return value, _null_vector(base.with_shift(lo - (hi - lo)))


def _split(lo, hi, frac, atol):
    """A point of (lo, hi): 0 when it straddles 0, else geometric (|σ| spans decades); also
    compiled, in the chain kernel's bisection."""
    if lo < 0 < hi and frac == 0.5:
        return 0.0
    if lo >= 0 and hi > max(lo, atol):
        a = max(lo, atol)
        return a * (hi / a) ** frac
    if hi <= 0 and -lo > max(-hi, atol):
        a = max(-hi, atol)
        return -a * (-lo / a) ** (1 - frac)
    return lo + frac * (hi - lo)


def _null_vector(kkt: ChainKKT, iterations: int = 3) -> np.ndarray:
    """A few inverse iterations of ``kkt`` (its shift just below the eigenvalue): the
    eigenvector in the solver's order (best effort, unit norm)."""
    n, m = kkt.layout.n, kkt.m
    v = np.ones((n, 1))
    for _ in range(iterations):
        v, _, _ = kkt.solve(v, np.zeros((m, 1)), refine=1)
        v /= np.linalg.norm(v) or 1.0
    out = np.empty(n)
    out[kkt.layout.order] = v[:, 0]
    return out


def _inverse_iteration(kkt: ChainKKT, lo, hi, rtol, atol, max_iter: int = 60):
    """``(eigenvalue, eigenvector)`` by inverse iteration with ``kkt`` shifted to ``lo`` (below
    the smallest eigenvalue, which lies in ``(lo, hi]``), or None if it does not converge into
    the bracket."""
    if not kkt.reliable:
        return None
    layout = kkt.layout
    n, m = layout.n, kkt.m
    rng = np.random.default_rng(0)
    v = rng.standard_normal((n, 1))
    prev = np.inf
    for _ in range(max_iter):
        x, _, res = kkt.solve(v, np.zeros((m, 1)), refine=1)
        nx = np.linalg.norm(x)
        if not np.isfinite(nx) or nx == 0 or res > SOLVE_RTOL:
            return None
        x /= nx
        rq = float(x[:, 0] @ kkt.w.matvec(x)[:, 0])  # Rayleigh quotient (x in the null space, |x| = 1)
        if abs(rq - prev) <= 0.1 * (rtol * abs(rq) + atol):
            if lo - atol <= rq <= hi + rtol * abs(hi) + atol:
                out = np.empty(n)
                out[layout.order] = x[:, 0]
                return rq, out
            return None
        prev, v = rq, x
    return None


@dataclass(frozen=True)
class ChainStability:
    """Eq. (23) verdict from one O(n) factorisation (Sturm count at the threshold).

    Attributes:
        stable: every eigenvalue of ``Zᵀ W_s Z`` exceeds ``tolerance`` (the reduced matrix of
            eq. 23, ``−Zᵀ W_s Z``, is negative definite with the margin of
            :func:`~vjm_pin.solver.stability.check_stability`).
        unstable_count: number of eigenvalues of ``Zᵀ W_s Z`` below ``tolerance`` (the number of
            unstable modes).
        null_dim: dimension of the null space of the task rows (``n − m``).
        tolerance: ``STABILITY_TOL · ‖K_θ‖₂`` (same units as ``W``).
    """

    stable: bool
    unstable_count: int
    null_dim: int
    tolerance: float


def chain_stability(
    layout: ChainLayout, jacobian, wrench, task, tol: float = 1e-10
) -> ChainStability | None:
    """The stability verdict of :func:`~vjm_pin.solver.stability.check_stability` (eq. 23, same
    relative threshold ``tol · ‖K_θ‖₂``) in O(n): ``count_below(threshold) == 0``. None when the
    count is not reliable (an eigenvalue at the threshold, a rank-deficient task Jacobian):
    the caller uses the dense path."""
    thr = tol * (layout.k_norm2() or 1.0)
    kkt = ChainKKT(layout, jacobian, wrench, task, symmetric=True, shift=thr)
    ine = kkt.reduced_inertia()
    if ine is None:
        return None
    return ChainStability(ine[1] == 0, ine[1], ine[0] + ine[1], float(thr))
