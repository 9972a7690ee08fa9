"""Batched lockstep maps of open serial chains: all poses of a chunk advance together.

The per-pose path of :mod:`vjm_pin.analysis.maps` solves each pose with
:meth:`~vjm_pin.solver.EquilibriumSolver.solve_wrench` and inverts the matrix of eq. (28) there;
most of its time is the interpreter around small numpy calls. Here the same **local Newton
iteration** (the first attempt of ``solve_wrench``: plain Newton steps from the unloaded reference,
each kept only if it halves the residual and stays within the step limit, then up to
``POLISH_ITERATIONS`` polishing steps) runs on a whole chunk at once:

- one Pinocchio call per pose per iteration (``computeFrameJacobian`` on the thread's shared
  ``pin.Data``, :func:`vjm_pin.kinematics.shared.data_for`, which also leaves the end placement in
  ``data.oMf``); nothing else per pose in Python;
- the Hessian of ``Ψ = g(θ)ᵀF`` (eq. 16) in screw form from J
  (:func:`vjm_pin.kinematics.screw.psi_hessian_screw`) for all poses as stacked matrix products;
- the Newton steps ``(K_θ − H) Δθ = −r`` of eq. (5) with one stacked ``np.linalg.solve``;
- or, for maps of many poses, all of one iteration's algebra after the Pinocchio call (residual,
  convergence test, ``K − H``, Cholesky step, at convergence ``C`` from the same factor, and where
  the pose may finish the stability verdict below) in one compiled kernel (:func:`kernel`, numba;
  the numpy twin above is its reference, equal to rounding, ``tests/test_map_batched.py``), pose
  by pose with ``K − H`` in a scratch matrix and its results written in place into the block's
  rows (no (P, n, n) temporaries: blocks of :data:`BLOCK_JIT` poses). Its sums are taken in a fixed
  order (independent ones side by side, ``tests/test_batched_speed_paths.py``), so its numbers do
  not depend on the block or on how the loops are scheduled. Why numba: as
  :mod:`vjm_pin.solver.kernel` (no compiler at install time, a pure-numpy fallback, machine code
  cached on disk);
- the start of each pose (joint values, θ₀), the scale ``L_c`` of prismatic coordinates (the joint
  origins by stacked forward kinematics, :meth:`BatchedChain.joint_origins`, or its compiled twin
  :func:`_origins_loops` with the kernel: the same numbers) and the deflection
  ``(p − p₀, log3(R R₀ᵀ))`` (:func:`log3_stacked`) on stacked arrays.

At the equilibrium the indices of :mod:`vjm_pin.analysis.maps` follow from the loaded compliance
without passive joints, the Schur complement of the matrix of eq. (28):
``C = K_C⁻¹ = J (K_θ − H)⁻¹ Jᵀ`` (task rows), ``k_along = 1/(f̂ᵀ C_tt f̂)``,
``k_min = 1/λ_max(sym C_tt)``; stability under the dead load (the verdict ``solve_wrench``
reports) is ``K_θ − H`` positive definite (eq. 23 with nothing held), certified by a Cholesky
factorisation of ``sym(K_θ − H) − τ I`` (:data:`STABLE_MARGIN`).

Scope and hand-back. Chains with spring and actuated (or locked) joints only: no passive joints,
no loop closures, no dead loads at frames or link weights, every joint revolute or prismatic
(screw form). A pose is handed back to the per-pose path (``keep`` False) whenever the
batch cannot vouch for the same answer: the local iteration fails (``solve_wrench`` would go on
with descent and continuation), ``K_θ − H`` is not clearly positive definite (unstable or near a
critical load: the per-pose path decides), or ``K_C`` is near singular (:data:`MAX_COND`, on the
equilibrated matrix as the per-pose tests of eq. 28 and of
:func:`~vjm_pin.analysis.indices.weakest_translation`). The poses that stay agree with the per-pose
path to rounding (``tests/test_map_batched.py``). Results depend only on the pose — the chunk's
other poses do not enter a pose's arithmetic (stacked products by :func:`_mm`, LAPACK one matrix
at a time) — so local and Dask maps agree bit for bit.
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin

from vjm_pin.kinematics.chain import flush_tiny
from vjm_pin.kinematics.closures import skew
from vjm_pin.kinematics.screw import screw_applicable, support_mask
from vjm_pin.kinematics.shared import data_for
from vjm_pin.model.format import VjmModel
from vjm_pin.solver.equilibrium import LOCAL_MAX_ITER, POLISH_ITERATIONS, POLISH_STEP

#: Newton tolerance of ``EquilibriumSolver`` (its default ``tol``).
TOL = 1e-10
#: Step limit of one Newton step (rad; m ×L_c), ``EquilibriumSolver.max_step``.
MAX_STEP = 0.3
#: A pose stays in the batch only when ``λ_min(sym(K_θ − H)) > STABLE_MARGIN · ‖K_θ‖₂`` (far
#: above the stability threshold ``STABILITY_TOL · ‖K_θ‖₂``: the verdict cannot flip by rounding).
STABLE_MARGIN = 1e-6
#: ... and (a bound of) the 2-norm condition number of the equilibrated task compliance ``D⁻¹ C D⁻¹`` (``D``
#: the scaling of ``K_C`` in :func:`~vjm_pin.analysis.indices.weakest_translation`) is below this:
#: 100× from its singular-direction test ``SINGULAR_TOL = 1e-10`` (the estimate's relative error is
#: about cond·ε ≤ 1e-8, so the verdict cannot flip), further from the ``1e-13`` reciprocal
#: condition of eq. (28), and the indices of a kept pose agree with the per-pose path's to about
#: cond·ε. About 1 random ur5 pose in 400 is beyond it (a wrist or elbow near a singular pose).
MAX_COND = 1e8
#: Poses solved together: ``BLOCK_ENTRIES / n²`` (the (P, n, n) temporaries of a block stay in the
#: processor's cache), between ``BLOCK_MIN`` and ``BLOCK_MAX`` (the interpreter's cost per
#: block is shared by enough poses). Numbers do not depend on it.
BLOCK_ENTRIES = 200_000
BLOCK_MIN = 64
BLOCK_MAX = 512
#: Poses solved together with the compiled kernel, whatever n: it keeps ``K − H`` of one pose at a
#: time in a scratch matrix (only a finishing pose's goes to the block's (P, n, n) array), so the
#: block is sized for the interpreter's cost per block alone. Numbers do not depend on it.
BLOCK_JIT = 512
#: Rotations of the deflection above this angle (rad) go through ``pin.log3`` one by one (near π
#: the stacked formula loses digits).
LOG3_STACKED_MAX = 3.0


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
    """The constant data of one model for batched solves (one per model and thread,
    :func:`shared_chain`). Its Pinocchio calls use the calling thread's shared ``pin.Data``
    (:func:`vjm_pin.kinematics.shared.data_for`, looked up per call): each call recomputes at its
    own configuration what it reads and copies it out before returning, the contract of that
    module, so the per-pose path's hand-backs on the same worker may share that Data."""

    def __init__(self, vm: VjmModel, jit: bool = False):
        self.vm = vm
        self.jit = bool(jit)  # the compiled kernel (:func:`kernel`) for the Newton systems
        model = self.model = vm.model
        self.fid = vm.frame_id
        nv = model.nv
        self.free = np.asarray(vm.theta_idx, int)
        self.free_i8 = np.ascontiguousarray(self.free, np.int64)
        self.all_free = bool(np.array_equal(self.free, np.arange(nv)))
        self.task = np.asarray(vm.task, int)
        self.K = np.ascontiguousarray(vm.K_theta, float)
        self.kscale = max(float(np.abs(self.K).max()), 1e-300)
        self.knorm = float(np.linalg.norm(self.K, 2)) if self.K.size else 1.0
        self.k_symmetric = bool(np.array_equal(self.K, self.K.T))
        self.mask = np.ascontiguousarray(support_mask(nv, self.free))
        prism = np.array([model.joints[i + 1].shortname().startswith("JointModelP") for i in range(nv)])
        self.prism = prism[self.free]
        self.index = {n: i for i, n in enumerate(vm.joint_names)}
        theta = {int(i): k for k, i in enumerate(vm.theta_idx)}
        self.theta_pos = {n: theta.get(i) for n, i in self.index.items() if vm.roles[n] == "actuated"}
        self._plans: dict = {}

    # ------------------------------------------------------------------ stacked kinematics
    def _origin_plan(self, names):
        """Forward kinematics of the joint origins for poses that set only the joints ``names``
        (the others stay at the reference): every transform between two set joints is constant
        (``jointPlacement · exp(S q_ref)`` multiplied out once), so a pose costs a few stacked
        products per set joint, not per joint. Returns (steps, groups): the set joints in tree
        order ``(joint, anchor, R, t, axis, prismatic, column)`` with ``oMi[joint] = oMi[anchor] ·
        (R, t) · exp(axis · pose[column])``; and per anchor the (joint indices, (3, m) origins in
        the anchor's frame) of the joints it carries."""
        key = tuple(names)
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        model = self.model
        data = data_for(model)
        pin.computeJointJacobians(model, data, pin.neutral(model))
        col = {model.getJointId(n): c for c, n in enumerate(names)}
        ref = self.vm.reference
        anchor = {0: (0, pin.SE3.Identity())}
        steps, groups = [], {}
        for j in range(1, model.njoints):
            jm = model.joints[j]
            sub = pin.getJointJacobian(model, data, j, pin.LOCAL)[:, jm.idx_v].copy()  # (v, ω)
            a, m = anchor[model.parents[j]]
            pre = m * model.jointPlacements[j]
            if j in col:
                pr = not np.any(sub[3:])
                steps.append((j, a, pre.rotation.copy(), pre.translation.copy(), (sub[:3] if pr else sub[3:]).copy(), pr, col[j]))
                anchor[j] = (j, pin.SE3.Identity())
                continue
            mj = pre * pin.exp6(pin.Motion(sub * float(ref[jm.idx_q])))
            anchor[j] = (a, mj)
            groups.setdefault(a, []).append((j - 1, mj.translation.copy()))
        plan = (
            steps,
            [(a, np.array([i for i, _ in g]), np.array([t for _, t in g]).T) for a, g in groups.items()],
        )
        self._plans[key] = plan
        return plan

    def joint_origins(self, names, poses: np.ndarray) -> np.ndarray:
        """(P, njoints − 1, 3) world positions of the joint origins (Pinocchio's ``data.oMi[1:]``
        translations) at the ``poses`` (P, n) of the joints ``names``, the other joints at the
        reference, by stacked forward kinematics (:meth:`_origin_plan`) instead of one Pinocchio
        call and njoints SE3 conversions per pose."""
        steps, groups = self._origin_plan(names)
        p = poses.shape[0]
        rot = {0: None}  # None: the identity (the universe)
        pos = {0: np.zeros((p, 3))}
        out = np.empty((p, self.model.njoints - 1, 3))
        for j, a, rp, tp, axis, pr, c in steps:
            ra, ta = rot[a], pos[a]
            r = rp if ra is None else _mm(ra, rp)
            t = ta + (tp if ra is None else _mm(ra, tp[:, None])[..., 0])
            q = poses[:, c]
            if pr:
                t = t + (_mm(r, axis[:, None])[..., 0]) * q[:, None]
                r = np.broadcast_to(r, (p, 3, 3))
            else:
                r = _mm(r, _rotations(axis, q))
            rot[j], pos[j] = r, t
            out[:, j - 1] = t
        for a, idx, c in groups:
            ra = rot[a]
            out[:, idx] = pos[a][:, None, :] + (c.T[None] if ra is None else np.swapaxes(_mm(ra, c), 1, 2))
        return out

    def _origin_arrays(self, names):
        """:meth:`_origin_plan` as the arrays of :func:`_origins_loops` (cached with the plan)."""
        key = ("arrays", tuple(names))
        arrays = self._plans.get(key)
        if arrays is not None:
            return arrays
        steps, groups = self._origin_plan(names)
        ns = len(steps)
        slot = {0: 0}
        anchor = np.zeros(ns, np.int64)
        for s, (j, a, *_) in enumerate(steps):
            anchor[s] = slot[a]
            slot[j] = s + 1
        kmat, kk = np.zeros((ns, 3, 3)), np.zeros((ns, 3, 3))
        for s, st in enumerate(steps):
            if not st[5]:
                kmat[s] = skew(st[4])
                kk[s] = kmat[s] @ kmat[s]  # as _rotations
        g_idx = [i for _, idx, _ in groups for i in idx]
        arrays = (
            anchor,
            np.array([st[2] for st in steps]).reshape(ns, 3, 3),
            np.array([st[3] for st in steps]).reshape(ns, 3),
            np.array([st[4] for st in steps]).reshape(ns, 3),
            np.array([st[5] for st in steps], bool),
            np.array([st[0] - 1 for st in steps], np.int64),
            kmat,
            kk,
            np.array([slot[a] for a, _, _ in groups], np.int64),
            np.cumsum([0] + [len(idx) for _, idx, _ in groups]).astype(np.int64),
            np.array(g_idx, np.int64),
            np.concatenate([c.T for _, _, c in groups]).reshape(len(g_idx), 3) if groups else np.zeros((0, 3)),
            [st[6] for st in steps],
        )
        self._plans[key] = arrays
        return arrays

    def _joint_origins_jit(self, names, poses: np.ndarray) -> np.ndarray:
        """:meth:`joint_origins` by the compiled :func:`_origins_loops`: the same numbers (the
        same products and sums in the same order; the sines and cosines by numpy, as there)."""
        anchor, rp, tp, axis, pr, jidx, kmat, kk, g_anchor, g_start, g_idx, g_c, cols = self._origin_arrays(names)
        p = poses.shape[0]
        q = np.empty((len(cols), p))
        sn = np.zeros((len(cols), p))
        cs = np.zeros((len(cols), p))
        for s, c in enumerate(cols):
            v = poses[:, c]  # the strided column, as joint_origins passes it to _rotations
            if pr[s]:
                q[s] = v
            else:
                sn[s], cs[s] = np.sin(v), np.cos(v)
        out = np.empty((p, self.model.njoints - 1, 3))
        kernel()  # loads _ORIGINS with the kernel (a fresh worker may not have yet)
        _ORIGINS(anchor, rp, tp, axis, pr, jidx, kmat, kk, q, sn, cs, g_anchor, g_start, g_idx, g_c, out)
        return out

    def _var_scale(self, names, poses: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """(P, n) ``EquilibriumSolver.var_scale`` at the reference of each pose, whose end position
        is ``p0``: prismatic coordinates by the size ``L_c`` of the chain (largest distance of a
        joint origin from the end, at least 1 mm), revolute ones by 1."""
        if not self.prism.any():
            return np.ones((poses.shape[0], len(self.free)))
        origins = self._joint_origins_jit(names, poses) if self.jit else self.joint_origins(names, poses)
        d = origins - p0[:, None, :]
        lc = np.maximum(np.sqrt((d * d).sum(axis=2)).max(axis=1), 1e-3)
        return np.where(self.prism[None, :], lc[:, None], 1.0)

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

    def _start(self, names, poses: np.ndarray):
        """(x (P, nq), θ₀ (P, n)): the reference and spring rest values of each pose."""
        vm = self.vm
        npose = poses.shape[0]
        x = np.repeat(vm.reference[None, :], npose, axis=0)
        th0 = np.repeat(vm.theta0[None, :], npose, axis=0)
        for c, n in enumerate(names):
            x[:, self.index[n]] = poses[:, c]
            k = self.theta_pos.get(n)
            if k is not None:
                th0[:, k] = poses[:, c]
        return x, th0

    def _evaluate_into(self, x: np.ndarray, rows: np.ndarray, jac: np.ndarray, hom: np.ndarray) -> None:
        """:meth:`_evaluate` at the configurations ``x[rows]`` into the rows ``rows`` of ``jac``
        (P, 6, nv: all columns) and ``hom`` (P, 4, 4): the same Pinocchio calls, without the
        stacked copies."""
        model, fid = self.model, self.fid
        data = data_for(model)
        cfj, lwa = pin.computeFrameJacobian, pin.LOCAL_WORLD_ALIGNED
        omf = data.oMf[fid]  # a reference to the placement in data, which each call updates
        for k in rows.tolist():
            jac[k] = cfj(model, data, x[k], fid, lwa)  # also sets data.oMf[fid]
            hom[k] = omf.homogeneous

    def _evaluate(self, xa: np.ndarray):
        """(A, 6, n) end-frame Jacobians (``LOCAL_WORLD_ALIGNED``, free columns) and (A, 4, 4) end
        placements at the configurations ``xa``: one Pinocchio call per pose."""
        model, fid = self.model, self.fid
        data = data_for(model)
        cfj, lwa = pin.computeFrameJacobian, pin.LOCAL_WORLD_ALIGNED
        omf = data.oMf[fid]  # a reference to the placement in data, which each call updates
        ja = np.empty((xa.shape[0], 6, model.nv))
        ha = np.empty((xa.shape[0], 4, 4))
        for k, xi in enumerate(xa):
            ja[k] = cfj(model, data, xi, fid, lwa)  # also sets data.oMf[fid]
            ha[k] = omf.homogeneous
        return (ja if self.all_free else ja[:, :, self.free]), ha

    def solve_arrays(self, names, poses: np.ndarray, wrench: np.ndarray):
        """The indices of :mod:`vjm_pin.analysis.maps` at the ``poses`` (P, n) of the joints
        ``names`` under the end ``wrench`` (6,), as stacked arrays.

        Returns:
            (keep, p0, deflection, k_along, k_min): (P,) bool, False for a pose handed back to the
            per-pose path (module docstring; its other entries are NaN); (P, 3) unloaded end
            positions (m); (P, 6) deflections (m, rad); (P,) stiffness along the force and
            weakest translational stiffness (N/m). A kept pose is stable with status ``ok``.
        """
        poses = np.asarray(poses, float)
        n = len(self.free)
        block = BLOCK_JIT if self.jit else max(BLOCK_MIN, min(BLOCK_MAX, BLOCK_ENTRIES // max(n * n, 1)))
        if poses.shape[0] > block:  # blocks whose (P, n, n) temporaries stay in cache
            parts = [self.solve_arrays(names, poses[i : i + block], wrench) for i in range(0, poses.shape[0], block)]
            return tuple(np.concatenate(a) for a in zip(*parts))
        npose = poses.shape[0]
        w = np.asarray(wrench, float)
        ti = self.free
        x, th0 = self._start(names, poses)
        jac = np.empty((npose, 6, self.model.nv))  # all columns (_free_columns: the free ones)
        hom = np.empty((npose, 4, 4))
        p0 = np.empty((npose, 3))
        var = np.ones((npose, n))
        polish = np.zeros(npose, int)
        kkt_prev = np.full(npose, np.inf)
        done = np.zeros(npose, bool)  # converged: x, jac, hom, amat are the equilibrium's
        amat = np.empty((npose, n, n))
        csol = np.empty((npose, len(self.task), len(self.task)))  # C at the equilibrium, when solved
        have_x = np.zeros(npose, bool)
        clear = np.zeros(npose, bool) if self.jit else None  # the compiled kernel's stability verdicts
        active = np.arange(npose)
        it = 0
        while active.size:
            self._evaluate_into(x, active, jac, hom)
            if it == 0:  # x is the unloaded reference: its end placement is p0, R0
                p0[:] = hom[:, :3, 3]
                r0 = hom[:, :3, :3].copy()
                var = self._var_scale(names, poses, p0)
            # the residual r = K(θ − θ₀) − Jᵀw (eq. 5), its convergence test, K − H and the Newton
            # step; where converged (a candidate to finish) also C = J (K − H)⁻¹ Jᵀ for the
            # indices, from the same factorisation
            dth = x[active][:, ti] - th0[active]
            if self.jit:  # C, the verdict and K − H straight into the rows ``active`` of csol, clear, amat
                r, rs, stat, conv, dx = self._system_jit(jac, dth, var[active], w, active, amat, csol, clear)
            else:
                r, rs, stat, conv, wm, dx, xa = self._system(self._free_columns(jac[active]), dth, w)
            conv0 = conv
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
            fx = finish & conv0
            if not self.jit:
                amat[active[finish]] = wm[finish]  # K − H at the equilibrium, for the indices
                csol[active[fx]] = xa[fx]
            have_x[active[fx]] = True
            active = idx
            it += 1
        return self._indices(done, jac, hom, amat, csol, have_x, p0, r0, w, clear)

    def _free_columns(self, ja: np.ndarray) -> np.ndarray:
        """The free columns (the variables θ) of the stacked (A, 6, nv) Jacobians ``ja``."""
        return ja if self.all_free else ja[:, :, self.free]

    def _system_jit(self, jac, dth, var, w, rows, amat, csol, clear):
        """:meth:`_system` by the compiled kernel (:func:`kernel`) for the Jacobians ``jac[rows]``
        (the block's (P, 6, nv), all columns) at the variable scales ``var`` (A, n): (r, |r|∞,
        scale, converged, step). For the indices, ``C`` of the converged poses and, of the poses
        that may finish now, the stability verdict of :meth:`_indices` and (not converged)
        ``K − H`` go to the rows ``rows`` of ``csol`` (P, m, m), ``clear`` (P,) and ``amat``
        (P, n, n) (:func:`_system_loops`)."""
        a, n = len(rows), len(self.free)
        out = (np.empty((a, n)), np.empty(a), np.empty(a), np.empty(a, bool), np.empty((a, n)))
        f, mo = w[:3], w[3:]
        sym = self.k_symmetric and not np.any(mo)
        kernel()(jac, self.free_i8, np.ascontiguousarray(dth), np.ascontiguousarray(var), self.K, w[self.task], TOL,
                 1e-6 * self.kscale, _skew_t(f), _skew_t(mo), bool(np.any(mo)), sym, self.mask, self.task, POLISH_STEP,
                 STABLE_MARGIN * self.knorm, np.ascontiguousarray(rows, np.int64), *out, amat, csol, clear)  # fmt: skip
        return out

    def _system(self, ja, dth, w):
        """One Newton iteration's algebra for the stacked (A, 6, n) Jacobians ``ja`` at the spring
        deflections ``dth = θ − θ₀`` (A, n) under the end wrench ``w``: the residual
        ``r = K dθ − J_tᵀ w_t`` (eq. 5), ``|r|∞``, its scale ``max(|K dθ|∞, |J_tᵀ w_t|∞, 1e-6 max|K|)``,
        the convergence test ``|r|∞ ≤ TOL · scale``, ``K − H`` (A, n, n), the Newton step
        ``−(K − H)⁻¹ r`` (A, n; NaN where ``K − H`` is singular) and, where converged, the task
        compliance ``C = J_t (K − H)⁻¹ J_tᵀ`` (A, m, m): the numpy twin of the compiled kernel
        (:meth:`_system_jit`; the same operations in the same order up to the factorisation:
        Cholesky in the kernel when ``K − H`` is symmetric positive definite, LU in the twin)."""
        a, n, m = ja.shape[0], ja.shape[2], len(self.task)
        wt = w[self.task]
        floor = 1e-6 * self.kscale
        jt = ja[:, self.task]  # (A, m, n) task rows
        tau = _mm(self.K, dth[:, :, None])[:, :, 0]
        load_g = _mm(wt[None, None, :], jt)[:, 0, :]
        r = tau - load_g
        rs = np.abs(r).max(axis=1)
        stat = np.maximum(np.maximum(np.abs(tau).max(axis=1), np.abs(load_g).max(axis=1)), floor)
        conv = rs <= TOL * stat
        wm = self.K - self.psi_hessian(ja, w)
        dx = np.empty(r.shape)
        cm = np.full((a, m, m), np.nan)
        with np.errstate(all="ignore"):
            for sel, rhs in ((conv, np.concatenate([-r[:, :, None], np.swapaxes(jt, 1, 2)], axis=2)), (~conv, -r[:, :, None])):
                if not sel.any():
                    continue
                aa, bb = wm[sel], rhs[sel]
                try:
                    sol = np.linalg.solve(aa, bb)
                except np.linalg.LinAlgError:  # one singular matrix: solve one by one
                    sol = np.stack([_solve_or_nan(x, y) for x, y in zip(aa, bb)])
                dx[sel] = sol[:, :, 0]
                if sol.shape[2] > 1:
                    cm[sel] = _mm(jt[sel], sol[:, :, 1:])
        return r, rs, stat, conv, wm, dx, cm

    def _indices(self, done, jac, hom, amat, csol, have_x, p0, r0, w, clear_jit=None):
        npose = len(done)
        keep = np.zeros(npose, bool)
        defl = np.full((npose, 6), np.nan)
        k_along = np.full(npose, np.nan)
        k_min = np.full(npose, np.nan)
        tt = [i for i, c in enumerate(self.task) if c < 3]
        ok = np.flatnonzero(done)
        if not ok.size or not tt:
            return keep, p0, defl, k_along, k_min
        # H is symmetric under a force alone (screw form: both triangles from the same products)
        sym = self.k_symmetric and not np.any(w[3:])
        tau = STABLE_MARGIN * self.knorm
        if clear_jit is not None:  # the compiled kernel's verdicts at the finishing iteration
            clear = clear_jit[ok]
        else:
            a = amat[ok]
            sa = a.copy() if sym else 0.5 * (a + np.swapaxes(a, 1, 2))
            diag = np.arange(a.shape[1])
            sa[:, diag, diag] -= tau
            clear = _positive_definite(sa)
        with np.errstate(all="ignore"):
            c = csol[ok]
            late = ~have_x[ok]  # converged by a negligible step alone: not solved yet
            if late.any():
                al = amat[ok[late]]
                jt = self._free_columns(jac[ok[late]])[:, self.task]
                c[late] = _mm(jt, np.stack([_solve_or_nan(aa, jj.T) for aa, jj in zip(al, jt)]))
            finite = np.all(np.isfinite(c), axis=(1, 2))
            c[~finite] = np.eye(c.shape[1])
            keep_ok = clear & finite & (_equilibrated_cond(c) < MAX_COND)
        ctt = c[:, tt][:, :, tt]
        lam = np.linalg.eigvalsh(0.5 * (ctt + np.swapaxes(ctt, 1, 2)))[:, -1]
        f = w[self.task][tt]
        nf = np.linalg.norm(f)
        sel = ok[keep_ok]
        keep[sel] = True
        if nf > 0:
            fh = f / nf
            along = _mm(_mm(fh[None, None, :], ctt), fh[None, :, None])[:, 0, 0]
            k_along[sel] = 1.0 / along[keep_ok]
        k_min[sel] = 1.0 / lam[keep_ok]
        h = hom[sel]
        defl[sel, :3] = h[:, :3, 3] - p0[sel]
        defl[sel, 3:] = log3_stacked(_mm(h[:, :3, :3], np.swapaxes(r0[sel], 1, 2)))
        return keep, p0, defl, k_along, k_min

    def solve(self, names, poses: np.ndarray, wrench: np.ndarray) -> list:
        """:meth:`solve_arrays` as rows (dicts of :func:`vjm_pin.analysis.maps.evaluate_pose`);
        ``None`` for a pose handed back to the per-pose path."""
        keep, p0, defl, k_along, k_min = self.solve_arrays(names, poses, wrench)
        return [
            {
                "p0": p0[i].copy(),
                "deflection": defl[i].copy(),
                "k_along": float(k_along[i]),
                "k_min": float(k_min[i]),
                "stable": True,
                "status": "ok",
            }
            if keep[i]
            else None
            for i in range(len(keep))
        ]


# ----------------------------------------------------------------------------- stacked algebra
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


def _rotations(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(P, 3, 3) rotations by the angles ``q`` (P,) about the unit ``axis`` (Rodrigues)."""
    k = skew(axis)
    return np.eye(3) + np.sin(q)[:, None, None] * k + (1.0 - np.cos(q))[:, None, None] * (k @ k)


def log3_stacked(r: np.ndarray) -> np.ndarray:
    """(P, 3) rotation vectors ``log3(R)`` of the stacked rotations ``r`` (P, 3, 3): axis times
    angle, ``θ/(2 sin θ) · vee(R − Rᵀ)`` with ``θ = atan2(|vee|/2, (tr R − 1)/2)`` (the series
    ``1 + θ²/6`` for θ < 1e-4); angles above :data:`LOG3_STACKED_MAX` by ``pin.log3``."""
    v = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=1)
    s = 0.5 * np.sqrt((v * v).sum(axis=1))
    cth = 0.5 * (r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2] - 1.0)
    th = np.arctan2(s, cth)
    with np.errstate(all="ignore"):
        fac = np.where(th < 1e-4, 0.5 * (1.0 + th * th / 6.0), 0.5 * th / s)
    out = fac[:, None] * v
    for i in np.flatnonzero(th > LOG3_STACKED_MAX):
        out[i] = pin.log3(np.ascontiguousarray(r[i]))
    return out


def _positive_definite(s: np.ndarray) -> np.ndarray:
    """(P,) whether each stacked symmetric matrix is positive definite (its Cholesky factorisation
    exists); one LAPACK call per matrix, one by one when the stacked call fails on one."""
    try:
        np.linalg.cholesky(s)
        return np.ones(s.shape[0], bool)
    except np.linalg.LinAlgError:
        out = np.zeros(s.shape[0], bool)
        for i, m in enumerate(s):
            try:
                np.linalg.cholesky(m)
                out[i] = True
            except np.linalg.LinAlgError:
                pass
        return out


def _equilibrated_cond(c: np.ndarray) -> np.ndarray:
    """(P,) upper bounds of the 2-norm condition numbers of the stacked compliances ``c`` (P, m, m)
    equilibrated as their inverse ``K = c⁻¹`` is by
    :func:`~vjm_pin.analysis.indices.weakest_translation` (``S = diag(d) K diag(d)``,
    ``d = 1/√(max row of max(|K|, |K|ᵀ))``): ``‖S⁻¹‖_F ‖S‖_F ≥ cond₂(S)`` (at most m times it), with
    ``S⁻¹ = c / (d dᵀ)``: no SVD."""
    with np.errstate(all="ignore"):
        try:
            k = np.linalg.inv(c)
        except np.linalg.LinAlgError:
            k = np.stack([_solve_or_nan(m, np.eye(c.shape[1])) for m in c])
        a = np.abs(k)
        rmax = np.maximum(a, np.swapaxes(a, 1, 2)).max(axis=2)
        d = 1.0 / np.sqrt(np.where(rmax == 0, 1.0, rmax))
        dd = d[:, :, None] * d[:, None, :]
        s, si = k * dd, c / dd
        cond = np.sqrt((s * s).sum(axis=(1, 2)) * (si * si).sum(axis=(1, 2)))
    cond[~np.isfinite(cond)] = np.inf
    return cond


def _skew_t(v) -> np.ndarray:
    """``[v]×ᵀ`` (3, 3): ``_skew_t(f) @ a = a × f``, the factor of the screw-form Hessian."""
    x, y, z = (float(c) for c in v)
    return np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])


def _cholesky_loops(a, shift, lo):  # pragma: no cover - compiled
    """Lower Cholesky factor of ``a − shift·I`` (symmetric, lower triangle read) into ``lo``;
    False when it is not positive definite.

    Each entry is ``(a_ij − Σ_{k<j} l_ik l_jk) / l_jj``, the terms subtracted one by one in
    ascending k (the diagonal ``√(a_jj − shift − Σ l_jk²)``); the entries below a diagonal are
    taken four rows at a time, four independent sums side by side sharing the loads of row j
    (the same numbers as one row at a time, less waiting on each subtraction)."""
    n = a.shape[0]
    for j in range(n):
        lj = lo[j]
        s = a[j, j] - shift
        for k in range(j):
            s -= lj[k] * lj[k]
        if not s > 0.0:
            return False
        dj = np.sqrt(s)
        lj[j] = dj
        i = j + 1
        while i + 3 < n:
            l0 = lo[i]
            l1 = lo[i + 1]
            l2 = lo[i + 2]
            l3 = lo[i + 3]
            t0 = a[i, j]
            t1 = a[i + 1, j]
            t2 = a[i + 2, j]
            t3 = a[i + 3, j]
            for k in range(j):
                c = lj[k]
                t0 -= l0[k] * c
                t1 -= l1[k] * c
                t2 -= l2[k] * c
                t3 -= l3[k] * c
            l0[j] = t0 / dj
            l1[j] = t1 / dj
            l2[j] = t2 / dj
            l3[j] = t3 / dj
            i += 4
        while i < n:
            li = lo[i]
            t = a[i, j]
            for k in range(j):
                t -= li[k] * lj[k]
            li[j] = t / dj
            i += 1
    return True


def _forward_loops(lo, y, c0, nc):  # pragma: no cover - compiled
    """``L y_c = b_c`` in place for the rows ``c0 .. c0 + nc − 1`` (nc ≤ 4) of ``y`` (right-hand
    sides in, solutions out): ``y_ci = (b_ci − Σ_{k<i} l_ik y_ck) / l_ii``, the terms subtracted one
    by one in ascending k, the columns side by side sharing the loads of row i of ``L``."""
    n = lo.shape[0]
    y0 = y[c0]
    if nc == 1:
        for i in range(n):
            li = lo[i]
            t = y0[i]
            for k in range(i):
                t -= li[k] * y0[k]
            y0[i] = t / li[i]
        return
    y1 = y[c0 + 1] if nc > 1 else y0
    y2 = y[c0 + 2] if nc > 2 else y0
    y3 = y[c0 + 3] if nc > 3 else y0
    for i in range(n):
        li = lo[i]
        t0 = y0[i]
        t1 = y1[i]
        t2 = y2[i]
        t3 = y3[i]
        for k in range(i):
            c = li[k]
            t0 -= c * y0[k]
            t1 -= c * y1[k]
            t2 -= c * y2[k]
            t3 -= c * y3[k]
        d = li[i]
        if nc > 3:
            y3[i] = t3 / d
        if nc > 2:
            y2[i] = t2 / d
        if nc > 1:
            y1[i] = t1 / d
        y0[i] = t0 / d


def _system_loops(  # pragma: no cover - compiled
    ja, free, dth, var, K, wt, tol, floor, sf, sm, moment, sym, mask, task, polish_step, tau, rows,
    r, rs, stat, conv, dx, amat, csol, clear,
):  # fmt: skip
    """The compiled twin of :meth:`BatchedChain._system`, one pose at a time: the residual, its
    test and ``K − H`` by explicit loops (the same operations in the same order as the numpy
    twin); the step (and where converged ``C = J (K − H)⁻¹ Jᵀ = YᵀY``, ``Y = L⁻¹Jᵀ``) by a Cholesky
    factorisation ``LLᵀ`` when ``K − H`` is symmetric (a force alone) and positive definite, else
    LAPACK ``dgesv`` (numba's ``np.linalg.solve``). A singular ``K − H`` gives NaN.

    Pose ``p`` (of ``dth`` and ``var`` (A, n) and of the outputs ``r``, ``rs``, ``stat``, ``conv``,
    ``dx``) is row ``rows[p]`` of the block's Jacobians ``ja`` (P, 6, nv; its columns ``free`` are
    the variables) and of its ``amat`` (P, n, n), ``csol`` (P, m, m) and ``clear`` (P,). The kernel
    leaves there ``C`` where converged; where the pose may finish in this iteration (converged, or
    its residual within ``1e3 tol`` of its scale and its step ``max |dx / var|`` within
    ``polish_step``, the looser test of :meth:`BatchedChain.solve_arrays`; here with margins, a
    superset) the stability verdict of :meth:`BatchedChain._indices` (``sym(K − H) − τ I`` positive
    definite, the Cholesky factorisation of :func:`_positive_definite`); and ``K − H`` itself where
    it may finish unconverged (the indices then solve with it). ``K − H`` stays in a scratch matrix
    otherwise.

    Every number is a sum taken term by term in the order of the numpy twin (of the previous
    kernel for the factorisations); sums independent of each other (the rows of ``K dθ`` and
    ``J_tᵀ w_t``, the entries of ``K − H``, rows of ``L``, right-hand sides) are taken side by
    side, which changes the schedule, not the numbers."""
    npose = rows.shape[0]
    n = free.shape[0]
    m = task.shape[0]
    d = np.empty((3, n))
    e = np.empty((3, n))
    kt = np.empty((n, n))  # Kᵀ: column k of K as a contiguous row
    for i in range(n):
        for k in range(n):
            kt[k, i] = K[i, k]
    tv = np.empty(n)
    gv = np.empty(n)
    wm = np.empty((n, n))  # K − H of the pose
    lo = np.zeros((n, n))
    yt = np.empty((1 + m, n))  # right-hand sides, then solutions, one per row
    near = 1e4 * tol  # > the 1e3 tol of solve_arrays' looser test, whatever the rounding
    s_clear = np.empty((n, n))
    jp = np.empty((6, n))  # the pose's Jacobian, free columns
    for p in range(npose):
        row = rows[p]
        for c in range(6):
            for j in range(n):
                jp[c, j] = ja[row, c, free[j]]
        d0 = dth[p, 0]
        for i in range(n):
            tv[i] = K[i, 0] * d0
        for k in range(1, n):
            dk = dth[p, k]
            for i in range(n):
                tv[i] = tv[i] + kt[k, i] * dk
        w0 = wt[0]
        t0 = task[0]
        for i in range(n):
            gv[i] = w0 * jp[t0, i]
        for c in range(1, m):
            wc = wt[c]
            tc = task[c]
            for i in range(n):
                gv[i] = gv[i] + wc * jp[tc, i]
        big_t = 0.0
        big_l = 0.0
        big_r = 0.0
        for i in range(n):
            t = tv[i]
            g = gv[i]
            r[p, i] = t - g
            big_t = max(big_t, abs(t))
            big_l = max(big_l, abs(g))
            big_r = max(big_r, abs(r[p, i]))
        rs[p] = big_r
        stat[p] = max(max(big_t, big_l), floor)
        conv[p] = big_r <= tol * stat[p]
        for k in range(3):
            for j in range(n):
                d[k, j] = sf[k, 0] * jp[0, j] + sf[k, 1] * jp[1, j] + sf[k, 2] * jp[2, j]
                e[k, j] = sm[k, 0] * jp[3, j] + sm[k, 1] * jp[4, j] + sm[k, 2] * jp[5, j]
        if moment:
            for i in range(n):
                for j in range(n):
                    if mask[i, j]:
                        h = jp[3, j] * d[0, i] + jp[4, j] * d[1, i] + jp[5, j] * d[2, i]
                        h = h + (e[0, i] * jp[3, j] + e[1, i] * jp[4, j] + e[2, i] * jp[5, j])
                    else:
                        h = jp[3, i] * d[0, j] + jp[4, i] * d[1, j] + jp[5, i] * d[2, j]
                    wm[i, j] = K[i, j] - h
        else:  # both products for every entry, then the masked choice: a loop that vectorises
            for i in range(n):
                di0 = d[0, i]
                di1 = d[1, i]
                di2 = d[2, i]
                ji3 = jp[3, i]
                ji4 = jp[4, i]
                ji5 = jp[5, i]
                for j in range(n):
                    hm = jp[3, j] * di0 + jp[4, j] * di1 + jp[5, j] * di2
                    hu = ji3 * d[0, j] + ji4 * d[1, j] + ji5 * d[2, j]
                    wm[i, j] = K[i, j] - (hm if mask[i, j] else hu)
        nr = 1 + m if conv[p] else 1
        for i in range(n):
            yt[0, i] = -r[p, i]
        for c in range(1, nr):
            tc = task[c - 1]
            for i in range(n):
                yt[c, i] = jp[tc, i]
        if sym and _cholesky_loops(wm, 0.0, lo):
            for c in range(0, nr, 4):  # L y = b, four right-hand sides at a time
                _forward_loops(lo, yt, c, min(4, nr - c))
            y0 = yt[0]
            for i in range(n - 1, -1, -1):  # the step also Lᵀ x = y
                t = y0[i]
                for k in range(i + 1, n):
                    t -= lo[k, i] * y0[k]
                y0[i] = t / lo[i, i]
            for a in range(nr - 1):  # C = J (LLᵀ)⁻¹ Jᵀ = YᵀY, Y = L⁻¹ Jᵀ: symmetric (products commute)
                ya = yt[a + 1]
                for b in range(a, nr - 1):
                    yb = yt[b + 1]
                    t = 0.0
                    for i in range(n):
                        t += ya[i] * yb[i]
                    csol[row, a, b] = t
                    csol[row, b, a] = t
            for i in range(n):
                dx[p, i] = y0[i]
        else:
            full = np.full((n, nr), np.nan)
            rhs = np.empty((n, nr))
            for i in range(n):
                for c in range(nr):
                    rhs[i, c] = yt[c, i]
            try:
                full = np.linalg.solve(wm, rhs)
            except Exception:  # noqa: BLE001, S110 - a singular matrix: NaN, as the numpy twin
                pass
            for a in range(nr - 1):  # C = J (K − H)⁻¹ Jᵀ
                for b in range(nr - 1):
                    t = 0.0
                    for i in range(n):
                        t += jp[task[a], i] * full[i, b + 1]
                    csol[row, a, b] = t
            for i in range(n):
                dx[p, i] = full[i, 0]
        cand = conv[p]
        if not cand and big_r <= near * stat[p]:
            st = 0.0
            for i in range(n):
                st = max(st, abs(dx[p, i] / var[p, i]))
            cand = st <= 2.0 * polish_step
        if cand:  # may finish now: the stability verdict, and K − H for a late solve
            for i in range(n):
                for j in range(i + 1):
                    s_clear[i, j] = wm[i, j] if sym else 0.5 * (wm[i, j] + wm[j, i])
            clear[row] = _cholesky_loops(s_clear, tau, lo)
            if not conv[p]:
                for i in range(n):
                    for j in range(n):
                        amat[row, i, j] = wm[i, j]


def _origins_loops(  # pragma: no cover - compiled
    anchor, rp, tp, axis, pr, jidx, kmat, kk, q, sn, cs, g_anchor, g_start, g_idx, g_c, out
):
    """The compiled :meth:`BatchedChain.joint_origins`, pose by pose, on the arrays of
    :meth:`BatchedChain._origin_arrays`: step ``s`` (a set joint) hangs from slot ``anchor[s]``
    (0: the universe, ``s' + 1``: step s') by ``(rp[s], tp[s])`` and turns about (slides along)
    ``axis[s]`` by its pose value (``sn``, ``cs``: its sine and cosine; ``q``: a prismatic one's
    value); group ``g`` places the joints ``g_idx[g_start[g]:g_start[g + 1]]`` at ``g_c`` in the
    frame of slot ``g_anchor[g]``. Each entry takes the operations of the stacked version in its
    order (:func:`_mm`'s sums, Rodrigues' ``(I + s K) + (1 − c) K²``, the universe's zero origin
    added)."""
    ns = anchor.shape[0]
    rot = np.empty((ns + 1, 3, 3))
    pos = np.empty((ns + 1, 3))
    r = np.empty((3, 3))
    rq = np.empty((3, 3))
    t = np.empty(3)
    for p in range(out.shape[0]):
        for s in range(ns):
            a = anchor[s]
            for i in range(3):
                if a == 0:
                    for j in range(3):
                        r[i, j] = rp[s, i, j]
                    t[i] = 0.0 + tp[s, i]
                else:
                    for j in range(3):
                        r[i, j] = rot[a, i, 0] * rp[s, 0, j] + rot[a, i, 1] * rp[s, 1, j] + rot[a, i, 2] * rp[s, 2, j]
                    t[i] = pos[a, i] + (rot[a, i, 0] * tp[s, 0] + rot[a, i, 1] * tp[s, 1] + rot[a, i, 2] * tp[s, 2])
            b = s + 1
            if pr[s]:
                v = q[s, p]
                for i in range(3):
                    t[i] = t[i] + (r[i, 0] * axis[s, 0] + r[i, 1] * axis[s, 1] + r[i, 2] * axis[s, 2]) * v
                    for j in range(3):
                        rot[b, i, j] = r[i, j]
            else:
                sv = sn[s, p]
                cv = 1.0 - cs[s, p]
                for i in range(3):
                    for j in range(3):
                        rq[i, j] = ((1.0 if i == j else 0.0) + sv * kmat[s, i, j]) + cv * kk[s, i, j]
                for i in range(3):
                    for j in range(3):
                        rot[b, i, j] = r[i, 0] * rq[0, j] + r[i, 1] * rq[1, j] + r[i, 2] * rq[2, j]
            for i in range(3):
                pos[b, i] = t[i]
                out[p, jidx[s], i] = t[i]
        for g in range(g_anchor.shape[0]):
            a = g_anchor[g]
            for m in range(g_start[g], g_start[g + 1]):
                jo = g_idx[m]
                for i in range(3):
                    if a == 0:
                        out[p, jo, i] = 0.0 + g_c[m, i]
                    else:
                        out[p, jo, i] = pos[a, i] + (rot[a, i, 0] * g_c[m, 0] + rot[a, i, 1] * g_c[m, 1] + rot[a, i, 2] * g_c[m, 2])


_KERNEL = None
_ORIGINS = None


def kernel():
    """The compiled :func:`_system_loops` (numba, machine code cached on disk next to this file),
    or None when numba cannot be imported. Loaded once per process."""
    global _KERNEL, _ORIGINS
    if _KERNEL is None:
        try:
            import numba
        except Exception:  # noqa: BLE001 - any import failure: the numpy twin
            _KERNEL = False
        else:
            global _cholesky_loops
            _cholesky_loops = numba.njit(cache=True, nogil=True)(_cholesky_loops)
            global _forward_loops
            _forward_loops = numba.njit(cache=True, nogil=True)(_forward_loops)
            _KERNEL = numba.njit(cache=True, nogil=True)(_system_loops)
            _ORIGINS = numba.njit(cache=True, nogil=True)(_origins_loops)
    return _KERNEL or None


def warm_kernel() -> None:
    """Compile (or load from the disk cache) the kernel now, on a 1-joint problem of the types
    the solves use: a process that forks its workers afterwards hands them the machine code."""
    fn = kernel()
    if fn is not None:
        z, e = np.zeros, np.empty
        fn(z((1, 6, 1)), z(1, np.int64), z((1, 1)), np.ones((1, 1)), np.ones((1, 1)), z(1), TOL, 1.0, z((3, 3)), z((3, 3)), False,
           True, np.ones((1, 1), bool), z(1, np.int64), POLISH_STEP, 0.0, z(1, np.int64), e((1, 1)), e(1), e(1),
           e(1, bool), e((1, 1)), e((1, 1, 1)), e((1, 1, 1)), e(1, bool))  # fmt: skip
        i8 = np.int64
        _ORIGINS(z(1, i8), z((1, 3, 3)), z((1, 3)), z((1, 3)), z(1, bool), z(1, i8), z((1, 3, 3)), z((1, 3, 3)), z((1, 1)),
                 z((1, 1)), z((1, 1)), z(1, i8), z(2, i8), z(1, i8), z((1, 3)), e((1, 1, 3)))  # fmt: skip


def jit_available() -> bool:
    """Whether maps use the compiled kernel: numba importable and ``VJM_PIN_JIT`` not ``0``
    (:func:`vjm_pin.solver.kernel.mode`). Decided once per map in the calling process and passed
    to every worker, so all chunks of a map take the same arithmetic."""
    from vjm_pin.solver.kernel import mode

    return mode() != "0" and kernel() is not None


def _solve_or_nan(a, b):
    try:
        return np.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        return np.full(np.shape(b), np.nan)


_CHAIN_CACHE: dict = {}


def shared_chain(vm: VjmModel, jit: bool = False) -> BatchedChain:
    """This thread's :class:`BatchedChain` of ``vm`` (on the thread's shared ``pin.Data``), using the
    compiled kernel when ``jit``."""
    key = (id(vm), threading.get_ident())
    hit = _CHAIN_CACHE.get(key)
    if hit is None or hit.vm is not vm:
        if len(_CHAIN_CACHE) >= 8:
            _CHAIN_CACHE.clear()
        hit = _CHAIN_CACHE[key] = BatchedChain(vm)  # holds vm: its id stays unique
    hit.jit = bool(jit)
    return hit
