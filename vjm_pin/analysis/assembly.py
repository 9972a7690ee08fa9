"""Re-assembly of a closed mechanism at new actuator positions (maps of closed mechanisms).

A mechanism with loop closures (``<vjm:closure>``, :mod:`vjm_pin.kinematics.closures`) is
assembled at its file's reference configuration only. To evaluate it at other actuator
positions ``a`` the passive coordinates ``q`` must be found again so that every closure holds,
``c(a, q, θ₀) = 0``, with the springs at rest (``θ = θ₀``: an unloaded mechanism; the loaded
equilibrium is then the business of :class:`~vjm_pin.solver.mechanism.MechanismSolver`).

Newton on ``q`` alone, with the closure Jacobian's passive columns ``C_q`` (least squares with a
rank cut: redundant closure rows of an over-constrained mechanism are implied, a passive
self-motion takes the minimum-norm step)::

    δq = −C_q⁺ c(a, q, θ₀)

converged when every closure residual is below :data:`ASSEMBLY_TOL` (× the mechanism size
``L_c`` for metres, rad for rotations). Continuation keeps the assembly branch of the
reference (a four-bar stays elbow-up): the actuator space is covered by a lattice of spacing
:data:`STEP_REVOLUTE` (rad) / :data:`STEP_PRISMATIC` × ``L_c`` (m) anchored at the reference; a
lattice point is assembled from its parent (one step closer to the reference, along the
coordinate furthest from it), and a pose from the nearest lattice point of its own chain
that assembled, in straight steps no longer than one lattice step. A step that does not
converge, or whose passive coordinates jump by more than :data:`MAX_JUMP` (a change of
branch), is halved up to :data:`MAX_HALVINGS` times; then the pose is *not assembled* (out of
the workspace reachable from the reference, or across a singular configuration) and says so.

Every lattice point's configuration depends only on its index (its chain from the reference
is fixed), so the memo a process keeps does not change any number: a map gives the same
result bit for bit whatever the order, chunking or backend that evaluates its poses.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from vjm_pin.exceptions import InputError, RoleError
from vjm_pin.model.format import VjmModel

#: Largest closure residual of an assembled configuration (m / L_c, rad).
ASSEMBLY_TOL = 1e-12
#: Newton iterations of one continuation step.
MAX_ITER = 25
#: Lattice spacing of revolute actuators (rad) and of prismatic ones (× the mechanism size L_c).
STEP_REVOLUTE = 0.1
STEP_PRISMATIC = 0.05
#: Largest Newton step (rad; × L_c for prismatic passive coordinates).
MAX_NEWTON_STEP = 0.3
#: Largest change of the passive coordinates over one continuation step (rad; × L_c):
#: more is taken as a jump to another assembly branch, and the step is halved.
MAX_JUMP = 0.5
#: Halvings of a continuation step before a pose is declared not assembled.
MAX_HALVINGS = 5
#: Relative singular-value cut of the least-squares Newton step.
RCOND = 1e-10
#: Lattice points memoised per assembler (a bound on memory; the numbers do not depend on it).
MAX_MEMO = 200_000


@dataclass(frozen=True)
class Assembly:
    """The mechanism assembled at one actuator position (:meth:`Assembler.assemble`).

    Attributes:
        x: (nq,) configuration (m, rad): the actuators at the requested values, springs at
            rest, passive coordinates closing every loop; None when not assembled.
        residual: Largest closure residual at ``x`` (m, rad); NaN when not assembled.
        ok: Whether the mechanism was assembled.
        reason: Why not (empty when ``ok``).
    """

    x: np.ndarray | None
    residual: float
    ok: bool
    reason: str = ""


def length_scale(vm: VjmModel) -> float:
    """The mechanism size ``L_c`` (m): largest distance of a joint origin from the task frame
    at the reference (as :class:`~vjm_pin.solver.mechanism.MechanismSolver`), at least 1 mm."""
    from vjm_pin.model.placements import joint_placements

    model = vm.model
    omi = joint_placements(model, vm.reference)  # no pin.Data (model/placements.py)
    fr = model.frames[vm.frame_id]
    p0 = (omi[fr.parentJoint] * fr.placement).translation
    return max(max((np.linalg.norm(m.translation - p0) for m in omi[1:]), default=0.0), 1e-3)


def _is_prismatic(model, idx) -> np.ndarray:
    return np.array(
        [model.joints[int(i) + 1].shortname().startswith("JointModelP") for i in idx], bool
    )


class Assembler:
    """Assembles ``vm`` at actuator positions of the joints ``names`` (module docstring).

    Holds one :class:`~vjm_pin.kinematics.closures.ClosureSet` (the thread's shared ``pin.Data``) and the
    memo of assembled lattice points; not thread-safe (one per process or thread).
    ``length_scale_m``: the mechanism size ``L_c`` when the caller knows it (:func:`length_scale`
    otherwise: a Pinocchio workspace of its own, costly for large models).

    Raises:
        JointNotFound: an unknown joint. RoleError: a joint in ``names`` that is not actuated
            (passive coordinates are found by the assembly, spring coordinates are at rest).
    """

    def __init__(self, vm: VjmModel, names, length_scale_m: float | None = None):
        from vjm_pin.kinematics.closures import ClosureSet

        self.vm = vm
        self.names = tuple(names)
        self.act = np.array([vm.joint_index(n) for n in self.names], int)
        for n in self.names:
            if vm.roles[n] not in ("actuated", "locked"):
                raise RoleError(
                    f"joint '{n}' is {vm.roles[n]}: the poses of a closed mechanism are set by its actuated "
                    "joints (passive joints are found by re-assembling it, spring joints stay at rest)"
                )
        self.q_idx = np.asarray(vm.q_idx, int)
        self.closures = ClosureSet(vm)
        self.lc = length_scale(vm) if length_scale_m is None else float(length_scale_m)
        model = vm.model
        self.h = np.where(_is_prismatic(model, self.act), STEP_PRISMATIC * self.lc, STEP_REVOLUTE)
        self.q_scale = np.where(_is_prismatic(model, self.q_idx), self.lc, 1.0)
        pos = [c in ("x", "y", "z") for cl in vm.closures for c in cl.components]
        self.r_scale = np.where(np.array(pos, bool), self.lc, 1.0) if pos else np.zeros(0)
        self.a0 = vm.reference[self.act].copy()
        base = self._newton(self.a0, vm.reference[self.q_idx].copy())
        self._origin = base
        self._memo: dict[tuple[int, ...], np.ndarray | None] = {(0,) * len(self.act): base}

    # ----------------------------------------------------------------- one configuration
    def configuration(self, a: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(nq,) the reference with the actuators at ``a`` and the passive coordinates ``q``
        (springs at rest)."""
        x = self.vm.reference.copy()
        x[self.act] = a
        x[self.q_idx] = q
        return x

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Closure residual ``c(x)`` (m, rad)."""
        return self.closures.evaluate(x, hessian=False).residual

    def _newton(self, a: np.ndarray, q0: np.ndarray) -> np.ndarray | None:
        """Passive coordinates closing every loop at actuators ``a``, from ``q0``; None if
        Newton does not converge (no assembly near ``q0``). Once converged, one more step
        (kept if it does not raise the residual) takes it down to round-off."""
        q = np.array(q0, float)
        prev = np.inf
        for _ in range(MAX_ITER):
            size, dq = self._newton_step(a, q)
            if not np.isfinite(size):
                return None
            if size <= ASSEMBLY_TOL:
                if dq is None:
                    return q
                q2 = q + dq
                size2, _ = self._newton_step(a, q2, step=False)
                return q2 if size2 <= size else q
            if size >= prev or dq is None:  # no progress: no assembly near q0
                return None
            prev = size
            q = q + dq
        return None

    def _newton_step(self, a, q, step: bool = True):
        """(scaled residual size, Newton step of ``q`` or None) at actuators ``a``."""
        st = self.closures.evaluate(self.configuration(a, q), hessian=False)
        r = st.residual / self.r_scale
        size = float(np.abs(r).max()) if r.size else 0.0
        if not step or self.q_idx.size == 0 or not np.isfinite(size):
            return size, None
        cq = st.jacobian[:, self.q_idx] * self.q_scale / self.r_scale[:, None]  # per L_c or rad
        dq = -np.linalg.lstsq(cq, r, rcond=RCOND)[0]
        big = np.abs(dq).max(initial=0.0)
        if big > MAX_NEWTON_STEP:
            dq *= MAX_NEWTON_STEP / big
        return size, dq * self.q_scale

    def _step(self, a_from, q_from, a_to, halvings: int = 0) -> np.ndarray | None:
        """Continue from an assembled (a_from, q_from) to a_to (halving on failure)."""
        q = self._newton(a_to, q_from)
        if q is not None and np.abs((q - q_from) / self.q_scale).max(initial=0.0) <= MAX_JUMP:
            return q
        if halvings >= MAX_HALVINGS:
            return None
        mid = 0.5 * (a_from + a_to)
        qm = self._step(a_from, q_from, mid, halvings + 1)
        return None if qm is None else self._step(mid, qm, a_to, halvings + 1)

    def _straight(self, a_from, q_from, a_to) -> np.ndarray | None:
        """Continue along the straight segment in steps of at most one lattice spacing."""
        n = max(1, int(np.ceil(np.abs((a_to - a_from) / self.h).max(initial=0.0) - 1e-9)))
        pts = [a_from + (a_to - a_from) * (k / n) for k in range(n)] + [np.asarray(a_to, float)]
        q = q_from
        for a_prev, a_next in itertools.pairwise(pts):
            q = self._step(a_prev, q, a_next)
            if q is None:
                return None
        return q

    # ----------------------------------------------------------------- lattice
    def _point(self, k: tuple[int, ...]) -> np.ndarray:
        return self.a0 + np.asarray(k, float) * self.h

    @staticmethod
    def _parent(k: tuple[int, ...]) -> tuple[int, ...]:
        """One step closer to the reference, along the coordinate furthest from it (first)."""
        i = int(np.argmax(np.abs(k)))
        p = list(k)
        p[i] -= int(np.sign(p[i]))
        return tuple(p)

    def _chain(self, k: tuple[int, ...]) -> list[tuple[int, ...]]:
        """Lattice indices from ``k`` back to the reference (``k`` first, the origin last)."""
        out = [k]
        while any(out[-1]):
            out.append(self._parent(out[-1]))
        return out

    def _lattice(self, chain) -> tuple[tuple[int, ...], np.ndarray]:
        """The furthest assembled point of ``chain`` (``k`` first, the origin last) and its
        passive coordinates; assembles the missing points in order (memoised). A lattice point
        has one parent, so a memoised point's ancestors assembled, and nothing beyond a point
        that failed is tried."""
        memo = self._memo
        i = len(chain) - 1
        while i > 0 and chain[i - 1] in memo:
            i -= 1
        if memo[chain[i]] is None:  # a known failure: its parent assembled
            return chain[i + 1], memo[chain[i + 1]]
        best, q = chain[i], memo[chain[i]]
        for j in range(i - 1, -1, -1):
            if len(memo) >= MAX_MEMO:  # forget (the numbers do not depend on the memo)
                memo.clear()
                memo[chain[-1]] = self._origin
                memo[best] = q
            qk = self._step(self._point(best), q, self._point(chain[j]))
            memo[chain[j]] = qk
            if qk is None:
                break
            best, q = chain[j], qk
        return best, q

    # ----------------------------------------------------------------- public
    def assemble(self, values) -> Assembly:
        """The mechanism at actuator positions ``values`` (one per joint of ``names``; m, rad)."""
        a = np.asarray(values, float).reshape(-1)
        if a.shape != self.a0.shape or not np.all(np.isfinite(a)):
            raise InputError(
                f"actuator positions must be {self.a0.size} finite numbers, got {a.tolist()}"
            )
        if self._memo[(0,) * len(self.act)] is None:
            return Assembly(
                None, float("nan"), False, "the reference configuration does not assemble"
            )
        k = tuple(int(v) for v in np.rint((a - self.a0) / self.h))
        best, q_best = self._lattice(self._chain(k))
        if q_best is None:
            return Assembly(
                None, float("nan"), False, "the reference configuration does not assemble"
            )
        q = self._straight(self._point(best), q_best, a)
        if q is None:
            return Assembly(
                None,
                float("nan"),
                False,
                "no assembly reached by continuation from the reference (out of the workspace or "
                "across a singular configuration)",
            )
        x = self.configuration(a, q)
        r = self.residual(x)
        return Assembly(x, float(np.abs(r).max(initial=0.0)), True)
