"""Independent checks of a mechanism equilibrium (:meth:`MechanismSolver.verify`, issue 13).

Everything is recomputed from the configuration ``x`` of the result with Pinocchio directly
(frame placements and ``LOCAL_WORLD_ALIGNED`` Jacobians; link weights from the bodies' inertias
and centre-of-mass Jacobians), not through the solver's evaluators:

1. **Eq. (5) with fresh multipliers.** The generalised force of the springs and the dead loads
   ``g = [K_θ(θ−θ₀); 0] − Q_loads − J_Lᵀ w_L`` (``w_L`` the loaded task components of the result)
   is balanced by the constraint reactions: the multipliers ``ν = (μ, λ)`` of the stacked
   Jacobian ``A = [C; J_H]`` (closure rows, held task rows) are recomputed by minimum-norm
   least squares, and the residual ``g − Aᵀν`` is judged per row against its own scale (as
   :meth:`EquilibriumSolver.verify`: revolute rows, N·m, against ``max(|τ|, F·L_c + M)``,
   prismatic rows, N, against ``max(|τ|, F + M/L_c)``; ``F``, ``M`` the largest force and
   moment of every wrench involved). The fresh multipliers are compared with the result's
   (closure multipliers and the task reaction on held rows), and so are their generalised
   forces ``Aᵀν`` (the unique part, also when the rows are redundant).
2. **Closures and held rows.** The closure residuals ``c(x)`` recomputed from the frame
   placements (m, rad); the held task components of the recomputed deflection against the
   result's (and against the prescribed deflection when the caller gives it).
3. **Stability.** The Hessian of the Lagrangian ``W`` by central differences of the
   constrained gradient ``G(z) = [K_θ(θ−θ₀); 0] − Q(z) − J(z)ᵀw − C(z)ᵀμ`` (``w``, ``μ`` fixed
   at the equilibrium values) along an orthonormal basis ``Z`` of the null space of the stacked
   Jacobian (closure + held rows for the control as run, closure + every task row for eq. 23);
   the verdict is the sign of the symmetric part of ``ZᵀWZ`` (stable iff its eigenvalues exceed
   the solver's threshold). A verdict whose deciding eigenvalue lies within 10× the threshold
   of zero is not contested.
4. **K_C** (optional) along its softest task direction ``u`` against central differences of
   the task wrench of re-solved equilibria at ``t ± h u`` (every task component held),
   ``h`` = 1e-6, 1e-8, 1e-10 × L_c: relative error ≤ ``rtol``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
from vjm_pin.kinematics.chain import deflection as pose_deflection
from vjm_pin.kinematics.closures import jlog3, skew
from vjm_pin.kinematics.shared import data_for
from vjm_pin.solver.checks import (
    softest_direction,
    statics_relative,
    stiffness_fd_error,
    verdict_agrees,
)

#: Tolerances of the checks: K_C against re-solved equilibria (relative), the eq. (5) residual
#: per row (relative to its scale; as :data:`vjm_pin.solver.equilibrium.VERIFY_STATICS`), the
#: fresh multipliers against the result's (relative to the largest), and the finite-difference
#: eigenvalues against the solver's (relative to ``max(‖K_θ‖₂, max|eigenvalue|)``).
VERIFY_RTOL = 1e-3
VERIFY_STATICS = 1e-8
VERIFY_MULTIPLIERS = 1e-7
VERIFY_HESSIAN = 1e-6
#: Central-difference step of the Hessian (rad, or ×L_c for prismatic coordinates).
HESSIAN_STEP = 1e-5


@dataclass(frozen=True)
class MechanismCheck:
    """What :meth:`MechanismSolver.verify` measured (recomputed with Pinocchio from ``x``).

    Attributes:
        statics_relative: Largest eq. (5) residual with the fresh multipliers, per row relative
            to that row's scale.
        statics_ok: ``statics_relative`` ≤ :data:`VERIFY_STATICS`, no wrench off the task, and
            the multipliers agree.
        closure_multipliers: (m_c,) fresh closure multipliers (N, N·m; minimum-norm).
        task_reaction: (6,) fresh reaction on the held task components (N, N·m; world axes),
            zero elsewhere.
        multipliers_relative: Largest difference between the fresh multipliers (closure and
            task reaction) and the result's, relative to the largest multiplier.
        reaction_relative: The same for their generalised forces ``Aᵀν`` (the part that is
            unique also with redundant rows), relative to the largest generalised force.
        closure_position_m, closure_orientation_rad: Largest closure residual (m, rad).
        position_m, orientation_rad: Largest held-row deflection error (m, rad): against the
            prescribed deflection when given, else against the result's deflection.
        geometry_ok: Closure and held-row errors within 10 × max(tol, 1e-12) (× L_c for m).
        stable, stable_end_held: Verdicts from the finite-difference Hessian (control as run;
            every task component held, eq. 23).
        eigenvalues, eigenvalues_end_held: Their eigenvalues (symmetric part of ``−ZᵀWZ``,
            ascending, as :class:`~vjm_pin.solver.stability.StabilityResult`).
        hessian_relative: Largest difference between these eigenvalues and the result's.
        stability_ok: Verdicts agree (or are within 10× the threshold of zero) and
            ``hessian_relative`` ≤ :data:`VERIFY_HESSIAN`.
        stiffness_checked: K_C was compared (False when not asked for or singular).
        stiffness_relative_error: K_C·u against the central difference (relative), or NaN.
        stiffness_ok: ``stiffness_relative_error`` ≤ ``rtol`` (True when not checked).
        ok: Everything above passed.
    """

    statics_relative: float
    statics_ok: bool
    closure_multipliers: np.ndarray
    task_reaction: np.ndarray
    multipliers_relative: float
    reaction_relative: float
    closure_position_m: float
    closure_orientation_rad: float
    position_m: float
    orientation_rad: float
    geometry_ok: bool
    stable: bool
    stable_end_held: bool
    eigenvalues: np.ndarray
    eigenvalues_end_held: np.ndarray
    hessian_relative: float
    stability_ok: bool
    stiffness_checked: bool
    stiffness_relative_error: float
    stiffness_ok: bool
    ok: bool


class _PinEvaluator:
    """Frame placements, Jacobians, dead loads and closures straight from Pinocchio.

    It works on the thread's shared ``pin.Data`` of the model
    (:func:`vjm_pin.kinematics.shared.data_for`; a private one of a large mechanism costs seconds
    and hundreds of MB): every read (:meth:`frame`, :meth:`load_force`, :meth:`closure_rows`)
    follows its own :meth:`update` within one check, with no other user of the Data between,
    and copies what it keeps."""

    def __init__(self, solver):
        vm = solver.vm
        self.vm, self.model = vm, vm.model
        self.data = data_for(self.model)
        self.loads = [(ld, int(self.model.getFrameId(ld.frame))) for ld in solver.loads.loads]
        g = solver.loads.gravity
        self.gravity = None if g is None or not np.any(g) else np.asarray(g, float)
        self.closures = [
            (c, int(self.model.getFrameId(c.frame_a)), int(self.model.getFrameId(c.frame_b)), list(c.indices))
            for c in vm.closures
        ]

    def update(self, x):
        pin.computeJointJacobians(self.model, self.data, x)
        pin.updateFramePlacements(self.model, self.data)

    def frame(self, fid):
        m = self.data.oMf[fid]
        j = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
        return m.translation.copy(), m.rotation.copy(), np.asarray(j)

    def load_force(self) -> np.ndarray:
        """(nv,) generalised force of the dead loads and link weights (after :meth:`update`)."""
        q = np.zeros(self.model.nv)
        for ld, fid in self.loads:
            q += self.frame(fid)[2].T @ ld.wrench
        if self.gravity is not None:
            for i in range(1, self.model.njoints):
                inertia = self.model.inertias[i]
                if inertia.mass <= 0:
                    continue
                om = self.data.oMi[i]
                jj = np.asarray(pin.getJointJacobian(self.model, self.data, i, pin.LOCAL_WORLD_ALIGNED))
                r = om.rotation @ inertia.lever
                q += (jj[:3] - skew(r) @ jj[3:]).T @ (inertia.mass * self.gravity)
        return q

    def closure_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Residual (m,) and Jacobian (m, nv) of the closure rows (after :meth:`update`):
        ``d(R_bᵀr)/dx = R_bᵀ(J^v_a − J^v_b) + [R_bᵀr]× R_bᵀJ^ω_b``, ``d log3(R_bᵀR_a)/dx =
        Jlog3 R_aᵀ(J^ω_a − J^ω_b)``."""
        res, jac = [], []
        for _, fa, fb, idx in self.closures:
            pa, ra, ja = self.frame(fa)
            pb, rb, jb = self.frame(fb)
            sp = rb.T @ (pa - pb)
            rel = rb.T @ ra
            sr = pin.log3(rel)
            jp = rb.T @ (ja[:3] - jb[:3]) + skew(sp) @ rb.T @ jb[3:]
            jr = jlog3(sr) @ ra.T @ (ja[3:] - jb[3:])
            res.append(np.concatenate([sp, sr])[idx])
            jac.append(np.vstack([jp, jr])[idx])
        nv = self.model.nv
        return (np.concatenate(res) if res else np.zeros(0)), (np.vstack(jac) if jac else np.zeros((0, nv)))


