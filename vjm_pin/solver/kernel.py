"""The fused Newton iteration of the serial solver's local path (issue 14).

One call does everything of one iteration of
:meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._fast_newton` after the Pinocchio call
(frame Jacobian ``J`` and end placement at ``x``):

1. gather of the free columns (θ, q order) and task rows of ``J``;
2. ``∇E = K_θ(θ − θ₀)`` (0 for the passive coordinates q);
3. complete Householder QR ``Jᵀ = [Y Z] [R; 0]`` (LAPACK ``dlarfg`` convention: ``Z`` is the
   explicit null-space basis of eq. 20–21, the same basis as ``dgeqrf`` + ``dorgqr``);
4. the least-squares multiplier ``F = R⁻¹ Yᵀ ∇E`` and the static residual ``r = ∇E − JᵀF``
   (eq. 5);
5. the Hessian of Ψ (eq. 16) in screw form from ``J`` (:mod:`vjm_pin.kinematics.screw`);
6. the task error and the convergence test of the solver (position ≤ 0.01·tol·L_c,
   orientation ≤ 0.01·tol, statics ≤ tol·max(|∇E|, 1e-6·max|K_θ|)) and the KKT norm;
7. away from convergence the Newton step of eq. (28) in null-space form, ``Rᵀ p_Y = e``,
   ``(ZᵀWZ) p_Z = −Zᵀ(r + W Y p_Y)``, ``W = K − H(F)``, with the ``follow_stable`` test
   (``½(ZᵀWZ + (ZᵀWZ)ᵀ) − shift·I`` positive definite: Cholesky) and the step limit;
   at convergence the unmodified (polish) step, and once that is negligible the rank test
   of ``J`` and the eigenvalues of eq. (23), ``−½(ZᵀWZ + (ZᵀWZ)ᵀ)`` (stability verdict),
   from the same reduced matrix;
8. the update ``x⁺ = x + δx`` with entries below 1e-150 flushed to zero
   (:func:`~vjm_pin.kinematics.chain.flush_tiny`).

Two implementations of the same contract: :func:`iterate_numpy` (vectorised numpy and scipy's
LAPACK, the fallback, exactly the arithmetic of the solver's unfused path) and the compiled
:func:`_iterate_loops` (numba ``@njit(cache=True)``: explicit loops; no explicit ``Q``, the
Householder reflectors are applied where it would multiply, so ``ZᵀWZ`` costs ``4mn²`` flops
instead of ``2n²(n − m)``; own Cholesky and LU; LAPACK ``dsyevd``/``dgesdd`` through numba's
``np.linalg`` for the eigenvalues and singular values of the verdict). They agree to rounding
(``tests/test_kernel.py``; a step differs by ~1e-15·cond(ZᵀWZ) relative). From
``chain_kernel.ITERATE_MIN_N`` free coordinates the compiled entry point hands the iteration to
:mod:`vjm_pin.solver.chain_kernel` (O(n) block elimination; at CONVERGED ``ev`` is then the largest
eigenvalue of eq. (23) alone, and the solver reports the rest lazily:
:class:`~vjm_pin.solver.stability.DeferredStability`). The direct call of the warm-started solve
(:func:`lean`, :func:`_iterate_into`) decides clear-cut verdicts without LAPACK: the rank test by the
bound ``‖R‖_F‖R⁻¹‖_F`` of ``cond(J)``, "stable" by a Cholesky factorisation past the threshold (the
eigenvalues then computed when first read, :func:`spectrum`); undecided cases take the SVD and the
eigenvalues as before, so every verdict is the same.

Why numba (and not C++ through Pinocchio's CasADi/CppAD code generation or a C extension):
it needs no compiler at install time (the wheel has LLVM inside), the fallback is the same
algorithm in plain numpy so the package works where numba does not (``VJM_PIN_JIT=0``, or
numba missing), and ``cache=True`` stores the machine code next to this file so only the
first run on a machine compiles (65–90 s measured on the loaded 2-core test machine); later
processes load it (numba's import and its target initialisation: ~1–2 s per process).
Pinocchio itself cannot be called from compiled code: for chains of 1-DoF revolute/prismatic joints
(the fused path's models) :mod:`vjm_pin.kinematics.compiled_chain` computes the end placement, frame
Jacobian and ``log3`` in numba (equal to Pinocchio's to rounding), and :func:`_iterations_into` (built by
:func:`looped`) runs the solver's whole plain local iteration, bookkeeping included, in one compiled
call; :func:`_restore_into` does the same for a least-energy restoration. Pinocchio stays the
kinematics of the numpy twin and of every other path.

Import policy (:func:`get`): numba is imported lazily, never at package import. ``VJM_PIN_JIT``
= ``0``: the numpy twin always; ``1``: compiled from the first solve; unset or ``auto``: the numpy
twin until the process has run :data:`JIT_AFTER_ITERATIONS` fused iterations (a long curve, a
map) or a caller asked for the compiled kernel (:func:`load`), compiled from then on. The rule
is by work done, not by "second solve": loading numba and the cached machine code costs
~1–2 s per process, which a compiled iteration (0.1–0.5 ms cheaper) repays only after
thousands of iterations; a one-shot ``vjm-pin analyze`` or a short curve never imports numba.
"""

from __future__ import annotations

import math
import os

import numpy as np

#: Status codes returned by an iteration.
CONTINUE = 0  #: not converged; ``dx``/``xn`` hold the descent step
POLISH = 1  #: converged, the unmodified step is not negligible: ``dx``/``xn`` hold it
CONVERGED = 2  #: converged and polished: ``ev`` holds the eigenvalues of eq. (23), rank test passed
FACTOR_FAIL = -1  #: a triangular factor is exactly singular (the iteration cannot go on)
STEP_FAIL = -2  #: not converged and no acceptable descent step (not PD, singular, too long)
RANK_FAIL = -3  #: converged but ``J`` is rank deficient (RANK_TOL)

#: Order of the scalar constants in ``cf`` (see :func:`pack`).
_CF = ("tol", "tol_p", "kscale", "stat_floor", "shift", "max_step", "follow_stable", "polish_step", "rank_tol",
       "pt0", "pt1", "pt2", "big")

_compiled = None  # the compiled iteration once loaded, False when numba is unavailable
_built = None  # the compiled iteration once built in this process


def pack(*, free, theta_idx, theta0, task, kz, mask, var_scale, err_scale, nq, tol, tol_p, kscale, stat_floor,
         shift, max_step, follow_stable, polish_step, rank_tol, big):
    """The solver's constant arrays in the layout both implementations take:
    ``(ci, cf, kz, mask, theta0, var_scale, err_scale)``; ``cf``'s target position slots are
    filled per solve by :func:`with_target`."""
    free = np.asarray(free, np.int64)
    theta_idx = np.asarray(theta_idx, np.int64)
    task = np.asarray(task, np.int64)
    ip = np.array([i for i, t in enumerate(task) if t < 3], np.int64)
    ir = np.array([i for i, t in enumerate(task) if t >= 3], np.int64)
    head = np.array([len(free), len(theta_idx), len(task), len(ip), len(ir), int(nq)], np.int64)
    ci = np.concatenate([head, free, theta_idx, task, ip, ir]).astype(np.int64)
    cf = np.array([tol, tol_p, kscale, stat_floor, shift, max_step, float(bool(follow_stable)), polish_step, rank_tol,
                   0.0, 0.0, 0.0, float(bool(big))], float)
    return (ci, cf, np.ascontiguousarray(kz, float), np.ascontiguousarray(mask, bool),
            np.ascontiguousarray(theta0, float), np.ascontiguousarray(var_scale, float),
            np.ascontiguousarray(err_scale, float))


def with_target(consts, pt):
    """``consts`` with the target position ``pt`` (3,) in ``cf``."""
    cf = consts[1].copy()
    cf[9:12] = pt
    return (consts[0], cf) + tuple(consts[2:])


