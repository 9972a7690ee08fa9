"""The per-point algebra of a serial curve (:mod:`vjm_pin.analysis.curve`) in one pass.

At every equilibrium of a serial chain the tracer needs, along the unit direction ``d``
(task rows ``d_t``):

- the tangent of eq. (29), ``δx = K_x d_t`` and ``δF = K_C d_t``, and the tangent stiffness
  ``k = dᵀK_C d``: the first columns of the inverse of the matrix of eq. (28) applied to ``d_t``;
- the force-control margin ``μ``: the largest eigenvalue of ``Vᵀ sym(H − K) V``, ``V`` a basis
  of the null space of ``P J`` (``J = [J_θ J_q]`` on the task rows, ``P``: rows spanning the
  complement of ``d_t``);
- its rate ``dμ/ds`` along the tangent (the cubic model of μ between points, the extremum
  search of an imperfect bifurcation).

The generic path builds the (6, 6) ``K_C``, ``K_q``, ``K_θ`` of
:func:`~vjm_pin.solver.stiffness.stiffness_eq30`, an SVD null space in
:func:`~vjm_pin.solver.stability.check_stability_held`, and ``dμ/ds`` by a forward difference
(a second kinematics evaluation and stability check). Here:

- the inverse of eq. (28) is the same equilibrated inverse with the same regularity test
  (:func:`~vjm_pin.solver.stiffness._inverse_if_regular`), applied to ``d_t`` only;
- one complete QR ``Jᵀ = [Y Z] [R; 0]``: ``y₀ = Y R⁻ᵀ d_t`` is the minimum-norm motion with
  ``J y₀ = d_t``, and ``P J x = 0`` iff ``J x ∥ d_t``, so ``V = [Z, y₀/‖y₀‖]`` is an
  orthonormal basis of the null space (eq. 23's basis ``Z`` plus one column); the eigenvalues
  do not depend on the basis, so ``μ`` is that of :func:`check_stability_held` to rounding;
- ``dμ/ds`` analytically (:meth:`PointKernel.margin_rate`: first-order perturbation of the
  constrained eigenvalue with its eigenvector, the Jacobian's derivative in screw form).

Where the generic regularity test is not conclusive, or ``J`` is not of full rank with a
margin (:data:`FAST_RANK`), the kernel returns None and the caller takes the generic path
(singular stiffness, ``inf``/``nan``, rank-deficient Jacobians: as before).

Two implementations of the same contract: the numpy methods of :class:`PointKernel` (scipy's
LAPACK directly for small orders) and the compiled :func:`_point_loops` (numba
``njit(cache=True)``, explicit loops and numba's ``np.linalg``: one call instead of ~60 small
numpy calls per point; ``Vᵀ(H − K)V`` from the QR's reflectors applied to ``H − K``, and only
the largest eigenpair of it, :func:`_top_eigpair`, instead of a full ``eigh``). numba is imported lazily (:func:`use_compiled`, the solver's
``VJM_PIN_JIT`` switch): never at import, never with ``VJM_PIN_JIT=0``, and in ``auto`` mode
only once numba is loaded anyway (the solver's kernel switches after
:data:`vjm_pin.solver.kernel.JIT_AFTER_ITERATIONS` iterations: one rule for the whole package).
``tests/test_point_kernel.py`` compares both implementations with each other and with the
generic path, and the analytic ``dμ/ds`` with finite differences.

A curve's common step (:meth:`~vjm_pin.analysis.curve._Tracer._fused_step`) has the QR already: the
compiled Newton corrector factors ``Jᵀ`` at the converged configuration (Householder reflectors,
:func:`vjm_pin.solver.kernel._qr_t`). :func:`_reuse_point_loops` takes those reflectors instead of a
second QR (and no explicit ``Q``: the reflectors are applied where ``Q`` would multiply), decides the
rank test from ``‖R‖_F ‖R⁻¹‖_F`` where that bound clears it (the SVD of ``R`` otherwise), and packs
its constants into two arrays (one argument each). It also solves eq. (28) on that factorisation
(:func:`_ns_tangent`, the issue's "one factorisation per Newton step reused for the step, the
stability verdict and K_C"): the null-space method, ``Qᵀ (K − H) Q`` once (the corrector's
operations; the margin's matrix too), one LU of ``Zᵀ(K − H)Z``, then one step of iterative refinement
on the residual of eq. (28) itself, instead of the equilibrated ``(m + n)``-square inverse: about
5 µs less per point of the Model C curve, and as accurate (against eq. 28 solved in rational
arithmetic, over a curve through buckling, within a factor 2 of the inverse's error either way; a
point whose refinement does not confirm the solve goes to the generic path). The compiled
:func:`_point_loops` factors ``J`` with the same function (:func:`~vjm_pin.solver.kernel._qr_t`) and
keeps the equilibrated inverse (:func:`_eq28_tangent`); μ and ``dμ/ds`` (:func:`_margin_tail`) agree
to rounding.
"""

from __future__ import annotations

import functools
import sys

import numpy as np

from vjm_pin.kinematics.chain import FLUSH_BELOW
from vjm_pin.solver.chain_kernel import _rate_lin, _rate_terms, _twist_rate_row, _twists
from vjm_pin.solver.kernel import _back_substitute, _q_vector, _qr_t, _qwq_t, _reflect_rows
from vjm_pin.solver.lapack import lapack as _lapack
from vjm_pin.solver.stability import SCIPY_LAPACK_MAX_N
from vjm_pin.solver.stiffness import SINGULAR_RCOND, _inverse_if_regular, eq28_matrix

#: Smallest ratio of the singular values of ``R`` (those of ``J``) for the shortcut; the
#: generic rank test is at 1e-10 (:data:`~vjm_pin.solver.stability.RANK_TOL`).
FAST_RANK = 1e-7