def _null_basis(a: np.ndarray, n: int, rtol: float) -> np.ndarray:
    """Orthonormal basis (n, d) of the null space of ``a`` (rows normalised; rank by SVD)."""
    if a.shape[0] == 0:
        return np.eye(n)
    norms = np.linalg.norm(a, axis=1)
    keep = norms > rtol * max(norms.max(), 1e-300)
    s = a[keep] / norms[keep, None]
    if s.shape[0] == 0:
        return np.eye(n)
    _, sv, vt = np.linalg.svd(s, full_matrices=True)
    rank = int(np.sum(sv > rtol * sv[0]))
    return vt[rank:].T.copy()


def _eigs(w_z: np.ndarray, z: np.ndarray) -> np.ndarray:
    red = -(z.T @ w_z)
    return np.linalg.eigvalsh(0.5 * (red + red.T)) if red.size else np.zeros(0)


def check_mechanism(solver, res, *, deflection=None, method="eq28", rtol=VERIFY_RTOL, stiffness=True) -> MechanismCheck:
    """The checks of the module docstring on the equilibrium ``res`` of ``solver`` (a
    :class:`~vjm_pin.solver.mechanism.MechanismSolver`); see :meth:`MechanismSolver.verify`."""
    if not res.converged:
        raise NoEquilibrium("the equilibrium did not converge: nothing to check", res, res.residual())
    # held task rows: components, or the orthonormal held axes of a solver with custom task axes
    axes = getattr(res, "held_axes", None)
    tarr = np.asarray(solver.task, int)
    hm = np.eye(6)[[c for c in tarr if c in set(res.held)]] if axes is None else np.asarray(axes, float)
    at = _At(solver, res, hm.reshape(-1, 6))
    st = _statics(solver, res, at)
    geo = _geometry(solver, res, at, deflection)
    stab = _stability(solver, res, at, st["a"], st["mu"])
    checked, kerr = False, float("nan")
    if stiffness:
        try:
            kc = solver.stiffness(res, method).task_stiffness
        except SingularStiffness:
            kc = None
        if kc is not None:
            checked, kerr = True, _stiffness_error(solver, res, kc, rtol)
    stiffness_ok = bool(not checked or kerr <= rtol)
    return MechanismCheck(
        statics_relative=st["statics"],
        statics_ok=st["ok"],
        closure_multipliers=st["mu"].copy(),
        task_reaction=at.hm.T @ st["lam"],
        multipliers_relative=st["mult_rel"],
        reaction_relative=st["react_rel"],
        **geo,
        **stab,
        stiffness_checked=checked,
        stiffness_relative_error=kerr,
        stiffness_ok=stiffness_ok,
        ok=bool(st["ok"] and geo["geometry_ok"] and stab["stability_ok"] and stiffness_ok),
    )


