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
(linearised buckling at fixed geometry) by power iteration, bounded by a count. The last two run
as compiled loops of their own (numba, with the chain kernel's helpers). Vectors are in chain
order; :meth:`HeldEigen.free_vector` puts one in (θ, q) order.

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
        of ``λ₁`` dominates by ``λ₂/λ₁`` per step) until the Rayleigh quotient settles (to 1e-13
        relative; the unit vector to 1e-6 per step: a start for later problems), then a Sturm count
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
        null space) from ``y`` (in the null space): ``(t, y, certified)`` with ``t = yᵀAy / yᵀBy``
        once it changes by at most ``rtol·t + atol`` (its error falls as ``(ν₂/ν₁)²`` per step) or
        after ``max_steps``; None where ``yᵀBy ≤ 0``. ``t`` bounds the smallest positive ``ΔF``
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


def _start_loops(starts, dpos, kp, kd, jz, cb, wrench, scale, max_steps, vtol):
    """:meth:`HeldEigen.smallest_definite`: ``(status, λ₁, y)`` (status 0: certified)."""
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
    rq = np.inf
    for it in range(max_steps):
        x = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, y, zero)[0]
        nrm = math.sqrt(np.sum(x * x))
        if not (math.isfinite(nrm) and nrm > 0.0):
            return 2, 0.0, y[:, 0].copy()
        x /= nrm
        dv = 0.0
        for i in range(n):
            dv = max(dv, abs(x[i, 0] - y[i, 0]))
        y = x
        prev = rq
        rq = np.sum(y * _matvec(starts, sd, su, sv, sp, sq, y))  # ≥ λ₁ (y in the null space)
        if it > 0 and abs(rq - prev) <= 1e-13 * abs(rq) + 1e-3 * atol and dv <= vtol:
            # certified: no eigenvalue below the quotient less its accuracy
            c2 = _count(bst, bd, bu, bv, bp, bq, s, dpos, k, rq - 1e-9 * abs(rq) - 1e2 * atol)[0]
            if c2 == 0:
                return 0, rq, y[:, 0].copy()
            return 3, rq, y[:, 0].copy()
    return 4, rq, y[:, 0].copy()


def _pencil_loops(starts, dpos, kp, kd, jz, cb, w0, w1, y0, rtol, max_steps, cert, atol):
    """:meth:`HeldEigen.pencil`: ``(status, t, y, certified)`` (status 0: a quotient)."""
    n = jz.shape[1]
    k = cb.shape[0]
    g0 = _w_gens(jz, w0, starts, kd, True)
    g1 = _w_gens(jz, w0 + w1, starts, kd, True)
    ok, bst, pinv, bu, fx, fy, bq, s, rho = _factor0(starts, dpos, kp, cb, g0)
    y = y0.copy().reshape(n, 1)
    if not ok:
        return 1, 0.0, y[:, 0].copy(), False
    zero = np.zeros((k, 1))
    t = 0.0
    t_prev = np.nan
    for _ in range(max_steps):
        a0 = _matvec(starts, g0[0], g0[1], g0[2], g0[3], g0[4], y)
        by = a0 - _matvec(starts, g1[0], g1[1], g1[2], g1[3], g1[4], y)  # H(w₁) y
        num = np.sum(y * a0)
        den = np.sum(y * by)
        if not (num > 0.0 and den > 0.0):
            return 2, 0.0, y[:, 0].copy(), False
        t = num / den
        if abs(t - t_prev) <= rtol * t + atol:
            break
        t_prev = t
        y = _raw_solve(bst, pinv, bu, fx, fy, bq, s, rho, by, zero)[0]
        nrm = math.sqrt(np.sum(y * y))
        if not (math.isfinite(nrm) and nrm > 0.0):
            return 3, 0.0, y[:, 0].copy(), False
        y /= nrm
    certified = False
    if cert > 0.0:
        gc = _w_gens(jz, w0 + (1.0 - cert) * t * w1, starts, kd, True)
        certified = _factor0(starts, dpos, kp, cb, gc)[0]
    return 0, t, y[:, 0].copy(), certified


_w_gens = _bordered = _count = _raw_solve = _matvec = None  # the chain kernel's, set by _loops()
_LOOPS: list = []
_LOCK = threading.Lock()


def _loops():
    """``(smallest_definite, pencil)`` compiled (numba, cached on disk; in memory without a
    writable cache location) with the chain kernel's helpers; the caller has checked that the
    chain kernel is loaded (:func:`held_eigen`)."""
    with _LOCK:
        if not _LOOPS:
            import numba

            g = globals()
            for name in ("_w_gens", "_bordered", "_count", "_raw_solve", "_matvec"):
                g[name] = getattr(_ck, name)
            fns = [
                getattr(g[n], "py_func", g[n])
                for n in ("_factor0", "_start_loops", "_pencil_loops")
            ]
            try:
                jit = [numba.njit(cache=True, nogil=True)(f) for f in fns]
            except RuntimeError:  # no writable cache location: compile in memory
                jit = [numba.njit(nogil=True)(f) for f in fns]
            g["_factor0"] = jit[0]
            _LOOPS.append((jit[1], jit[2]))
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
    j6 = np.asarray(jacobian, float)
    jz = np.ascontiguousarray(j6[:, lay.cols])
    cb = jz[pk.task]
    if rows is not None:
        cb = np.asarray(rows, float) @ cb
    cb = np.ascontiguousarray(cb)
    if cb.shape[0] == 0 or cb.shape[0] >= cb.shape[1] or not np.isfinite(jz).all():
        return None
    sv = np.linalg.svd(cb, compute_uv=False)
    if not sv[-1] > RANK_RATIO * sv[0]:
        return None
    return HeldEigen(lay, jz, cb, vtol)


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