class PointKernel:
    """The per-point algebra for one model and direction (module docstring).

    Args:
        k_theta: (nθ, nθ) spring stiffness.
        free: (n,) the free coordinates (nθ + nq), ordered (θ, q) as the blocks.
        d_task: (m,) the direction's task rows.
        task: (m,) the task components (rows of the 6-D wrench), default ``0..m−1``.
        kz: (n, n) ``K_θ ⊕ 0`` (``k_theta`` in the leading block, zeros elsewhere) when the
            caller already holds it (the solver's, shared and only read: saves a copy of order
            n² per curve); default built here.
    """

    def __init__(self, k_theta: np.ndarray, free: np.ndarray, d_task: np.ndarray, task=None, kz=None):
        nt = k_theta.shape[0]
        n = len(free)
        self.free = np.asarray(free, dtype=int)
        self.task = np.arange(d_task.size) if task is None else np.asarray(task, dtype=int)
        self.n, self.nt, self.m = int(n), nt, int(d_task.size)
        if kz is None:
            kz = np.zeros((n, n))
            kz[:nt, :nt] = k_theta
        elif kz.shape != (n, n) or kz.dtype != np.float64:
            raise ValueError(f"PointKernel: kz must be a float ({n}, {n}) array, got {kz.dtype} {kz.shape}")
        self.kz = kz
        self.dt = np.ascontiguousarray(d_task, dtype=float)
        self.big = n > SCIPY_LAPACK_MAX_N

    @functools.cached_property
    def _qfull(self):
        """(n, n) Fortran-ordered workspace of :meth:`factor` (LAPACK ``dorgqr``, n ≤ 48)."""
        return np.zeros((self.n, self.n), order="F")

    @functools.cached_property
    def _nomask(self):
        """(n, n) all-false support mask (the compiled kernels' argument without a mask)."""
        return np.zeros((self.n, self.n), dtype=bool)

    # ------------------------------------------------------------------ pieces
    def matrices(self, b):
        """(J (m, n), H (n, n)) in (θ, q) order from :class:`~vjm_pin.solver.blocks.Blocks`."""
        nt, n = self.nt, self.n
        jac = np.empty((self.m, n))
        jac[:, :nt] = b.J_theta
        jac[:, nt:] = b.J_q
        return jac, self.hessian(b)

    def hessian(self, b):
        """H (n, n) in (θ, q) order from :class:`~vjm_pin.solver.blocks.Blocks`."""
        nt, n = self.nt, self.n
        hz = np.empty((n, n))
        hz[:nt, :nt] = b.H_tt
        hz[:nt, nt:] = b.H_tq
        hz[nt:, :nt] = b.H_qt
        hz[nt:, nt:] = b.H_qq
        return hz

    def factor(self, jac: np.ndarray):
        """(Q = [Y Z] (n, n), R (m, m) upper triangular, y₀ = Y R⁻ᵀ d_t) of ``Jᵀ``, or None
        when ``J`` is not safely of full row rank (:data:`FAST_RANK`)."""
        m, n = self.m, self.n
        if m == 0 or m > n:
            return None
        if self.big:
            q, r = np.linalg.qr(jac.T, mode="complete")
            r = r[:m]
            sv = np.linalg.svd(r, compute_uv=False)
        else:
            qr, tau, _, info = _lapack.dgeqrf(jac.T)
            if info:
                return None
            qfull = self._qfull
            qfull[:, :m] = qr
            q, _, info = _lapack.dorgqr(qfull, tau)
            if info:
                return None
            r = np.triu(qr[:m])
            _, sv, _, info = _lapack.dgesdd(r, compute_uv=0)
            if info:
                return None
        if not sv.min() > FAST_RANK * sv.max():
            return None
        u, info = _lapack.dtrtrs(r, self.dt, trans=1)  # Rᵀ u = d_t
        if info:
            return None
        return q, r, q[:, :m] @ u

    def margin_from(self, q, y0, hz, vector: bool = False):
        """``μ``: the largest eigenvalue of ``Vᵀ sym(H − K) V``, ``V = [Z, y₀/‖y₀‖]``; with
        ``vector``, ``(μ, w)`` where ``w = V u`` (n,) is its unit eigenvector in the free
        coordinates."""
        m, n = self.m, self.n
        v = np.empty((n, n - m + 1))
        v[:, : n - m] = q[:, m:]
        v[:, -1] = y0 / np.sqrt(y0 @ y0)
        a = hz - self.kz
        red = v.T @ a @ v
        red = 0.5 * (red + red.T)
        if vector:
            ev, u = np.linalg.eigh(red)
            return float(ev[-1]), v @ u[:, -1]
        if self.big:
            return float(np.linalg.eigvalsh(red)[-1])
        ev, _, info = _lapack.dsyevd(red, compute_v=0)
        if info:
            return float(np.linalg.eigvalsh(red)[-1])
        return float(ev[-1])

    def margin_rate(self, jfree, mask, wrench, xd, wd_task, mu, w, q, r, hz) -> float:
        """``dμ/ds`` along the tangent ``(δx, δF)`` of eq. (29), analytically (first-order
        perturbation of the constrained eigenvalue, no second evaluation of the kinematics).

        ``μ = max wᵀ sym(A) w`` over unit ``w`` with ``C w = 0`` (``A = H − K``, ``C = P J``).
        With the eigenvector ``w`` and the multiplier ``g`` of the constraint
        (``sym(A) w − μ w = Jᵀ g``, ``g ⊥ d_t``: ``g = R⁻¹ Yᵀ(sym(A) w − μ w)``)::

            dμ/ds = wᵀ H' w − 2 gᵀ J' w,

        ``H' = dH/ds`` and ``J' = dJ/ds`` along the tangent. ``J'`` in screw form (the
        derivatives of the twists of :mod:`~vjm_pin.kinematics.screw`, summed along ``δx``:
        ``δω_i = Ω_i × ω_i``, ``δv_i = Ω_i × v_i + ω_i × Σ_{j>i} δx_j v_j`` with
        ``Ω_i = Σ_{j≤i} δx_j ω_j``); ``H`` is bilinear in the Jacobian columns and linear in
        the wrench, so ``H' = [H(J + tJ', F) − H(J − tJ', F)]/2t + H(J, δF)`` exactly (any
        ``t``). ``tests/test_point_kernel.py`` checks it against finite differences.

        Args:
            jfree: (6, n) frame Jacobian, free columns in (θ, q) order.
            mask: (n, n) :func:`~vjm_pin.kinematics.screw.support_mask` of those columns.
            wrench: (6,) end wrench; xd: (n,) δx; wd_task: (m,) δF (task rows).
            mu, w: ``μ`` and its eigenvector (:meth:`margin_from` with ``vector``).
            q, r: the QR of ``Jᵀ`` (:meth:`factor`); hz: (n, n) Hessian of Ψ.
        """
        from vjm_pin.kinematics.screw import psi_hessian_screw

        m = self.m
        a = hz - self.kz
        res = 0.5 * (a @ w + a.T @ w) - mu * w
        g, info = _lapack.dtrtrs(r, q[:, :m].T @ res)
        if info:
            return float("nan")
        lin, om = jfree[:3], jfree[3:]
        xm = mask * xd  # xm[i, j] = δx_j where j supports i (j ≤ i)
        big_om = xm @ om.T  # (n, 3): Ω_i
        vd = (xd * lin) @ (~mask).T  # (3, n): Σ_{j>i} δx_j v_j
        jd = np.empty_like(jfree)
        jd[3:] = np.cross(big_om, om.T).T
        jd[:3] = np.cross(big_om, lin.T).T + np.cross(om.T, vd.T).T
        scale = np.abs(jd).max()
        t = np.abs(jfree).max() / scale if scale > 0 else 1.0
        wd = np.zeros(6)
        wd[self.task] = wd_task
        hd = (psi_hessian_screw(jfree + t * jd, wrench, mask) - psi_hessian_screw(jfree - t * jd, wrench, mask)) / (
            2.0 * t
        ) + psi_hessian_screw(jfree, wd, mask)
        return float(w @ hd @ w - 2.0 * g @ (jd[self.task] @ w))

    def tangent(self, b):
        """``(δx (n,) in (θ, q) order, δF (m,))``: the solution of eq. (28) for the right-hand
        side ``d_t`` (module docstring), or None when the generic path must decide.

        The inverse of the equilibrated matrix of eq. (28) and its regularity test are those of
        :func:`~vjm_pin.solver.stiffness.stiffness_eq30` (:func:`~vjm_pin.solver.stiffness._inverse_if_regular`):
        where that test is not conclusive the generic path decides (and may find the matrix
        singular); only the (6, 6) embedding, the result object and the SVD fallback are saved."""
        a = eq28_matrix(b)
        m, nq = self.m, b.J_q.shape[1]
        inv, regular = _inverse_if_regular(a)
        if not regular:
            return None
        x = inv[:, :m] @ self.dt
        if not np.isfinite(x).all():
            return None
        xd = np.empty(self.n)
        xd[: self.nt] = x[m + nq :]
        xd[self.nt :] = x[m : m + nq]
        return xd, x[:m]

    # ------------------------------------------------------------------ public
    def point(self, b, mask=None, wrench=None, fn=None):
        """At the equilibrium whose blocks are ``b``: ``(k, δx (n,), δF (m,), μ, dμ/ds)``
        (module docstring; ``δx`` in (θ, q) order, ``k = d_tᵀ δF``; ``dμ/ds`` by
        :meth:`margin_rate` when the support ``mask`` of the free columns and the 6-D
        ``wrench`` are given — the Hessian in screw form — else None), or None where the
        generic path must decide (near-singular ``J`` or matrix of eq. 28). ``fn``: the
        compiled twin (:func:`compiled`) to use instead of numpy."""
        if fn is not None:
            # a long chain: O(n) algebra (chain_kernel), the dense kernel where it is unsure
            from vjm_pin.solver import chain_kernel

            if self.n >= chain_kernel.POINT_MIN_N and mask is not None and wrench is not None:
                got = chain_kernel.point(self, b, mask, wrench, FAST_RANK)
                if got is not None:
                    return got
            hz = self.hessian(b)
            jfree = np.ascontiguousarray(b.state.jacobian.take(self.free, axis=1))
            rate_wanted = mask is not None
            try:
                st, k, xd, fd, mu, rate = fn(
                    jfree, hz, self.kz, self.task, self.dt, mask if rate_wanted else self._nomask,
                    np.asarray(wrench if rate_wanted else np.zeros(6), dtype=float), self.nt, rate_wanted,
                    FAST_RANK, SINGULAR_RCOND,
                )
            except np.linalg.LinAlgError:  # an exactly singular matrix (numba's np.linalg raises)
                return None
            if st:
                return None
            return k, xd, fd, mu, (rate if rate_wanted else None)
        t = self.tangent(b)
        if t is None:
            return None
        jac, hz = self.matrices(b)
        f = self.factor(jac)
        if f is None:
            return None
        q, r, y0 = f
        xd, fd = t
        if mask is None:
            return float(self.dt @ fd), xd, fd, self.margin_from(q, y0, hz), None
        mu, w = self.margin_from(q, y0, hz, vector=True)
        jfree = b.state.jacobian.take(self.free, axis=1)
        rate = self.margin_rate(jfree, mask, wrench, xd, fd, mu, w, q, r, hz)
        return float(self.dt @ fd), xd, fd, mu, rate

    def margin(self, b) -> float | None:
        """``μ`` alone at the blocks ``b`` (None: take the generic path)."""
        jac, hz = self.matrices(b)
        f = self.factor(jac)
        if f is None:
            return None
        q, _, y0 = f
        return self.margin_from(q, y0, hz)