def _unpack_ci(ci):
    n, nt, m, nip, nir, nq = ci[0], ci[1], ci[2], ci[3], ci[4], ci[5]
    o = 6
    free = ci[o:o + n]
    o += n
    theta_idx = ci[o:o + nt]
    o += nt
    task = ci[o:o + m]
    o += m
    ip = ci[o:o + nip]
    o += nip
    ir = ci[o:o + nir]
    return n, nt, m, nq, free, theta_idx, task, ip, ir


# --------------------------------------------------------------------------- numpy fallback
def iterate_numpy(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts):
    """One fused iteration in numpy (the fallback; the arithmetic of the unfused solver path).

    Args:
        J6: (6, nv) ``LOCAL_WORLD_ALIGNED`` frame Jacobian at ``x`` (ignored if not ``refactor``).
        pos: (3,) end position at ``x``; erot: (3,) ``log3(R* Rᵀ)`` (zeros without rotation rows).
        x: (nq,) configuration.
        refactor: compute the factorisation at ``x`` (else reuse ``fact``, computed at ``x``).
        polish_left: at convergence, take the polish step (else go to the verdict directly).
        flush: flush |x| < 1e-150 to zero in the update.
        keep: return the factorisation whatever the status (else only when CONVERGED: the
            compiled twin then returns the input ``fact`` in its place, and input arrays in the
            other unused slots).
        fact: ``(jac, qf, rr, f, r, tau, hz, f6)`` when not ``refactor`` (else anything).
        consts: from :func:`pack` / :func:`with_target`.

    Returns:
        ``(status, kkt, ep, er, rs, fact, dx, xn, ev)``; ``fact`` the factorisation at ``x``
        (``jac`` (m, n) task rows/free columns, ``qf`` = [Y Z] (n, n) — the compiled twin holds
        the Householder reflectors there instead, so a ``fact`` is only passed back to the
        implementation that made it —, ``rr`` R (m, m, upper triangle meaningful), ``f`` (m,), ``r``, ``tau`` (n,), ``hz`` (n, n) Hessian of Ψ,
        ``f6`` (6,)); ``dx`` (n,) and ``xn`` (nq,) the step and new iterate (status
        CONTINUE/POLISH); ``ev`` the eigenvalues of eq. (23) (status CONVERGED).
    """
    from vjm_pin.kinematics.screw import psi_hessian_screw
    from vjm_pin.solver.lapack import lapack as _lapack

    global _numpy_iterations
    _numpy_iterations += 1  # auto mode's switch to the compiled kernel (get)
    ci, cf, kz, mask, theta0, vscale, escale = consts
    n, nt, m, _, free, theta_idx, task, ip, ir = _unpack_ci(ci)
    tol, tol_p, kscale, stat_floor, shift, max_step = cf[:6]
    follow, polish_step, rank_tol, pt, big = cf[6] != 0.0, cf[7], cf[8], cf[9:12], cf[12] != 0.0
    empty = np.zeros(0)
    if refactor:
        jfree = J6.take(free, axis=1)
        jac = jfree.take(task, axis=0)
        tau = np.zeros(n)
        tau[:nt] = kz[:nt, :nt] @ (x.take(theta_idx) - theta0)
        if big:
            qf, rf = np.linalg.qr(jac.T, mode="complete")
            rr, info, info2 = rf[:m], 0, 0
        else:
            qr, tq, _, info = _lapack.dgeqrf(jac.T)
            qfull = np.zeros((n, n), order="F")
            qfull[:, :m] = qr
            qf, _, info2 = _lapack.dorgqr(qfull, tq)
            rr = qr[:m]
        if info or info2:
            return FACTOR_FAIL, 0.0, 0.0, 0.0, 0.0, None, empty, empty, empty
        f, info = _lapack.dtrtrs(rr, qf[:, :m].T @ tau)
        if info:
            return FACTOR_FAIL, 0.0, 0.0, 0.0, 0.0, None, empty, empty, empty
        r = tau - jac.T @ f
        f6 = np.zeros(6)
        f6[task] = f
        hz = psi_hessian_screw(jfree, f6, mask)
        fact = (jac, qf, rr, f, r, tau, hz, f6)
    else:
        jac, qf, rr, f, r, tau, hz, f6 = fact
    y, z = qf[:, :m], qf[:, m:]
    e = np.concatenate([pt - pos, erot]).take(task)
    ae = np.abs(e)
    ep = ae[ip].max() if ip.size else 0.0
    er = ae[ir].max() if ir.size else 0.0
    rs = np.abs(r).max()
    es = e / escale
    kkt = math.sqrt(es @ es) + math.sqrt(r @ r) / kscale
    converged = ep <= 0.01 * tol_p and er <= 0.01 * tol and rs <= tol * max(np.abs(tau).max(), stat_floor)
    w = kz - hz
    red = z.T @ w @ z
    if not converged:
        if follow:  # ½(red + redᵀ) − shift·I ≻ 0
            sym = red + red.T
            sym.flat[np.arange(n - m) * (n - m + 1)] -= 2.0 * shift
            if big:
                try:
                    np.linalg.cholesky(sym)
                except np.linalg.LinAlgError:
                    return STEP_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
            elif _lapack.dpotrf(sym, overwrite_a=1)[1]:
                return STEP_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
        dx = _null_space_step(w, red, y, z, rr, e, r, big, _lapack)
        if dx is None:
            return STEP_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
        smax = np.abs(dx / vscale).max()
        if not smax <= max_step:  # also catches NaN
            return STEP_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
        return CONTINUE, kkt, ep, er, rs, fact, dx, _moved(x, free, dx, flush), empty
    if polish_left:
        dx = _null_space_step(w, red, y, z, rr, e, r, big, _lapack)
        if dx is not None and np.all(np.isfinite(dx)) and np.abs(dx / vscale).max() > polish_step:
            return POLISH, kkt, ep, er, rs, fact, dx, _moved(x, free, dx, flush), empty
    _, sv, _, info = _lapack.dgesdd(np.triu(rr[:, :m]), compute_uv=0)
    if info or not sv[-1] > rank_tol * sv[0]:  # descending
        return RANK_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
    neg = -red
    if big:
        ev = np.linalg.eigvalsh(0.5 * (neg + neg.T))
    else:
        ev, _, info = _lapack.dsyevd(0.5 * (neg + neg.T), compute_v=0)
        if info:
            return RANK_FAIL, kkt, ep, er, rs, fact, empty, empty, empty
    return CONVERGED, kkt, ep, er, rs, fact, empty, empty, ev


def _null_space_step(w, red, y, z, rr, e, r, big, _lapack):
    """``δx = Y p_Y − Z p_Z`` with ``Rᵀ p_Y = e``, ``(ZᵀWZ) p_Z = Zᵀ(r + W Y p_Y)``; None if singular."""
    py, info = _lapack.dtrtrs(rr, e, trans=1)
    if info:
        return None
    dy = y @ py
    rhs = z.T @ (r + w @ dy)
    if big:
        try:
            pz = np.linalg.solve(red, rhs)
        except np.linalg.LinAlgError:
            return None
    else:
        _, _, pz, info = _lapack.dgesv(red, rhs)
        if info:
            return None
    return dy - z @ pz


def _moved(x, free, dx, flush):
    xn = x.copy()
    xn[free] += dx
    if flush:
        xn[np.abs(xn) < 1e-150] = 0.0
    return xn


# --------------------------------------------------------------------------- compiled kernel
def _iterate_loops(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, ci, cf, kz, mask, theta0, vscale, escale):
    """The compiled twin of :func:`iterate_numpy` (same contract; ``consts`` passed unpacked):
    :func:`_iterate_body` with the whole verdict."""
    return _iterate_body(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, ci, cf, kz, mask, theta0, vscale,
                         escale, False)


