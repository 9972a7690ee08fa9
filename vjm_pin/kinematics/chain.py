"""Kinematics of a VJM model through Pinocchio: ``t = g(q, θ)``, Jacobians and Hessians.

Conventions (Pinocchio's ``LOCAL_WORLD_ALIGNED``):

- the end location is the position ``p`` (m) of the end frame origin and its orientation
  ``R``; a deflection is ``(p − p₀, log3(R R₀ᵀ))``: position change and the world-aligned
  rotation vector (rad) from the reference orientation;
- the Jacobian ``J`` (6 × nv) maps joint velocities to the linear velocity of the frame
  origin and the angular velocity, both in world axes; the wrench ``F`` conjugate to it
  is the force (N) at the frame origin and the moment (N·m) about it, in world axes;
- the "Hessian of Ψ = g(q, θ)ᵀF" of eq. (16) is the derivative of the generalised
  force ``JᵀF`` for a fixed (dead) wrench ``F``: ``H[i, j] = Σ_k F_k ∂J[k, i]/∂x_j``,
  which is exactly the differential δ(JᵀF) that eq. (14)–(15) and (27) use. It is
  symmetric when the wrench is a pure force; a moment makes it non-symmetric (the
  angular-velocity Jacobian is not the gradient of a function), see footnote 2 of the
  paper.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import ArgumentError, InputError
from vjm_pin.kinematics.screw import psi_hessian_screw, screw_applicable, support_mask
from vjm_pin.kinematics.shared import data_for

#: Configuration coordinates smaller than this (m, rad) are set to exactly zero after every
#: solver update (:func:`flush_tiny`). On a straight column the symmetric-mode coordinates
#: converge quadratically towards ~1e-320 (subnormal floats), where a Pinocchio J + kinematic
#: Hessian evaluation costs more (1.2–7×, machine-dependent: ``scripts/benchmark.py``); 1e-150
#: is far below any physical displacement and its square is still a normal float, so results
#: are unchanged to all digits.
FLUSH_BELOW = 1e-150
#: Private switch of :func:`flush_tiny` (False: the old behaviour, for benchmarks and the tests
#: that show the flush changes no result).
_flush_enabled = True
#: Private switch of the screw-form Hessian (:mod:`vjm_pin.kinematics.screw`): False makes
#: :meth:`Kinematics.psi_hessian` contract Pinocchio's kinematic Hessian tensor for every model
#: (the behaviour before issue 14; for benchmarks and the tests that compare the two).
_screw_enabled = True


def flush_tiny(x: np.ndarray) -> np.ndarray:
    """Set the entries of the float array ``x`` with ``|x| <`` :data:`FLUSH_BELOW` to exactly
    zero, in place; returns ``x`` (NaN and inf are left alone)."""
    if _flush_enabled:
        x[np.abs(x) < FLUSH_BELOW] = 0.0
    return x


def fix_hessian_layout(h: np.ndarray) -> np.ndarray:
    """Reorder a kinematic Hessian returned by Pinocchio 4.1 so that
    ``out[k, i, j] = ∂J[k, i]/∂x_j``.

    ``getFrameKinematicHessian`` returns a ``(6, nv, nv)`` array whose memory order is
    scrambled; the true tensor is ``h.reshape(-1).reshape((6, nv, nv), order="F")``.
    ``tests/test_kinematics.py`` checks this against finite differences, so a fix in
    Pinocchio will be noticed.
    """
    nv = h.shape[1]
    return np.asarray(h).reshape(-1).reshape((6, nv, nv), order="F")


@dataclass(frozen=True)
class KinematicState:
    """Kinematics at one configuration.

    Attributes:
        position: (3,) end frame origin, world (m).
        rotation: (3, 3) end frame orientation in world.
        jacobian: (6, nv) ``LOCAL_WORLD_ALIGNED`` frame Jacobian (m/rad, m/m, rad/rad).
        hessian: (6, nv, nv) with ``hessian[k, i, j] = ∂jacobian[k, i]/∂x_j``, or None.
    """

    position: np.ndarray
    rotation: np.ndarray
    jacobian: np.ndarray
    hessian: np.ndarray | None = None

    def psi_hessian(self, wrench: np.ndarray) -> np.ndarray:
        """(nv, nv) ``H[i, j] = ∂(J[:, i]·F)/∂x_j`` for the 6-D wrench ``F`` (eq. 16)."""
        if self.hessian is None:
            raise InputError("this KinematicState was evaluated without Hessian: evaluate(x, hessian=True)")
        wrench = _vector(wrench, 6, "wrench", "(Fx, Fy, Fz, Mx, My, Mz) in N and N·m")
        return contract_hessian(self.hessian, wrench)


def contract_hessian(hessian: np.ndarray, wrench: np.ndarray) -> np.ndarray:
    """``H[i, j] = Σ_k F_k hessian[k, i, j]`` (eq. 16) as one matrix–vector product on a
    memory view of ``hessian`` (6, nv, nv), whichever its memory order."""
    nv = hessian.shape[1]
    if hessian.flags.c_contiguous:
        return (wrench @ hessian.reshape(6, nv * nv)).reshape(nv, nv)
    if hessian.flags.f_contiguous:  # the layout :func:`fix_hessian_layout` returns
        return (hessian.T.reshape(nv * nv, 6) @ wrench).reshape(nv, nv).T
    return np.tensordot(wrench, hessian, axes=(0, 0))


#: :func:`~vjm_pin.kinematics.screw.support_mask` by its whole input ``(nv, cols as int64 bytes)``
#: (read only; :meth:`Kinematics.support_mask` hands out copies): ~20 µs per new solver at n = 146.
_MASKS: dict[tuple[int, bytes], np.ndarray] = {}


class Kinematics:
    """Evaluates ``g``, ``J`` and the kinematic Hessian of the end frame of a model.

    Uses the thread's shared ``pin.Data`` of the model (:mod:`vjm_pin.kinematics.shared`):
    every call recomputes what it reads at its ``x``. The caller's ``pin.Model`` is never
    modified. The last evaluation is kept: asking again at the same configuration (bit for bit) returns the same
    :class:`KinematicState` without calling Pinocchio (a curve point's final iterate is
    the next solve's start, and its stiffness and stability are evaluated there too).
    """

    def __init__(self, model: pin.Model, frame_id: int):
        if not isinstance(model, pin.Model):
            raise ArgumentError(f"model must be a pinocchio.Model, got {type(model).__name__}")
        if isinstance(frame_id, bool) or not isinstance(frame_id, (int, np.integer)) or not (
            0 <= frame_id < model.nframes
        ):
            raise ArgumentError(
                f"frame_id must be a frame index 0..{model.nframes - 1} of the model, got {frame_id!r}"
            )
        self.model = model
        self.frame_id = int(frame_id)
        self._last: tuple[bytes, KinematicState] | None = None
        #: Whether the Hessian of Ψ can be taken in screw form from J alone (every joint a 1-DoF
        #: revolute or prismatic joint): :meth:`psi_hessian`.
        self.screw = screw_applicable(model)
        self._masks: dict[bytes, np.ndarray] = {}

    @property
    def data(self) -> pin.Data:
        """This thread's shared ``pin.Data`` of the model (:func:`~vjm_pin.kinematics.shared.data_for`;
        scratch: valid only right after a call that recomputed what you read)."""
        return data_for(self.model)

    @property
    def uses_screw(self) -> bool:
        """True when :meth:`psi_hessian` takes the screw form (no kinematic Hessian tensor needed)."""
        return self.screw and _screw_enabled

    def psi_hessian(self, state: KinematicState, wrench: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
        """``H[i, j] = ∂(J[:, i]·F)/∂x_j`` (eq. 16) at ``state`` for the 6-D ``wrench``, rows and
        columns restricted to (and ordered as) the velocity indices ``cols`` (default all).

        In screw form from ``state.jacobian`` (:func:`~vjm_pin.kinematics.screw.psi_hessian_screw`)
        when :attr:`uses_screw`, else the contraction of Pinocchio's kinematic Hessian (which
        ``state`` must then carry). Both agree to rounding (``tests/test_screw.py``)."""
        wrench = np.asarray(wrench, dtype=float)
        if self.uses_screw:
            if cols is None:
                return psi_hessian_screw(state.jacobian, wrench, self.support_mask(None))
            return psi_hessian_screw(state.jacobian.take(cols, axis=1), wrench, self.support_mask(cols))
        h = state.psi_hessian(wrench)
        return h if cols is None else h[np.ix_(cols, cols)]

    def support_mask(self, cols: np.ndarray | None) -> np.ndarray:
        """:func:`~vjm_pin.kinematics.screw.support_mask` for the columns ``cols``, kept per ``cols``
        (this object's own array; a new Kinematics copies the one computed for equal
        ``(nv, cols)`` before: :data:`_MASKS`)."""
        key = b"" if cols is None else np.asarray(cols, np.int64).tobytes()
        mask = self._masks.get(key)
        if mask is None:
            ck = (self.model.nv, key)
            kept = _MASKS.get(ck)
            if kept is None:
                kept = support_mask(self.model.nv, cols)
                kept.flags.writeable = False
                if len(_MASKS) >= 8:
                    _MASKS.pop(next(iter(_MASKS)), None)
                _MASKS[ck] = kept
            mask = self._masks[key] = kept.copy()
        return mask

    def placement(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """End frame (position (3,) m, rotation (3, 3)) at configuration ``x``."""
        x = _vector(x, self.model.nq, "x", "the configuration (m, rad)")
        pin.framesForwardKinematics(self.model, self.data, x)
        m = self.data.oMf[self.frame_id]
        return m.translation.copy(), m.rotation.copy()

    def evaluate(self, x: np.ndarray, hessian: bool = True) -> KinematicState:
        """Placement, Jacobian and (optionally) kinematic Hessian at ``x`` (nq,).

        The returned state is shared with later calls at the same ``x``: do not modify it."""
        x = _vector(x, self.model.nq, "x", "the configuration (m, rad)")
        key = x.tobytes()
        last = self._last
        if last is not None and last[0] == key and (last[1].hessian is not None or not hessian):
            return last[1]
        model, data, fid = self.model, self.data, self.frame_id
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacement(model, data, fid)
        nv = model.nv
        # (pin returns a 1-D array for a one-joint model: keep the (6, nv) shape)
        jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, nv)
        hes = None
        if hessian:
            pin.computeJointKinematicHessians(model, data)
            hes = fix_hessian_layout(
                np.asarray(pin.getFrameKinematicHessian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)).reshape(6, nv, nv)
            )
        m = data.oMf[fid]
        state = KinematicState(m.translation.copy(), m.rotation.copy(), jac.copy(), hes)
        self._last = (key, state)
        return state


def _vector(v, n: int, name: str, meaning: str) -> np.ndarray:
    """``v`` as a float array of shape (n,); :class:`InputError` naming ``name`` otherwise."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be {n} numbers ({meaning}), got {v!r}") from None
    if a.shape != (n,):
        raise InputError(f"{name} must be {n} numbers ({meaning}), got shape {a.shape}")
    return a


def pose_error(p_target, r_target, p, r) -> np.ndarray:
    """6-D error from the pose (p, r) to the target: ``(p* − p, log3(R* Rᵀ))`` (m, rad)."""
    return np.concatenate([np.asarray(p_target) - p, pin.log3(np.asarray(r_target) @ r.T)])


def deflection(p0, r0, p, r) -> np.ndarray:
    """6-D deflection of the pose (p, r) from (p0, r0): ``(p − p0, log3(R R0ᵀ))``."""
    return np.concatenate([np.asarray(p) - p0, pin.log3(np.asarray(r) @ np.asarray(r0).T)])


def displace(p0, r0, dt) -> tuple[np.ndarray, np.ndarray]:
    """The pose reached from (p0, r0) by the 6-D deflection ``dt`` (inverse of :func:`deflection`)."""
    dt = np.asarray(dt, float)
    return np.asarray(p0) + dt[:3], pin.exp3(dt[3:]) @ np.asarray(r0)
