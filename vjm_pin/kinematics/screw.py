"""The Hessian of ``Ψ = g(q, θ)ᵀF`` (eq. 16) in screw form, from the Jacobian alone.

For a chain of 1-DoF joints the columns of the ``LOCAL_WORLD_ALIGNED`` frame Jacobian are
twists ``J[:, i] = (v_i, ω_i)`` in world axes: for a revolute joint of unit axis ``a_i``
through ``o_i``, ``ω_i = a_i`` and ``v_i = a_i × (p − o_i)`` (``p`` the frame origin); for a
prismatic joint ``v_i = a_i``, ``ω_i = 0``. Moving joint ``j``:

- when ``j`` supports joint ``i`` or is ``i`` (``j ≤ i`` along the chain), the whole twist
  ``i`` is carried along by ``j``'s motion: ``∂J[:, i]/∂x_j = (ω_j × v_i, ω_j × ω_i)``
  (the Jacobi identity collapses the derivative of ``v_i = ω_i × (p − o_i)`` to ``ω_j × v_i``;
  for a prismatic ``j``, ``ω_j = 0`` and nothing changes);
- when ``j`` is distal to ``i`` (``j > i``), axis ``i`` stays and only the frame origin moves,
  by ``v_j``: ``∂J[:, i]/∂x_j = (ω_i × v_j, 0)``.

Contracted with the dead wrench ``F = (f, m)`` (N, N·m)::

    H[i, j] = ω_j · (v_i × f + ω_i × m)     for j ≤ i,
    H[i, j] = ω_i · (v_j × f)               for j > i,

which is ``H[i, j] = Σ_k F_k ∂J[k, i]/∂x_j`` (:func:`~vjm_pin.kinematics.chain.contract_hessian`
of Pinocchio's kinematic Hessian) without the 6 × nv × nv tensor: two (nv × 3)(3 × nv)
products. Columns of joints that do not support the frame are zero and give zero rows and
columns; among the joints that do, Pinocchio numbers a parent before its children, so "``j``
supports ``i``" is ``j ≤ i``. Valid when every joint is a 1-DoF revolute or prismatic joint
(:func:`screw_applicable`); other joint types (spherical, free-flyer, …) keep Pinocchio's tensor.

This function is the vectorised numpy form (two small matrix products), used wherever a
Hessian is formed on its own; the serial solver's Newton loop evaluates the same formula inside
its fused compiled iteration (:mod:`vjm_pin.solver.kernel`, numba, with a numpy twin), and
:mod:`vjm_pin.solver.chain_algebra` uses its rank-3 generators (``ω``, ``v × f + ω × m``,
``v × f``) to factor ``K − H`` in O(n) along the chain.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

#: Pinocchio joint short names of 1-DoF joints whose twist is a revolute screw (pitch 0) or a pure
#: translation; the screw-form Hessian is exact for chains of these.
_REVOLUTE = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")
_PRISMATIC = ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned")


#: Answers of :func:`screw_applicable` by model (the model kept with its answer, so an id is never
#: reused while its entry lives; a few entries: one per model a process works with).
_APPLICABLE: dict[int, tuple[pin.Model, int, bool]] = {}


def screw_applicable(model: pin.Model) -> bool:
    """True when every joint of ``model`` is a 1-DoF revolute or prismatic joint (nq = nv), the
    case where :func:`psi_hessian_screw` equals the contraction of Pinocchio's kinematic Hessian.
    Remembered per model object (reading the joint types copies every joint model: ~2 ms at 148
    joints, paid by every new solver otherwise)."""
    hit = _APPLICABLE.get(id(model))
    if hit is not None and hit[0] is model and hit[1] == model.njoints:  # a joint added since: asked again
        return hit[2]
    ok = model.nq == model.nv and all(
        jm.shortname() in _REVOLUTE + _PRISMATIC for jm in list(model.joints)[1:]
    )
    if len(_APPLICABLE) >= 16:
        _APPLICABLE.pop(next(iter(_APPLICABLE)))
    _APPLICABLE[id(model)] = (model, model.njoints, ok)
    return ok


def support_mask(nv: int, cols: np.ndarray | None = None) -> np.ndarray:
    """(n, n) boolean ``mask[a, b] = cols[b] ≤ cols[a]`` for the joint velocity indices ``cols``
    (default ``0..nv−1``): where :func:`psi_hessian_screw` uses the "``j`` supports ``i``"
    branch, for columns taken in the order ``cols`` (e.g. the solver's (θ, q) order)."""
    c = np.arange(nv) if cols is None else np.asarray(cols, int)
    return c[None, :] <= c[:, None]


def psi_hessian_screw(jacobian: np.ndarray, wrench: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """``H[i, j] = ∂(J[:, i]·F)/∂x_j`` (eq. 16) from the (6, n) ``LOCAL_WORLD_ALIGNED`` frame
    Jacobian of a chain of 1-DoF revolute/prismatic joints and the 6-D wrench ``F = (f, m)``
    (N at the frame origin, N·m, world axes), in screw form (module docstring).

    Args:
        jacobian: (6, n) Jacobian columns, in any order of the joints.
        wrench: (6,) wrench.
        mask: (n, n) from :func:`support_mask` for the column order of ``jacobian``; default
            the Pinocchio order (columns ``0..n−1`` are joints ``0..n−1``).

    Returns:
        (n, n) array, rows and columns in the order of the Jacobian's columns (N·m/rad, N/rad, N…).
    """
    jac = np.asarray(jacobian, float)
    n = jac.shape[1]
    if mask is None:
        mask = support_mask(n)
    fx, fy, fz, mx, my, mz = np.asarray(wrench, float).tolist()
    w = jac[3:]
    # d_j = v_j × f = −[f]× v_j; u[i, j] = ω_i·d_j; ω_j·(v_i × f) = u[j, i]
    d = np.array([[0.0, fz, -fy], [-fz, 0.0, fx], [fy, -fx, 0.0]]) @ jac[:3]
    u = w.T @ d
    if mx or my or mz:  # + ω_j·(ω_i × m), ω_i × m = −[m]× ω_i
        e = np.array([[0.0, mz, -my], [-mz, 0.0, mx], [my, -mx, 0.0]]) @ w
        return np.where(mask, u.T + e.T @ w, u)
    return np.where(mask, u.T, u)
