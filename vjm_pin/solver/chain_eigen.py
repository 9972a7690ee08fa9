"""The smallest eigenpair of eq. (23) with the end held in chosen task rows, in O(n), for long serial
chains: the compiled chain algebra of :mod:`vjm_pin.solver.chain_kernel` offered one eigenvalue
problem at a time (:func:`vjm_pin.analysis.critical.critical_load` asks it at fixed geometry under
several wrenches).

With ``W(F) = K − H(F)`` (``K = diag(K_θ, 0)``, ``H`` of eq. 23, linear in the wrench ``F``) and
``Z`` an orthonormal basis of the null space of ``C = R·J`` (``J`` the task rows of the frame
Jacobian over the free coordinates, ``R`` the held rows: the identity for eq. 23 itself, the rows
orthogonal to a direction ``d`` for the force-control margin ``μ``), :meth:`HeldEigen.smallest`
returns ``λ₁``, the smallest eigenvalue of ``Zᵀ sym(W) Z`` (the largest eigenvalue of eq. 23's
matrix is ``−λ₁``), and its unit eigenvector ``y = Z u``, certified by Sturm counts of the bordered
matrix (:func:`~vjm_pin.solver.chain_kernel._smallest`, the point kernel's routine).
:meth:`HeldEigen.rayleigh` is ``yᵀ sym(W(F)) y`` for a vector of that null space,
:meth:`HeldEigen.count_below` the number of eigenvalues below a shift (Sylvester's count of the
bordered matrix's pivots), :meth:`HeldEigen.smallest_definite` ``λ₁`` of a positive definite
problem without a start vector (inverse iteration at shift 0, certified by a count), and
:meth:`HeldEigen.pencil` the largest eigenvalue of the pencil ``(Zᵀ H(w₁) Z, Zᵀ sym(W(w₀)) Z)``
(linearised buckling at fixed geometry) by power iteration accelerated by Rayleigh–Ritz on its
Krylov space, bounded by a count. The last two run as compiled loops of their own (numba, with the
chain kernel's helpers), and so does :func:`held_eigen`'s setup (the Jacobian's columns in chain
order, the held rows and their rank test in one call). Vectors are in chain order;
:meth:`HeldEigen.free_vector` puts one in (θ, q) order.

Only on the compiled path (``VJM_PIN_JIT`` not 0, numba importable), for chains of
:data:`~vjm_pin.solver.chain_kernel.POINT_MIN_N` free coordinates or more whose support is the chain
order, and a held Jacobian of full row rank; :func:`held_eigen` returns None otherwise (the caller's
dense routine decides). ``tests/test_critical.py`` compares it with dense eigenvalue problems.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from vjm_pin.solver import chain_kernel as _ck

#: Smallest ratio of the singular values of the held Jacobian ``C`` (the point kernel's
#: ``FAST_RANK``): below it the dense routine decides.
RANK_RATIO = 1e-7


class HeldEigen:
    """:func:`held_eigen`'s problem for one configuration and one set of held rows (module
    docstring). Attributes: ``n`` (free coordinates), ``m`` (held rows: the null space has
    dimension ``n − m``), ``order`` (chain position → position in the (θ, q) order)."""

    def __init__(self, lay, jz, cb, vtol):
        self._lay, self._jz, self._cb, self._vtol = lay, jz, cb, vtol
        self._loop_args = (lay.starts, lay.dpos, lay.kp, lay.kd, jz, cb)  # (the compiled loops' leading arguments)
        self.n = int(jz.shape[1])
        self.m = int(cb.shape[0])
        self.order = lay.order

    def smallest(self, wrench, guess=None):
        """``(λ₁, y)`` of ``Zᵀ sym(K − H(wrench)) Z`` (module docstring; ``y`` unit, chain order),
        started from ``guess`` (chain order) when given; None when not certified."""
        lay = self._lay
        has = guess is not None and guess.shape == (self.n,)
        g = np.ascontiguousarray(guess, float) if has else np.zeros(self.n)
        ok, lam, vec = _ck._smallest(
            lay.starts,
            lay.dpos,
            lay.kp,
            self._jz,
            np.ascontiguousarray(wrench, float),
            lay.kd,
            self._cb,
            lay.kscale,
            has,
            g,
            self._vtol,
        )
        if not ok or not np.isfinite(lam):
            return None
        return float(lam), vec

    def rayleigh(self, wrench, y) -> float:
        """``yᵀ sym(K − H(wrench)) y / yᵀy`` (``y`` in chain order)."""
        lay = self._lay
        gens = _ck._w_gens(self._jz, np.ascontiguousarray(wrench, float), lay.starts, lay.kd, True)
        return float(_ck._rayleigh(lay.starts, *gens, np.ascontiguousarray(y, float)))

    def count_below(self, wrench, sigma: float = 0.0) -> int:
        """The number of eigenvalues of ``Zᵀ sym(K − H(wrench)) Z`` below ``σ`` (Sylvester's count
        of the bordered matrix's pivots), −1 when the count is not reliable (a near-singular
        pivot)."""
        lay = self._lay
        gens = _ck._w_gens(self._jz, np.ascontiguousarray(wrench, float), lay.starts, lay.kd, True)
        bst, bd, bu, bv, bp, bq, s, _ = _ck._bordered(*gens, lay.starts, lay.dpos, lay.kp, self._cb)
        return int(_ck._count(bst, bd, bu, bv, bp, bq, s, lay.dpos, self.m, float(sigma))[0])

    def smallest_definite(self, wrench, max_steps: int = 40):
        """:meth:`smallest` where ``Zᵀ sym(K − H(wrench)) Z`` is positive definite (a Sturm count
        at 0; else None): inverse iteration at shift 0 from a fixed generic vector (the eigenvector
        of ``λ₁`` dominates by ``λ₂/λ₁`` per step), accelerated by Rayleigh–Ritz on the space of
        the iterates, until the Rayleigh quotient settles (to 1e-13 relative; the unit vector to
        1e-6 per step: a start for later problems), then a Sturm count
        certifies it (no eigenvalue below it, less ``1e-9`` relative): ``(λ₁, y)``, or None when
        not definite, not settled in ``max_steps`` or not certified."""
        lay = self._lay
        st, lam, y = _loops()[0](
            *self._loop_args,
            np.ascontiguousarray(wrench, float),
            lay.kscale,
            max_steps,
            1e-6,
        )
        if st != 0 or not np.isfinite(lam):
            return None
        return float(lam), y

    def pencil(
        self,
        w0,
        w1,
        y,
        rtol: float = 1e-12,
        max_steps: int = 40,
        cert: float = 0.0,
        atol: float = 0.0,
    ):
        """The largest ``ν`` of the pencil ``Zᵀ H(w₁) Z u = ν Zᵀ sym(W(w₀)) Z u`` by power iteration
        ``y ← A⁻¹B y`` (``A = sym W(w₀)``, positive definite on the null space, else None;
        ``B = H(w₁)``; one solve of the bordered matrix per step, so every iterate lies in the
        null space) from ``y`` (projected on the null space), accelerated by Rayleigh–Ritz: ``y``
        is the Ritz vector of the largest ``ν`` of the pencil projected on the space of the
        iterates so far (the next solve is applied to it), so its quotient is at most the plain
        power iterate's: ``(t, y, certified)`` with ``t = yᵀAy / yᵀBy`` (``y`` unit) once it
        changes by at most ``rtol·t + atol`` (~6 solves at 1e-12 on the k = 8 column, where the
        plain iteration took 11) or after ``max_steps`` solves; None where ``yᵀBy ≤ 0``. ``t`` bounds the smallest positive ``ΔF``
        where ``A − ΔF·B`` becomes singular from above (``1/ν_max``, the quotient's minimum);
        ``certified`` (with ``cert > 0``): a Sturm count finds ``Zᵀ sym(A − (1 − cert)·t·B) Z``
        positive definite, so that root lies in ``[(1 − cert)·t, t]``."""
        st, t, yy, certified = _loops()[1](
            *self._loop_args,
            np.ascontiguousarray(w0, float),
            np.ascontiguousarray(w1, float),
            np.ascontiguousarray(y, float),
            rtol,
            max_steps,
            cert,
            atol,
        )
        if st != 0:
            return None
        return t, yy, bool(certified)

    def free_vector(self, y) -> np.ndarray:
        """``y`` (chain order) in the (θ, q) order of the free coordinates."""
        out = np.empty(self.n)
        out[self.order] = y
        return out


# --------------------------------------------------------------------------- compiled loops
def _factor0(starts, dpos, kp, cb, gens):
    """The bordered matrix of ``sym(W)`` (generators ``gens``) factorised at shift 0, and whether
    ``Zᵀ sym(W) Z`` is positive definite there (Sturm count 0, reliable)."""
    sd, su, sv, sp, sq = gens
    bst, bd, bu, bv, bp, bq, s, rho = _bordered(sd, su, sv, sp, sq, starts, dpos, kp, cb)
    c, pinv, fx, fy = _count(bst, bd, bu, bv, bp, bq, s, dpos, cb.shape[0], 0.0)
    return c == 0, bst, pinv, bu, fx, fy, bq, s, rho


def _orthogonalise(x, vb, m, n):
    """``x`` (n, 1) orthogonalised in place against the first ``m`` columns of the orthonormal
    ``vb``, twice (each column's component removed in turn)."""
    for _ in range(2):
        for j in range(m):
            c = 0.0
            for i in range(n):
                c += vb[i, j] * x[i, 0]
            for i in range(n):
                x[i, 0] -= c * vb[i, j]


def _lower_solve(lo, b, z, m):
    """``z ← L⁻¹ b`` (forward substitution; ``L = lo``, lower triangular, m × m; ``b``, ``z``
    vectors of at least m entries, views allowed)."""
    for i in range(m):
        t = b[i]
        for c in range(i):
            t -= lo[i, c] * z[c]
        z[i] = t / lo[i, i]


def _start_loops(starts, dpos, kp, kd, jz, cb, wrench, scale, max_steps, vtol):
    """:meth:`HeldEigen.smallest_definite`: ``(status, λ₁, y)`` (status 0: certified).

    Inverse iteration at shift 0 accelerated by Rayleigh–Ritz: the basis grows by ``A⁻¹`` applied
    to the last Ritz vector (orthogonalised twice; every vector lies in the null space), and ``y``
    is the Ritz vector of the smallest eigenvalue of the projected matrix (its quotient is at most
    the plain inverse iterate's: the space holds it). ``max_steps`` bounds the solves."""
    n = jz.shape[1]
    k = cb.shape[0]
    gens = _w_gens(jz, wrench, starts, kd, True)
    sd, su, sv, sp, sq = gens
    bst, bd, bu, bv, bp, bq, s, rho = _bordered(sd, su, sv, sp, sq, starts, dpos, kp, cb)
    c, pinv, fx, fy = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, 0.0)
    y = np.empty((n, 1))
    for i in range(n):
        y[i, 0] = math.sin(1.0 + 0.7 * i) + 0.3 * math.cos(2.3 * i)
    if c != 0:
        return 1, 0.0, y[:, 0].copy()
    zero = np.zeros((k, 1))
    atol = 1e-13 * scale
    mmax = max(max_steps, 1)
    vb = np.zeros((n, mmax))  # orthonormal basis (null space of cb)
    av = np.zeros((n, mmax))  # A vb
    eye = np.eye(mmax)
    nh = np.zeros((mmax, mmax))  # −Vᵀ A V (symmetrised): its largest eigenvalue is −λ₁ of the space
    ay = np.zeros(n)
    rq = np.inf
    m = 0
    for it in range(max_steps):
        x = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, y, zero)[0]
        nx0 = math.sqrt(np.sum(x * x))
        if not (math.isfinite(nx0) and nx0 > 0.0):
            return 2, 0.0, y[:, 0].copy()
        _orthogonalise(x, vb, m, n)
        nx = math.sqrt(np.sum(x * x))
        invariant = not nx > 1e-12 * nx0  # the space holds an eigenvector: its Ritz pair is exact
        if not invariant:
            x /= nx
            a = _matvec(starts, sd, su, sv, sp, sq, x)
            for i in range(n):
                vb[i, m] = x[i, 0]
                av[i, m] = a[i, 0]
            for j in range(m + 1):
                t = 0.0
                for i in range(n):
                    t += vb[i, j] * av[i, m] + vb[i, m] * av[i, j]
                nh[j, m] = -0.5 * t
                nh[m, j] = -0.5 * t
            m += 1
        st, _nu, u = _ritz(eye, nh, m)
        if st != 0:
            return 2, 0.0, y[:, 0].copy()
        x = np.zeros((n, 1))
        for i in range(n):
            xi, ai = 0.0, 0.0
            for j in range(m):
                xi += vb[i, j] * u[j]
                ai += av[i, j] * u[j]
            x[i, 0], ay[i] = xi, ai
        nrm = math.sqrt(np.sum(x * x))
        if not (math.isfinite(nrm) and nrm > 0.0):
            return 2, 0.0, y[:, 0].copy()
        dot = 0.0
        for i in range(n):
            dot += x[i, 0] * y[i, 0]
        sg = (1.0 if dot >= 0.0 else -1.0) / nrm  # unit, and the sign of the previous vector
        dv = 0.0
        num = 0.0
        for i in range(n):
            x[i, 0] *= sg
            dv = max(dv, abs(x[i, 0] - y[i, 0]))
            num += x[i, 0] * ay[i] * sg
        y = x
        prev = rq
        rq = num  # ≥ λ₁ (y in the null space)
        if (it > 0 and abs(rq - prev) <= 1e-13 * abs(rq) + 1e-3 * atol and dv <= vtol) or invariant:
            # certified: no eigenvalue below the quotient less its accuracy
            c2 = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, rq - 1e-9 * abs(rq) - 1e2 * atol)[0]
            if c2 == 0:
                return 0, rq, y[:, 0].copy()
            return 3, rq, y[:, 0].copy()
    return 4, rq, y[:, 0].copy()