# --------------------------------------------------------------------------- compiled twin
def _sturm_count(d, e, s, pivmin):
    """The number of eigenvalues below ``s`` of the symmetric tridiagonal matrix with diagonal ``d``
    and off-diagonal ``e`` (``e[i]`` couples ``i`` and ``i + 1``): the negative pivots of ``T − sI``,
    pivots below ``pivmin`` in size taken as ``−pivmin`` (``dstebz``'s rule; the recurrence the
    quadrisection of :func:`_top_eigpair` runs three at a time, side by side)."""
    n = d.shape[0]
    c = 0
    q = d[0] - s
    for i in range(n):
        if i > 0:
            q = d[i] - s - e[i - 1] * e[i - 1] / q
        if abs(q) < pivmin:
            q = -pivmin
        if q < 0:
            c += 1
    return c


def _top_eigpair(a, hlo=np.nan, hhi=np.nan):
    """The largest eigenvalue of the symmetric (n, n) ``a`` (lower triangle read; ``a`` is
    overwritten) and a unit eigenvector, for :func:`_point_loops` (compiled with it): Householder
    tridiagonalisation ``a = Q T Qᵀ`` (``4n³/3``; on both triangles, by rows), bisection (by quarters) on the Sturm count
    of ``T`` from the Gershgorin bracket until the largest eigenvalue is alone in it, then Laguerre's
    method on ``det(T − σI)`` from above (monotone; to LAPACK's tolerance ``max(2ε|λ|, ε‖T‖)``; a
    multiple top eigenvalue is never alone: bisection to that tolerance), inverse
    iteration on ``T`` (partial pivoting, three solves from a fixed start) and ``Q`` applied to
    the vector — instead of every eigenpair
    (``np.linalg.eigh``): the value to a few units of ``ε‖a‖`` as LAPACK's, the vector to
    ``ε‖a‖/gap`` (in a multiple top eigenvalue some unit vector of its eigenspace). ``(hlo, hhi)``: a
    predicted bracket of the largest eigenvalue (NaN: none), each end used where the Sturm count
    confirms it (one pass for both), so a wrong prediction costs that pass and nothing else."""
    n = a.shape[0]
    d = np.zeros(n)
    e = np.zeros(n)
    vs = np.zeros((n, n))  # Householder vectors: row k acts on entries k+1..n-1
    taus = np.zeros(n)
    p = np.zeros(n)
    # the lower triangle mirrored, then both triangles kept (a stays exactly symmetric: the two
    # products of an entry and of its mirror are added in either order), so every access is along a
    # row: ``p = τ A22 v`` as a sum of rows ``v_j a[j]`` (each p_i accumulated in the same order
    # j = k+1.. as the dot product of the lower-triangle formulation: the same numbers)
    for i in range(n):
        for j in range(i):
            a[j, i] = a[i, j]
    for k in range(n - 2):
        nrm = 0.0
        for i in range(k + 1, n):
            nrm += a[k, i] * a[k, i]
        nrm = np.sqrt(nrm)
        d[k] = a[k, k]
        if nrm == 0.0:
            e[k] = 0.0
            continue
        alpha = -nrm if a[k, k + 1] >= 0 else nrm
        vv = 0.0
        for i in range(k + 1, n):
            vi = a[k, i] - alpha if i == k + 1 else a[k, i]
            vs[k, i] = vi
            vv += vi * vi
        e[k] = alpha
        if vv == 0.0:
            continue
        tau = 2.0 / vv
        taus[k] = tau
        # p = τ A22 v, K = τ/2 pᵀv, w = p − K v, A22 −= v wᵀ + w vᵀ (on views from k+1: loops
        # from 0 compile to vector instructions, indices from k+1 do not)
        vk = vs[k, k + 1:]
        pk = p[k + 1:]
        nk = n - k - 1
        for i in range(nk):
            pk[i] = 0.0
        for j in range(nk):
            vj = vk[j]
            aj = a[k + 1 + j, k + 1:]
            for i in range(nk):
                pk[i] += aj[i] * vj
        for i in range(nk):
            pk[i] *= tau
        pv = 0.0
        for i in range(nk):
            pv += pk[i] * vk[i]
        kk = 0.5 * tau * pv
        for i in range(nk):
            pk[i] -= kk * vk[i]
        for i in range(nk):
            vi = vk[i]
            pi = pk[i]
            ai = a[k + 1 + i, k + 1:]
            for j in range(nk):
                ai[j] -= vi * pk[j] + pi * vk[j]
    if n >= 2:
        d[n - 2] = a[n - 2, n - 2]
        e[n - 2] = a[n - 1, n - 2]
    d[n - 1] = a[n - 1, n - 1]
    # Gershgorin bracket of the largest eigenvalue of T, bisection on the Sturm count
    tnorm = 0.0
    lo = np.inf
    hi = -np.inf
    for i in range(n):
        r = (abs(e[i - 1]) if i > 0 else 0.0) + (abs(e[i]) if i < n - 1 else 0.0)
        lo = min(lo, d[i] - r)
        hi = max(hi, d[i] + r)
        tnorm = max(tnorm, abs(d[i]) + r)
    eps = 2.220446049250313e-16
    pivmin = max(tnorm * eps * eps, 1e-300)
    if tnorm == 0.0:
        lam = 0.0
    else:
        lo -= 2.0 * eps * tnorm
        hi += 2.0 * eps * tnorm
        atol = max(eps * tnorm, pivmin)  # LAPACK's (dstebz) default absolute tolerance
        clo = 0  # eigenvalues below lo (the Gershgorin bound: none)
        if lo < hlo < hhi < hi:
            # a predicted bracket (the caller's: the previous point's μ moved along its rate), kept
            # only as far as the Sturm counts confirm it: hhi an upper bound when every eigenvalue is
            # below it, hlo a lower one when some eigenvalue is above it
            if _sturm_count(d, e, hhi, pivmin) == n:
                hi = hhi
            c1 = _sturm_count(d, e, hlo, pivmin)
            if c1 < n:
                lo = hlo
                clo = c1
        newton = False
        for _ in range(200):
            if hi - lo <= max(2.0 * eps * max(abs(lo), abs(hi)), atol):
                break
            if clo == n - 1:  # the top eigenvalue alone in (lo, hi]: Laguerre's method from above
                newton = True
                break
            # quadrisection: three independent Sturm counts (their division chains overlap)
            w4 = 0.25 * (hi - lo)
            s1 = lo + w4
            s2 = lo + 2.0 * w4
            s3 = hi - w4
            if not (lo < s1 < s2 < s3 < hi):
                break
            c1 = 0
            c2 = 0
            c3 = 0
            q1 = d[0] - s1
            q2 = d[0] - s2
            q3 = d[0] - s3
            for i in range(n):
                if i > 0:
                    e2 = e[i - 1] * e[i - 1]
                    q1 = d[i] - s1 - e2 / q1
                    q2 = d[i] - s2 - e2 / q2
                    q3 = d[i] - s3 - e2 / q3
                if abs(q1) < pivmin:
                    q1 = -pivmin
                if abs(q2) < pivmin:
                    q2 = -pivmin
                if abs(q3) < pivmin:
                    q3 = -pivmin
                if q1 < 0:
                    c1 += 1
                if q2 < 0:
                    c2 += 1
                if q3 < 0:
                    c3 += 1
            if c1 == n:  # every eigenvalue below s1
                hi = s1
            elif c2 == n:
                lo, hi = s1, s2
                clo = c1
            elif c3 == n:
                lo, hi = s2, s3
                clo = c2
            else:
                lo = s3
                clo = c3
        lam = 0.5 * (lo + hi)
        if newton:
            # Laguerre's method on det(T − σI) = Π(λ_j − σ) from σ = hi, which has no root above λ_max:
            # it decreases monotonically to λ_max (cubically once close, fast from far: exact for one
            # root apart from a multiple one): σ − N/(G + √((N−1)(N·H − G²))), G = Σ_j 1/(σ − λ_j),
            # H = Σ_j 1/(σ − λ_j)², both by the pivots' recurrence (q_i = d_i − σ − e²/q_{i−1}:
            # G = Σ q_i'/q_i, H = Σ (q_i'/q_i)² − q_i''/q_i). The same pass counts the negative pivots
            # (the Sturm count): an iterate below λ_max (an overshoot in rounding) becomes the lower end
            # of the bracket and the iteration bisects (lo, up), ``up`` the last iterate above λ_max
            sig = hi
            up = hi
            prev = np.inf
            nn = float(n)
            for _ in range(80):
                q = d[0] - sig
                if abs(q) < pivmin:
                    q = -pivmin
                cnt = 1 if q < 0 else 0
                dq = -1.0
                d2q = 0.0
                g = dq / q
                h2 = g * g
                for i in range(1, n):
                    e2 = e[i - 1] * e[i - 1]
                    r = 1.0 / q
                    rr = r * r
                    d2q = e2 * (d2q * rr - 2.0 * dq * dq * rr * r)
                    dq = -1.0 + e2 * dq * rr
                    q = d[i] - sig - e2 * r
                    if abs(q) < pivmin:
                        q = -pivmin
                    if q < 0:
                        cnt += 1
                    t = dq / q
                    g += t
                    h2 += t * t - d2q / q
                if cnt < n:  # λ_max above σ: bisect the bracket
                    lo = sig
                    prev = np.inf
                    sig = 0.5 * (lo + up)
                    lam = sig
                    if not (lo < sig < up) or up - lo <= max(2.0 * eps * max(abs(lo), abs(up)), atol):
                        break
                    continue
                up = sig
                disc = (nn - 1.0) * (nn * h2 - g * g)
                den = g + np.sqrt(disc if disc > 0.0 else 0.0)
                step = nn / den if den > 0.0 else np.inf
                tol = max(2.0 * eps * abs(sig), atol)
                lam = sig
                if step <= tol or (step <= 1e3 * tol and step > 0.5 * prev):
                    # converged, or no longer converging fast (the step is the recurrence's rounding)
                    if lo < sig - step:
                        lam = sig - step
                    break
                prev = step
                new = sig - step
                if not (lo < new < sig):
                    new = 0.5 * (lo + sig)
                    prev = np.inf
                    if not (lo < new < sig):
                        break
                sig = new
    # inverse iteration on T − λI (tridiagonal LU with partial pivoting, pivots floored)
    floor = max(eps * tnorm, 1e-300)
    y = np.empty(n)
    for i in range(n):
        y[i] = 1.0 + ((i * 7919) % 101) / 101.0
    dl = np.empty(n)
    dd = np.empty(n)
    du = np.empty(n)
    du2 = np.zeros(n)
    piv = np.zeros(n, np.bool_)
    for i in range(n):
        dd[i] = d[i] - lam
        if i < n - 1:
            dl[i] = e[i]
            du[i] = e[i]
    for i in range(n - 1):  # LAPACK dgttrf
        if abs(dd[i]) >= abs(dl[i]):
            if abs(dd[i]) < floor:
                dd[i] = floor
            f = dl[i] / dd[i]
            dl[i] = f
            dd[i + 1] -= f * du[i]
            if i < n - 2:
                du2[i] = 0.0
        else:
            f = dd[i] / dl[i]
            dd[i] = dl[i]
            dl[i] = f
            t = du[i]
            du[i] = dd[i + 1]
            dd[i + 1] = t - f * dd[i + 1]
            if i < n - 2:
                du2[i] = du[i + 1]
                du[i + 1] = -f * du[i + 1]
            piv[i] = True
    if abs(dd[n - 1]) < floor:
        dd[n - 1] = floor
    for _ in range(3):
        for i in range(n - 1):  # forward: L
            if piv[i]:
                t = y[i]
                y[i] = y[i + 1]
                y[i + 1] = t - dl[i] * y[i + 1]
            else:
                y[i + 1] -= dl[i] * y[i]
        y[n - 1] /= dd[n - 1]  # backward: U
        if n >= 2:
            y[n - 2] = (y[n - 2] - du[n - 2] * y[n - 1]) / dd[n - 2]
        for i in range(n - 3, -1, -1):
            y[i] = (y[i] - du[i] * y[i + 1] - du2[i] * y[i + 2]) / dd[i]
        big = 0.0
        for i in range(n):
            big = max(big, abs(y[i]))
        nrm = 0.0
        for i in range(n):
            y[i] /= big
            nrm += y[i] * y[i]
        nrm = np.sqrt(nrm)
        for i in range(n):
            y[i] /= nrm
    # x = H_0 H_1 ⋯ H_{n−3} y
    for k in range(n - 3, -1, -1):
        if taus[k] == 0.0:
            continue
        s = 0.0
        for i in range(k + 1, n):
            s += vs[k, i] * y[i]
        s *= taus[k]
        for i in range(k + 1, n):
            y[i] -= s * vs[k, i]
    return lam, y