class _At:
    """What the checks read at the configuration of the result, recomputed with Pinocchio
    (:class:`_PinEvaluator`): end placement and Jacobian, closure rows, spring forces, loads."""

    def __init__(self, solver, res, hm):
        vm = solver.vm
        self.hm = hm  # (h, 6) held task rows
        self.ev = ev = _PinEvaluator(solver)
        self.x = x = np.asarray(res.x, float).copy()
        self.w6 = np.asarray(res.wrench, float)
        ev.update(x)
        self.p, self.rot, self.jend = ev.frame(vm.frame_id)
        self.cres, self.cjac = ev.closure_rows()
        self.tau = np.zeros(len(solver.free))
        self.tau[: solver.nt] = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        self.qload = ev.load_force()[solver.free]


def _statics(solver, res, at) -> dict:
    """Check 1: eq. (5) with the multipliers recomputed from scratch (module docstring)."""
    free, lc, ev, hm, w6 = solver.free, solver.length_scale, at.ev, at.hm, at.w6
    tau, qload, jf = at.tau, at.qload, at.jend[:, free]
    nc = at.cres.size
    lam_res = hm @ w6  # the reaction on the held rows; the rest of w6 is the dead task wrench
    wl = w6 - hm.T @ lam_res
    g = tau - qload - jf.T @ wl
    a = np.vstack([at.cjac[:, free], hm @ jf])
    nu = np.linalg.lstsq(a.T, g, rcond=solver.rank_rtol)[0] if a.shape[0] else np.zeros(0)
    r = g - a.T @ nu
    mu, lam = nu[:nc], nu[nc:]
    nu_res = np.concatenate([np.asarray(res.closure_multipliers, float), lam_res])
    big_nu = max(np.abs(nu).max() if nu.size else 0.0, np.abs(nu_res).max() if nu_res.size else 0.0, 1e-300)
    mult_rel = float(np.abs(nu - nu_res).max() / big_nu) if nu.size else 0.0
    gen, gen_res = a.T @ nu, a.T @ nu_res
    big_gen = max(np.abs(gen).max() if gen.size else 0.0, np.abs(tau).max() if tau.size else 0.0,
                  np.abs(qload).max() if qload.size else 0.0, 1e-300)
    react_rel = float(np.abs(gen - gen_res).max() / big_gen) if gen.size else 0.0
    fmax, mmax = _largest_force_and_moment(ev, w6, mu)
    prism = solver._prism
    floor = 1e-12 * solver.kscale * np.where(prism, 1.0, lc)  # an unloaded equilibrium
    statics = statics_relative(r, tau, prism, fmax, mmax, lc, floor)
    off_task = [i for i in range(6) if i not in set(np.asarray(solver.task, int).tolist())]
    ok = bool(
        statics <= VERIFY_STATICS and not np.any(w6[off_task]) and mult_rel <= VERIFY_MULTIPLIERS
        and react_rel <= VERIFY_MULTIPLIERS
    )
    return {"statics": statics, "ok": ok, "a": a, "mu": mu, "lam": lam, "mult_rel": mult_rel, "react_rel": react_rel}