def _iterate_body(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, ci, cf, kz, mask, theta0, vscale, escale,
                  lazy):
    """:func:`_iterate_loops`; ``lazy``: at convergence neither the rank test nor the eigenvalues, ``ev``
    holds the matrix of eq. (23) ``−½(ZᵀWZ + (ZᵀWZ)ᵀ)`` row by row instead (``nz²``; RANK_FAIL still
    when it is not finite): :func:`_iterate_into` decides the verdict.

    Plain loops (numba) and no explicit ``Q``: the reflectors ``H_k = I − τ_k v_k v_kᵀ`` of the QR
    are kept (``fact[1]``: rows ``v_k``, last row ``τ``) and applied where ``Q`` would multiply,
    ``Qᵀ W Q`` on both sides (``4 m n²`` flops instead of ``2 n² (n − m)``; its trailing block is
    ``ZᵀWZ``); own Cholesky and partially pivoted LU (``dpotrf`` / ``dgesv`` semantics: failure on
    a non-positive / an exactly zero pivot); numba's ``np.linalg.svd`` / ``eigvalsh`` (LAPACK)
    for the verdict."""
    n, nt, m, nip, nir = ci[0], ci[1], ci[2], ci[3], ci[4]
    free = ci[6:6 + n]
    theta_idx = ci[6 + n:6 + n + nt]
    task = ci[6 + n + nt:6 + n + nt + m]
    ip = ci[6 + n + nt + m:6 + n + nt + m + nip]
    ir = ci[6 + n + nt + m + nip:6 + n + nt + m + nip + nir]
    shift, max_step = cf[4], cf[5]
    follow, polish_step, rank_tol = cf[6] != 0.0, cf[7], cf[8]
    nz = n - m
    # unused result slots hold input arrays (no new array to box: numba boxes a new array
    # through a pickled dtype, ~µs each); the factorisation is returned when kept or converged
    fact_in = fact
    empty = fact_in[3]
    if refactor:
        jfree = np.empty((6, n))
        for a_ in range(6):
            for b in range(n):
                jfree[a_, b] = J6[a_, free[b]]
        jac = np.empty((m, n))
        for i in range(m):
            for c in range(n):
                jac[i, c] = jfree[task[i], c]
        tau = np.zeros(n)
        _spring_gradient(kz, x, theta_idx, theta0, nt, tau)
        hh = _qr_t(jac, m, n)
        ok, rr, f, r, f6 = _multiplier(jac, hh, tau, task, m, n)
        if not ok:
            return FACTOR_FAIL, 0.0, 0.0, 0.0, 0.0, fact, empty, empty, empty
        hz = _hessian(jfree, f6, mask, n)
        fact = (jac, hh, rr, f, r, tau, hz, f6)
    jac, hh, rr, f, r, tau, hz, f6 = fact
    e, ep, er, rs, kkt, converged = _progress(pos, erot, ip, ir, task, cf, escale, r, tau)
    # Qᵀ W Q, W = K − H: its trailing block is ZᵀWZ, its block [m:, :m] is ZᵀWY. Both sides as
    # left applications of the reflectors (row operations: contiguous, vectorisable loops):
    # A = Qᵀ W, then Qᵀ Aᵀ = (Qᵀ W Q)ᵀ
    wt = np.empty((n, n))
    _qwq_t(hh, hz, kz, m, n, wt)
    if not converged:
        if follow:  # Cholesky of (red + redᵀ) − 2·shift·I, red = ZᵀWZ
            if not _shifted_cholesky(wt, m, nz, shift, np.empty((nz, nz)), np.empty(nz)):
                return STEP_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty
        ok, dx = _step_t(wt, hh, rr, e, r, n, m)
        if not ok:
            return STEP_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty
        smax = 0.0
        for c in range(n):
            v = abs(dx[c] / vscale[c])
            if not v <= smax:  # NaN propagates
                smax = v
        if not smax <= max_step:
            return STEP_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty
        return CONTINUE, kkt, ep, er, rs, fact if keep else fact_in, dx if keep else empty, _moved_loops(x, free, dx, flush), empty
    if polish_left:
        ok, dx = _step_t(wt, hh, rr, e, r, n, m)
        if ok:
            finite = True
            smax = 0.0
            for c in range(n):
                if not math.isfinite(dx[c]):
                    finite = False
                smax = max(smax, abs(dx[c] / vscale[c]))
            if finite and smax > polish_step:
                return POLISH, kkt, ep, er, rs, fact if keep else fact_in, dx if keep else empty, _moved_loops(x, free, dx, flush), empty
    if not lazy and not _full_rank(rr, m, rank_tol):
        return RANK_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty
    sym = np.empty((nz, nz))
    for i in range(nz):
        for j in range(nz):
            v = 0.5 * (-wt[m + j, m + i] + -wt[m + i, m + j])
            if not math.isfinite(v):
                return RANK_FAIL, kkt, ep, er, rs, fact if keep else fact_in, empty, empty, empty
            sym[i, j] = v
    if lazy:  # (the step slot: (Qᵀ W Q)ᵀ at the convergence, row by row, for _iterations_into's ws[11])
        return CONVERGED, kkt, ep, er, rs, fact, wt.ravel(), empty, sym.ravel()
    ev = np.linalg.eigvalsh(sym)
    return CONVERGED, kkt, ep, er, rs, fact, empty, empty, ev


def _spring_gradient(kz, x, theta_idx, theta0, nt, tau):
    """``τ[:nθ] = K_θ (θ − θ₀)`` into ``tau``: each entry the sum over ``j`` in index order of
    ``K[i, j]·(x[θ_j] − θ₀_j)`` (the difference computed once per ``j``: the same value), four rows at a time
    (independent chains instead of one: the same numbers, not one sum after the other)."""
    dth = np.empty(nt)
    for j in range(nt):
        dth[j] = x[theta_idx[j]] - theta0[j]
    i = 0
    while i + 4 <= nt:
        k0 = kz[i]
        k1 = kz[i + 1]
        k2 = kz[i + 2]
        k3 = kz[i + 3]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        for j in range(nt):
            dj = dth[j]
            s0 += k0[j] * dj
            s1 += k1[j] * dj
            s2 += k2[j] * dj
            s3 += k3[j] * dj
        tau[i] = s0
        tau[i + 1] = s1
        tau[i + 2] = s2
        tau[i + 3] = s3
        i += 4
    while i < nt:
        s = 0.0
        for j in range(nt):
            s += kz[i, j] * dth[j]
        tau[i] = s
        i += 1


def _qr_t(jac, m, n):
    """Householder QR of ``Jᵀ`` (n × m), dgeqr2 / dlarfg: row k of ``hh`` is column k of ``Jᵀ``,
    then the reflector ``v_k`` (``v_k[k] = 1`` implicit, entries < k unused); ``hh[m, k] = τ_k``."""
    hh = np.empty((m + 1, n))
    for i in range(m):
        for c in range(n):
            hh[i, c] = jac[i, c]
    for c in range(n):
        hh[m, c] = 0.0
    for k in range(m):
        alpha = hh[k, k]
        xn2 = 0.0
        for i in range(k + 1, n):
            xn2 += hh[k, i] * hh[k, i]
        xnorm = math.sqrt(xn2)
        if xnorm == 0.0:
            hh[m, k] = 0.0
        else:
            beta = -math.copysign(math.hypot(alpha, xnorm), alpha)
            t = (beta - alpha) / beta
            hh[m, k] = t
            scal = 1.0 / (alpha - beta)
            for i in range(k + 1, n):
                hh[k, i] *= scal
            hh[k, k] = beta
            for j in range(k + 1, m):  # apply H_k to the remaining columns of Jᵀ
                s = hh[j, k]
                for i in range(k + 1, n):
                    s += hh[j, i] * hh[k, i]
                s *= t
                hh[j, k] -= s
                for i in range(k + 1, n):
                    hh[j, i] -= s * hh[k, i]
    return hh