def _ritz(ah, bh, m):
    """The largest ``ν`` of the projected pencil ``bh u = ν ah u`` (the leading ``m × m`` blocks;
    ``ah`` symmetric positive definite): ``(status, ν, u)`` by a Cholesky factor ``ah = LLᵀ`` and
    the symmetric eigenproblem of ``L⁻¹ bh L⁻ᵀ``; status 1 where ``ah`` is not positive definite."""
    lo = np.zeros((m, m))
    for j in range(m):
        d = ah[j, j]
        for c in range(j):
            d -= lo[j, c] * lo[j, c]
        if not (d > 0.0 and math.isfinite(d)):
            return 1, 0.0, np.zeros(m)
        d = math.sqrt(d)
        lo[j, j] = d
        for i in range(j + 1, m):
            t = ah[i, j]
            for c in range(j):
                t -= lo[i, c] * lo[j, c]
            lo[i, j] = t / d
    # c = L⁻¹ bh L⁻ᵀ: forward substitution on the columns of bh, then on the rows
    y = np.zeros((m, m))
    for col in range(m):
        _lower_solve(lo, bh[:, col], y[:, col], m)
    cm = np.zeros((m, m))
    for row in range(m):
        _lower_solve(lo, y[row], cm[row], m)
    for i in range(m):
        for j in range(i + 1, m):
            t = 0.5 * (cm[i, j] + cm[j, i])
            cm[i, j] = t
            cm[j, i] = t
    ev, vec = np.linalg.eigh(cm)
    # u = L⁻ᵀ z (back substitution)
    u = np.zeros(m)
    for i in range(m - 1, -1, -1):
        t = vec[i, m - 1]
        for c in range(i + 1, m):
            t -= lo[c, i] * u[c]
        u[i] = t / lo[i, i]
    return 0, ev[m - 1], u