def _largest_force_and_moment(ev, w6, mu) -> tuple[float, float]:
    """The largest force (N) and moment (N·m) of every wrench in eq. (5): the task wrench, the
    dead loads, the weight of the links, the closure multipliers ``mu``."""
    forces = [w6, *(ld.wrench for ld, _ in ev.loads)]
    fmax = max(np.abs(f[:3]).max() for f in forces)
    mmax = max(np.abs(f[3:]).max() for f in forces)
    if ev.gravity is not None:
        mass = sum(ev.model.inertias[i].mass for i in range(1, ev.model.njoints))
        fmax = max(fmax, mass * np.linalg.norm(ev.gravity))
    k = 0
    for c, *_ in ev.closures:
        idx = list(c.indices)
        for comp, v in zip(idx, mu[k : k + len(idx)]):
            if comp < 3:
                fmax = max(fmax, abs(v))
            else:
                mmax = max(mmax, abs(v))
        k += len(idx)
    return fmax, mmax


def _geometry(solver, res, at, deflection) -> dict:
    """Check 2: closure residuals and held task rows (module docstring)."""
    lc, hm = solver.length_scale, at.hm
    cpos = np.array([i < 3 for c, *_ in at.ev.closures for i in c.indices], bool)
    cres = at.cres
    cp = float(np.abs(cres[cpos]).max()) if np.any(cpos) else 0.0
    cr = float(np.abs(cres[~cpos]).max()) if np.any(~cpos) else 0.0
    d_now = pose_deflection(solver.p0, solver.r0, at.p, at.rot)
    d_ref = np.asarray(res.deflection, float) if deflection is None else solver._vector6(deflection, "deflection", "m, rad")
    herr = np.abs(hm @ (d_now - d_ref))
    trans = np.any(hm[:, :3] != 0, axis=1)
    pos_err = float(herr[trans].max()) if np.any(trans) else 0.0
    rot_err = float(herr[~trans].max()) if np.any(~trans) else 0.0
    gtol = 10 * max(solver.tol, 1e-12)
    return {
        "closure_position_m": cp,
        "closure_orientation_rad": cr,
        "position_m": pos_err,
        "orientation_rad": rot_err,
        "geometry_ok": bool(max(cp, pos_err) <= gtol * lc and max(cr, rot_err) <= gtol),
    }


