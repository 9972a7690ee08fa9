"""The matrices of the paper evaluated at one configuration and wrench.

``Blocks`` bundles what eq. (5)–(33) need: the spring and passive Jacobians restricted
to the constrained task components, and the four blocks of the Hessian of
``Ψ = g(q, θ)ᵀF`` (eq. 16).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import Kinematics, KinematicState
from ..model import VjmModel


@dataclass(frozen=True)
class Blocks:
    """Jacobians and Hessians at one loaded configuration.

    Attributes:
        J_theta: (m, nθ) Jacobian of the spring coordinates, task rows (m/rad, m/m, …).
        J_q: (m, nq) Jacobian of the passive coordinates, task rows.
        H_tt: (nθ, nθ) ``∂(J_θᵀF)/∂θ``  (N·m/rad …), eq. (16).
        H_tq: (nθ, nq) ``∂(J_θᵀF)/∂q``.
        H_qt: (nq, nθ) ``∂(J_qᵀF)/∂θ``.
        H_qq: (nq, nq) ``∂(J_qᵀF)/∂q``.
        K_theta: (nθ, nθ) spring stiffness.
        state: The full :class:`~vjm_pin.kinematics.KinematicState`.
    """

    J_theta: np.ndarray
    J_q: np.ndarray
    H_tt: np.ndarray
    H_tq: np.ndarray
    H_qt: np.ndarray
    H_qq: np.ndarray
    K_theta: np.ndarray
    state: KinematicState


def full_wrench(vm: VjmModel, f_task: np.ndarray) -> np.ndarray:
    """6-D wrench with the task components set from ``f_task`` and zeros elsewhere."""
    w = np.zeros(6)
    w[list(vm.task)] = f_task
    return w


def evaluate_blocks(
    vm: VjmModel, kin: Kinematics, x: np.ndarray, wrench: np.ndarray, state: KinematicState | None = None
) -> Blocks:
    """Evaluate :class:`Blocks` at configuration ``x`` (nq,) under the 6-D ``wrench`` (N, N·m)."""
    if state is None or state.hessian is None:
        state = kin.evaluate(x, hessian=True)
    task = list(vm.task)
    jt = state.jacobian[task]
    ti, qi = vm.theta_idx, vm.q_idx
    h = state.psi_hessian(wrench)
    return Blocks(
        J_theta=jt[:, ti],
        J_q=jt[:, qi],
        H_tt=h[np.ix_(ti, ti)],
        H_tq=h[np.ix_(ti, qi)],
        H_qt=h[np.ix_(qi, ti)],
        H_qq=h[np.ix_(qi, qi)],
        K_theta=vm.K_theta,
        state=state,
    )