def _multiplier(jac, hh, tau, task, m, n):
    """The multiplier ``F`` of ``R F = Yᵀ ∇E = (Qᵀ ∇E)[:m]``, the residual ``r = ∇E − Jᵀ F`` and
    ``F`` in the six wrench slots: ``(ok, R, F, r, F6)``; not ok where ``R`` has a zero pivot."""
    rr = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            rr[i, j] = hh[j, i]
    for i in range(m):
        if rr[i, i] == 0.0:
            return False, rr, np.zeros(m), tau, np.zeros(m)
    f = _back_substitute(rr, _apply_qt(hh, tau, m, n), m)
    r = tau.copy()
    for c in range(n):
        s = 0.0
        for i in range(m):
            s += jac[i, c] * f[i]
        r[c] -= s
    f6 = np.zeros(6)
    for i in range(m):
        f6[task[i]] = f[i]
    return True, rr, f, r, f6


def _back_substitute(rr, y, m):
    """``x`` of ``R x = y[:m]`` (``R`` upper triangular, m × m)."""
    x = np.zeros(m)
    for i in range(m - 1, -1, -1):
        s = y[i]
        for j in range(i + 1, m):
            s -= rr[i, j] * x[j]
        x[i] = s / rr[i, i]
    return x


def _hessian(jfree, f6, mask, n):
    """The (θ, q)-ordered Hessian of Ψ in screw form (kinematics/screw.py): row by row, both cases of
    the support mask computed and one selected (no branch in the inner loop), every entry the same
    expression in the same order (:func:`vjm_pin.solver.chain_kernel._hessian_rows`: the same bits)."""
    fx, fy, fz, mx, my, mz = f6[0], f6[1], f6[2], f6[3], f6[4], f6[5]
    d = np.empty((3, n))
    em = np.empty((3, n))
    w = np.empty((3, n))
    for b in range(n):
        v0, v1, v2 = jfree[0, b], jfree[1, b], jfree[2, b]
        w0, w1, w2 = jfree[3, b], jfree[4, b], jfree[5, b]
        d[0, b] = fz * v1 - fy * v2
        d[1, b] = -fz * v0 + fx * v2
        d[2, b] = fy * v0 - fx * v1
        em[0, b] = mz * w1 - my * w2
        em[1, b] = -mz * w0 + mx * w2
        em[2, b] = my * w0 - mx * w1
        w[0, b] = w0
        w[1, b] = w1
        w[2, b] = w2
    d0, d1, d2 = d[0], d[1], d[2]
    wa, wb, wc = w[0], w[1], w[2]
    hz = np.empty((n, n))
    for i in range(n):
        di0, di1, di2 = d0[i], d1[i], d2[i]
        ei0, ei1, ei2 = em[0, i], em[1, i], em[2, i]
        wi0, wi1, wi2 = wa[i], wb[i], wc[i]
        row = hz[i]
        mrow = mask[i]
        for j in range(n):
            ta = wa[j] * di0 + wb[j] * di1 + wc[j] * di2 + (ei0 * wa[j] + ei1 * wb[j] + ei2 * wc[j])
            tb = wi0 * d0[j] + wi1 * d1[j] + wi2 * d2[j]
            row[j] = ta if mrow[j] else tb
    return hz


def _progress(pos, erot, ip, ir, task, cf, escale, r, tau):
    """Task error and convergence quantities: ``(e, ep, er, rs, kkt, converged)``."""
    m = task.shape[0]
    n = r.shape[0]
    tol, tol_p, kscale, stat_floor = cf[0], cf[1], cf[2], cf[3]
    e = np.empty(m)
    for i in range(m):
        t_ = task[i]
        e[i] = cf[9 + t_] - pos[t_] if t_ < 3 else erot[t_ - 3]
    ep = 0.0
    for i in ip:
        ep = max(ep, abs(e[i]))
    er = 0.0
    for i in ir:
        er = max(er, abs(e[i]))
    rs = 0.0
    r2 = 0.0
    taumax = 0.0
    for c in range(n):
        rs = max(rs, abs(r[c]))
        r2 += r[c] * r[c]
        taumax = max(taumax, abs(tau[c]))
    es2 = 0.0
    for i in range(m):
        es2 += (e[i] / escale[i]) ** 2
    kkt = math.sqrt(es2) + math.sqrt(r2) / kscale
    converged = ep <= 0.01 * tol_p and er <= 0.01 * tol and rs <= tol * max(taumax, stat_floor)
    return e, ep, er, rs, kkt, converged


def _full_rank(rr, m, rank_tol):
    """The rank test of ``J`` on ``R``: finite, and ``σ_min > rank_tol · σ_max``."""
    ru = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            if not math.isfinite(rr[i, j]):
                return False
            ru[i, j] = rr[i, j]
    sv = np.linalg.svd(ru)[1]
    return sv[m - 1] > rank_tol * sv[0]


def _qwq_t(hh, hz, kz, m, n, wt):
    """``wt ← (Qᵀ W Q)ᵀ``, ``W = K − H`` (n, n), from the reflectors ``hh`` of ``Jᵀ``: ``A = Qᵀ W``
    then ``Qᵀ Aᵀ`` (row operations only: contiguous, vectorisable loops; ``4 m n²`` flops). Its
    trailing block is ``(ZᵀWZ)ᵀ``, its block ``[:m, m:]`` is ``(ZᵀWY)ᵀ``. The one implementation of the
    corrector (:func:`_iterate_body`) and of the curve point's tangent
    (:func:`vjm_pin.analysis.point_kernel._ns_tangent`): on the same ``hh``, ``H``, ``K`` the same bits."""
    wq = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            wq[i, j] = kz[i, j] - hz[i, j]
    _reflect_rows(hh, wq, m, n)
    for i in range(n):
        for j in range(n):
            wt[i, j] = wq[j, i]
    _reflect_rows(hh, wt, m, n)


def _reflect_rows(hh, a, m, n):
    """``a ← Qᵀ a = H_{m−1} … H_0 a`` in place for an (n, n) array ``a`` (row operations)."""
    s = np.empty(n)
    for k in range(m):
        t = hh[m, k]
        if t == 0.0:
            continue
        for c in range(n):
            s[c] = a[k, c]
        for i in range(k + 1, n):
            v = hh[k, i]
            for c in range(n):
                s[c] += v * a[i, c]
        for c in range(n):
            s[c] *= t
            a[k, c] -= s[c]
        for i in range(k + 1, n):
            v = hh[k, i]
            for c in range(n):
                a[i, c] -= s[c] * v


def _q_vector(hh, v, m, n, transposed):
    """``Qᵀ v`` (``transposed``) or ``Q v`` in place, ``Q = H_0 ⋯ H_{m−1}`` from the reflectors ``hh``
    (``H_k = I − τ_k v_k v_kᵀ``, ``v_k[k] = 1``, ``v_k[i] = hh[k, i]`` for ``i > k``, ``τ_k = hh[m, k]``)."""
    for kk in range(m):
        k = kk if transposed else m - 1 - kk
        t = hh[m, k]
        if t == 0.0:
            continue
        s = v[k]
        for i in range(k + 1, n):
            s += hh[k, i] * v[i]
        s *= t
        v[k] -= s
        for i in range(k + 1, n):
            v[i] -= s * hh[k, i]


def _apply_qt(hh, v, m, n):
    """``Qᵀ v = H_{m−1} … H_0 v`` from the reflectors ``hh`` (see :func:`_iterate_loops`), a new array."""
    out = v.copy()
    _q_vector(hh, out, m, n, True)
    return out