def _stability(solver, res, at, a, mu) -> dict:
    """Check 3: both verdicts from a finite-difference Hessian of the Lagrangian on the null
    spaces of the stacked Jacobians (module docstring)."""
    vm, free, nt, ev, x, w6 = solver.vm, solver.free, solver.nt, at.ev, at.x, at.w6
    nc = at.cres.size
    tarr = np.asarray(solver.task, int)

    def gradient(z):
        xz = x.copy()
        xz[free] = z
        ev.update(xz)
        _, _, je = ev.frame(vm.frame_id)
        _, cj = ev.closure_rows()
        t = np.zeros(len(free))
        t[:nt] = vm.K_theta @ (xz[vm.theta_idx] - vm.theta0)
        out = t - ev.load_force()[free] - je[:, free].T @ w6
        return out - cj[:, free].T @ mu if nc else out

    z0 = x[free]
    n = len(free)
    z_ctl = _null_basis(a, n, solver.rank_rtol)
    z_end = _null_basis(np.vstack([at.cjac[:, free], at.jend[tarr][:, free]]), n, solver.rank_rtol)
    cols = {}

    def w_times(v):
        key = v.tobytes()
        if key not in cols:
            t = HESSIAN_STEP / max(np.abs(v / solver.var_scale).max(), 1e-300)
            cols[key] = (gradient(z0 + t * v) - gradient(z0 - t * v)) / (2 * t)
        return cols[key]

    wz_ctl = np.column_stack([w_times(v) for v in z_ctl.T]) if z_ctl.shape[1] else np.zeros((n, 0))
    wz_end = np.column_stack([w_times(v) for v in z_end.T]) if z_end.shape[1] else np.zeros((n, 0))
    e_ctl, e_end = _eigs(wz_ctl, z_ctl), _eigs(wz_end, z_end)
    thr = solver.threshold
    st_ctl = bool(e_ctl.size == 0 or e_ctl.max() < -thr)
    st_end = bool(e_end.size == 0 or e_end.max() < -thr)
    escale = max(np.linalg.norm(vm.K_theta, 2) if vm.K_theta.size else 0.0,
                 *(np.abs(e).max() for e in (e_ctl, e_end) if e.size), 1e-300)
    hrel = 0.0
    agree = True
    for given, fresh, stable in ((res.stability, e_ctl, st_ctl), (res.stability_end_held, e_end, st_end)):
        if given is None:
            continue
        if given.eigenvalues.shape == fresh.shape and fresh.size:
            hrel = max(hrel, float(np.abs(given.eigenvalues - fresh).max() / escale))
        elif given.eigenvalues.shape != fresh.shape:
            hrel = np.inf
        agree = agree and verdict_agrees(given, stable, fresh, thr)
    return {
        "stable": st_ctl,
        "stable_end_held": st_end,
        "eigenvalues": e_ctl,
        "eigenvalues_end_held": e_end,
        "hessian_relative": float(hrel),
        "stability_ok": bool(agree and hrel <= VERIFY_HESSIAN),
    }


def held_deflection(solver, res, dt: np.ndarray) -> np.ndarray:
    """(6,) deflection (from the reference, as :meth:`MechanismSolver.solve` takes it) of the
    task frame of ``res`` moved by ``dt`` = (δp m, world rotation vector δφ rad), zero off the
    task."""
    d = pose_deflection(solver.p0, solver.r0, res.position + dt[:3], pin.exp3(dt[3:]) @ res.rotation)
    out = np.zeros(6)
    out[list(solver.task)] = d[list(solver.task)]
    return out


def _stiffness_error(solver, res, kc, rtol) -> float:
    """Check 4: K_C along its softest direction against central differences of the task wrench
    of re-solved equilibria (every task component held, plain Newton from ``res``)."""
    from vjm_pin.solver.mechanism import MechanismSolver

    task = list(solver.task)
    lc = solver.length_scale
    u = softest_direction(kc, task, lc)
    plain = MechanismSolver(
        solver.vm, solver.loads.loads, solver.loads.gravity, tol=solver.tol, max_iter=solver.max_iter,
        restarts=0, follow_stable=False, rank_rtol=solver.rank_rtol,
    )

    def task_wrench(dt):
        try:
            rr = plain.solve(deflection=held_deflection(solver, res, dt), held=tuple(task), x0=res.x)
        except NoEquilibrium:
            return None
        return rr.wrench[task]

    return stiffness_fd_error(kc, u, task, lc, task_wrench, rtol)


__all__ = ["MechanismCheck", "check_mechanism", "held_deflection"]