def _reduced(bt, uh, m, n):
    """``Vᵀ sym(A) V`` (``n − m + 1`` square) from ``bt = (Qᵀ sym(A) Q)ᵀ`` (:func:`_q_both_sides`) and
    ``û`` (m,), ``V = Q [[0, û], [I, 0]]`` (the margin's matrix of :func:`_point_loops` and
    :func:`_reuse_point_loops`; every entry of ``Qᵀ sym(A) Q`` read from its mirror in ``bt``)."""
    dim = n - m + 1
    red = np.empty((dim, dim))
    for i in range(n - m):
        for j in range(i + 1):
            t = 0.5 * (bt[m + j, m + i] + bt[m + i, m + j])
            red[i, j] = t
            red[j, i] = t
        s = 0.0
        for a3 in range(m):
            s += uh[a3] * 0.5 * (bt[m + i, a3] + bt[a3, m + i])
        red[dim - 1, i] = s
        red[i, dim - 1] = s
    s = 0.0
    for a3 in range(m):
        for b3 in range(m):
            s += uh[a3] * bt[b3, a3] * uh[b3]
    red[dim - 1, dim - 1] = s
    return red


def _abs_sums(s, cs):
    """``(‖s‖₁, ‖s‖∞)``: the largest column and row sums of ``|s|`` in one row-major pass (the
    column sums accumulated in ``cs``), every sum in index order (the numbers of the column-by-column
    loops they replace)."""
    e = s.shape[0]
    for j in range(e):
        cs[j] = 0.0
    rmax = 0.0
    for i in range(e):
        r = 0.0
        for j in range(e):
            t = abs(s[i, j])
            r += t
            cs[j] += t
        rmax = max(rmax, r)
    cmax = 0.0
    for j in range(e):
        cmax = max(cmax, cs[j])
    return cmax, rmax


def _eq28_tangent(jac, hz, kz, dt, nt, sing_rcond, xd, fd):
    """The tangent of eq. (29) along ``d_t`` for the point kernels (:func:`_point_loops`,
    :func:`_reuse_point_loops`): eq. (28) in the order (F, q, θ), equilibrated as
    ``stiffness._ruiz`` (the same numbers), inverted by LAPACK (numba's ``np.linalg.inv``: the
    numbers of the generic path, which the tests compare at 1e-9 where ``k`` is a small difference of
    large terms), with the regularity test of :func:`~vjm_pin.solver.stiffness._inverse_if_regular`
    (``√(‖S‖₁‖S‖∞)·√(‖S⁻¹‖₁‖S⁻¹‖∞)·SINGULAR_RCOND·10 ≤ 1``, the norms by :func:`_abs_sums`); ``δx``
    (θ, q order) into ``xd``, ``δF`` into ``fd``. Returns ``(ok, k = d_tᵀ δF)``; not ok (``xd``,
    ``fd`` untouched) when the test fails or the matrix is exactly singular or not finite (declined,
    not raised)."""
    m, n = jac.shape
    nq = n - nt
    e = m + n
    perm = np.empty(n, np.int64)
    for c in range(n):
        perm[c] = m + nq + c if c < nt else m + (c - nt)
    a = np.zeros((e, e))
    for r in range(m):
        for c in range(n):
            a[r, perm[c]] = jac[r, c]
            a[perm[c], r] = jac[r, c]
    for i in range(n):
        for j in range(n):
            a[perm[i], perm[j]] = hz[i, j] - kz[i, j]
    mm = np.empty((e, e))
    for i in range(e):
        for j in range(e):
            mm[i, j] = max(abs(a[i, j]), abs(a[j, i]))
    d = np.ones(e)
    rr = np.empty(e)
    for sweep in range(4):
        for i in range(e):
            v = 0.0
            for j in range(e):
                v = max(v, mm[i, j])
            rr[i] = 1.0 / np.sqrt(v if v != 0.0 else 1.0)
        if sweep < 3:  # (the last sweep's scaled matrix is not read)
            for i in range(e):
                ri = rr[i]
                for j in range(e):
                    mm[i, j] *= ri * rr[j]
        for i in range(e):
            d[i] *= rr[i]
    sm = np.empty((e, e))
    for i in range(e):
        for j in range(e):
            sm[i, j] = a[i, j] * (d[i] * d[j])
    cs = rr  # (scratch)
    c1s, r1s = _abs_sums(sm, cs)
    try:
        inv = np.linalg.inv(sm)
    except Exception:  # exactly singular or not finite (numba's LinAlgError): declined, not raised
        return False, np.nan
    for i in range(e):  # (np.all(np.isfinite(inv)) without its temporary)
        for j in range(e):
            if not np.isfinite(inv[i, j]):
                return False, np.nan
    c1i, r1i = _abs_sums(inv, cs)
    if not np.sqrt(c1s * r1s) * np.sqrt(c1i * r1i) * sing_rcond * 10.0 <= 1.0:
        return False, np.nan
    xv = np.empty(e)
    for i in range(e):
        acc = 0.0
        for c in range(m):
            acc += (inv[i, c] * d[i] * d[c]) * dt[c]
        xv[i] = acc
    k = 0.0
    for r in range(m):
        fd[r] = xv[r]
        k += dt[r] * xv[r]
    for c in range(n):
        xd[c] = xv[perm[c]]
    return True, k