def _pencil_loops(starts, dpos, kp, kd, jz, cb, w0, w1, y0, rtol, max_steps, cert, atol):
    """:meth:`HeldEigen.pencil`: ``(status, t, y, certified)`` (status 0: a quotient).

    The power iteration ``y ← A⁻¹B y`` accelerated by Rayleigh–Ritz on the Krylov space it spans:
    the basis grows by ``A⁻¹B`` applied to the last Ritz vector (orthogonalised twice against the
    basis; every vector lies in the null space), and the Ritz vector of the projected pencil's
    largest ``ν`` has the smallest quotient ``yᵀAy / yᵀBy`` over that space (at most the power
    iterate's: the space contains it). ``max_steps`` bounds the solves."""
    n = jz.shape[1]
    k = cb.shape[0]
    g0 = _w_gens(jz, w0, starts, kd, True)
    g1 = _w_gens(jz, w0 + w1, starts, kd, True)
    ok, bst, pinv, bu, fx, fy, bq, s, rho = _factor0(starts, dpos, kp, cb, g0)
    y = y0.copy().reshape(n, 1)
    if not ok:
        return 1, 0.0, y[:, 0].copy(), False
    mmax = max_steps + 1
    vb = np.zeros((n, mmax))  # orthonormal basis (null space of cb)
    av = np.zeros((n, mmax))  # A vb
    bv = np.zeros((n, mmax))  # B vb
    ah = np.zeros((mmax, mmax))
    bh = np.zeros((mmax, mmax))
    zero = np.zeros((k, 1))
    v = _project(cb, y[:, 0]).reshape(n, 1)  # (the start, in the null space up to rounding)
    nrm = math.sqrt(np.sum(v * v))
    if not (math.isfinite(nrm) and nrm > 0.0):
        return 3, 0.0, y[:, 0].copy(), False
    v /= nrm
    m = 0
    t = 0.0
    t_prev = np.nan
    ay = np.zeros(n)
    by = np.zeros(n)
    while m < mmax:
        a0 = _matvec(starts, g0[0], g0[1], g0[2], g0[3], g0[4], v)
        a1 = _matvec(starts, g1[0], g1[1], g1[2], g1[3], g1[4], v)
        for i in range(n):
            vb[i, m] = v[i, 0]
            av[i, m] = a0[i, 0]
            bv[i, m] = a0[i, 0] - a1[i, 0]  # H(w₁) v
        for j in range(m + 1):  # the new row and column of the projected pencil (symmetrised)
            sa = 0.0
            sb = 0.0
            for i in range(n):
                sa += vb[i, j] * av[i, m] + vb[i, m] * av[i, j]
                sb += vb[i, j] * bv[i, m] + vb[i, m] * bv[i, j]
            ah[j, m] = 0.5 * sa
            ah[m, j] = 0.5 * sa
            bh[j, m] = 0.5 * sb
            bh[m, j] = 0.5 * sb
        m += 1
        st, nu, u = _ritz(ah, bh, m)
        if st != 0:
            return 4, 0.0, y[:, 0].copy(), False
        if not nu > 0.0:
            return 2, 0.0, y[:, 0].copy(), False
        for i in range(n):
            yi, ai, bi = 0.0, 0.0, 0.0
            for j in range(m):
                yi += vb[i, j] * u[j]
                ai += av[i, j] * u[j]
                bi += bv[i, j] * u[j]
            y[i, 0], ay[i], by[i] = yi, ai, bi
        num = 0.0
        den = 0.0
        for i in range(n):
            num += y[i, 0] * ay[i]
            den += y[i, 0] * by[i]
        if not (num > 0.0 and den > 0.0):
            return 2, 0.0, y[:, 0].copy(), False
        t = num / den
        if abs(t - t_prev) <= rtol * t + atol or m == mmax:
            break
        t_prev = t
        x = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, by.reshape(n, 1), zero)[0]
        nx0 = math.sqrt(np.sum(x * x))
        if not (math.isfinite(nx0) and nx0 > 0.0):
            return 3, 0.0, y[:, 0].copy(), False
        _orthogonalise(x, vb, m, n)
        nx = math.sqrt(np.sum(x * x))
        if not nx > 1e-12 * nx0:  # the space is invariant: its Ritz value is the root's
            break
        v = x / nx
    nrm = math.sqrt(np.sum(y * y))
    y /= nrm
    certified = False
    if cert > 0.0:
        gc = _w_gens(jz, w0 + (1.0 - cert) * t * w1, starts, kd, True)
        certified = _factor0(starts, dpos, kp, cb, gc)[0]
    return 0, t, y[:, 0].copy(), certified


