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
numpy calls per point). numba is imported lazily (:func:`use_compiled`, the solver's
``VJM_PIN_JIT`` switch): never at import, never with ``VJM_PIN_JIT=0``, and in ``auto`` mode
only once numba is loaded anyway (the solver's kernel switches after
:data:`vjm_pin.solver.kernel.JIT_AFTER_ITERATIONS` iterations: one rule for the whole package).
``tests/test_point_kernel.py`` compares both implementations with each other and with the
generic path, and the analytic ``dμ/ds`` with finite differences.
"""

from __future__ import annotations

import sys

import numpy as np

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
    """

    def __init__(self, k_theta: np.ndarray, free: np.ndarray, d_task: np.ndarray, task=None):
        nt = k_theta.shape[0]
        n = len(free)
        self.free = np.asarray(free, dtype=int)
        self.task = np.arange(d_task.size) if task is None else np.asarray(task, dtype=int)
        self.n, self.nt, self.m = int(n), nt, int(d_task.size)
        self.kz = np.zeros((n, n))
        self.kz[:nt, :nt] = k_theta
        self.dt = np.ascontiguousarray(d_task, dtype=float)
        self.big = n > SCIPY_LAPACK_MAX_N
        self._qfull = np.zeros((n, n), order="F")
        self._nomask = np.zeros((n, n), dtype=bool)

    # ------------------------------------------------------------------ pieces
    def matrices(self, b):
        """(J (m, n), H (n, n)) in (θ, q) order from :class:`~vjm_pin.solver.blocks.Blocks`."""
        nt, n = self.nt, self.n
        jac = np.empty((self.m, n))
        jac[:, :nt] = b.J_theta
        jac[:, nt:] = b.J_q
        hz = np.empty((n, n))
        hz[:nt, :nt] = b.H_tt
        hz[:nt, nt:] = b.H_tq
        hz[nt:, :nt] = b.H_qt
        hz[nt:, nt:] = b.H_qq
        return jac, hz

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
            _, hz = self.matrices(b)
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
def _point_loops(jfree, hz, kz, task, dt, mask, wrench, nt, use_rate, fast_rank, sing_rcond):
    """The whole of :meth:`PointKernel.point` in one compiled call (numba, explicit loops and
    numba's ``np.linalg``): the equilibrated inverse of eq. (28) with the regularity test of
    :func:`~vjm_pin.solver.stiffness._inverse_if_regular`, a Householder QR of ``Jᵀ``, the
    margin ``μ`` with its eigenvector and, with ``use_rate``, ``dμ/ds`` of
    :meth:`PointKernel.margin_rate`. Returns ``(status, k, δx, δF, μ, dμ/ds)``; ``status`` 0
    when every number is valid, 1 when the generic path must decide."""
    n = jfree.shape[1]
    m = task.shape[0]
    nq = n - nt
    e = m + n
    xd = np.zeros(n)
    fd = np.zeros(m)
    nan = np.nan
    if m == 0 or m > n:
        return 1, nan, xd, fd, nan, nan
    jac = np.empty((m, n))
    for r in range(m):
        for c in range(n):
            jac[r, c] = jfree[task[r], c]
    # ---- eq. (28) in the order (F, q, θ), equilibrated as stiffness._ruiz, inverted
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
    for _ in range(4):
        for i in range(e):
            v = 0.0
            for j in range(e):
                v = max(v, mm[i, j])
            rr[i] = 1.0 / np.sqrt(v if v != 0.0 else 1.0)
        for i in range(e):
            for j in range(e):
                mm[i, j] *= rr[i] * rr[j]
            d[i] *= rr[i]
    sm = np.empty((e, e))
    for i in range(e):
        for j in range(e):
            sm[i, j] = a[i, j] * (d[i] * d[j])
    inv = np.linalg.inv(sm)
    if not np.all(np.isfinite(inv)):
        return 1, nan, xd, fd, nan, nan
    c1s = 0.0
    r1s = 0.0
    c1i = 0.0
    r1i = 0.0
    for i in range(e):
        cs = 0.0
        rs = 0.0
        ci = 0.0
        ri = 0.0
        for j in range(e):
            cs += abs(sm[j, i])
            rs += abs(sm[i, j])
            ci += abs(inv[j, i])
            ri += abs(inv[i, j])
        c1s = max(c1s, cs)
        r1s = max(r1s, rs)
        c1i = max(c1i, ci)
        r1i = max(r1i, ri)
    if not np.sqrt(c1s * r1s) * np.sqrt(c1i * r1i) * sing_rcond * 10.0 <= 1.0:
        return 1, nan, xd, fd, nan, nan
    xv = np.zeros(e)
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
    # ---- complete QR of Jᵀ (Householder): Q = [Y Z], R (m, m)
    w0 = jac.T.copy()
    q = np.eye(n)
    for j in range(m):
        nrm = 0.0
        for i in range(j, n):
            nrm += w0[i, j] * w0[i, j]
        nrm = np.sqrt(nrm)
        if nrm == 0.0:
            return 1, nan, xd, fd, nan, nan
        alpha = -nrm if w0[j, j] >= 0 else nrm
        v = w0[j:, j].copy()
        v[0] -= alpha
        vv = 0.0
        for i in range(v.shape[0]):
            vv += v[i] * v[i]
        if vv == 0.0:
            continue
        for c in range(j, m):
            s = 0.0
            for i in range(v.shape[0]):
                s += v[i] * w0[j + i, c]
            s *= 2.0 / vv
            for i in range(v.shape[0]):
                w0[j + i, c] -= s * v[i]
        for r in range(n):
            s = 0.0
            for i in range(v.shape[0]):
                s += q[r, j + i] * v[i]
            s *= 2.0 / vv
            for i in range(v.shape[0]):
                q[r, j + i] -= s * v[i]
    rmat = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            rmat[i, j] = w0[i, j]
    sv = np.linalg.svd(rmat)[1]
    if not sv.min() > fast_rank * sv.max():
        return 1, nan, xd, fd, nan, nan
    u = np.zeros(m)  # Rᵀ u = d_t (forward substitution)
    for i in range(m):
        s = dt[i]
        for j in range(i):
            s -= rmat[j, i] * u[j]
        u[i] = s / rmat[i, i]
    y0 = np.zeros(n)
    for r in range(n):
        s = 0.0
        for j in range(m):
            s += q[r, j] * u[j]
        y0[r] = s
    ny = np.sqrt(np.sum(y0 * y0))
    dim = n - m + 1
    vb = np.empty((n, dim))
    for r in range(n):
        for c in range(n - m):
            vb[r, c] = q[r, m + c]
        vb[r, dim - 1] = y0[r] / ny
    asym = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            asym[i, j] = 0.5 * (hz[i, j] + hz[j, i]) - kz[i, j]
    red = vb.T @ (asym @ vb)
    for i in range(dim):
        for j in range(i):
            t = 0.5 * (red[i, j] + red[j, i])
            red[i, j] = t
            red[j, i] = t
    ev, uu = np.linalg.eigh(red)
    mu = ev[dim - 1]
    if not use_rate:
        return 0, k, xd, fd, mu, nan
    w = vb @ uu[:, dim - 1].copy()
    # ---- dμ/ds = wᵀH'w − 2 gᵀJ'w (PointKernel.margin_rate)
    res = asym @ w - mu * w
    yr = np.zeros(m)
    for j in range(m):
        s = 0.0
        for r in range(n):
            s += q[r, j] * res[r]
        yr[j] = s
    g = np.zeros(m)  # R g = Yᵀ res (back substitution)
    for i in range(m - 1, -1, -1):
        s = yr[i]
        for j in range(i + 1, m):
            s -= rmat[i, j] * g[j]
        g[i] = s / rmat[i, i]
    om = np.empty((n, 3))
    li = np.empty((n, 3))
    for c in range(n):
        for a3 in range(3):
            li[c, a3] = jfree[a3, c]
            om[c, a3] = jfree[3 + a3, c]
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
        dom[i, 0] = o1 * om[i, 2] - o2 * om[i, 1]
        dom[i, 1] = o2 * om[i, 0] - o0 * om[i, 2]
        dom[i, 2] = o0 * om[i, 1] - o1 * om[i, 0]
        dli[i, 0] = o1 * li[i, 2] - o2 * li[i, 1] + om[i, 1] * p2 - om[i, 2] * p1
        dli[i, 1] = o2 * li[i, 0] - o0 * li[i, 2] + om[i, 2] * p0 - om[i, 0] * p2
        dli[i, 2] = o0 * li[i, 1] - o1 * li[i, 0] + om[i, 0] * p1 - om[i, 1] * p0
    # F and δF (task rows of δF; the other components carry no wrench)
    wdot = np.zeros(6)
    for r in range(m):
        wdot[task[r]] = fd[r]
    f0, f1, f2, m0, m1, m2 = wrench[0], wrench[1], wrench[2], wrench[3], wrench[4], wrench[5]
    g0, g1, g2, n0, n1, n2 = wdot[0], wdot[1], wdot[2], wdot[3], wdot[4], wdot[5]
    # per column: a = v×f + ω×m, da = δv×f + v×δf + δω×m + ω×δm, b = v×f, db = δv×f + v×δf
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
        b1 = v2 * f0 - v0 * f2
        b2 = v0 * f1 - v1 * f0
        bb[c, 0], bb[c, 1], bb[c, 2] = b0, b1, b2
        aa[c, 0] = b0 + w1_ * m2 - w2_ * m1
        aa[c, 1] = b1 + w2_ * m0 - w0_ * m2
        aa[c, 2] = b2 + w0_ * m1 - w1_ * m0
        e0 = dv1 * f2 - dv2 * f1 + v1 * g2 - v2 * g1
        e1 = dv2 * f0 - dv0 * f2 + v2 * g0 - v0 * g2
        e2 = dv0 * f1 - dv1 * f0 + v0 * g1 - v1 * g0
        db[c, 0], db[c, 1], db[c, 2] = e0, e1, e2
        da[c, 0] = e0 + dw1 * m2 - dw2 * m1 + w1_ * n2 - w2_ * n1
        da[c, 1] = e1 + dw2 * m0 - dw0 * m2 + w2_ * n0 - w0_ * n2
        da[c, 2] = e2 + dw0 * m1 - dw1 * m0 + w0_ * n1 - w1_ * n0
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
    # gᵀ (J' w) on the task rows
    jw = np.zeros(6)
    for c in range(n):
        for a3 in range(3):
            jw[a3] += dli[c, a3] * w[c]
            jw[3 + a3] += dom[c, a3] * w[c]
    lin = 0.0
    for r in range(m):
        lin += g[r] * jw[task[r]]
    return 0, k, xd, fd, mu, quad - 2.0 * lin


_compiled = None  # the compiled _point_loops once loaded, False when numba is unavailable


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
        try:
            _compiled = numba.njit(cache=True, nogil=True)(_point_loops)
        except RuntimeError:  # no writable cache location: compile in memory
            _compiled = numba.njit(nogil=True)(_point_loops)
    return _compiled


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
