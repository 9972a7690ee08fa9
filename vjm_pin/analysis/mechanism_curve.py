"""The curve tracer of :mod:`vjm_pin.analysis.curve` on the mechanism solver (issue 13).

:func:`~vjm_pin.analysis.curve.trace_curve` runs the same continuation, the same critical-point
rule (the force-control margin ``μ``) and the same branch switch for every model kind; this
module supplies what changes when the model has loop closures, dead loads anywhere, or a task
frame held only along the direction (``free=True``): the equilibria come from
:class:`~vjm_pin.solver.mechanism.MechanismSolver` (one Newton over all coordinates) and the
quantities of one point from its :class:`~vjm_pin.solver.mechanism.Linearization` at ``x``
(``W`` the Lagrangian Hessian on ``z = (θ, q)``, ``C`` the closure rows, ``J`` the task rows):

* ``λ`` (the control as run, eq. 23 generalised): largest eigenvalue of the symmetric part of
  ``−ZᵀWZ``, ``Z`` an orthonormal basis of the null space of ``[C; H J]`` (``H``: the held task
  axes: every task component, or only ``d`` with ``free=True``);
* ``μ`` (force control along ``d``): the same on the null space of ``[C; P J]``, ``P`` the held
  axes orthogonal to ``d`` (none with ``free=True``);
* the tangent (eq. 28 bordered with the independent closure rows ``C_I``)::

      [[0, 0, HJ], [0, 0, C_I], [(HJ)ᵀ, C_Iᵀ, −W]] [δν; δμ; δz] = [H d; 0; 0] δs

  ``dw/ds = Hᵀδν`` (the loaded task components keep their dead wrench), ``dF/ds = dᵀ dw/ds``
  the tangent stiffness along ``d`` (``inf`` when ``H d`` is not reachable to first order: the
  closures and held rows fix the task frame along ``d``; ``nan`` when the matrix is singular
  otherwise).

``stable`` of a curve point is the verdict for the control as run, ``stable_end_held`` eq. (23)
with every task component held (they coincide unless ``free``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vjm_pin.analysis.curve import _BP, CurvePoint, _Tracer, rigid_start_force
from vjm_pin.exceptions import InputError, NoEquilibrium
from vjm_pin.kinematics.chain import displace, flush_tiny
from vjm_pin.solver.mechanism import (
    DESCENT_ITER_FACTOR,
    LOCAL_MAX_ITER,
    STALL_WINDOW,
    MechanismSolver,
    _null_basis,
    _verdict,
)
from vjm_pin.solver.stability import RANK_TOL, StabilityResult
from vjm_pin.solver.stiffness import SINGULAR_RCOND, _inverse_if_regular, _rcond

#: Iterations of the chord corrector before it hands over to Newton; its largest step (scaled).
CHORD_MAX_ITER = 12
#: How far past a bifurcation a marginally stable new branch is checked (× the critical deflection).
CONFIRM_REL = 0.05
MAX_CHORD_STEP = 0.05
#: The plain Newton of a short continuation step gives up beyond this many times the corrector's
#: bound from the prediction (:meth:`MechanismTracer.step`).
SHORT_STEP_RADIUS = 10.0


def task_axes(task, d: np.ndarray) -> np.ndarray:
    """(m, 6) orthonormal task axes ``[d; complement]``: ``d`` first, then an orthonormal basis of
    the task components orthogonal to it, each row a pure translation or a pure rotation."""
    rows = [d.copy()]
    for block in ((0, 1, 2), (3, 4, 5)):
        comps = [c for c in task if c in block]
        if not comps:
            continue
        e = np.eye(6)[comps]  # (k, 6)
        if np.any(d[list(block)]):
            _, s, vt = np.linalg.svd(e - np.outer(e @ d, d), full_matrices=False)
            rows.extend(vt[s > 1e-9])
        else:
            rows.extend(e)
    return np.array(rows)


class _MBP(_BP):
    """A branch point of the mechanism tracer: also the two stability verdicts and the
    linearisation's null space and Hessian (for the branch switch).

    ``mu``, ``lam``, ``run``, ``z_run`` and ``end`` are computed from ``lin`` when first read
    (:meth:`MechanismTracer.margin`, :meth:`~MechanismTracer.run_verdict`,
    :meth:`~MechanismTracer.end_verdict`): the sub-steps of a reach are continued from (their
    tangent, from :meth:`~MechanismTracer.bordered`, is computed at once) but never judged, and a
    point off the grid never reports ``end``. The numbers are those of :meth:`MechanismTracer.evaluate`."""

    __slots__ = ("_tr", "_v", "kinv", "lin")

    def __init__(self, s, eq, force, k, tr, lin):
        self._tr, self._v, self.lin, self.kinv = tr, {}, lin, None
        super().__init__(s, eq, force, k, None, None, None)

    def _get(self, key):
        v = self._v
        if key not in v:
            tr = self._tr
            if key == "mu":
                v["mu"] = tr.margin(self.lin)
            elif key == "end":
                v["end"] = tr.end_verdict(self.lin, self.run)
            else:
                v["run"], v["z_run"] = tr.run_verdict(self.lin)
                v.setdefault("lam", _top(v["run"]))
        return v[key]

    def _set(self, key, value):
        if value is None:  # (_BP.__init__: not computed yet)
            self._v.pop(key, None)
        else:
            self._v[key] = value

    mu = property(lambda p: p._get("mu"), lambda p, v: p._set("mu", v))
    lam = property(lambda p: p._get("lam"), lambda p, v: p._set("lam", v))
    run = property(lambda p: p._get("run"))
    z_run = property(lambda p: p._get("z_run"))
    end = property(lambda p: p._get("end"))


class MechanismTracer(_Tracer):
    """:class:`~vjm_pin.analysis.curve._Tracer` on :class:`MechanismSolver` (module docstring)."""

    def __init__(self, vm, d, max_deflection, msolver: MechanismSolver, refine_tol, free: bool):
        self.vm, self.d = vm, d
        self.range = float(max_deflection)
        self.free = msolver.free
        self.var_scale = msolver.var_scale
        from vjm_pin.analysis.curve import MIN_STEP, OFFSET_ABS

        self.hmin = MIN_STEP * self.range
        self.eps_abs = OFFSET_ABS * self.range
        self.refine_tol = refine_tol
        # The branch logic (loss of the control as run, branch switch) judges λ against 0: the
        # margin μ ≥ λ (its null space contains λ's), so μ's crossing, a critical point, always
        # comes first. (Against −threshold, a free platform whose μ and λ nearly coincide would
        # lose λ inside the band before μ crosses zero, and the critical point would be missed.)
        # The reported verdicts keep the solver's threshold.
        self.thr = 0.0
        self.verdict_thr = msolver.threshold
        self.h = self.range
        self.seg_margin = 0.0
        m = len(msolver.task)
        axes = task_axes(list(msolver.task), d)
        self.axes_solver = msolver.with_task_axes(axes)
        if free:
            self.run, self.hrows = self.axes_solver, [0]
        else:
            self.run, self.hrows = msolver, list(range(m))
        self.run = self.run.sibling(follow_stable=True)
        self.cont = self.run.sibling(follow_stable=False, restarts=0)
        # force control along d: the held axes orthogonal to d
        self.p_rows = np.zeros((0, 6)) if free else axes[1:]
        self.p_hrows = [] if free else list(range(1, m))
        self.held6 = self.run._split_axes(self.hrows)[0]
        self.all6 = np.eye(6)[list(msolver.task)]
        hrot = [c for c in msolver.task if c >= 3]
        self.partial_rotation = (not free) and 0 < len(hrot) < 3
        self.wdead = np.zeros(6)
        self.solver = msolver

    # ------------------------------------------------------------------ evaluation
    def target(self, s: float):
        return displace(self.run.p0, self.run.r0, s * self.d)

    def evaluate(self, lin, need_tangent: bool = True, mu_only: bool = False):
        """(mu, lam, run verdict, end verdict, tangent or None, k, z_run) from a Linearization;
        ``mu_only``: μ alone (the others None: the margin's derivative and the rigid-start search
        need no more)."""
        mu = self.margin(lin)
        if mu_only:
            return mu, None, None, None, None, float("nan"), None
        run, z_run = self.run_verdict(lin)
        end = self.end_verdict(lin, run)
        tan, k = None, float("nan")
        if need_tangent:
            tan, k = self.bordered(lin)
        return mu, _top(run), run, end, tan, k, z_run

    def margin(self, lin) -> float:
        """μ: the largest eigenvalue on the null space of ``[C; P J]`` (force control along ``d``)."""
        c, j = lin.closure_jacobian, lin.task_jacobian
        z = _null_basis(np.vstack([c, self.p_rows @ j]), self.run.rank_rtol)[0]
        return _top(_verdict(lin.hessian, z, self.verdict_thr))

    def run_verdict(self, lin):
        """(verdict for the control as run, ``Z`` of ``[C; H J]``)."""
        c, j = lin.closure_jacobian, lin.task_jacobian
        z_run, _ = _null_basis(np.vstack([c, self.held6 @ j]), self.run.rank_rtol)
        return _verdict(lin.hessian, z_run, self.verdict_thr), z_run

    def end_verdict(self, lin, run):
        """Eq. (23) with every task component held (``run`` when the run holds them all)."""
        if self.held6.shape[0] == self.all6.shape[0]:
            return run
        c, j = lin.closure_jacobian, lin.task_jacobian
        z = _null_basis(np.vstack([c, self.all6 @ j]), self.run.rank_rtol)[0]
        return _verdict(lin.hessian, z, self.verdict_thr)

    def bordered(self, lin):
        """(tangent (dx/ds, dw/ds) or None, dF/ds) from eq. 28 bordered with the closure rows."""
        c = lin.closure_jacobian[lin.closure_independent]
        hj = self.held6 @ lin.task_jacobian
        kh, kc, n = hj.shape[0], c.shape[0], hj.shape[1]
        big = np.zeros((kh + kc + n, kh + kc + n))
        big[:kh, kh + kc :] = hj
        big[kh : kh + kc, kh + kc :] = c
        big[kh + kc :, :kh] = hj.T
        big[kh + kc :, kh : kh + kc] = c.T
        big[kh + kc :, kh + kc :] = -lin.hessian
        rhs = np.zeros(kh + kc + n)
        rhs[:kh] = self.held6 @ self.d
        inv, regular = _inverse_if_regular(big)
        if not regular and _rcond(big) >= SINGULAR_RCOND:
            inv = np.linalg.inv(big)
        if inv is None:
            # reachable along d to first order? (displacements allowed by the closures)
            nc, _ = _null_basis(lin.closure_jacobian, self.run.rank_rtol)
            reach = hj @ nc
            t = rhs[:kh]
            u, sv, _ = np.linalg.svd(reach, full_matrices=True)
            rank = int(np.sum(sv > RANK_TOL * max(np.abs(hj).max(initial=0.0), 1e-300)))
            miss = np.linalg.norm(u[:, rank:].T @ t)
            return None, (float("inf") if miss > 1e-6 else float("nan"))
        sol = inv @ rhs
        self._kinv = inv
        xd = np.zeros_like(lin.x)
        xd[self.free] = sol[kh + kc :]
        wd = self.held6.T @ sol[:kh]
        if not (np.all(np.isfinite(xd)) and np.all(np.isfinite(wd))):
            return None, float("nan")
        return (xd, wd, sol[:kh], sol[kh : kh + kc]), float(self.d @ wd)

    def point(self, eq, s: float, lin=None) -> _MBP:
        lin = lin if lin is not None else self.run.linearize(eq.x, self.hrows, self.wdead)
        self._kinv = None
        tan, k = self.bordered(lin)
        p = _MBP(s, eq, self.d @ eq.wrench, k, self, lin)  # μ and the verdicts when first read
        p.tan, p.kinv = tan, self._kinv
        return p

    def _tangent(self, p):  # set by point(); None when the bordered matrix is singular
        return None

    def mu_at(self, x) -> float:
        lin = self.run.linearize(x, self.hrows, self.wdead)
        return self.evaluate(lin, need_tangent=False, mu_only=True)[0]

    def dmu(self, p) -> float:
        """``dμ/ds`` at ``p``: forward difference along the tangent (as the serial tracer)."""
        if p.dmu is None:
            t = self.tangent(p)
            if t is None:
                p.dmu = float("nan")
            else:
                xd = t[0]
                sc = float(np.abs(xd[self.free] / self.var_scale).max())
                h = 1e-6 * self.range
                if sc * h > 1e-6:
                    h = 1e-6 / sc
                p.dmu = (self.mu_at(p.eq.x + h * xd) - p.mu) / h
        return p.dmu

    # ------------------------------------------------------------------ solves
    def solve(self, s: float, x0, solver=None):
        """The stable (or, with ``solver=self.cont``, plain) solve at ``s`` from ``x0``."""
        sv = solver or self.run
        if self.partial_rotation:
            hcomp = tuple(sv.task)
            return sv._rotation_targets(s * self.d, hcomp, self.hrows, self.wdead, np.asarray(x0, float))
        p_t, r_t = self.target(s)
        return sv._solve_target(p_t, r_t, self.hrows, self.wdead, np.asarray(x0, float))

    def chord(self, a, x_pred, ds, p_t, r_t):
        """Corrector with the factorised bordered matrix of ``a`` (eq. 28 with the closure rows,
        the matrix of the Newton iteration): ``(x, iterations, converged, state)``; only the
        residuals (no Hessians) are evaluated per iteration, the state (with Hessians) once at the
        end. Fails (the caller falls back to Newton) unless the steps shrink by half or more."""
        t = a.tan
        if a.kinv is None or t is None:
            return x_pred, 0, False, None
        rows = a.lin.closure_independent
        kh, kc = self.held6.shape[0], len(rows)
        nu = self.held6 @ a.lin.wrench + ds * t[2]
        mu = a.lin.independent_multipliers + ds * t[3]
        x = x_pred.copy()
        prev = np.inf
        for it in range(CHORD_MAX_ITER):
            r, bh, c, conv = self.cont.kkt_residual(x, self.hrows, self.wdead, p_t, r_t, rows, mu, nu)
            if conv:
                st = self.cont._state(x, self.hrows, self.wdead, p_t, r_t, 1.0, True)
                return x, it, True, st
            sol = a.kinv @ np.concatenate([bh, -c[rows], r])
            if not np.all(np.isfinite(sol)):
                break
            size = self.scaled_free(sol[kh + kc :])
            if size > 0.5 * prev or size > MAX_CHORD_STEP:
                break
            prev = size
            nu = nu + sol[:kh]
            mu = mu + sol[kh : kh + kc]
            x = x.copy()
            x[self.free] += sol[kh + kc :]
        return x_pred, 0, False, None

    def scaled_free(self, dz) -> float:
        return float(np.abs(dz / self.var_scale).max()) if dz.size else 0.0

    def descend(self, s: float, x0):
        """Descent steps of the stable solver at ``s`` from ``x0``, without its plain local attempt
        (which would return to the saddle next to a bifurcation); the result may be unconverged."""
        if self.partial_rotation:
            return self.solve(s, x0)
        p_t, r_t = self.target(s)
        x, it, ok, st = self.run._newton(
            np.asarray(x0, float), self.hrows, self.wdead, p_t, r_t, 1.0, DESCENT_ITER_FACTOR * self.run.max_iter,
            stall=STALL_WINDOW, soc=True,
        )
        # no fall-back to the full solver here: a failed descent from one perturbed start is one
        # candidate less (switch tries the others, then the full solver once); a descent that
        # stalls on a flat saddle (next to a multiple bifurcation) gives up early (STALL_WINDOW)
        return self.run._result(x, it, ok, self.hrows, self.wdead, p_t, r_t, "descent",
                                state=st if ok else None, verdicts=False)

    def step(self, a, s: float):
        s = float(s)
        t = self.tangent(a)
        ds = s - a.s
        x_pred = flush_tiny(a.eq.x + ds * t[0]) if t is not None else a.eq.x.copy()
        move = self.scaled(x_pred - a.eq.x)
        if move > 0.1:
            return None
        # the corrector must stay this close to the prediction (else a shorter step)
        bound = 0.25 * move + 1e-9 if t is not None else 1e-2
        lin = None
        if self.partial_rotation:
            eq = self.solve(s, x_pred, self.cont)
            if not eq.converged:
                return None
        else:
            p_t, r_t = self.target(s)
            x, it, ok, st = self.chord(a, x_pred, ds, p_t, r_t)
            if not ok:
                x, it, ok, st = self.cont._newton(
                    x_pred, self.hrows, self.wdead, p_t, r_t, 1.0, LOCAL_MAX_ITER, local=True
                )
            if ok:
                eq = self.cont._result(x, it, True, self.hrows, self.wdead, p_t, r_t, "continuation",
                                       state=st, verdicts=False)
                lin = self.cont.linearize(x, self.hrows, self.wdead, state=st)
            else:
                if abs(ds) > 1e-4 * self.range:
                    return None  # a shorter step first
                # a short step: the plain Newton with its line search (no continuation), given up
                # once it strays SHORT_STEP_RADIUS × the bound from the prediction (next to a fold or a
                # singular point it wanders there for its whole budget, and a solution it reached
                # that far away would be rejected below)
                x, it, ok, st = self.cont._newton(x_pred, self.hrows, self.wdead, p_t, r_t, 1.0, self.cont.max_iter,
                                                  radius=SHORT_STEP_RADIUS * bound)
                if not ok:
                    return None
                eq = self.cont._result(x, it, True, self.hrows, self.wdead, p_t, r_t, "continuation",
                                       state=st, verdicts=False)
                lin = self.cont.linearize(x, self.hrows, self.wdead, state=st)
        return self.point(eq, s, lin) if self.scaled(eq.x - x_pred) <= bound else None

    def switch(self, u, s: float):
        """The stable branch leaving the bifurcation at ``u``, solved at ``s`` (as the serial
        tracer: ``u`` perturbed along ± the critical eigenvector of the control as run, then
        the stable solver, descent first; the lower energy on a tie). Next to the bifurcation
        the new branch is only marginally stable (its eigenvalue grows from zero): a converged
        point distinct from the continued branch at ``s`` whose verdict is not clearly unstable
        (``λ <`` the solver's threshold) is accepted, after :meth:`confirm`, when none has
        ``λ < 0``."""
        z, w = u.z_run, u.lin.hessian
        cands = []
        if z.shape[1]:
            t = self.tangent(u)
            ref = u.eq.x + (s - u.s) * t[0] if t is not None else u.eq.x  # the continued branch at s
            red = -(z.T @ w @ z)
            ev, v = np.linalg.eigh(0.5 * (red + red.T))
            # the critical eigenvector, and every other one of a multiple bifurcation (a cluster
            # of eigenvalues within the threshold of the largest: a symmetric mechanism)
            cluster = [j for j in range(len(ev) - 1, -1, -1) if j == len(ev) - 1 or ev[j] >= ev[-1] - self.verdict_thr]
            vecs = []
            for j in cluster:
                vec = np.zeros_like(u.eq.x)
                vec[self.free] = z @ v[:, j]
                vecs.append(vec / max(self.scaled(vec), 1e-300))
            for amp in (1e-3, 1e-2, 1e-1):
                for vec in vecs:
                    for sign in (1.0, -1.0):
                        eq = self.descend(s, u.eq.x + sign * amp * vec)
                        if eq.converged and self.scaled(eq.x - ref) > 1e-7:
                            p = self.point(eq, s)
                            if p.lam < self.verdict_thr:
                                cands.append(p)
                if cands:
                    break
        if not cands:
            eq = self.solve(s, u.eq.x)
            return self.point(eq, s) if eq.converged else None
        clear = [p for p in cands if p.lam < -self.thr]
        if not clear:
            return self.confirm(u, s, cands)
        pool = clear
        best = pool[0]
        for p in pool[1:]:
            if p.eq.energy < best.eq.energy - 1e-9 * max(abs(best.eq.energy), 1e-300):
                best = p
        return best

    def confirm(self, u, s: float, cands):
        """Of marginal candidates at ``s`` (next to the bifurcation at ``u``), the first, most
        stable first, whose branch is clearly stable a little further on (at ``u.s`` plus
        :data:`CONFIRM_REL` of ``|u.s|`` or ten times ``s − u.s``); the most stable one otherwise."""
        cands = sorted(cands, key=lambda p: p.lam)
        probe = u.s + max(CONFIRM_REL * abs(u.s), 10.0 * (s - u.s))
        for p in cands:
            q = self.reach(p, probe)
            if q is not None and q.lam < -self.verdict_thr:
                return p
        return cands[0]

    def jump(self, a, s: float):
        eq = self.solve(s, a.eq.x)
        if not eq.converged:
            raise NoEquilibrium(
                f"no equilibrium of the mechanism at deflection {s:.6g} along the direction "
                f"(residuals {eq.residuals})",
                eq,
                eq.residual(),
            )
        return self.point(eq, s)

    # ------------------------------------------------------------------ rigid start
    def force_control_lin(self, x, f: float):
        """Linearisation at ``x`` with a dead force ``f`` along ``d`` and the held axes
        orthogonal to ``d`` (the force control of the margin μ)."""
        return self.axes_solver.linearize(x, self.p_hrows, f * self.d)

    def start(self):
        """The first point (s = 0) and whether the start is rigid along ``d``."""
        eq = self.solve(0.0, self.vm.reference)
        if not eq.converged:
            raise NoEquilibrium(f"no equilibrium of the mechanism at the start (residuals {eq.residuals})",
                                eq, eq.residual())
        p = self.point(eq, 0.0)
        if np.isfinite(p.k):
            return p, False
        # rigid along d: the force along d is indeterminate; start from zero force along d
        lin = self.force_control_lin(eq.x, 0.0)
        eq0 = replace(eq, wrench=lin.wrench, closure_multipliers=lin.closure_multipliers)
        return self.point(eq0, 0.0, lin), True

    def rigid_start(self, p0):
        x = p0.eq.x

        def mu(f):
            lin = self.force_control_lin(x, f)
            return self.evaluate(lin, need_tangent=False, mu_only=True)[0]

        f = rigid_start_force(mu, max(self.run.kscale / self.run.length_scale, 1e-300))
        if f is None:
            return None
        lin = self.force_control_lin(x, f)
        eq = replace(p0.eq, wrench=lin.wrench, closure_multipliers=lin.closure_multipliers)
        return f, self.point(eq, 0.0, lin)


def _top(v: StabilityResult) -> float:
    return float(v.eigenvalues.max()) if v.eigenvalues.size else -np.inf


def curve_point(p: _MBP, thr: float) -> CurvePoint:
    """The reported :class:`CurvePoint` (verdicts filled into the equilibrium)."""
    eq = replace(p.eq, stability=p.run, stability_end_held=p.end)
    return CurvePoint(
        deflection=float(p.s),
        force=float(p.force),
        wrench=np.asarray(p.eq.wrench, float).copy(),
        stable=bool(p.run.stable),
        stiffness=p.k,
        equilibrium=eq,
        stable_end_held=bool(p.end.stable),
        force_control_margin=float(-p.mu),
    )


def check_free_direction(d: np.ndarray) -> None:
    """``free=True`` holds ``d`` through the pose error: exact for a translation only."""
    if np.any(d[3:]):
        raise InputError("free=True needs a translation direction (the other task components carry no load)")