#: Largest relative size of the iterative-refinement correction :func:`_ns_tangent` accepts: the first
#: solve's forward error, ~``cond(S)·ε``; above it (``cond`` of eq. 28 beyond ~1e10) the kernel declines and
#: the generic path decides with its exact regularity test.
REFINE_TOL = 1e-6


def _lu_factor(a, piv):
    """LU with partial pivoting of the square ``a`` in place (``dgetrf``'s semantics: row ``k``
    swapped with ``piv[k]``); False on an exactly zero or non-finite pivot."""
    n = a.shape[0]
    for k in range(n):
        p = k
        best = abs(a[k, k])
        for i in range(k + 1, n):
            v = abs(a[i, k])
            if v > best:
                best = v
                p = i
        piv[k] = p
        if not (best > 0.0 and best < np.inf):
            return False
        if p != k:
            for j in range(n):
                t = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = t
        rk = a[k, k + 1:]
        for i in range(k + 1, n):
            f = a[i, k] / a[k, k]
            a[i, k] = f
            ri = a[i, k + 1:]
            for j in range(n - k - 1):
                ri[j] -= f * rk[j]
    return True


def _ns_solve(hh, rmat, wt, lu, piv, ry, rx, xd, fd):
    """Solve eq. (28) ``J δx = r_y``, ``Jᵀ δF + (H − K) δx = r_x`` on the null-space factorisation of
    :func:`_ns_tangent` (``Jᵀ = Q [R; 0]`` by the reflectors ``hh``, ``wt = (Qᵀ W Q)ᵀ`` with
    ``W = K − H``, ``lu``/``piv``: LU of ``ZᵀWZ``): ``δx = Q [p; u]`` with ``Rᵀ p = r_y``,
    ``(ZᵀWZ) u = −(Qᵀ r_x)_Z − (ZᵀWY) p``, and ``R δF = (Qᵀ r_x)_Y + (YᵀWY) p + (YᵀWZ) u``;
    ``δx`` into ``xd`` (n,), ``δF`` into ``fd`` (m,)."""
    m = rmat.shape[0]
    n = xd.shape[0]
    nz = n - m
    qx = rx.copy()
    _q_vector(hh, qx, m, n, True)
    p = np.empty(m)
    for i in range(m):
        s = ry[i]
        for j in range(i):
            s -= rmat[j, i] * p[j]
        p[i] = s / rmat[i, i]
    u = np.empty(nz)
    for j in range(nz):
        s = qx[m + j]
        for i in range(m):
            s += wt[i, m + j] * p[i]
        u[j] = -s
    for k in range(nz):  # the row swaps, then L y = b, U u = y
        q = piv[k]
        if q != k:
            t = u[k]
            u[k] = u[q]
            u[q] = t
    for i in range(nz):
        s = u[i]
        for j in range(i):
            s -= lu[i, j] * u[j]
        u[i] = s
    u = _back_substitute(lu, u, nz)  # U u = y
    sv = np.empty(m)
    for i in range(m):
        s = qx[i]
        for j in range(m):
            s += wt[j, i] * p[j]
        for j in range(nz):
            s += wt[m + j, i] * u[j]
        sv[i] = s
    fd[:] = _back_substitute(rmat, sv, m)  # R δF = sv
    for i in range(m):
        xd[i] = p[i]
    for j in range(nz):
        xd[m + j] = u[j]
    _q_vector(hh, xd, m, n, False)


def _ns_tangent(jac, hh, hz, kz, dt, xd, fd, wt):
    """The tangent of eq. (29) along ``d_t`` on the converged Newton iteration's own QR of ``Jᵀ``
    (the reflectors ``hh``, :func:`vjm_pin.solver.kernel._qr_t`) by the null-space method: ``wt =
    (Qᵀ W Q)ᵀ``, ``W = K − H`` (written into ``wt``, (n, n): the corrector's own operations, and the
    margin's matrix, :func:`_margin_tail`), one LU of ``ZᵀWZ`` (``(n − m)³/3`` instead of the
    ``(m + n)³`` of an inverse of eq. 28), :func:`_ns_solve`, then one step of iterative refinement on the
    residual of eq. (28) itself (``J``, ``H``, ``K`` as given). ``δx`` into ``xd``, ``δF`` into ``fd``.
    Returns ``(ok, k = d_tᵀ δF)``; not ok when a pivot is zero or not finite, a number is not
    finite, or the refinement's correction exceeds :data:`REFINE_TOL` of the solution (eq. 28 is
    near-singular: the generic path decides).

    Against eq. (28) solved in 40 digits at the 73 points of a Model C curve through buckling, the
    error of ``k`` is at most 2.7e-10 (median 4e-14) against 5.5e-10 (median 1e-13) for the
    equilibrated LAPACK inverse of :func:`_eq28_tangent`; ``tests/test_point_kernel_speed_paths.py``
    checks it against a reference refined in extended precision."""
    m, n = jac.shape
    _qwq_t(hh, hz, kz, m, n, wt)  # (Qᵀ W Q)ᵀ: kernel._iterate_body's operations
    return _ns_tangent_on(jac, hh, hz, kz, dt, xd, fd, wt)


def _ns_tangent_on(jac, hh, hz, kz, dt, xd, fd, wt):
    """:func:`_ns_tangent` on ``wt`` = ``(Qᵀ W Q)ᵀ`` given (read only): the converged corrector's own
    (:func:`vjm_pin.solver.kernel._qwq_t` on the same reflectors, ``H`` and ``K``: the same bits)."""
    m, n = jac.shape
    nz = n - m
    rmat = _householder_r(hh, m)
    for i in range(m):
        if not (rmat[i, i] != 0.0 and abs(rmat[i, i]) < np.inf):
            return False, np.nan
    lu = np.empty((nz, nz))
    for i in range(nz):
        for j in range(nz):
            lu[i, j] = wt[m + j, m + i]
    piv = np.empty(nz, np.int64)
    if not _lu_factor(lu, piv):
        return False, np.nan
    rx = np.zeros(n)
    _ns_solve(hh, rmat, wt, lu, piv, dt, rx, xd, fd)
    # one refinement step: the residual of eq. (28) with J, H − K as given
    ry = np.empty(m)
    for r in range(m):
        s = dt[r]
        for c in range(n):
            s -= jac[r, c] * xd[c]
        ry[r] = s
    for i in range(n):
        s = 0.0
        for r in range(m):
            s -= jac[r, i] * fd[r]
        rx[i] = s
    for i in range(n):
        s = rx[i]
        hi = hz[i]
        ki = kz[i]
        for j in range(n):
            s -= (hi[j] - ki[j]) * xd[j]
        rx[i] = s
    cx = np.empty(n)
    cf = np.empty(m)
    _ns_solve(hh, rmat, wt, lu, piv, ry, rx, cx, cf)
    sx = 0.0
    ex = 0.0
    for i in range(n):
        xd[i] += cx[i]
        sx = max(sx, abs(xd[i]))
        ex = max(ex, abs(cx[i]))
    sf = 0.0
    ef = 0.0
    k = 0.0
    for i in range(m):
        fd[i] += cf[i]
        sf = max(sf, abs(fd[i]))
        ef = max(ef, abs(cf[i]))
        k += dt[i] * fd[i]
    if not (ex <= REFINE_TOL * sx and ef <= REFINE_TOL * sf and abs(k) < np.inf):
        return False, np.nan
    return True, k


def _point_loops(jfree, hz, kz, task, dt, mask, wrench, nt, use_rate, fast_rank, sing_rcond):
    """The whole of :meth:`PointKernel.point` in one compiled call (numba, explicit loops and
    numba's ``np.linalg``): the equilibrated inverse of eq. (28) with the regularity test of
    :func:`~vjm_pin.solver.stiffness._inverse_if_regular` (:func:`_eq28_tangent`), a Householder QR of
    ``Jᵀ`` (:func:`vjm_pin.solver.kernel._qr_t`, the corrector's own), the margin ``μ`` with its
    eigenvector and, with ``use_rate``, ``dμ/ds`` of :meth:`PointKernel.margin_rate`
    (:func:`_margin_tail`, shared with :func:`_reuse_point_loops`: on the same ``J`` the same numbers).
    Returns ``(status, k, δx, δF, μ, dμ/ds)``; ``status`` 0 when every number is valid, 1 when the
    generic path must decide."""
    n = jfree.shape[1]
    m = task.shape[0]
    xd = np.zeros(n)
    fd = np.zeros(m)
    nan = np.nan
    if m == 0 or m > n:
        return 1, nan, xd, fd, nan, nan
    jac = np.empty((m, n))
    for r in range(m):
        for c in range(n):
            jac[r, c] = jfree[task[r], c]
    ok, k = _eq28_tangent(jac, hz, kz, dt, nt, sing_rcond, xd, fd)
    if not ok:
        return 1, nan, xd, fd, nan, nan
    hh = _qr_t(jac, m, n)
    st, mu, rate = _margin_tail(jfree, hh, hz, kz, task, dt, mask, wrench, use_rate, fast_rank, xd, fd,
                                np.empty((0, 0)), np.nan, np.nan)
    return st, k, xd, fd, mu, rate


