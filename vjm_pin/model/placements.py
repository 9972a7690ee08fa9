"""Frame placements at a configuration without a ``pin.Data`` (model layer).

Pinocchio 4.1 allocates nv³ second-order tensors in every ``pin.Data`` (seconds and ~600 MB for
the 231-coordinate ``orthoglide-loop-q0``); the loader only needs placements (assembly check,
leg frames), so it composes them here from the joint models: ``oMi[i] = oMi[parent] ·
(jointPlacement[i] · M_i(q))`` and ``oMf = oMi[parentJoint] · frame.placement`` — the products
``pin.framesForwardKinematics`` forms, in the same order, so the result equals Pinocchio's to
round-off (bit for bit at generic configurations; Pinocchio's revolute-specialised products may
round entries of ~1e-16 differently, by ~1e-32: ``tests/test_shared_data.py``). About 15 ms for 231 joints, against ~2.5 s for ``createData``.
Kinematics that also need Jacobians use the shared Data of :mod:`vjm_pin.kinematics.shared`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import ArgumentError


def joint_placements(model: pin.Model, q: np.ndarray) -> list[pin.SE3]:
    """``oMi`` (world placement of every joint frame, index 0 the universe) at ``q`` (nq,)."""
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (model.nq,) or not np.all(np.isfinite(q)):
        raise ArgumentError(f"q must be {model.nq} finite numbers (m, rad), got shape {q.shape}")
    omi = [pin.SE3.Identity()]
    parents, places, joints = model.parents, model.jointPlacements, model.joints
    for i in range(1, model.njoints):
        jm = joints[i]
        jd = jm.createData()
        jm.calc(jd, q)
        li = places[i] * jd.M
        p = parents[i]
        omi.append(li if p == 0 else omi[p] * li)
    return omi


def frame_placements(model: pin.Model, q: np.ndarray) -> list[pin.SE3]:
    """``oMf`` (world placement of every frame of ``model``, frame index order) at ``q`` (nq,)."""
    omi = joint_placements(model, q)
    return [omi[f.parentJoint] * f.placement for f in model.frames]


__all__ = ["frame_placements", "joint_placements"]