def _lu_eliminate(a, y, k):
    """In place: the LU factorisation with partial pivoting of ``a`` (k × k; ``dgesv``: ``L`` below the
    diagonal, unit diagonal implied, ``U`` on and above it) with its row swaps and the forward
    elimination applied to ``y`` (k,): ``U x = y`` then gives ``a⁻¹ y₀``. False on an exactly zero
    pivot (``a`` and ``y`` partly eliminated)."""
    for c in range(k):
        p = c
        big = abs(a[c, c])
        for i in range(c + 1, k):
            if abs(a[i, c]) > big:
                big = abs(a[i, c])
                p = i
        if a[p, c] == 0.0:
            return False
        if p != c:
            for j in range(k):
                tmp = a[c, j]
                a[c, j] = a[p, j]
                a[p, j] = tmp
            tmp2 = y[c]
            y[c] = y[p]
            y[p] = tmp2
        inv = 1.0 / a[c, c]
        uc = a[c, c + 1:]  # (row views: loops from 0 vectorise, loops from c + 1 do not)
        nk = k - c - 1
        for i in range(c + 1, k):
            lik = a[i, c] * inv
            a[i, c] = lik
            if lik != 0.0:
                ai = a[i, c + 1:]
                for j in range(nk):
                    ai[j] -= lik * uc[j]
                y[i] -= lik * y[c]
    return True


def _shifted_cholesky(wt, m, nz, shift, lt, col):
    """Whether ``(red + redᵀ) − 2·shift·I`` (``red`` = ZᵀWZ, the trailing block of ``wt`` = ``(Qᵀ W Q)ᵀ``)
    has a Cholesky factorisation (``dpotrf``: fails on a non-positive pivot), the ``follow_stable`` test
    of :func:`_iterate_body`. Column by column with the factor stored transposed (``lt[k, i] = L[i, k]``):
    every entry ``s = a_ij − Σ_k L[i, k] L[j, k]`` accumulated in the same order (k ascending) as the
    row-oriented loops, across rows ``i`` at once (contiguous: vectorised): the same numbers. ``lt``
    (nz, nz) and ``col`` (nz,): scratch."""
    for j in range(nz):
        s = wt[m + j, m + j] + wt[m + j, m + j] - 2.0 * shift
        for k in range(j):
            s -= lt[k, j] * lt[k, j]
        if not s > 0.0:
            return False
        dj = math.sqrt(s)
        lt[j, j] = dj
        for i in range(j + 1, nz):
            col[i] = wt[m + j, m + i] + wt[m + i, m + j]
        cj = col[j + 1:]  # (views: loops from 0 vectorise)
        nj = nz - j - 1
        for k in range(j):
            ljk = lt[k, j]
            lk = lt[k, j + 1:]
            for i in range(nj):
                cj[i] -= lk[i] * ljk
        lj = lt[j, j + 1:]
        for i in range(nj):
            lj[i] = cj[i] / dj
    return True


def _step_t(wt, hh, rr, e, r, n, m):
    """Compiled ``δx = Y p_Y − Z p_Z`` (see :func:`_null_space_step`) in the rotated basis, from
    ``wt`` = ``(Qᵀ W Q)ᵀ`` read transposed (no transposed copy): ``Rᵀ p_Y = e``, ``(ZᵀWZ) p_Z =
    (Qᵀ r)[m:] + (ZᵀWY) p_Y`` (LU with partial pivoting, as ``dgesv``; fails on an exactly zero
    pivot), ``δx = Q [p_Y; −p_Z]``: (ok, δx)."""
    nz = n - m
    py = np.zeros(m)
    for i in range(m):  # Rᵀ p_Y = e
        if rr[i, i] == 0.0:
            return False, np.zeros(0)
    for i in range(m):
        s = e[i]
        for j in range(i):
            s -= rr[j, i] * py[j]
        py[i] = s / rr[i, i]
    qr_ = _apply_qt(hh, r, m, n)
    rhs = np.zeros(nz)
    for j in range(nz):
        s = qr_[m + j]
        for i in range(m):
            s += wt[i, m + j] * py[i]
        rhs[j] = s
    lu = np.empty((nz, nz))
    for i in range(nz):
        for j in range(nz):
            lu[i, j] = wt[m + j, m + i]
    if not _lu_eliminate(lu, rhs, nz):
        return False, np.zeros(0)
    pz = _back_substitute(lu, rhs, nz)
    dx = np.empty(n)
    for i in range(m):
        dx[i] = py[i]
    for j in range(nz):
        dx[m + j] = -pz[j]
    for k in range(m - 1, -1, -1):
        t = hh[m, k]
        if t == 0.0:
            continue
        s = dx[k]
        for i in range(k + 1, n):
            s += hh[k, i] * dx[i]
        s *= t
        dx[k] -= s
        for i in range(k + 1, n):
            dx[i] -= s * hh[k, i]
    return True, dx


def _moved_loops(x, free, dx, flush):
    xn = x.copy()
    for c in range(free.shape[0]):
        xn[free[c]] += dx[c]
    if flush:
        for i in range(xn.shape[0]):
            if abs(xn[i]) < 1e-150:
                xn[i] = 0.0
    return xn


_iterate_jit = None  # the compiled _iterate_body, set by lean() before it compiles _iterate_into
_eig_jit = None  # the compiled _sym_eigvalsh, set by lean()

#: Margin of the stability certificate of :func:`_certified_stable`, relative to ``‖A‖_F + thr``: far
#: above the rounding of a Cholesky factorisation and of ``dsyevd`` (``~n²ε‖A‖``), so a certified
#: verdict is the one the eigenvalues give.
CERT_MARGIN = 1e-10


def _iterate_into(J6, pos, erot, x, refactor, polish_left, flush, fact, ci, cf, kz, mask, theta0, vscale, escale,
                  xout, ws, thr, defer):
    """:func:`_iterate_loops` (``keep`` False) with its arrays written into the caller's buffers
    instead of returned (compiled by :func:`lean`): ``xout`` (nq,) the new iterate (status CONTINUE /
    POLISH); ``ws`` (:func:`workspace`) = ``(jac, hh, rr, f, r, tau, hz, f6, ev, sym, info, wt)`` shaped as
    the compiled kernel's factorisation, the eigenvalues of eq. (23), its matrix and ``info`` (2,)
    (status CONVERGED; ``wt`` (n, n) is :func:`_iterations_into`'s alone, not written here). Returns ``(status, kkt, ep, er, rs)``: no array crosses back into Python
    (each returned array costs its boxing, ~1 µs).

    At convergence the same verdicts as :func:`_iterate_loops`, cheaper where they are clear-cut:
    the rank test passes without the SVD when ``rank_tol · ‖R‖_F ‖R⁻¹‖_F < ½`` (``σ_max ≤ ‖R‖_F``,
    ``σ_min ≥ 1/‖R⁻¹‖_F``); ``info[1]`` holds that bound of ``cond(J)`` (inf when not computable).
    ``defer``: the verdict "stable" (every eigenvalue of ``sym`` below ``−thr``) is certified by a
    Cholesky factorisation of ``−sym − (thr + δ)·I`` (:func:`_certified_stable`) and the eigenvalues
    are left to the caller (``info[0]`` = 1: ``ev`` not written; :func:`spectrum` of ``sym`` gives
    them, bit for bit those of ``_iterate_loops``); otherwise (``info[0]`` = 0) ``ev`` holds them."""
    status, kkt, ep, er, rs, kf, _dx, xn, ev = _iterate_jit(
        J6, pos, erot, x, refactor, polish_left, flush, False, fact, ci, cf, kz, mask, theta0, vscale, escale, True
    )
    if status == CONTINUE or status == POLISH:
        for i in range(xn.shape[0]):
            xout[i] = xn[i]
    elif status == CONVERGED:
        rr = kf[2]
        m = rr.shape[0]
        cond = _cond_bound(rr, m)
        if not cf[8] * cond < 0.5 and not _full_rank(rr, m, cf[8]):
            return RANK_FAIL, kkt, ep, er, rs
        nz = ci[0] - m
        sym = ev.reshape((nz, nz))
        ws[0][:, :] = kf[0]
        ws[1][:, :] = kf[1]
        ws[2][:, :] = kf[2]
        ws[3][:] = kf[3]
        ws[4][:] = kf[4]
        ws[5][:] = kf[5]
        ws[6][:, :] = kf[6]
        ws[7][:] = kf[7]
        ws[9][:, :] = sym
        info = ws[10]
        info[1] = cond
        if defer and _certified_stable(sym, nz, thr):
            info[0] = 1.0
        else:
            info[0] = 0.0
            ws[8][:] = np.linalg.eigvalsh(sym)
    return status, kkt, ep, er, rs