def _rate_value(jfree, mask, wrench, task, xd, fd, w, g):
    """``dμ/ds = wᵀH'w − 2 gᵀJ'w`` (:meth:`PointKernel.margin_rate`) for the point kernels, from the
    free columns ``jfree`` (6, n) of the frame Jacobian, their support ``mask``, the wrench, the
    tangent ``(δx, δF)``, the unit eigenvector ``w`` of ``μ`` and the multiplier ``g``."""
    n = jfree.shape[1]
    li, om = _twists(jfree)
    dom = np.empty((n, 3))
    dli = np.empty((n, 3))
    for i in range(n):
        o0 = 0.0
        o1 = 0.0
        o2 = 0.0
        p0 = 0.0
        p1 = 0.0
        p2 = 0.0
        for j in range(n):
            if mask[i, j]:
                o0 += xd[j] * om[j, 0]
                o1 += xd[j] * om[j, 1]
                o2 += xd[j] * om[j, 2]
            else:
                p0 += xd[j] * li[j, 0]
                p1 += xd[j] * li[j, 1]
                p2 += xd[j] * li[j, 2]
        _twist_rate_row(i, o0, o1, o2, p0, p1, p2, li, om, dli, dom)
    # per column: a = v×f + ω×m, da = δv×f + v×δf + δω×m + ω×δm, b = v×f, db = δv×f + v×δf
    aa, da, bb, db = _rate_terms(li, om, dli, dom, wrench, fd, task)
    quad = 0.0
    for i in range(n):
        acc = 0.0
        for j in range(n):
            if mask[i, j]:  # H[i, j] = ω_j·a_i
                hd = dom[j, 0] * aa[i, 0] + dom[j, 1] * aa[i, 1] + dom[j, 2] * aa[i, 2]
                hd += om[j, 0] * da[i, 0] + om[j, 1] * da[i, 1] + om[j, 2] * da[i, 2]
            else:  # H[i, j] = ω_i·b_j
                hd = dom[i, 0] * bb[j, 0] + dom[i, 1] * bb[j, 1] + dom[i, 2] * bb[j, 2]
                hd += om[i, 0] * db[j, 0] + om[i, 1] * db[j, 1] + om[i, 2] * db[j, 2]
            acc += hd * w[j]
        quad += w[i] * acc
    return quad - 2.0 * _rate_lin(dli, dom, w, g, task)


def _scaled_diff(a, b, free, vscale):
    """``max |(a − b)[free] / vscale|`` (NaN when any term is NaN, 0 without ``free``), the numbers of
    ``float(np.abs((a − b)[free] / vscale).max())`` (:meth:`~vjm_pin.analysis.curve._Tracer.scaled`)."""
    mv = 0.0
    nan = False
    for c in range(free.shape[0]):
        f = free[c]
        v = abs((a[f] - b[f]) / vscale[c])
        if v > mv:
            mv = v
        elif np.isnan(v):
            nan = True
    return np.nan if nan else mv


def _predict_loops(ax, xd, ds, free, vscale, flush, xp):
    """The tangent prediction of a curve's sub-step (:meth:`~vjm_pin.analysis.curve._Tracer.step`):
    ``xp = ax + ds·xd`` with entries below :data:`~vjm_pin.kinematics.chain.FLUSH_BELOW` flushed to zero when ``flush``
    (:func:`~vjm_pin.kinematics.chain.flush_tiny`), written into ``xp``; returns the scaled move
    ``max |(xp − ax)[free] / vscale|`` (:func:`_scaled_diff`). The same operations as the numpy
    expressions, element by element: the same numbers."""
    for i in range(ax.shape[0]):
        v = ax[i] + ds * xd[i]
        if flush and abs(v) < FLUSH_BELOW:
            v = 0.0
        xp[i] = v
    return _scaled_diff(xp, ax, free, vscale)


def _predict2_loops(ax, xd, hx, ds, c, free, vscale, flush, xp):
    """:func:`_predict_loops` with the second-order term of
    :meth:`~vjm_pin.analysis.curve._Tracer.step`: ``xp = ax + (ds·xd + c·(xd − hx))`` (``hx``: the tangent
    at the point the branch was continued from), element by element as the numpy expressions (the
    same numbers), flushed as :func:`_predict_loops`; returns the scaled move."""
    for i in range(ax.shape[0]):
        v = ax[i] + (ds * xd[i] + c * (xd[i] - hx[i]))
        if flush and abs(v) < FLUSH_BELOW:
            v = 0.0
        xp[i] = v
    return _scaled_diff(xp, ax, free, vscale)


def _fused_point_loops(x, x_pred, limit, free, vscale, j6, hz, kz, task, dt, mask, wrench, nt, use_rate,
                       fast_rank, sing_rcond, x_dot, w_dot):
    """The continuity check of a corrected sub-step and its point in one call (the fused step of
    :meth:`~vjm_pin.analysis.curve._Tracer._fused_step`): the scaled corrector displacement
    ``‖x − x_pred‖`` (:func:`_scaled_diff`) against ``limit``, then :func:`_point_loops` on the free
    columns of the frame Jacobian ``j6`` (6, nq) and ``hz``, and the tangent of eq. (29) scattered into
    ``x_dot`` (nq,, zero outside ``free``) and ``w_dot`` (6,, zero outside ``task``). Returns
    ``(status, k, μ, dμ/ds)``: status −1 when the corrector strayed (nothing else done), 1 when the point
    kernel declines (the generic path decides), 0 when every number is valid."""
    nan = np.nan
    corr = _scaled_diff(x, x_pred, free, vscale)
    if not corr <= limit:
        return -1, nan, nan, nan
    n = free.shape[0]
    jfree = np.empty((6, n))
    for a_ in range(6):
        for b in range(n):
            jfree[a_, b] = j6[a_, free[b]]
    st, k, xd, fd, mu, rate = _point_jit(jfree, hz, kz, task, dt, mask, wrench, nt, use_rate, fast_rank, sing_rcond)
    if st:
        return 1, nan, nan, nan
    for i in range(x_dot.shape[0]):
        x_dot[i] = 0.0
    for c in range(n):
        x_dot[free[c]] = xd[c]
    for i in range(6):
        w_dot[i] = 0.0
    for r in range(task.shape[0]):
        w_dot[task[r]] = fd[r]
    return 0, k, mu, rate


def _householder_r(hh, m):
    """The triangle ``R`` (m, m) of the reflectors ``hh`` of :func:`vjm_pin.solver.kernel._qr_t` (row k of
    ``hh``: column k of ``Jᵀ`` reduced; ``R[i, j] = hh[j, i]``, ``j ≥ i``)."""
    rmat = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            rmat[i, j] = hh[j, i]
    return rmat


def _q_both_sides(hh, a, m, n):
    """``(Qᵀ a Q)ᵀ`` for an (n, n) ``a`` (the reflectors of :func:`_q_vector`), a new array; ``a`` is
    overwritten by ``Qᵀ a``. Row operations only (:func:`vjm_pin.solver.kernel._reflect_rows`):
    ``Qᵀ a``, its transpose, ``Qᵀ (Qᵀ a)ᵀ = (Qᵀ a Q)ᵀ`` — column ``r`` of the result is row ``r`` of
    ``Qᵀ a`` reflected with the same operations as :func:`_q_vector` would apply to it (the same
    numbers), vectorised across the rows instead of one row at a time."""
    _reflect_rows(hh, a, m, n)
    at = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            at[i, j] = a[j, i]
    _reflect_rows(hh, at, m, n)
    return at


