"""Loaded static equilibrium (paper §4.1, eq. 5–11).

For a prescribed end location ``t`` the unknowns are the wrench ``F`` and the
configuration ``(q, θ)`` that satisfy eq. (5)::

    J_θᵀ F = K_θ (θ − θ₀),    J_qᵀ F = 0,    t = g(q, θ).

This is the stationarity (KKT) system of "minimise the spring energy
E = ½(θ−θ₀)ᵀK_θ(θ−θ₀) subject to g(q, θ) = t", with ``F`` the Lagrange multiplier; a
stable equilibrium is a constrained energy minimum (eq. 23).

Two iterations are offered:

``"fixed-point"`` — the paper's scheme (eq. 9–10), written in increments so that
    orientation errors use ``log3``: ``[[J_θ K_θ⁻¹ J_θᵀ, J_q], [J_qᵀ, 0]] [F; Δq] =
    [e + J_θ(θ − θ₀); 0]``, ``θ⁺ = θ₀ + K_θ⁻¹ J_θᵀ F``. It ignores the Hessians, converges
    linearly far from buckling, stalls next to a bifurcation and is singular for a straight
    chain of rigid links.
``"newton"`` (default) — Newton's method on eq. (5); its Jacobian is the matrix of
    eq. (28). When a stable branch is followed the reduced Hessian is shifted to be
    positive definite (so the step descends the energy) and a step is only accepted if it
    decreases the ℓ₁ merit ``E + ρ‖t − g‖₁`` or, when it is an unmodified Newton step,
    the residual of eq. (5); an energy-increasing step is never taken.

    Every Newton attempt first tries the plain local iteration (:meth:`EquilibriumSolver._fast_newton`):
    unmodified Newton steps of eq. (28) from the start, without restoration, taken only
    while the reduced Hessian is positive definite (stable branch followed) and the step
    is within the step limit, and kept only if the residual of eq. (5) at least halves at
    every step and the converged equilibrium is stable. These are exactly the steps the
    safeguarded iteration accepts by its residual test; when any condition fails the
    attempt restarts from the same start on the safeguarded path. A warm start from a
    neighbouring equilibrium (curve tracing) usually converges in one or two such steps.

Both are wrapped in continuation (``t_i = α_i t + (1−α_i) t₀``, eq. after 10) and
perturbed restarts (small seeded random noise on ``(q, θ)``, §4.1) when an iteration
stalls or converges to an unstable equilibrium. The result says which path was used.
"""

from __future__ import annotations

import copy
import inspect
import math
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack as _lapack

from ..exceptions import InputError, NoEquilibrium, SingularStiffness
from ..kinematics import Kinematics, contract_hessian, deflection, displace, pose_error
from ..model import VjmModel
from .blocks import Blocks, evaluate_blocks, full_wrench, remember_blocks
from .stability import (
    RANK_TOL,
    SCIPY_LAPACK_MAX_N,
    STABILITY_TOL,
    StabilityResult,
    check_stability,
    null_space,
    spectral_norm,
)
from .stiffness import stiffness_from_blocks

METHODS = ("newton", "fixed-point")


@dataclass(frozen=True)
class EquilibriumResult:
    """A loaded equilibrium.

    Attributes:
        x: (nq,) full configuration (m, rad), Pinocchio order.
        q: (n_q,) perfect passive coordinates.
        theta: (n_θ,) spring coordinates.
        wrench: (6,) external wrench applied to the end frame at equilibrium: force (N) at
            the frame origin and moment (N·m), world axes; zero for unconstrained components.
        deflection: (6,) end location minus the unloaded one: (m, world rotation vector rad).
        position: (3,) end frame position (m). rotation: (3, 3) end frame orientation.
        converged: Whether eq. (5) holds to the tolerance.
        iterations: Total iterations over all attempts.
        residuals: ``position`` (m), ``orientation`` (rad), ``statics`` (max |eq. 5 static
            residual|, N·m or N) at the returned configuration.
        energy: Spring energy ½(θ−θ₀)ᵀK_θ(θ−θ₀) (J).
        path: How it was found, e.g. ``"newton"``, ``"newton+continuation(4)"``,
            ``"newton+restart(2)"``, ``"fixed-point"``.
        stability: :class:`StabilityResult` of eq. (23), or None if not evaluated.
    """

    x: np.ndarray
    q: np.ndarray
    theta: np.ndarray
    wrench: np.ndarray
    deflection: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    converged: bool
    iterations: int
    residuals: dict = field(default_factory=dict)
    energy: float = 0.0
    path: str = ""
    stability: StabilityResult | None = None

    @property
    def stable(self) -> bool | None:
        return None if self.stability is None else self.stability.stable

    def residual(self) -> float:
        """Largest of the three residual norms (mixed units; 0 at an exact equilibrium)."""
        return float(max(self.residuals.values())) if self.residuals else float("nan")


def _singular_values(a: np.ndarray) -> np.ndarray:
    """Singular values of a small matrix (LAPACK ``gesdd`` directly; numpy's wrapper costs more)."""
    if a.size:
        _, sv, _, info = _lapack.dgesdd(a, compute_uv=0)
        if not info:
            return sv
    return np.linalg.svd(a, compute_uv=False)


