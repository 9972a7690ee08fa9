"""Batched lockstep maps of open serial chains: all poses of a chunk advance together.

The per-pose path of :mod:`vjm_pin.analysis.maps` solves each pose with
:meth:`~vjm_pin.solver.EquilibriumSolver.solve_wrench` and inverts the matrix of eq. (28) there;
most of its time is the interpreter around small numpy calls. Here the same **local Newton
iteration** (the first attempt of ``solve_wrench``: plain Newton steps from the unloaded reference,
each kept only if it halves the residual and stays within the step limit, then up to
``POLISH_ITERATIONS`` polishing steps) runs on a whole chunk at once:

- one Pinocchio frame-Jacobian evaluation per pose per iteration (``computeJointJacobians``,
  ``updateFramePlacement``, ``getFrameJacobian`` on one shared ``pin.Data``);
- the Hessian of ``Ψ = g(θ)ᵀF`` (eq. 16) in screw form from J
  (:func:`vjm_pin.kinematics.screw.psi_hessian_screw`) for all poses as stacked matrix products;
- the Newton steps ``(K_θ − H) Δθ = −r`` of eq. (5) with one stacked ``np.linalg.solve``.

At the equilibrium the indices of :mod:`vjm_pin.analysis.maps` follow from the loaded compliance
without passive joints, the Schur complement of the matrix of eq. (28):
``C = K_C⁻¹ = J (K_θ − H)⁻¹ Jᵀ`` (task rows), ``k_along = 1/(f̂ᵀ C_tt f̂)``,
``k_min = 1/λ_max(sym C_tt)``; stability under the dead load (the verdict ``solve_wrench``
reports) is ``K_θ − H`` positive definite (eq. 23 with nothing held).

Scope and hand-back. Chains with spring and actuated (or locked) joints only: no passive joints,
no loop closures, no dead loads at frames or link weights, every joint revolute or prismatic
(screw form). A pose is handed back to the per-pose path (``None`` in the result) whenever the
batch cannot vouch for the same answer: the local iteration fails (``solve_wrench`` would go on
with descent and continuation), ``K_θ − H`` is not clearly positive definite (unstable or near a
critical load: the per-pose path decides), or ``C`` is ill-conditioned (near a singular pose,
where eq. (28) may be singular). The poses that stay agree with the per-pose path to rounding
(``tests/test_map_batched.py``). Results depend only on the pose and the chunk's other poses
do not enter a pose's arithmetic, so local and Dask maps agree bit for bit.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pinocchio as pin

from vjm_pin.kinematics.chain import deflection, flush_tiny
from vjm_pin.kinematics.screw import screw_applicable, support_mask
from vjm_pin.model.format import VjmModel
from vjm_pin.solver.equilibrium import LOCAL_MAX_ITER, POLISH_ITERATIONS, POLISH_STEP

#: Newton tolerance of ``EquilibriumSolver`` (its default ``tol``).
TOL = 1e-10
#: Step limit of one Newton step (rad; m ×L_c), ``EquilibriumSolver.max_step``.
MAX_STEP = 0.3
#: A pose stays in the batch only when ``λ_min(sym(K_θ − H)) > STABLE_MARGIN · ‖K_θ‖₂`` (far
#: above the stability threshold ``STABILITY_TOL · ‖K_θ‖₂``: the verdict cannot flip by rounding).
STABLE_MARGIN = 1e-6
#: ... and the 2-norm condition number of the task compliance ``C`` is below this (far from the
#: ``SINGULAR_RCOND`` test of eq. 28, and from the singular directions of ``weakest_translation``).
MAX_COND = 1e8


def batch_applicable(vm: VjmModel, gravity=None, loads=()) -> bool:
    """Whether the poses of ``vm`` can be solved here (module docstring: open chain, springs and
    actuated/locked joints only, revolute/prismatic joints, loaded at its end only)."""
    return (
        not vm.closures
        and vm.n_q == 0
        and vm.n_theta > 0
        and gravity is None
        and not len(loads)
        and screw_applicable(vm.model)
    )


class BatchedChain:
    """The constant data of one model for batched solves (one per model and thread; it holds the
    thread's ``pin.Data``)."""

    def __init__(self, vm: VjmModel):
        self.vm = vm
        self.model = vm.model
        self.data = vm.model.createData()
        self.fid = vm.frame_id
        self.free = np.asarray(vm.theta_idx, int)
        self.task = np.asarray(vm.task, int)
        self.K = np.asarray(vm.K_theta, float)
        self.kscale = max(float(np.abs(self.K).max()), 1e-300)
        self.knorm = float(np.linalg.norm(self.K, 2)) if self.K.size else 1.0
        self.mask = support_mask(vm.model.nv, self.free)
        nv = vm.model.nv
        prism = np.array([vm.model.joints[i + 1].shortname().startswith("JointModelP") for i in range(nv)])
        self.prism = prism[self.free]
        self.index = {n: i for i, n in enumerate(vm.joint_names)}
        theta = {int(i): k for k, i in enumerate(vm.theta_idx)}
        self.theta_pos = {n: theta.get(i) for n, i in self.index.items() if vm.roles[n] == "actuated"}

    # ------------------------------------------------------------------ per pose
    def _start(self, names, values):
        vm = self.vm
        ref = vm.reference.copy()
        theta0 = vm.theta0.copy()
        for n, x in zip(names, values):
            x = float(x)
            ref[self.index[n]] = x
            k = self.theta_pos.get(n)
            if k is not None:
                theta0[k] = x
        return ref, theta0

    def _var_scale(self, p0) -> np.ndarray:
        """``EquilibriumSolver.var_scale`` at the reference whose kinematics ``self.data`` holds:
        prismatic coordinates by the size of the chain, revolute ones by 1."""
        if not self.prism.any():
            return np.ones(len(self.free))
        pts = [o.translation for o in self.data.oMi[1:]] + [p0]
        lc = max(max(np.linalg.norm(p - p0) for p in pts), 1e-3)
        return np.where(self.prism, lc, 1.0)

    def _jacobian(self, x):
        model, data, fid = self.model, self.data, self.fid
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacement(model, data, fid)
        jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, model.nv)
        m = data.oMf[fid]
        return jac[:, self.free], m.translation.copy(), m.rotation.copy()

    # ------------------------------------------------------------------ batch
    def psi_hessian(self, jac: np.ndarray, wrench: np.ndarray) -> np.ndarray:
        """(P, n, n) eq. (16) Hessians of the stacked (P, 6, n) Jacobians in screw form
        (:func:`vjm_pin.kinematics.screw.psi_hessian_screw`, the same formula on stacked arrays)."""
        fx, fy, fz, mx, my, mz = (float(v) for v in wrench)
        w = jac[:, 3:]
        wt = np.swapaxes(w, 1, 2)
        d = _mm(np.array([[0.0, fz, -fy], [-fz, 0.0, fx], [fy, -fx, 0.0]]), jac[:, :3])
        u = _mm(wt, d)
        ut = np.swapaxes(u, 1, 2)
        if mx or my or mz:
            e = _mm(np.array([[0.0, mz, -my], [-mz, 0.0, mx], [my, -mx, 0.0]]), w)
            return np.where(self.mask, ut + _mm(np.swapaxes(e, 1, 2), w), u)
        return np.where(self.mask, ut, u)

    def solve(self, names, poses: np.ndarray, wrench: np.ndarray) -> list:
        """Rows (dicts of :func:`vjm_pin.analysis.maps.evaluate_pose`) of the ``poses`` (P, n) of
        the joints ``names`` under the end ``wrench`` (6,); ``None`` for a pose handed back to the
        per-pose path (module docstring)."""
        poses = np.asarray(poses, float)
        npose = poses.shape[0]
        n = len(self.free)
        w = np.asarray(wrench, float)
        wt = w[self.task]
        ti = self.free
        x = np.empty((npose, self.model.nq))
        th0 = np.empty((npose, n))
        p0 = np.empty((npose, 3))
        r0 = np.empty((npose, 3, 3))
        var = np.empty((npose, n))
        for i in range(npose):
            x[i], th0[i] = self._start(names, poses[i])
        jac = np.empty((npose, 6, n))
        pos = np.empty((npose, 3))
        rot = np.empty((npose, 3, 3))
        polish = np.zeros(npose, int)
        kkt_prev = np.full(npose, np.inf)
        done = np.zeros(npose, bool)  # converged: x, jac, pos, rot are the equilibrium's
        failed = np.zeros(npose, bool)
        active = np.arange(npose)
        it = 0
        while active.size:
            for i in active:
                jac[i], pos[i], rot[i] = self._jacobian(x[i])
                if it == 0:  # x is the unloaded reference: its end placement is p0, R0
                    p0[i], r0[i], var[i] = pos[i], rot[i], self._var_scale(pos[i])
            ja = jac[active]
            jt = ja[:, self.task]  # (A, m, n) task rows
            tau = _mm(self.K, (x[active][:, ti] - th0[active])[:, :, None])[:, :, 0]
            load_g = _mm(wt[None, None, :], jt)[:, 0, :]
            r = tau - load_g
            rs = np.abs(r).max(axis=1)
            stat = np.maximum(np.maximum(np.abs(tau).max(axis=1), np.abs(load_g).max(axis=1)), 1e-6 * self.kscale)
            conv = rs <= TOL * stat
            wm = self.K - self.psi_hessian(ja, w)
            with np.errstate(all="ignore"):
                try:
                    dx = -np.linalg.solve(wm, r[:, :, None])[:, :, 0]
                except np.linalg.LinAlgError:  # one singular matrix: solve one by one
                    dx = np.array([_solve_or_nan(a, b) for a, b in zip(wm, r)])
            finite = np.all(np.isfinite(dx), axis=1)
            step = np.abs(dx / var[active]).max(axis=1)
            small = step <= POLISH_STEP
            conv = conv | (~conv & small & (rs <= 1e3 * TOL * stat))
            finish = conv & ((polish[active] >= POLISH_ITERATIONS) | small) & finite
            fail = ~finite | (~conv & ((it - polish[active] >= LOCAL_MAX_ITER) | (step > MAX_STEP)))
            kkt0 = np.linalg.norm(r, axis=1) / self.kscale
            fail |= ~conv & ~(kkt0 < 0.5 * kkt_prev[active])
            fail &= ~finish
            move = ~finish & ~fail
            idx = active[move]
            polish[idx] += conv[move]
            upd = move & ~conv
            kkt_prev[active[upd]] = kkt0[upd]
            xs = x[idx]
            xs[:, ti] += dx[move]
            flush_tiny(xs)
            x[idx] = xs
            done[active[finish]] = True
            failed[active[fail]] = True
            active = idx
            it += 1
        return self._rows(done, x, jac, pos, rot, p0, r0, w)

    def _rows(self, done, x, jac, pos, rot, p0, r0, w) -> list:
        rows: list = [None] * len(done)
        ok = np.flatnonzero(done)
        if not ok.size:
            return rows
        ja = jac[ok]
        a = self.K - self.psi_hessian(ja, w)
        ev = np.linalg.eigvalsh(0.5 * (a + np.swapaxes(a, 1, 2)))
        clear = ev[:, 0] > STABLE_MARGIN * self.knorm
        tt = [i for i, c in enumerate(self.task) if c < 3]
        if not tt:
            return rows
        jt = ja[:, self.task]
        with np.errstate(all="ignore"):
            try:
                c = _mm(jt, np.linalg.solve(a, np.swapaxes(jt, 1, 2)))
            except np.linalg.LinAlgError:
                c = _mm(jt, np.stack([_solve_or_nan(aa, jj.T) for aa, jj in zip(a, jt)]))
        finite = np.all(np.isfinite(c), axis=(1, 2))
        cond = np.full(len(ok), np.inf)
        cond[finite] = np.linalg.cond(c[finite])
        keep = clear & finite & (cond < MAX_COND)
        ctt = c[:, tt][:, :, tt]
        lam = np.linalg.eigvalsh(0.5 * (ctt + np.swapaxes(ctt, 1, 2)))[:, -1]
        f = w[self.task][tt]
        nf = np.linalg.norm(f)
        fh = f / nf if nf > 0 else None
        along = _mm(_mm(fh[None, None, :], ctt), fh[None, :, None])[:, 0, 0] if fh is not None else None
        for j in np.flatnonzero(keep):
            i = ok[j]
            rows[i] = {
                "p0": p0[i].copy(),
                "deflection": deflection(p0[i], r0[i], pos[i], rot[i]),
                "k_along": float(1.0 / along[j]) if along is not None else math.nan,
                "k_min": float(1.0 / lam[j]),
                "stable": True,
                "status": "ok",
            }
        return rows


def _mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` on stacked small matrices (broadcast over the leading axes) as a sequence of
    elementwise products and sums over the contraction index, in index order. Unlike ``@``
    (a BLAS call per matrix, whose kernels may round differently with the memory alignment of
    each matrix in the stack), every pose gets the same operations whatever its place in the
    chunk: a pose's numbers do not depend on the chunk it is in."""
    acc = a[..., :, 0, None] * b[..., None, 0, :]
    for k in range(1, a.shape[-1]):
        acc = acc + a[..., :, k, None] * b[..., None, k, :]
    return acc


def _solve_or_nan(a, b):
    try:
        return np.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        return np.full(np.shape(b), np.nan)


_CHAIN_CACHE: dict = {}


def shared_chain(vm: VjmModel) -> BatchedChain:
    """This thread's :class:`BatchedChain` of ``vm`` (one ``pin.Data`` per worker thread)."""
    key = (id(vm), threading.get_ident())
    hit = _CHAIN_CACHE.get(key)
    if hit is None or hit.vm is not vm:
        if len(_CHAIN_CACHE) >= 8:
            _CHAIN_CACHE.clear()
        hit = _CHAIN_CACHE[key] = BatchedChain(vm)  # holds vm: its id stays unique
    return hit