def _margin_tail(jfree, hh, hz, kz, task, dt, mask, wrench, use_rate, fast_rank, xd, fd, wt, hlo, hhi):
    """The margin ``μ`` and, with ``use_rate``, ``dμ/ds`` of the point kernels (:func:`_point_loops`,
    :func:`_reuse_point_loops`) from the reflectors ``hh`` of ``Jᵀ`` (:func:`~vjm_pin.solver.kernel._qr_t`) and the
    tangent ``(xd, fd)``: the rank test of ``J`` (:data:`FAST_RANK`; from ``‖R‖_F ‖R⁻¹‖_F ≥ σ_max/σ_min``
    where that bound clears it, else the singular values of ``R``), ``Vᵀ sym(H − K) V`` from ``QᵀAQ``
    (the m reflectors applied on both sides of ``A``: ``4mn²`` instead of the products with ``V``),
    its largest eigenpair (:func:`_top_eigpair`) and :func:`_rate_value`. Returns ``(status, μ, dμ/ds)``:
    status 1 when ``J`` is not safely of full rank (the generic path decides)."""
    nan = np.nan
    m = task.shape[0]
    n = hz.shape[0]
    rmat = _householder_r(hh, m)
    # σ_max ≤ ‖R‖_F, 1/σ_min ≤ ‖R⁻¹‖_F: the rank test without an SVD where the bound clears it
    rinv = np.zeros((m, m))
    nr = 0.0
    for i in range(m):
        for j in range(i, m):
            nr += rmat[i, j] * rmat[i, j]
    for c in range(m):  # column c of R⁻¹ (back substitution of e_c)
        for i in range(c, -1, -1):
            s = 1.0 if i == c else 0.0
            for j in range(i + 1, c + 1):
                s -= rmat[i, j] * rinv[j, c]
            rinv[i, c] = s / rmat[i, i]
    ni = 0.0
    for i in range(m):
        for j in range(i, m):
            ni += rinv[i, j] * rinv[i, j]
    if not fast_rank * (np.sqrt(nr) * np.sqrt(ni)) < 0.5:
        for i in range(m):
            for j in range(i, m):
                if not np.isfinite(rmat[i, j]):
                    return 1, nan, nan
        sv = np.linalg.svd(rmat)[1]
        if not sv.min() > fast_rank * sv.max():
            return 1, nan, nan
    u = np.zeros(m)  # Rᵀ u = d_t (forward substitution): y₀ = Y u
    for i in range(m):
        s = dt[i]
        for j in range(i):
            s -= rmat[j, i] * u[j]
        u[i] = s / rmat[i, i]
    nu = 0.0
    for j in range(m):
        nu += u[j] * u[j]
    nu = np.sqrt(nu)
    uh = np.empty(m)
    for j in range(m):
        uh[j] = u[j] / nu
    dim = n - m + 1
    asym = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            asym[i, j] = 0.5 * (hz[i, j] + hz[j, i]) - kz[i, j]
    if wt.shape[0] == n:  # (Qᵀ (H − K) Q)ᵀ = −wt: :func:`_reduced` reads its symmetric part
        bt = np.empty((n, n))
        for i in range(n):
            for j in range(n):
                bt[i, j] = -wt[i, j]
    else:
        bq = asym.copy()
        bt = _q_both_sides(hh, bq, m, n)
    red = _reduced(bt, uh, m, n)
    mu, top = _top_eigpair(red, hlo, hhi)
    if not use_rate:
        return 0, mu, nan
    w = np.empty(n)  # V top = Q [û top[−1]; top[:n−m]]
    for j in range(m):
        w[j] = uh[j] * top[dim - 1]
    for c in range(n - m):
        w[m + c] = top[c]
    _q_vector(hh, w, m, n, False)
    res = asym @ w  # (BLAS dgemv, as before; then − μw in place: the same numbers)
    for i in range(n):
        res[i] -= mu * w[i]
    _q_vector(hh, res, m, n, True)  # Yᵀ res: its first m entries
    g = _back_substitute(rmat, res, m)  # R g = Yᵀ res
    return 0, mu, _rate_value(jfree, mask, wrench, task, xd, fd, w, g)


def _reuse_point_loops(x, x_pred, limit, j6, hh, hz, f6, wtk, ci, cfl, kz, mask, out):
    """The fused step's point (:func:`_fused_point_loops`) on the factorisation of the converged Newton
    iteration itself: the Householder reflectors ``hh`` of ``Jᵀ`` (:func:`vjm_pin.solver.kernel._qr_t`,
    the ``fact[1]`` of the corrector's compiled kernel), ``hz`` = ``H(F)`` and ``f6`` = ``F`` at the same
    configuration ``x`` whose frame Jacobian is ``j6`` (6, nq), and ``wtk`` = the iteration's ``(Qᵀ W Q)ᵀ``
    (n, n; read only: ``ws[11]`` of :func:`vjm_pin.solver.kernel._iterations_into`, the same bits as
    computed here), or a (0, 0) array: computed here. No second QR, no explicit ``Q``; the
    rank test of ``J`` (:data:`FAST_RANK`) from ``‖R‖_F ‖R⁻¹‖_F ≥ σ_max/σ_min`` where that bound clears
    it, else the singular values of ``R`` as :func:`_point_loops`; the tangent of eq. (29) by
    :func:`_ns_tangent` on the same reflectors (refined: as accurate as :func:`_eq28_tangent`, not
    the same bits). ``μ`` and ``dμ/ds`` are those of :func:`_point_loops` to rounding (another QR of
    the same ``Jᵀ``: another basis of the same subspaces; ``Qᵀ(H − K)Q`` from the tangent's matrix).

    The constants packed (one argument each instead of eleven): ``ci`` (int) = ``[n, nθ, m, use_rate,
    free (n), task (m)]``, ``cfl`` (float) = ``[fast_rank, sing_rcond, d (6), d_t (m), vscale (n), μ_lo, μ_hi]``
    (the last two: a predicted bracket of μ for :func:`_top_eigpair`, written by the caller before each
    call, NaN for none); ``out``
    (nq + 6,): the tangent ``(δx, δF)`` laid out as ``x_dot`` (nq,) then ``w_dot`` (6,). Returns
    ``(status, k, μ, dμ/ds, dᵀF)``: as :func:`_fused_point_loops` (status −1: the corrector strayed,
    nothing else done; 1: the kernel declines; 0: every number valid) and the force along ``d`` of
    the wrench ``F`` given as ``f6`` (``Σ dᵢFᵢ`` in order)."""
    nan = np.nan
    n, nt, m = ci[0], ci[1], ci[2]
    use_rate = ci[3] != 0
    free = ci[4:4 + n]
    task = ci[4 + n:4 + n + m]
    fast_rank, sing_rcond = cfl[0], cfl[1]
    dt = cfl[8:8 + m]
    vscale = cfl[8 + m:8 + m + n]
    corr = _scaled_diff(x, x_pred, free, vscale)
    if not corr <= limit:
        return -1, nan, nan, nan, nan
    force = 0.0
    for i in range(6):
        force += cfl[2 + i] * f6[i]
    if m == 0 or m > n:
        return 1, nan, nan, nan, force
    jfree = np.empty((6, n))
    for a_ in range(6):
        for b in range(n):
            jfree[a_, b] = j6[a_, free[b]]
    jac = np.empty((m, n))
    for r in range(m):
        for c in range(n):
            jac[r, c] = jfree[task[r], c]
    xd = np.zeros(n)
    fd = np.zeros(m)
    if wtk.shape[0] == n and wtk.shape[1] == n:
        ok, k = _ns_tangent_on(jac, hh, hz, kz, dt, xd, fd, wtk)
        wt = wtk
    else:
        wt = np.empty((n, n))
        ok, k = _ns_tangent(jac, hh, hz, kz, dt, xd, fd, wt)
    if not ok:
        return 1, nan, nan, nan, force
    nc = cfl.shape[0]  # the predicted bracket of μ, when the caller wrote one (else NaN)
    st, mu, rate = _margin_tail(jfree, hh, hz, kz, task, dt, mask, f6, use_rate, fast_rank, xd, fd, wt,
                                cfl[nc - 2], cfl[nc - 1])
    if st:
        return 1, nan, nan, nan, force
    nq = out.shape[0] - 6
    for i in range(nq + 6):
        out[i] = 0.0
    for c in range(n):
        out[free[c]] = xd[c]
    for r in range(m):
        out[nq + task[r]] = fd[r]
    return 0, k, mu, rate, force