def _as_target(vm, kin, p0, r0, deflection_=None, target=None):
    if (deflection_ is None) == (target is None):
        raise InputError("give exactly one of a deflection or a target pose")
    if deflection_ is not None:
        d = np.asarray(deflection_, dtype=float).ravel()
        if d.size == 3:
            d = np.concatenate([d, np.zeros(3)])
        if d.size != 6:
            raise InputError(f"deflection must have 3 or 6 components (m, rad), got {d.size}")
        if not np.all(np.isfinite(d)):
            raise InputError(f"deflection contains NaN or infinite values: {d.tolist()}")
        free = [i for i in range(6) if i not in vm.task and d[i] != 0.0]
        if free:
            names = ["x", "y", "z", "rx", "ry", "rz"]
            raise InputError(
                f"deflection components {[names[i] for i in free]} are not constrained by this model "
                f"(task is {vm.task_names}): they cannot be prescribed"
            )
        return displace(p0, r0, d)
    p, r = target
    p = np.asarray(p, float)
    r = np.asarray(r, float)
    if p.shape != (3,) or r.shape != (3, 3) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(r))):
        raise InputError("target must be a finite position (3,) and rotation (3, 3)")
    return p, r


class EquilibriumSolver:
    """Solves eq. (5) for one model; keeps a Pinocchio ``Data`` and the reference pose.

    Args:
        vm: The model.
        method: ``"newton"`` (default) or ``"fixed-point"`` (eq. 10).
        tol: Relative tolerance: position error ≤ tol·L_c (L_c = size of the chain),
            orientation error ≤ tol rad, static residual ≤ tol·max(|K_θ(θ−θ₀)|, 1e-6·|K_θ|).
        max_iter: Iterations per attempt.
        restarts: Perturbed restarts after a stall or an unstable result.
        perturbation: Size of the restart noise (rad; ×L_c·1e-3 for prismatic coordinates).
        seed: Seed of the restart noise (results are reproducible).
        follow_stable: Prefer stable equilibria: inertia-corrected Newton steps and restarts
            when the converged equilibrium is unstable (eq. 23).
    """

    def __init__(
        self,
        vm: VjmModel,
        *,
        method: str = "newton",
        tol: float = 1e-10,
        max_iter: int = 60,
        restarts: int = 8,
        perturbation: float = 1e-3,
        seed: int = 0,
        follow_stable: bool = True,
    ):
        if method not in METHODS:
            raise ValueError(f"unknown method '{method}'; choose one of {METHODS}")
        self.vm = vm
        self.kin = Kinematics(vm.model, vm.frame_id)
        self.method = method
        self.tol = tol
        self.max_iter = max_iter
        self.restarts = restarts
        self.perturbation = perturbation
        self.seed = seed
        self.follow_stable = follow_stable
        self.max_step = 0.3
        self.p0, self.r0 = self.kin.placement(vm.reference)
        self.task = list(vm.task)
        self.free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
        self.nt = vm.n_theta
        pin.forwardKinematics(vm.model, self.kin.data, vm.reference)
        pts = [m.translation for m in self.kin.data.oMi[1:]] + [self.p0]
        self.length_scale = max(max(np.linalg.norm(p - self.p0) for p in pts), 1e-3)
        prism = np.array([vm.model.joints[i + 1].shortname().startswith("JointModelP") for i in range(vm.model.nv)])
        self.var_scale = np.where(prism[self.free], self.length_scale, 1.0)
        self.kscale = float(np.abs(vm.K_theta).max())
        self.Kinv = np.linalg.inv(vm.K_theta)
        metric = np.diag(1e-6 * self.kscale / self.var_scale**2)
        metric[: self.nt, : self.nt] += vm.K_theta
        self.Minv = np.linalg.inv(metric)
        # per-task-row scale of pose errors (m rows by L_c, rad rows by 1), and the row groups
        self._err_scale = np.where(np.array(self.task) < 3, self.length_scale, 1.0)
        self._rows_p = [i for i, t in enumerate(self.task) if t < 3]
        self._rows_r = [i for i, t in enumerate(self.task) if t >= 3]
        # the fast local Newton path: (θ, q)-ordered gathers of J and H by precomputed indices
        nv = vm.model.nv
        self._kz = np.zeros((len(self.free),) * 2)
        self._kz[: self.nt, : self.nt] = vm.K_theta
        self._hidx = (self.free[:, None] * nv + self.free[None, :]).ravel()
        self._all_task = self.task == [0, 1, 2, 3, 4, 5]
        self._ip = np.array(self._rows_p, int)
        self._ir = np.array(self._rows_r, int)
        self._triu = np.triu(np.ones((len(self.task),) * 2))
        t = self.task
        contiguous = bool(t) and t == list(range(t[0], t[-1] + 1))
        self._task_rows = slice(t[0], t[-1] + 1) if contiguous else np.array(t, int)
        self._fast_max_iter = 8
        self._fast_cache: tuple[bytes, dict, StabilityResult | None] | None = None
        self._fast_fact: tuple | None = None  # factorisation at the last fast-path equilibrium

    def _sibling(self, **options) -> EquilibriumSolver:
        """A solver of the same model with the given options (the defaults of ``__init__``
        for the others) that shares this one's :class:`Kinematics`: creating a ``pin.Data``
        costs seconds for finely subdivided models. Use in the same thread only."""
        params = inspect.signature(EquilibriumSolver.__init__).parameters
        opts = {k: p.default for k, p in params.items() if k not in ("self", "vm")}
        opts.update(options)
        if opts["method"] not in METHODS:
            raise ValueError(f"unknown method '{opts['method']}'; choose one of {METHODS}")
        new = copy.copy(self)
        for k, v in opts.items():
            setattr(new, k, v)
        new.max_step = 0.3
        new._fast_cache = None
        new._fast_fact = None
        return new

    # ----------------------------------------------------------------- helpers
    def energy(self, x: np.ndarray) -> float:
        d = x[self.vm.theta_idx] - self.vm.theta0
        return 0.5 * float(d @ self.vm.K_theta @ d)

    def _residuals(self, x, f, state, p_t, r_t):
        vm = self.vm
        e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
        jz = state.jacobian[self.task][:, self.free]
        tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        grad = np.concatenate([tau, np.zeros(vm.n_q)])
        r = grad - jz.T @ f
        tp, tr = self._rows_p, self._rows_r
        res = {
            "position": float(np.abs(e[tp]).max()) if tp else 0.0,
            "orientation": float(np.abs(e[tr]).max()) if tr else 0.0,
            "statics": float(np.abs(r).max()) if r.size else 0.0,
        }
        stat_scale = max(float(np.abs(tau).max()) if tau.size else 0.0, 1e-6 * self.kscale)
        ok = (
            res["position"] <= self.tol * self.length_scale
            and res["orientation"] <= self.tol
            and res["statics"] <= self.tol * stat_scale
        )
        return e, jz, grad, r, res, ok

    def _kkt_norm(self, e, r):
        return float(np.linalg.norm(e / self._err_scale) + np.linalg.norm(r) / max(self.kscale, 1e-300))

    # ----------------------------------------------------------------- iterations
    def _iterate(self, x, f, p_t, r_t, max_iter):
        """One attempt from (x, f); returns (x, f, iterations, converged, state)."""
        if self.method == "fixed-point":
            return self._fixed_point(x, f, p_t, r_t, max_iter)
        return self._newton(x, f, p_t, r_t, max_iter)

    def _fast_newton(self, x, p_t, r_t):
        """Plain local Newton on eq. (5) from ``x``; None when it must give way to the
        safeguarded iteration (see the module docstring).

        Each iteration: ``J`` and the Hessian at ``x`` (one Pinocchio evaluation), the
        complete QR ``Jᵀ = [Y Z] [R; 0]`` (``Z``: null space of eq. 20–21; the singular
        values of ``R`` are those of ``J``, checked against :data:`RANK_TOL`), the
        least-squares multiplier ``F = R⁻¹ Yᵀ ∇E`` (as the safeguarded path), the
        residual test of :meth:`_residuals`, then the Newton step of eq. (28),
        ``[[W, −Jᵀ], [J, 0]] [δx; δF] = [−r; e]`` with ``W = K − H(F)``, solved in the
        null-space form ``Rᵀ p_Y = e``, ``(ZᵀWZ) p_Z = −Zᵀ(r + W Y p_Y)``. The positive
        definiteness of ``ZᵀWZ`` (symmetric part, margin ``1e-8·max|K_θ|``) is the
        condition of the safeguarded path for an unmodified step; at convergence its
        negative is the matrix of eq. (23), so the stability verdict comes for free.

        Returns (x, f, iterations, state) with the verdict cached for :meth:`_result`.
        """
        vm, kin, kz, task, free = self.vm, self.kin, self._kz, self.task, self.free
        ti, th0, kt, nt = vm.theta_idx, vm.theta0, vm.K_theta, self.nt
        m, n = len(task), len(free)
        if m == 0 or m >= n:
            return None
        tol = self.tol
        tol_p = tol * self.length_scale
        kscale = max(self.kscale, 1e-300)
        stat_floor = 1e-6 * self.kscale
        shift = 1e-8 * self.kscale
        diag = np.arange(n - m) * (n - m + 1)
        ip, ir, escale = self._ip, self._ir, self._err_scale
        rot = ir.size > 0  # log3 only when orientation rows are constrained
        rows = None if self._all_task else self._task_rows
        pt = np.asarray(p_t, float)
        rt = np.asarray(r_t, float)
        kkt_prev = np.inf
        x = np.array(x, dtype=float)
        f6 = np.zeros(6)
        tau = np.zeros(n)
        qfull = np.zeros((n, n), order="F")
        # LAPACK directly for small models: numpy.linalg's wrappers cost more than these small
        # factorisations; numpy.linalg for large ones (see SCIPY_LAPACK_MAX_N)
        big = n > SCIPY_LAPACK_MAX_N
        for it in range(self._fast_max_iter + 1):
            key = x.tobytes()
            fact = self._fast_fact
            if fact is not None and fact[0] == key and fact[1] is self.kin:
                # a warm start from the equilibrium this solver just found: its J, QR,
                # multiplier and Hessian depend on x only (the target does not enter them)
                st, jac, qf, rr, f, r, tau, hz = fact[2:]
                y, z = qf[:, :m], qf[:, m:]
                f6[self._task_rows] = f
            else:
                st = kin.evaluate(x)
                if st.hessian is None:
                    return None
                jac = st.jacobian if rows is None else st.jacobian[rows]
                jac = jac.take(free, axis=1)
                tau = np.zeros(n)
                tau[:nt] = kt @ (x.take(ti) - th0)  # ∇E: K_θ(θ − θ₀), 0 for q
                # complete QR of Jᵀ (n × m): Q = [Y Z], R = upper triangle of qr[:m]
                if big:
                    qf, rf = np.linalg.qr(jac.T, mode="complete")
                    rr, info, info2 = rf[:m], 0, 0
                else:
                    qr, tq, _, info = _lapack.dgeqrf(jac.T)
                    qfull[:, :m] = qr
                    qf, _, info2 = _lapack.dorgqr(qfull, tq)
                    rr = qr[:m]  # R is its upper triangle (dtrtrs reads only that)
                if info or info2:
                    return None
                # the rank test (RANK_TOL, as null_space) is made where the result is used: at
                # convergence; before it a rank-deficient J gives a non-finite or clipped step
                y, z = qf[:, :m], qf[:, m:]
                f, info = _lapack.dtrtrs(rr, y.T @ tau)  # least-squares multiplier
                if info:
                    return None
                r = tau - jac.T @ f
                f6[self._task_rows] = f
                hz = contract_hessian(st.hessian, f6).take(self._hidx).reshape(n, n)
            if rot:
                e = np.concatenate([pt - st.position, pin.log3(rt @ st.rotation.T)])
                if rows is not None:
                    e = e[rows]
            else:
                e = (pt - st.position)[rows]
            ae = np.abs(e)
            if rot:
                ep = ae[ip].max() if ip.size else 0.0
                er = ae[ir].max()
            else:
                ep, er = ae.max(), 0.0
            rs = np.abs(r).max()
            es = e / escale
            kkt = math.sqrt(es @ es) + math.sqrt(r @ r) / kscale
            # the test of _residuals, with the end placed as accurately as the safeguarded
            # path's restoration places it (0.01·tol): wrench-driven loops (eq. 11) rely on it
            if ep <= 0.01 * tol_p and er <= 0.01 * tol and rs <= tol * max(np.abs(tau).max(), stat_floor):
                _, sv, _, info = _lapack.dgesdd(rr * self._triu, compute_uv=0)
                if info or not sv[-1] > RANK_TOL * sv[0]:  # descending
                    return None
                res = {"position": float(ep), "orientation": float(er), "statics": float(rs)}
                # eq. (23) in the basis Z (its eigenvalues do not depend on the basis)
                red = z.T @ (hz - kz) @ z
                if big:
                    ev = np.linalg.eigvalsh(0.5 * (red + red.T))
                else:
                    ev, _, info = _lapack.dsyevd(0.5 * (red + red.T), compute_v=0)
                    if info:
                        return None
                thr = STABILITY_TOL * (spectral_norm(kt) if kt.size else 1.0)
                stab = StabilityResult(bool(ev.size == 0 or ev.max() < -thr), ev, n - m, float(thr))
                if self.follow_stable and not stab.stable:
                    self._fast_its = it
                    return None
                self._fast_cache = (key + f6.tobytes() + pt.tobytes() + rt.tobytes(), res, stab)
                self._fast_fact = (key, kin, st, jac, qf, rr, f, r, tau, hz)
                # the Blocks at this equilibrium, as evaluate_blocks would build them (the
                # stiffness of a curve point is evaluated here next)
                blocks = Blocks(jac[:, :nt], jac[:, nt:], hz[:nt, :nt], hz[:nt, nt:], hz[nt:, :nt], hz[nt:, nt:], kt, st)
                remember_blocks(vm, kin, x, f6, blocks)
                return x, f, it, st
            self._fast_its = it
            if it and not kkt < 0.5 * kkt_prev or it == self._fast_max_iter:
                return None
            w = kz - hz
            red = z.T @ w @ z
            if self.follow_stable:  # ½(red + redᵀ) − shift·I ≻ 0
                sym = red + red.T
                sym.flat[diag] -= 2.0 * shift
                if big:
                    try:
                        np.linalg.cholesky(sym)
                    except np.linalg.LinAlgError:
                        return None
                elif _lapack.dpotrf(sym, overwrite_a=1)[1]:
                    return None  # not positive definite: the safeguarded path shifts it
            py, info = _lapack.dtrtrs(rr, e, trans=1)  # Rᵀ p_Y = e
            dy = y @ py
            if big:
                try:
                    pz, info2 = np.linalg.solve(red, z.T @ (r + w @ dy)), 0
                except np.linalg.LinAlgError:
                    return None
            else:
                _, _, pz, info2 = _lapack.dgesv(red, z.T @ (r + w @ dy), overwrite_b=1)
            if info or info2:
                return None
            dx = dy - z @ pz
            smax = np.abs(dx / self.var_scale).max()
            if not smax <= self.max_step:  # also catches NaN
                return None
            x = x.copy()
            x[free] += dx
            kkt_prev = kkt
        return None

    def _newton(self, x, f, p_t, r_t, max_iter):
        """Newton on eq. (5) (matrix of eq. 28), kept on the constraint ``g = t``.

        Every iterate is first made geometrically feasible by least-energy restoration
        steps (:meth:`_restore`); then the spring energy itself is the merit function. When a
        stable branch is followed the reduced Hessian is shifted to be positive definite, so
        the step descends the energy, and a step is accepted only if the energy does not
        increase (Armijo), or, for an unmodified Newton step, if the residual of eq. (5)
        falls. With ``follow_stable=False`` full Newton steps are taken (unstable branches).
        The plain local iteration (:meth:`_fast_newton`) is tried first.
        """
        self._fast_its = 0
        fast = self._fast_newton(x, p_t, r_t)
        if fast is not None:
            xf, ff, itf, stf = fast
            return xf, ff, itf, True, stf
        x, f, it, ok, state = self._newton_safeguarded(x, f, p_t, r_t, max_iter)
        return x, f, it + self._fast_its, ok, state

    def _newton_safeguarded(self, x, f, p_t, r_t, max_iter):
        vm = self.vm
        kz = np.zeros((len(self.free), len(self.free)))
        kz[: self.nt, : self.nt] = vm.K_theta
        m = len(self.task)
        n = len(self.free)
        x, state, ok = self._restore(x.copy(), None, p_t, r_t, max_iter=40)
        if not ok:
            return x, f, 0, False, state
        for it in range(max_iter + 1):
            jz = state.jacobian[self.task][:, self.free]
            tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
            grad = np.concatenate([tau, np.zeros(vm.n_q)])
            f = np.linalg.lstsq(jz.T, grad, rcond=None)[0]  # least-squares multiplier
            e, jz, grad, r, res, ok = self._residuals(x, f, state, p_t, r_t)
            if ok:
                return x, f, it, True, state
            if it == max_iter:
                break
            if state.hessian is None:  # restoration evaluates J only; the Hessian when needed
                state = self.kin.evaluate(x)
            h = state.psi_hessian(full_wrench(vm, f))[np.ix_(self.free, self.free)]
            w = kz - h
            modified = False
            if self.follow_stable:
                z = null_space(jz[:, : self.nt], jz[:, self.nt :])
                if z.shape[1]:
                    red = z.T @ w @ z
                    lam = np.linalg.eigvalsh(0.5 * (red + red.T)).min()
                    delta = 1e-8 * self.kscale
                    if lam < delta:
                        w = w + (delta - lam + 1e-3 * abs(lam)) * np.eye(n)
                        modified = True
            a = np.zeros((n + m, n + m))
            a[:n, :n] = w
            a[:n, n:] = -jz.T
            a[n:, :n] = jz
            rhs = np.concatenate([-r, e])
            try:
                sol = np.linalg.solve(a, rhs)
                if not np.all(np.isfinite(sol)):
                    raise np.linalg.LinAlgError
            except np.linalg.LinAlgError:
                sol = np.linalg.lstsq(a, rhs, rcond=None)[0]
            dz = sol[:n]
            smax = np.abs(dz / self.var_scale).max() if n else 0.0
            if smax > self.max_step:
                dz = dz * (self.max_step / smax)
                modified = True
            e0 = self.energy(x)
            slope = float(grad @ dz)
            kkt0 = self._kkt_norm(e, r)
            alpha = 1.0
            accepted = False
            for _ in range(30):
                xn = x.copy()
                xn[self.free] += alpha * dz
                xn, sn, feas = self._restore(xn, None, p_t, r_t)
                if feas:
                    en_ = self.energy(xn)
                    if not self.follow_stable:
                        accepted = True
                    elif en_ <= e0 + 1e-4 * alpha * min(slope, 0.0) + 1e-14 * max(abs(e0), 1e-300):
                        accepted = True
                    elif alpha == 1.0 and not modified:
                        tau_n = vm.K_theta @ (xn[vm.theta_idx] - vm.theta0)
                        jn = sn.jacobian[self.task][:, self.free]
                        gn = np.concatenate([tau_n, np.zeros(vm.n_q)])
                        fn = np.linalg.lstsq(jn.T, gn, rcond=None)[0]
                        e_n, _, _, r_n, _, _ = self._residuals(xn, fn, sn, p_t, r_t)
                        accepted = self._kkt_norm(e_n, r_n) < 0.5 * kkt0
                if accepted:
                    break
                alpha *= 0.5
            if not accepted:
                return x, f, it + 1, False, state
            x, state = xn, sn
        return x, f, max_iter, False, state

    def _restore(self, x, state, p_t, r_t, max_iter: int = 12):
        """Least-energy restoration of ``g(x) = t``: repeated steps ``δ = M⁻¹Jᵀ(J M⁻¹ Jᵀ)⁻¹ e``
        with the metric ``M = diag(K_θ, 0) + ε·I`` (passive joints move first, as in the
        fixed-point scheme of eq. 10). Returns (x, state, converged); ``state`` carries no
        Hessian (callers evaluate it when they need it)."""
        tol_p = self.tol * self.length_scale
        for _ in range(max_iter + 1):
            if state is None:
                state = self.kin.evaluate(x, hessian=False)
            e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
            scaled = np.abs(e / self._err_scale).max() if e.size else 0.0
            if scaled <= 0.01 * self.tol:
                return x, state, True
            jz = state.jacobian[self.task][:, self.free]
            a = jz @ self.Minv @ jz.T
            try:
                delta = self.Minv @ jz.T @ np.linalg.solve(a, e)
            except np.linalg.LinAlgError:
                return x, state, False
            if not np.all(np.isfinite(delta)):
                return x, state, False
            big = np.abs(delta / self.var_scale).max()
            if big > self.max_step:  # damped (far from the constraint, e.g. a straight chain)
                delta *= self.max_step / big
            x = x.copy()
            x[self.free] += delta
            state = None
        state = self.kin.evaluate(x, hessian=False)
        e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
        return x, state, bool(np.abs(e).max() <= max(tol_p, self.tol))

    def _fixed_point(self, x, f, p_t, r_t, max_iter):
        vm = self.vm
        x = x.copy()
        state = self.kin.evaluate(x, hessian=False)
        for it in range(max_iter + 1):
            e, jz, _, _, res, ok = self._residuals(x, f, state, p_t, r_t)
            if ok and it > 0:
                return x, f, it, True, self.kin.evaluate(x)
            if it == max_iter:
                break
            jt, jq = jz[:, : self.nt], jz[:, self.nt :]
            m, nq = jt.shape[0], jq.shape[1]
            a = np.zeros((m + nq, m + nq))
            a[:m, :m] = jt @ self.Kinv @ jt.T
            a[:m, m:] = jq
            a[m:, :m] = jq.T
            theta = x[vm.theta_idx]
            rhs = np.concatenate([e + jt @ (theta - vm.theta0), np.zeros(nq)])
            try:
                sol = np.linalg.solve(a, rhs)
            except np.linalg.LinAlgError:
                return x, f, it, False, self.kin.evaluate(x)
            f = sol[:m]
            x[vm.q_idx] += sol[m:]
            x[vm.theta_idx] = vm.theta0 + self.Kinv @ jt.T @ f
            if not np.all(np.isfinite(x)):
                return x, f, it, False, self.kin.evaluate(np.nan_to_num(x))
            state = self.kin.evaluate(x, hessian=False)
        return x, f, max_iter, False, self.kin.evaluate(x)

    # ----------------------------------------------------------------- public
    def _result(self, x, f, iters, ok, state, p_t, r_t, path, with_stability=True) -> EquilibriumResult:
        vm = self.vm
        w6 = full_wrench(vm, f)
        fc = self._fast_cache
        if fc is not None and fc[0] == x.tobytes() + w6.tobytes() + p_t.tobytes() + r_t.tobytes():  # by _fast_newton
            res, stab = dict(fc[1]), fc[2]
        else:
            _, _, _, _, res, _ = self._residuals(x, f, state, p_t, r_t)
            stab = None
        if not (with_stability and ok):
            stab = None
        elif stab is None:
            stab = check_stability(evaluate_blocks(vm, self.kin, x, w6, state))
        return EquilibriumResult(
            x=x.copy(),
            q=x[vm.q_idx].copy(),
            theta=x[vm.theta_idx].copy(),
            wrench=w6,
            deflection=deflection(self.p0, self.r0, state.position, state.rotation),
            position=state.position.copy(),
            rotation=state.rotation.copy(),
            converged=bool(ok),
            iterations=int(iters),
            residuals=res,
            energy=self.energy(x),
            path=path,
            stability=stab,
        )

    def _solve_local(self, deflection, x0: np.ndarray) -> EquilibriumResult | None:
        """The plain local Newton iteration alone (:meth:`_fast_newton`) from ``x0``: its
        equilibrium when it converges to an acceptable one (stable when ``follow_stable``),
        else None and the caller solves as usual. No safeguards, restarts or continuation:
        for a predicted start (tangent predictor of :func:`~vjm_pin.solver.trace_curve`).
        ``self._fast_its`` holds the iterations spent when it returns None."""
        self._fast_its = 0
        if self.method != "newton":
            return None
        p_t, r_t = _as_target(self.vm, self.kin, self.p0, self.r0, deflection, None)
        out = self._fast_newton(np.asarray(x0, float), p_t, r_t)
        if out is None:
            return None
        x, f, it, st = out
        return self._result(x, f, it, True, st, p_t, r_t, "newton+tangent-predictor")

    def _perturb(self, x, rng):
        if not isinstance(rng, np.random.Generator):  # a one-element box: created when first needed
            if not rng:
                rng.append(np.random.default_rng(self.seed))
            rng = rng[0]
        xn = x.copy()
        noise = rng.standard_normal(len(self.free)) * self.perturbation
        noise = np.where(self.var_scale > 1.0, noise * 1e-3 * self.length_scale, noise)
        xn[self.free] += noise
        return xn

    def solve(
        self,
        deflection=None,
        *,
        target=None,
        x0: np.ndarray | None = None,
        wrench0: np.ndarray | None = None,
        raise_on_failure: bool = True,
        fast_fail: bool = False,
    ) -> EquilibriumResult:
        """Equilibrium for a prescribed end location.

        Args:
            deflection: (6,) or (3,) deflection from the unloaded end location: position
                (m) and world rotation vector (rad). Or give ``target``.
            target: (position (3,), rotation (3, 3)) of the end frame.
            x0: Starting configuration (nq,); default the unloaded reference (warm start
                from a neighbouring equilibrium when tracing a curve).
            wrench0: Starting wrench (6,) (N, N·m); default zero.
            raise_on_failure: Raise :class:`NoEquilibrium` (carrying the last iterate) when
                no attempt converges; otherwise return it with ``converged=False``.
            fast_fail: One Newton attempt from ``x0``, without continuation or perturbed
                restarts: for trial points of a line search, where a failure only shortens
                the step and the full recovery (up to thousands of iterations) is wasted.
        """
        vm = self.vm
        p_t, r_t = _as_target(vm, self.kin, self.p0, self.r0, deflection, target)
        x_start = vm.reference.copy() if x0 is None else np.asarray(x0, float).copy()
        if x_start.shape != (vm.model.nq,) or not np.all(np.isfinite(x_start)):
            raise InputError(f"x0 must be a finite configuration of size {vm.model.nq}")
        f_start = np.zeros(len(self.task)) if wrench0 is None else np.asarray(wrench0, float)[self.task]
        if not np.all(np.isfinite(f_start)):
            raise InputError("wrench0 contains NaN or infinite values")
        rng = []  # the restart noise generator, seeded with ``seed`` when first used
        total = 0
        best = None
        name = self.method

        def attempt(x_init, f_init, label):
            nonlocal total
            x, f, it, ok, st = self._iterate(x_init, f_init, p_t, r_t, self.max_iter)
            total += it
            if not ok and fast_fail:
                return self._result(x, f, total, False, st, p_t, r_t, label, with_stability=False)
            if not ok:
                # continuation from the attempt's start towards the target
                ps, rs = self.kin.placement(x_init)
                for nsteps in (4, 16):
                    xc, fc, okc = x_init.copy(), f_init.copy(), True
                    dlog = pin.log3(r_t @ rs.T)
                    for k in range(1, nsteps + 1):
                        a = k / nsteps
                        pk = (1 - a) * ps + a * p_t
                        rk = pin.exp3(a * dlog) @ rs
                        xc, fc, itc, okc, st = self._iterate(xc, fc, pk, rk, self.max_iter)
                        total += itc
                        if not okc:
                            break
                    if okc:
                        return self._result(xc, fc, total, True, st, p_t, r_t, f"{label}+continuation({nsteps})")
                return self._result(x, f, total, False, st, p_t, r_t, label, with_stability=False)
            return self._result(x, f, total, True, st, p_t, r_t, label)

        # A start where the end cannot move in some constrained direction (e.g. a straight
        # chain of rigid links) gives a singular eq. (28)/(10) matrix: perturb it first (§4.1).
        jz0 = self.kin.evaluate(x_start, hessian=False).jacobian[self.task][:, self.free]
        sv = _singular_values(jz0)
        if sv.size < len(self.task) or sv.min() <= 1e-9 * max(sv.max(), 1e-300):
            x_start = self._perturb(x_start, rng)
            name += "+perturbed-start"
        res = attempt(x_start, f_start, name)
        if res.converged and (res.stable or not self.follow_stable):
            return res if res.iterations == total else replace(res, iterations=total)
        best = res
        for k in range(1, 0 if fast_fail else self.restarts + 1):
            xr = self._perturb(x_start if not res.converged else res.x, rng)
            r2 = attempt(xr, f_start if not res.converged else res.wrench[self.task], f"{name}+restart({k})")
            if r2.converged and (r2.stable or not self.follow_stable):
                return replace(r2, iterations=total)
            if r2.converged and (not best.converged or r2.energy < best.energy):
                best = r2
        best = replace(best, iterations=total)
        if not best.converged and raise_on_failure:
            raise NoEquilibrium(
                f"no equilibrium found for deflection {np.round(best.deflection, 9).tolist()} after "
                f"{total} iterations and {self.restarts} restarts (residuals {best.residuals})",
                best,
                best.residual(),
            )
        return best

    # ----------------------------------------------------------------- dual problem
    def solve_wrench(
        self,
        wrench,
        *,
        x0: np.ndarray | None = None,
        max_outer: int = 50,
        method: str = "eq30",
        raise_on_failure: bool = True,
    ) -> EquilibriumResult:
        """Equilibrium for a prescribed external wrench (the dual problem, eq. 11).

        Outer loop ``t_{i+1} = t_i + K_i⁻¹ (F − F_i)`` around the displacement-driven
        solve, with step halving when the wrench error grows. Meaningful only where the
        stiffness ``K_i`` is non-singular: a single serial chain with passive joints has
        a singular stiffness (its passive joints let the end move freely along some
        direction), and :class:`SingularStiffness` says so.

        Args:
            wrench: (6,) force (N) at the end frame origin and moment (N·m), world axes;
                components outside the task must be zero.
        """
        vm = self.vm
        w = np.asarray(wrench, dtype=float).ravel()
        if w.size == 3:
            w = np.concatenate([w, np.zeros(3)])
        if w.size != 6 or not np.all(np.isfinite(w)):
            raise InputError(f"wrench must be 3 or 6 finite numbers (N, N·m), got {np.asarray(wrench).tolist()}")
        free_comp = [i for i in range(6) if i not in self.task]
        if np.any(np.abs(w[free_comp]) > 0):
            names = ["x", "y", "z", "rx", "ry", "rz"]
            raise InputError(
                f"wrench components {[names[i] for i in free_comp if w[i] != 0]} act on unconstrained task "
                f"directions (task is {vm.task_names}): they cannot be balanced"
            )
        ft = w[self.task]
        res = self.solve(np.zeros(6), x0=x0)
        total = res.iterations
        fscale = max(float(np.abs(ft).max()), 1e-300)
        for outer in range(max_outer):
            err = ft - res.wrench[self.task]
            b = evaluate_blocks(vm, self.kin, res.x, res.wrench)
            try:
                k = stiffness_from_blocks(b, vm.task, method).task_stiffness
            except SingularStiffness as e:
                raise SingularStiffness(f"wrench-driven equilibrium (eq. 11) impossible: {e}", e.eigenvalues) from None
            # the inner solves place the end to tol·L_c: the wrench is known to ~|K|·tol·L_c
            tol_w = max(100 * self.tol * fscale, 10 * np.abs(k).max() * self.tol * self.length_scale)
            if np.abs(err).max() <= tol_w:
                return replace(res, iterations=total, path=res.path + f"+eq11({outer})")
            ev = np.linalg.eigvals(0.5 * (k + k.T)).real
            if np.abs(ev).min() <= 1e-9 * np.abs(ev).max():
                raise SingularStiffness(
                    "wrench-driven equilibrium (eq. 11) impossible: the Cartesian stiffness is singular "
                    f"(eigenvalues {np.round(np.sort(ev), 6).tolist()}); passive joints let the end move freely "
                    "along some direction, so a wrench there has no equilibrium. Prescribe a deflection instead.",
                    ev,
                )
            dt_task = np.linalg.solve(k, err)
            step = 1.0
            for _ in range(30):
                dt = np.zeros(6)
                dt[self.task] = step * dt_task
                p_n, r_n = displace(res.position, res.rotation, dt)
                try:
                    rn = self.solve(target=(p_n, r_n), x0=res.x, wrench0=res.wrench)
                    total += rn.iterations
                except NoEquilibrium:
                    rn = None
                if rn is not None and np.abs(ft - rn.wrench[self.task]).max() < np.abs(err).max():
                    break
                step *= 0.5
            else:
                rn = None
            if rn is None:
                break
            res = rn
        res = replace(res, iterations=total, converged=False, path=res.path + "+eq11")
        if raise_on_failure:
            raise NoEquilibrium(
                f"wrench-driven equilibrium (eq. 11) did not converge: wrench error "
                f"{np.abs(ft - res.wrench[self.task]).max():.3g} after {max_outer} outer iterations",
                res,
                float(np.abs(ft - res.wrench[self.task]).max()),
            )
        return res


def solve_equilibrium(vm: VjmModel, deflection=None, *, target=None, **kwargs) -> EquilibriumResult:
    """Convenience: :meth:`EquilibriumSolver.solve` with a fresh solver.

    Solver options (``method``, ``tol``, ``max_iter``, ``restarts``, ``seed``, ...) and
    ``x0``/``wrench0``/``raise_on_failure`` may be passed as keywords."""
    call = {k: kwargs.pop(k) for k in ("x0", "wrench0", "raise_on_failure") if k in kwargs}
    return EquilibriumSolver(vm, **kwargs).solve(deflection, target=target, **call)


def solve_for_wrench(vm: VjmModel, wrench, **kwargs) -> EquilibriumResult:
    """Convenience: :meth:`EquilibriumSolver.solve_wrench` with a fresh solver (eq. 11)."""
    call = {k: kwargs.pop(k) for k in ("x0", "max_outer", "raise_on_failure") if k in kwargs}
    return EquilibriumSolver(vm, **kwargs).solve_wrench(wrench, **call)