def _cond_bound(rr, m):
    """``‖R‖_F ‖R⁻¹‖_F`` (≥ ``σ_max/σ_min``) of the upper triangle of ``R`` (m × m); inf when ``R`` is
    not finite or has a zero pivot (the caller's test then fails)."""
    nr = 0.0
    for i in range(m):
        for j in range(i, m):
            nr += rr[i, j] * rr[i, j]
    ni = 0.0
    col = np.empty(m)
    for i in range(m):
        if rr[i, i] == 0.0:  # (numba raises on a division by zero)
            return math.inf
    for c in range(m):  # column c of R⁻¹: R y = e_c
        for i in range(m - 1, -1, -1):
            s = 1.0 if i == c else 0.0
            for j in range(i + 1, m):
                s -= rr[i, j] * col[j]
            col[i] = s / rr[i, i]
            ni += col[i] * col[i]
    v = math.sqrt(nr) * math.sqrt(ni)
    return v if math.isfinite(v) else math.inf


def _certified_stable(sym, nz, thr):
    """True when ``A = −sym − (thr + δ)·I`` has a Cholesky factorisation, ``δ`` = :data:`CERT_MARGIN`
    ``· (‖sym‖_F + thr)``: then every eigenvalue of ``sym`` is below ``−thr − δ + ‖E‖`` with the
    factorisation's backward error ``‖E‖ ≪ δ``, and those ``dsyevd`` computes are below ``−thr``
    (False: undecided, the caller computes the eigenvalues)."""
    fro = 0.0
    for i in range(nz):
        for j in range(nz):
            fro += sym[i, j] * sym[i, j]
    sh = thr + CERT_MARGIN * (math.sqrt(fro) + thr)
    # column by column, the factor stored transposed (lt[k, i] = L[i, k]): every entry accumulated in
    # the same order (k ascending) as the row-oriented loops, across rows at once (vectorised); sym is
    # exactly symmetric (:func:`_iterate_body` sums the two mirrored entries), row j read for column j
    lt = np.empty((nz, nz))
    col = np.empty(nz)
    for j in range(nz):
        s = -sym[j, j] - sh
        for k in range(j):
            s -= lt[k, j] * lt[k, j]
        if not s > 0.0:
            return False
        dj = math.sqrt(s)
        lt[j, j] = dj
        sj = sym[j, j + 1:]
        cj = col[j + 1:]  # (views: loops from 0 vectorise)
        nj = nz - j - 1
        for i in range(nj):
            cj[i] = -sj[i]
        for k in range(j):
            ljk = lt[k, j]
            lk = lt[k, j + 1:]
            for i in range(nj):
                cj[i] -= lk[i] * ljk
        lj = lt[j, j + 1:]
        for i in range(nj):
            lj[i] = cj[i] / dj
    return True


def _sym_eigvalsh(sym):
    """The eigenvalues (ascending) of the symmetric ``sym`` as :func:`_iterate_loops` computes them."""
    return np.linalg.eigvalsh(sym)


def _restore_step(pos, erot, jac6, x, task, free, minv, escale, vscale, pt, lim, max_step, flush, xout):
    """One step of the least-energy restoration of
    :meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._restore` at ``x`` (end position ``pos``,
    ``erot`` = ``log3(R* Rᵀ)`` or zeros, frame Jacobian ``jac6`` (6, nv)), compiled by :func:`restorer`:
    the task error ``e``; done (1) when ``max|e / escale| ≤ lim``; else ``δ = M⁻¹Jᵀ(J M⁻¹ Jᵀ)⁻¹ e``
    (``J`` task rows, free columns; LU with partial pivoting, failing on an exactly zero pivot as
    ``numpy.linalg.solve``), damped to ``max|δ / vscale| ≤ max_step``, ``xout = x + δ`` (free
    coordinates; entries below 1e-150 flushed when ``flush``): status 0; -1 when singular or not
    finite. The same arithmetic as the numpy loop up to the summation order of its products."""
    m = task.shape[0]
    n = free.shape[0]
    e = np.empty(m)
    for i in range(m):
        t_ = task[i]
        e[i] = pt[t_] - pos[t_] if t_ < 3 else erot[t_ - 3]
    scaled = 0.0
    for i in range(m):
        v = abs(e[i] / escale[i])
        if not v <= scaled:  # NaN propagates
            scaled = v
    if scaled <= lim:
        return 1
    jz = np.empty((m, n))
    for i in range(m):
        for c in range(n):
            jz[i, c] = jac6[task[i], free[c]]
    b = np.zeros((m, n))  # J M⁻¹
    for i in range(m):
        for k in range(n):
            v = jz[i, k]
            for c in range(n):
                b[i, c] += v * minv[k, c]
    a = np.zeros((m, m))  # J M⁻¹ Jᵀ
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for c in range(n):
                acc += b[i, c] * jz[j, c]
            a[i, j] = acc
    y = e.copy()
    if not _lu_eliminate(a, y, m):  # LU with partial pivoting (dgesv)
        return -1
    for i in range(m - 1, -1, -1):
        acc = y[i]
        for j in range(i + 1, m):
            acc -= a[i, j] * y[j]
        y[i] = acc / a[i, i]
    delta = np.zeros(n)  # (M⁻¹ Jᵀ) y
    for k in range(n):
        acc = 0.0
        for i in range(m):
            s_ = 0.0
            for c in range(n):
                s_ += minv[k, c] * jz[i, c]
            acc += s_ * y[i]
        delta[k] = acc
    big = 0.0
    for c in range(n):
        if not math.isfinite(delta[c]):
            return -1
        big = max(big, abs(delta[c] / vscale[c]))
    if big > max_step:
        f = max_step / big
        for c in range(n):
            delta[c] *= f
    for i in range(x.shape[0]):
        xout[i] = x[i]
    for c in range(n):
        xout[free[c]] += delta[c]
    if flush:
        for i in range(xout.shape[0]):
            if abs(xout[i]) < 1e-150:
                xout[i] = 0.0
    return 0


#: Codes of :func:`_iterations_into`: the local iteration gave way / converged.
GAVE_WAY = 0
DONE = 1

_fk_jit = None  # the compiled vjm_pin.kinematics.compiled_chain.forward, set by looped()
_roterr_jit = None  # the compiled compiled_chain.rotation_error, set by looped()


def _same_bits(a, b):
    """``a.tobytes() == b.tobytes()`` for float64 vectors."""
    if a.shape[0] != b.shape[0]:
        return False
    av = a.view(np.int64)
    bv = b.view(np.int64)
    for i in range(a.shape[0]):
        if av[i] != bv[i]:
            return False
    return True


def _copy1(dst, src):
    """``dst[:] = src`` (explicit loop: cheaper than numba's slice assignment at these sizes)."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


def _copy2(dst, src):
    """``dst[:, :] = src`` (explicit loops)."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


