"""Kinematics of several frames at one configuration (kinematics layer).

The mechanism core needs, at each configuration, the placement, Jacobian and kinematic
Hessian of more frames than the end frame: both frames of every loop closure and every frame
that carries a dead load. :class:`FrameKinematics` evaluates them in one Pinocchio pass, with
the conventions of :mod:`vjm_pin.kinematics.chain` (``LOCAL_WORLD_ALIGNED`` Jacobians: linear
velocity of the frame origin and angular velocity, world axes; Hessians with
``hessian[k, i, j] = ∂jacobian[k, i]/∂x_j``, the pin 4.1 layout fixed by
:func:`~vjm_pin.kinematics.chain.fix_hessian_layout`).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import ArgumentError
from vjm_pin.kinematics.chain import KinematicState, _vector, fix_hessian_layout
from vjm_pin.kinematics.shared import data_for


class FrameKinematics:
    """Placements, Jacobians and (optionally) kinematic Hessians of a set of frames.

    Uses the thread's shared ``pin.Data`` of the model (:func:`~vjm_pin.kinematics.shared.data_for`,
    created on the first evaluation, none at construction): every evaluation recomputes all it
    reads at its ``x`` and copies it out. The caller's ``pin.Model`` is never modified. The last
    evaluation is kept: asking again at the same configuration (bit for bit) returns the same
    states without calling Pinocchio.

    Args:
        model: A Pinocchio model with nq = nv (the VJM coordinates).
        frame_ids: Frame indices to evaluate (duplicates are evaluated once).
    """

    def __init__(self, model: pin.Model, frame_ids: Iterable[int]):
        if not isinstance(model, pin.Model):
            raise ArgumentError(f"model must be a pinocchio.Model, got {type(model).__name__}")
        ids = []
        for f in frame_ids:
            if (
                isinstance(f, bool)
                or not isinstance(f, (int, np.integer))
                or not 0 <= f < model.nframes
            ):
                raise ArgumentError(
                    f"frame ids must be frame indices 0..{model.nframes - 1} of the model, got {f!r}"
                )
            if int(f) not in ids:
                ids.append(int(f))
        self.model = model
        self.frame_ids: tuple[int, ...] = tuple(ids)
        self._last: tuple[bytes, dict[int, KinematicState]] | None = None

    def evaluate(self, x: np.ndarray, hessian: bool = True) -> dict[int, KinematicState]:
        """Frame id → :class:`~vjm_pin.kinematics.chain.KinematicState` at ``x`` (nq,) (m, rad).

        The returned states are shared with later calls at the same ``x``: do not modify them."""
        x = _vector(x, self.model.nq, "x", "the configuration (m, rad)")
        key = x.tobytes()
        last = self._last
        if (
            last is not None
            and last[0] == key
            and (hessian is False or all(s.hessian is not None for s in last[1].values()))
        ):
            return last[1]
        model, nv = self.model, self.model.nv
        data = data_for(model)
        pin.computeJointJacobians(model, data, x)
        if hessian:
            pin.computeJointKinematicHessians(model, data)
        states = {}
        for fid in self.frame_ids:
            pin.updateFramePlacement(model, data, fid)
            jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, nv)
            hes = None
            if hessian:
                raw = pin.getFrameKinematicHessian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
                hes = fix_hessian_layout(np.asarray(raw).reshape(6, nv, nv))
            m = data.oMf[fid]
            states[fid] = KinematicState(m.translation.copy(), m.rotation.copy(), jac.copy(), hes)
        self._last = (key, states)
        return states

    @property
    def data(self) -> pin.Data:
        """This thread's shared ``pin.Data`` of the model (scratch: valid only right after a call
        that recomputed what you read)."""
        return data_for(self.model)
