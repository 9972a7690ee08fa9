"""Kinematics layer: what Pinocchio gives the solver (paper eq. 1–4, 16).

- :mod:`~vjm_pin.kinematics.chain`: the task frame's pose, Jacobian and kinematic Hessian
  (:class:`~vjm_pin.kinematics.chain.Kinematics`), pose errors and deflections.
- :mod:`~vjm_pin.kinematics.frames`: the same for any set of frames at once.
- :mod:`~vjm_pin.kinematics.closures`: loop-closure constraints ``c(x) = 0`` and their
  derivatives.
- :mod:`~vjm_pin.kinematics.dead_loads`: dead wrenches at frames and link weights as
  generalised forces.
"""

from vjm_pin.kinematics.chain import (
    FLUSH_BELOW,
    Kinematics,
    KinematicState,
    contract_hessian,
    deflection,
    displace,
    fix_hessian_layout,
    flush_tiny,
    pose_error,
)

__all__ = [
    "FLUSH_BELOW",
    "KinematicState",
    "Kinematics",
    "contract_hessian",
    "deflection",
    "displace",
    "fix_hessian_layout",
    "flush_tiny",
    "pose_error",
]