def _iterations_into(x0, kx, have, kf, kpos, krot, geo, jinfo, rt, rot, flush, ci, cf, kz, mask, theta0, vscale,
                     escale, xout, ws, kbuf, thr, defer, lim):
    """The whole plain local iteration of :meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._fused_iterations`
    (compiled by :func:`looped`): per iteration the end placement and frame Jacobian by the compiled
    forward kinematics of :mod:`vjm_pin.kinematics.compiled_chain` (``geo``, ``jinfo``: its
    :class:`~vjm_pin.kinematics.compiled_chain.ChainTable`), the orientation error ``log3(R* Rᵀ)``
    (``rt`` = R*, when ``rot``) and :func:`_iterate_into`'s iteration, with the solver's bookkeeping:
    the polish counter (``lim[1]`` polish steps at most), the progress test (the KKT norm halves at
    every step after the first, unless ``lim[2]`` > 0: at most that many relaxed steps; else at most
    ``lim[0]`` steps), the verdict of a convergence (rank test, stable: every eigenvalue of eq. (23)
    below ``−thr`` when ``cf`` asks for stable equilibria). A warm start: where ``x`` is bit for bit
    ``kx`` and ``have``, the factorisation ``kf`` and placement ``(kpos, krot)`` kept there are used
    (no kinematics, no factorisation), as the solver does.

    Writes at convergence the equilibrium into ``xout``, the factorisation, eigenvalues, matrix of
    eq. (23), ``info`` and the converged iteration's ``(Qᵀ W Q)ᵀ`` (:func:`_qwq_t`, ``ws[11]``: the curve
    point's tangent reads it instead of computing it again) into ``ws`` (:func:`_iterate_into`'s layout) and the Jacobian, position
    and rotation there into ``kbuf`` = ``(j6, pos, rot)`` (unless reused). Returns ``(code,
    iterations, counted, kkt, ep, er, rs, reused)``: ``code`` :data:`DONE` or :data:`GAVE_WAY`;
    ``counted`` the last iteration the solver records in ``_fast_its`` (−1: none); ``reused``: the
    converged iterate is ``kx`` (the kept placement and Jacobian are its state)."""
    max_iter, polish_max, relaxed = lim[0], lim[1], lim[2]
    j6, pos, rotm = kbuf[0], kbuf[1], kbuf[2]
    x = x0.copy()
    erot = np.zeros(3)
    kkt_prev = math.inf
    polish = 0
    counted = -1
    follow = cf[6] != 0.0
    n = ci[0]
    for it in range(max_iter + 1 + polish_max):
        reuse = have and _same_bits(x, kx)
        if reuse:
            if rot:
                _roterr_jit(rt, krot, erot)
            status, kkt, ep, er, rs, kf2, _dx, xn, ev = _iterate_jit(
                j6, kpos, erot, x, False, polish < polish_max, flush, False, kf, ci, cf, kz, mask, theta0, vscale,
                escale, True)
        else:
            _fk_jit(x, geo, jinfo, j6, pos, rotm)
            if rot:
                _roterr_jit(rt, rotm, erot)
            status, kkt, ep, er, rs, kf2, _dx, xn, ev = _iterate_jit(
                j6, pos, erot, x, True, polish < polish_max, flush, False, kf, ci, cf, kz, mask, theta0, vscale,
                escale, True)
        if status == FACTOR_FAIL or status == RANK_FAIL:
            return GAVE_WAY, it, counted, kkt, ep, er, rs, reuse
        if status == POLISH:
            polish += 1
            x = xn
            kkt_prev = math.inf
            continue
        if status == CONVERGED:
            rr = kf2[2]
            m = rr.shape[0]
            cond = _cond_bound(rr, m)
            if not cf[8] * cond < 0.5 and not _full_rank(rr, m, cf[8]):
                return GAVE_WAY, it, counted, kkt, ep, er, rs, reuse
            nz = n - m
            sym = ev.reshape((nz, nz))
            _copy2(ws[0], kf2[0])
            _copy2(ws[1], kf2[1])
            _copy2(ws[2], kf2[2])
            _copy1(ws[3], kf2[3])
            _copy1(ws[4], kf2[4])
            _copy1(ws[5], kf2[5])
            _copy2(ws[6], kf2[6])
            _copy1(ws[7], kf2[7])
            _copy2(ws[9], sym)
            _copy2(ws[11], _dx.reshape((n, n)))
            info = ws[10]
            info[1] = cond
            if defer and _certified_stable(sym, nz, thr):
                info[0] = 1.0
                stable = True
            else:
                info[0] = 0.0
                evs = np.linalg.eigvalsh(sym)
                ws[8][:] = evs
                stable = nz == 0 or evs[nz - 1] < -thr
            if follow and not stable:
                return GAVE_WAY, it, it, kkt, ep, er, rs, reuse
            for i in range(x.shape[0]):
                xout[i] = x[i]
            return DONE, it, counted, kkt, ep, er, rs, reuse
        counted = it
        if (it and relaxed == 0 and not kkt < 0.5 * kkt_prev) or it - polish >= (relaxed if relaxed else max_iter):
            return GAVE_WAY, it, counted, kkt, ep, er, rs, reuse
        if status != CONTINUE:
            return GAVE_WAY, it, counted, kkt, ep, er, rs, reuse
        x = xn
        kkt_prev = kkt
    return GAVE_WAY, max_iter + polish_max, counted, 0.0, 0.0, 0.0, 0.0, False


def _restore_into(x0, geo, jinfo, rt, rot, task, free, minv, escale, vscale, pt, lim, max_step, flush, max_iter,
                  xout, kbuf):
    """The whole least-energy restoration of :meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._restore`
    (compiled by :func:`looped`): up to ``max_iter + 1`` steps of :func:`_restore_step`, each at the
    end placement and frame Jacobian of the compiled forward kinematics (``geo``, ``jinfo``) and the
    orientation error ``log3(R* Rᵀ)`` (``rt`` = R*, when ``rot``). Writes the last iterate into
    ``xout`` and its Jacobian, position and rotation into ``kbuf`` = ``(j6, pos, rot)``. Returns
    ``(status, evaluations)``: 1 restored (``max|e / escale| ≤ lim``), −1 singular or not finite,
    0 the steps ran out (the caller tests the final error); ``evaluations`` the kinematics
    evaluations done (the numpy loop's count)."""
    j6, pos, rotm = kbuf[0], kbuf[1], kbuf[2]
    x = x0.copy()
    xn = np.empty(x.shape[0])
    erot = np.zeros(3)
    evals = 0
    for _ in range(max_iter + 1):
        _fk_jit(x, geo, jinfo, j6, pos, rotm)
        evals += 1
        if rot:
            _roterr_jit(rt, rotm, erot)
        status = _restore_jit(pos, erot, j6, x, task, free, minv, escale, vscale, pt, lim, max_step, flush, xn)
        if status != 0:
            for i in range(x.shape[0]):
                xout[i] = x[i]
            return status, evals
        for i in range(x.shape[0]):
            x[i] = xn[i]
    _fk_jit(x, geo, jinfo, j6, pos, rotm)
    evals += 1
    for i in range(x.shape[0]):
        xout[i] = x[i]
    return 0, evals


_looped = None  # the compiled _iterations_into once built, False when numba is unavailable
_restore_jit = None  # the compiled _restore_step, set by looped()
_restore_looped = None  # the compiled _restore_into, set by looped()


def looped():
    """The compiled :func:`_iterations_into` (kinematics included), or None when numba cannot be
    imported."""
    global _looped
    if _looped is None:
        if lean() is None:
            _looped = False
        else:
            import numba

            from vjm_pin.kinematics import compiled_chain

            fk = compiled_chain.compiled()
            if fk is None:
                _looped = False
            else:
                g = globals()
                opts = {"cache": True, "nogil": True, "error_model": "numpy"}
                g["_fk_jit"], g["_roterr_jit"] = fk[0], fk[2]
                g["_same_bits"] = numba.njit(**opts)(_same_bits)
                g["_copy1"] = numba.njit(**opts)(_copy1)
                g["_copy2"] = numba.njit(**opts)(_copy2)
                g["_restore_jit"] = restorer()
                g["_restore_looped"] = numba.njit(**opts)(_restore_into)
                _looped = numba.njit(**opts)(_iterations_into)
    return _looped or None


def restore_looped():
    """The compiled :func:`_restore_into` (kinematics included), or None when numba cannot be imported."""
    return _restore_looped if looped() is not None else None


_restorer = None  # the compiled _restore_step once built, False when numba is unavailable