def _setup_loops(j6, cols, task, rows, has_rows, ratio):
    """:func:`held_eigen`'s problem data in one pass: ``(status, jz, cb)`` with ``jz`` the
    Jacobian columns ``cols`` (chain order, 6 rows), ``cb`` its task rows ``task`` (times
    ``rows`` when ``has_rows``, summed as the point kernel forms its held rows); status 0 when
    ``jz`` is finite, ``0 < k < n`` and the singular values of ``cb`` (those of ``R`` in its QR,
    the point kernel's rank test) have a ratio above ``ratio``."""
    n = cols.shape[0]
    jz, cb = _gather(j6, cols, task)
    if has_rows:
        cb = _held_rows(rows, cb)
    k = cb.shape[0]
    for c in range(n):
        for a_ in range(6):
            if not math.isfinite(jz[a_, c]):
                return 1, jz, cb
    if k == 0 or k >= n:
        return 2, jz, cb
    if not _qr_rank(cb, k, n, ratio)[0]:
        return 3, jz, cb
    return 0, jz, cb


# the chain kernel's, set by _loops()
_w_gens = _bordered = _count = _raw_solve = _matvec = _project = _gather = _held_rows = _qr_rank = None
_LOOPS: list = []
_LOCK = threading.Lock()


def _loops():
    """``(smallest_definite, pencil, setup)`` compiled (numba, cached on disk; in memory without
    a writable cache location) with the chain kernel's helpers; the caller has checked that the
    chain kernel is loaded (:func:`held_eigen`)."""
    if _LOOPS:
        return _LOOPS[0]
    with _LOCK:
        if not _LOOPS:
            import numba

            g = globals()
            for name in ("_w_gens", "_bordered", "_count", "_raw_solve", "_matvec", "_project", "_gather",
                         "_held_rows", "_qr_rank"):
                g[name] = getattr(_ck, name)
            fns = [
                getattr(g[n], "py_func", g[n])
                for n in ("_factor0", "_ritz", "_orthogonalise", "_lower_solve", "_start_loops", "_pencil_loops",
                          "_setup_loops")
            ]
            try:
                jit = [numba.njit(cache=True, nogil=True)(f) for f in fns]
            except RuntimeError:  # no writable cache location: compile in memory
                jit = [numba.njit(nogil=True)(f) for f in fns]
            g["_factor0"], g["_ritz"], g["_orthogonalise"], g["_lower_solve"] = jit[:4]
            _LOOPS.append((jit[4], jit[5], jit[6]))
    return _LOOPS[0]