def _step_loops(ax, xd, hx, ds, c, second, max_move, p0d, s, xp, pt, kx, have, kf, kpos, krot, kj6, geo, jinfo,
                rt, rot, flush, ci, cf, kz, mask, theta0, vscale, escale, xout, ws, kbuf, thr, defer, lim, ratio,
                hint, mu0, rate0, pci, pcfl, pkz, pmask, out):
    """A curve's common sub-step (:meth:`~vjm_pin.analysis.curve._Tracer.step` through
    :meth:`~vjm_pin.analysis.curve._Tracer._fused_step`) in one compiled call: the same three compiled
    calls in the same order on the same arrays, so the same numbers bit for bit, without the Python
    between them (two calls' argument unboxing, the corrector's per-call checks).

    1. The prediction :func:`_predict_loops` (``second``: :func:`_predict2_loops` with ``hx``, ``c``) from
       ``ax`` along ``xd`` over ``ds`` into ``xp``, its scaled move (the free coordinates and scales of
       ``pci``/``pcfl``: the tracer's). Beyond ``max_move`` the sub-step is rejected before the corrector.
    2. The target position ``p₀ + s·d[:3]`` (``p0d`` = ``[p₀, d[:3]]``, element by element as the tracer's
       Python floats) into ``pt`` and the constants' target slots (``cf[9:12]``, as
       :func:`vjm_pin.solver.kernel.with_target`); the rotation ``rt`` is the kept one (a translation ``d``).
    3. The corrector :func:`vjm_pin.solver.kernel._iterations_into` from ``xp`` (its arguments ``kx`` …
       ``lim`` as :meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._corrector_looped` passes them;
       ``kj6``: the kept state's frame Jacobian, read where the loop reuses it).
    4. At its convergence the point :func:`_reuse_point_loops` on the converged iteration's buffers
       (``ws``: reflectors, ``H(F)``, ``F``, ``(QᵀWQ)ᵀ``; the frame Jacobian ``kbuf[0]``, or ``kj6`` when
       reused) with the continuity limit ``ratio·move + 1e-9`` and μ's bracket predicted from ``mu0``,
       ``rate0`` (``hint``; NaN otherwise) written into ``pcfl``'s last two slots, as the tracer writes it.

    Returns ``(phase, code, iterations, counted, kkt, ep, er, rs, reused, move, status, k, μ, dμ/ds,
    dᵀF)``: ``phase`` 0 rejected by the move (nothing else done), 1 the corrector gave way (``code``),
    2 converged (``status`` and the rest: :func:`_reuse_point_loops`'s)."""
    nan = np.nan
    n, m = pci[0], pci[2]
    free = pci[4:4 + n]
    vsc = pcfl[8 + m:8 + m + n]
    if second:
        move = _predict2_jit(ax, xd, hx, ds, c, free, vsc, flush, xp)
    else:
        move = _predict_jit(ax, xd, ds, free, vsc, flush, xp)
    if move > max_move:
        return 0, 0, 0, -1, 0.0, 0.0, 0.0, 0.0, False, move, 0, nan, nan, nan, nan
    for i in range(3):
        v = p0d[i] + s * p0d[3 + i]
        pt[i] = v
        cf[9 + i] = v
    code, it, counted, kkt, ep, er, rs, reused = _loop_jit(xp, kx, have, kf, kpos, krot, geo, jinfo, rt, rot, flush,
                                                           ci, cf, kz, mask, theta0, vscale, escale, xout, ws, kbuf,
                                                           thr, defer, lim)
    if code != _LOOP_DONE:
        return 1, code, it, counted, kkt, ep, er, rs, reused, move, 0, nan, nan, nan, nan
    nc = pcfl.shape[0]
    if hint:
        half = 2.0 * abs(ds * rate0) + 1e-6 * abs(mu0) + 1e-300
        pcfl[nc - 2] = mu0 + ds * rate0 - half
        pcfl[nc - 1] = mu0 + ds * rate0 + half
    else:
        pcfl[nc - 2] = nan
        pcfl[nc - 1] = nan
    j6 = kj6 if reused else kbuf[0]
    st, k, mu, rate, force = _reuse_jit(xout, xp, ratio * move + 1e-9, j6, ws[1], ws[6], ws[7], ws[11], pci, pcfl,
                                        pkz, pmask, out)
    return 2, code, it, counted, kkt, ep, er, rs, reused, move, st, k, mu, rate, force


#: numba options of this module's compiled functions: numpy's error model (a division by zero gives
#: inf or NaN, which the status tests decline, instead of raising and an extra test in every division
#: loop; the numbers are otherwise the same).
_NJIT = {"nogil": True, "error_model": "numpy"}
_point_jit = _point_loops  # the point kernel :func:`_fused_point_loops` calls (compiled by compiled())
_fused = None  # the compiled (_predict_loops, _fused_point_loops, _scaled_diff, _predict2_loops) once loaded
_compiled = None  # the compiled _point_loops once loaded, False when numba is unavailable
_reuse = None  # the compiled _reuse_point_loops once loaded (compiled())
_step = None  # the compiled _step_loops once loaded (step()), False where it cannot be
#: (the compiled callees of _step_loops: set by step() before it compiles it)
_predict_jit = _predict2_jit = _loop_jit = _reuse_jit = None
_LOOP_DONE = 1  # (vjm_pin.solver.kernel.DONE, checked by step())
#: This module's njit helpers, compiled (before the kernels that call them) by compiled().
_OWN_HELPERS = ("_sturm_count", "_top_eigpair", "_abs_sums", "_eq28_tangent", "_reduced", "_rate_value", "_householder_r",
                "_q_both_sides", "_margin_tail", "_lu_factor", "_ns_solve", "_ns_tangent_on", "_ns_tangent")
#: The dense kernel's helpers (:mod:`vjm_pin.solver.kernel`) this module calls, compiled there once
#: (numba's on-disk cache of this module does not see edits of kernel.py: clear ``__pycache__`` then).
_KERNEL_HELPERS = ("_q_vector", "_qr_t", "_reflect_rows", "_qwq_t")


def _jit_mode() -> str:
    """``VJM_PIN_JIT`` read now: the solver's switch (:func:`vjm_pin.solver.kernel.mode`)."""
    from vjm_pin.solver.kernel import mode

    return mode()


def compiled():
    """The compiled :func:`_point_loops` (numba ``njit(cache=True)``, imported lazily), or False
    when numba cannot be imported."""
    global _compiled
    if _compiled is None:
        try:
            import numba
        except Exception:  # noqa: BLE001 - any import failure: the numpy path
            _compiled = False
            return _compiled
        from vjm_pin.solver import chain_kernel, kernel

        g = globals()
        try:
            chain_kernel._load()  # the dμ/ds helpers shared with the chain kernel, compiled there
            for name in chain_kernel.RATE_HELPERS:
                g[name] = getattr(chain_kernel, name)
            for name in _KERNEL_HELPERS:  # (chain_kernel._load has loaded the dense kernel)
                g[name] = getattr(kernel, name)
            for name in _OWN_HELPERS:
                g[name] = numba.njit(cache=True, **_NJIT)(g[name])
            _compiled = numba.njit(cache=True, **_NJIT)(_point_loops)
            _fused_load(numba, {"cache": True, **_NJIT})
        except RuntimeError:  # no writable cache location: compile in memory
            for name in (*_OWN_HELPERS, *chain_kernel.RATE_HELPERS, *_KERNEL_HELPERS):
                fn = g[name]
                g[name] = numba.njit(**_NJIT)(getattr(fn, "py_func", fn))
            _compiled = numba.njit(**_NJIT)(_point_loops)
            _fused_load(numba, dict(_NJIT))
    return _compiled


def _fused_load(numba, opts) -> None:
    """Compile the fused step's helpers (:func:`fused`) with the compiled point kernel."""
    global _fused, _point_jit, _reuse
    _point_jit = _compiled
    g = globals()
    sd = g["_scaled_diff"] = numba.njit(**opts)(getattr(_scaled_diff, "py_func", _scaled_diff))
    _fused = (
        numba.njit(**opts)(getattr(_predict_loops, "py_func", _predict_loops)),
        numba.njit(**opts)(getattr(_fused_point_loops, "py_func", _fused_point_loops)),
        sd,
        numba.njit(**opts)(getattr(_predict2_loops, "py_func", _predict2_loops)),
    )
    _reuse = numba.njit(**opts)(getattr(_reuse_point_loops, "py_func", _reuse_point_loops))


def fused():
    """The compiled ``(_predict_loops, _fused_point_loops, _scaled_diff, _predict2_loops)`` (the fused step of
    :meth:`~vjm_pin.analysis.curve._Tracer._fused_step`), loaded with :func:`compiled`; None when
    numba cannot be imported."""
    if _fused is None:
        compiled()
    return _fused or None


def reuse():
    """The compiled :func:`_reuse_point_loops` (the fused step's point on the corrector's own QR),
    loaded with :func:`compiled`; None when numba cannot be imported."""
    if _fused is None:
        compiled()
    return _reuse or None


def step():
    """The compiled :func:`_step_loops` (a curve's common sub-step in one call), loaded with
    :func:`compiled` and the solver's one-call loop (:func:`vjm_pin.solver.kernel.looped`); None when
    either cannot be (numba missing, no compiled kinematics)."""
    global _step, _predict_jit, _predict2_jit, _loop_jit, _reuse_jit
    if _step is None:
        from vjm_pin.solver import kernel

        loop = kernel.looped() if fused() is not None else None
        if loop is None or kernel.DONE != _LOOP_DONE:
            _step = False
        else:
            import numba

            _predict_jit, _predict2_jit, _loop_jit, _reuse_jit = _fused[0], _fused[3], loop, _reuse
            try:
                _step = numba.njit(cache=True, **_NJIT)(_step_loops)
            except RuntimeError:  # no writable cache location: compile in memory
                _step = numba.njit(**_NJIT)(_step_loops)
    return _step or None


def use_compiled(points_so_far: int) -> bool:
    """Whether the compiled kernel is wanted now (``VJM_PIN_JIT``; ``auto``: numba already
    imported in this process, e.g. by the solver's kernel after its iteration threshold).
    ``points_so_far`` is kept for the caller's bookkeeping; the rule does not count points, so a
    short curve never pays numba's import (~1-2 s)."""
    md = _jit_mode()
    if md == "0":
        return False
    if md == "1" or _compiled or "numba" in sys.modules:
        return bool(compiled())
    return False