def restorer():
    """The compiled :func:`_restore_step`, or None when numba cannot be imported."""
    global _restorer
    if _restorer is None:
        if not _load_compiled():
            _restorer = False
        else:
            import numba

            _restorer = numba.njit(cache=True, nogil=True, error_model="numpy")(_restore_step)
    return _restorer or None


#: The njit helpers of :func:`_iterate_loops`, compiled (in this order) by :func:`_load_compiled`;
#: the chain kernel (:mod:`vjm_pin.solver.chain_kernel`) calls the same ones (not ``_iterate_body``).
_HELPERS = ("_q_vector", "_apply_qt", "_qr_t", "_back_substitute", "_multiplier", "_hessian", "_progress", "_full_rank", "_reflect_rows",
            "_qwq_t", "_lu_eliminate", "_shifted_cholesky", "_step_t", "_moved_loops", "_spring_gradient",
            "_iterate_body")
_lean = None  # the compiled _iterate_into once built, False when numba is unavailable


def lean():
    """The compiled :func:`_iterate_into` (for :meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._corrector`),
    or None when numba cannot be imported."""
    global _lean
    if _lean is None:
        it = _load_compiled()
        disp = getattr(it, "dispatcher", None) if it else None
        if disp is None:
            _lean = False
        else:
            import numba

            g = globals()
            opts = {"cache": True, "nogil": True, "error_model": "numpy"}
            g["_iterate_jit"] = g["_iterate_body"]  # (compiled by _load_compiled)
            g["_cond_bound"] = numba.njit(**opts)(_cond_bound)
            g["_certified_stable"] = numba.njit(**opts)(_certified_stable)
            g["_eig_jit"] = numba.njit(**opts)(_sym_eigvalsh)
            _lean = numba.njit(**opts)(_iterate_into)
    return _lean or None


def spectrum(sym):
    """The eigenvalues (ascending) of the matrix of eq. (23) ``sym`` kept by :func:`_iterate_into` (a
    deferred verdict): compiled, bit for bit those :func:`_iterate_loops` returns."""
    return _eig_jit(sym)


def workspace(ci, nq: int) -> tuple:
    """Fresh buffers ``(xout, ws)`` of :func:`_iterate_into` for the constants ``ci`` (:func:`pack`)."""
    n, m = int(ci[0]), int(ci[2])
    ws = (np.empty((m, n)), np.empty((m + 1, n)), np.empty((m, m)), np.empty(m), np.empty(n), np.empty(n),
          np.empty((n, n)), np.empty(6), np.empty(n - m), np.empty((n - m, n - m)), np.zeros(2), np.empty((n, n)))
    return np.empty(nq), ws


#: Workspaces carved per allocation by :func:`workspace_after` (each buffer a view of a block of this
#: many: one ``numpy.empty`` per buffer kind and block instead of per buffer and solve).
WORKSPACE_BLOCK = 32


def workspace_after(ws: tuple, certified: bool, pool: list) -> tuple:
    """Fresh buffers ``ws`` of :func:`_iterate_into` after a convergence into ``ws`` (whose arrays
    then belong to the caller's caches), as :func:`workspace` lays them out (C-contiguous, writable,
    never handed out before): ``info`` (read at once by the caller), ``wt`` (read by the curve's point
    right after the convergence, before the next call: valid until then) and, for a verdict certified
    without the eigenvalues (``certified``), the eigenvalue buffer (not written) are ``ws``'s own;
    the others are views of blocks of :data:`WORKSPACE_BLOCK` buffers kept in ``pool`` (a list
    owned by one caller's context, used by one thread: ``[blocks, next index]``)."""
    blocks, i = pool if pool else (None, WORKSPACE_BLOCK)
    if i >= WORKSPACE_BLOCK:
        blocks = tuple(np.empty((WORKSPACE_BLOCK,) + ws[k].shape) for k in (0, 1, 2, 3, 4, 5, 6, 7, 9, 8))
        i = 0
    pool[:] = (blocks, i + 1)
    return (blocks[0][i], blocks[1][i], blocks[2][i], blocks[3][i], blocks[4][i], blocks[5][i], blocks[6][i],
            blocks[7][i], ws[8] if certified else blocks[9][i], blocks[8][i], ws[10], ws[11])


def _load_compiled():
    """The compiled iteration (numba, cached on disk), or False when numba cannot be imported."""
    global _compiled, _built
    if _compiled is None:
        try:
            import numba
        except Exception:  # noqa: BLE001 - any import failure: numpy fallback
            _compiled = False
            return _compiled
        if _built is not None:  # built before (and reset by a test): the same dispatchers
            _compiled = _built
            return _compiled
        # numpy's error model: no zero test before every division (each divisor here is nonzero by its
        # guard: a zero pivot, norm or scale is tested first), the same numbers
        opts = {"cache": True, "nogil": True, "error_model": "numpy"}
        g = globals()
        for name in _HELPERS:
            g[name] = numba.njit(**opts)(g[name])
        fn = numba.njit(**opts)(_iterate_loops)
        # long chains: O(n) algebra (chain_kernel), this kernel where it is unsure
        from vjm_pin.solver import chain_kernel

        def iterate_dense(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts):
            return fn(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, *consts)

        def iterate_compiled(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts):
            if consts[0][0] >= chain_kernel.ITERATE_MIN_N:
                return chain_kernel.iterate(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, consts,
                                            iterate_dense)
            return fn(J6, pos, erot, x, refactor, polish_left, flush, keep, fact, *consts)

        iterate_compiled.dispatcher = fn
        _compiled = _built = iterate_compiled
    return _compiled


#: ``auto`` mode: the compiled kernel is loaded once this many fused iterations have run on the
#: numpy twin in this process. Loading numba and the cached machine code costs ~1–2 s (more on a
#: loaded machine); a compiled iteration saves ~0.1–0.5 ms at the orders of VJM chains, so the
#: switch pays off only for long runs (maps, long or finely subdivided curves): a one-shot
#: ``vjm-pin analyze`` or a short curve never imports numba.
JIT_AFTER_ITERATIONS = 2000

_numpy_iterations = 0


_mode_read = (None, "auto")  # (the last VJM_PIN_JIT value read by mode(), its mode)


def mode() -> str:
    """``VJM_PIN_JIT`` read now: ``"0"`` (numpy), ``"1"`` (compiled) or ``"auto"`` (the value's parse
    kept while the value stays the same)."""
    global _mode_read
    raw = os.environ.get("VJM_PIN_JIT")
    last = _mode_read
    if raw == last[0]:
        return last[1]
    v = ("auto" if raw is None else raw).strip().lower()
    if v in ("0", "false", "no", "off"):
        md = "0"
    elif v in ("1", "true", "yes", "on"):
        md = "1"
    else:
        md = "auto"
    _mode_read = (raw, md)
    return md


def loaded() -> bool:
    """True when the compiled kernel is loaded in this process."""
    return bool(_compiled)


def load() -> bool:
    """Load the compiled kernel now (the caller expects a long run); in ``auto`` mode every solver
    uses it from then on. False when numba is not importable (the numpy twin stays in use)."""
    return bool(_load_compiled())


def get(md: str | None = None):
    """The iteration function to use now: :func:`iterate_numpy` when ``VJM_PIN_JIT=0`` or numba is
    not importable; the compiled kernel when ``VJM_PIN_JIT=1``, or in ``auto`` mode when it is
    already loaded (:func:`load`) or :data:`JIT_AFTER_ITERATIONS` numpy iterations have run.
    ``md``: :func:`mode` as read by the caller earlier (a curve reads the environment once), else
    read now."""
    if md is None:
        md = mode()
    if md == "0":
        return iterate_numpy
    if md == "1" or _compiled or (_compiled is None and _numpy_iterations >= JIT_AFTER_ITERATIONS):
        return _load_compiled() or iterate_numpy
    return iterate_numpy