def held_eigen(pk, mask, jacobian, rows=None, vtol: float = _ck.VEC_TOL_MARGIN) -> HeldEigen | None:
    """The held eigenproblem (module docstring) of the point kernel ``pk``'s model
    (:class:`~vjm_pin.analysis.point_kernel.PointKernel`: ``K_θ``, the free coordinates, the task
    rows) at the configuration whose (6, nv) frame Jacobian (world axes) is ``jacobian``, with the
    held rows ``rows`` ((k, m), of the m task rows; default all of them: eq. 23), or None where the
    chain algebra does not apply (module docstring). ``mask``: the support mask of the free
    columns (:meth:`~vjm_pin.kinematics.chain.Kinematics.support_mask`), or None."""
    if pk.n < _ck.POINT_MIN_N:
        return None
    if _ck._load() is None:
        return None
    lay = _ck._layout(pk.kz, pk.kz, pk.free, pk.nt, mask)
    if not lay.ok:
        return None
    j6 = np.ascontiguousarray(jacobian, float)
    task = pk.task if pk.task.dtype == np.int64 else pk.task.astype(np.int64)
    has_rows = rows is not None
    r = np.ascontiguousarray(rows, float) if has_rows else _NO_ROWS
    if j6.shape[0] != 6 or (has_rows and (r.ndim != 2 or r.shape[1] != task.shape[0])):
        raise ValueError("held_eigen: a (6, nv) Jacobian and (k, m) held rows of the m task rows")
    st, jz, cb = _loops()[2](j6, lay.cols, task, r, has_rows, RANK_RATIO)
    if st != 0:
        return None
    return HeldEigen(lay, jz, cb, vtol)


_NO_ROWS = np.zeros((0, 0))  # (held_eigen without rows: every task row held)


def remembered(key_obj, n: int):
    """The eigenvector (chain order, length ``n``) the chain kernel last found for ``key_obj`` (a
    :class:`~vjm_pin.analysis.point_kernel.PointKernel`: ``μ``'s; a solver's kernel constants:
    eq. 23's), or None."""
    has, vec = _ck._guess(key_obj, n)
    return vec if has else None


def remember(key_obj, vec) -> None:
    """Start the chain kernel's next eigenvalue problem for ``key_obj`` (see :func:`remembered`)
    from ``vec`` (chain order): a warm start only, every result is certified as before."""
    _ck._remember(key_obj, np.ascontiguousarray(vec, float))
