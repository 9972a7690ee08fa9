"""Compiled forward kinematics of the end frame of a chain of 1-DoF joints (issue 14).

The fused Newton iteration of the serial solver (:mod:`vjm_pin.solver.kernel`) needs, per iteration,
the end frame's placement ``(p, R)`` (eq. 1) and its ``LOCAL_WORLD_ALIGNED`` frame Jacobian ``J``
(eq. 2–4), and the orientation error ``log3(R* Rᵀ)``. Pinocchio gives them, but a Python-level call
costs more than the arithmetic at the orders of VJM chains (~7–9 µs for ``computeFrameJacobian``,
~4 µs for ``pin.log3`` through the bindings). This module computes the same quantities in numba
(``@njit(cache=True)``, imported lazily as :mod:`vjm_pin.solver.kernel` does) so the kernel can run
whole iterations without returning to Python:

- :func:`chain_table` reads, once per model and frame (kept while the model is unchanged), the joints on the end frame's support
  path (every one a 1-DoF revolute or prismatic joint: ``JointModelRX/RY/RZ/RevoluteUnaligned/
  PX/PY/PZ/PrismaticUnaligned``; ``nq == nv``), their placements in the parent joint's frame,
  axes and velocity indices, and the frame's placement in its joint's frame; None when the
  model is not such a chain (a free-flyer, spherical, planar, … joint anywhere).
- :func:`forward` (compiled by :func:`compiled`): ``oMi = oMi[parent] · jointPlacement ·
  M_joint(q)`` along the path (Pinocchio's order of products), ``oMf = oMi · framePlacement``,
  and the frame Jacobian columns ``[ω × (p_f − p_i); ω]`` (revolute, ``ω = R_i a``) or ``[R_i a; 0]``
  (prismatic), zero off the path. Equal to Pinocchio's to rounding (``tests/test_compiled_chain.py``).
- :func:`log3`: Pinocchio 4's ``log3`` (``src/spatial/log.hxx``: renormalised rotation, the
  nominal branch with its Taylor expansion near the identity, the singular branch near π)
  transcribed operation for operation.

numpy only at import; numba when :func:`compiled` is first called (None when numba is missing).
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pinocchio as pin

#: Joint kinds of :func:`chain_table`: the short name → (kind, axis) with kind 0 revolute, 1 prismatic
#: (an unaligned joint's axis is read from the joint model).
_KINDS = {
    "JointModelRX": (0, (1.0, 0.0, 0.0)), "JointModelRY": (0, (0.0, 1.0, 0.0)), "JointModelRZ": (0, (0.0, 0.0, 1.0)),
    "JointModelRevoluteUnaligned": (0, None),
    "JointModelPX": (1, (1.0, 0.0, 0.0)), "JointModelPY": (1, (0.0, 1.0, 0.0)), "JointModelPZ": (1, (0.0, 0.0, 1.0)),
    "JointModelPrismaticUnaligned": (1, None),
}

#: Columns of a row of the ``geo`` table: rotation (row-major, 9), translation (3), axis (3).
GEO_COLS = 15

_EPS = float(np.finfo(float).eps)
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<2>()


class ChainTable:
    """The arrays of :func:`forward` for one model and end frame (read only).

    ``geo`` (k + 1, 15): row ``i < k`` the ``i``-th joint of the support path (root first): its
    placement in the parent joint's frame (rotation row-major, translation) and its unit axis;
    row ``k``: the frame's placement in its joint's frame (axis unused). ``jinfo`` (k, 2) int64:
    kind (0 revolute, 1 prismatic) and the joint's index in ``x`` (``idx_q == idx_v``). ``nv``
    the model's velocity dimension (the Jacobian's columns)."""

    __slots__ = ("geo", "jinfo", "nv")

    def __init__(self, geo: np.ndarray, jinfo: np.ndarray, nv: int):
        self.geo = geo
        self.jinfo = jinfo
        self.nv = nv


def chain_table(model: pin.Model, frame_id: int) -> ChainTable | None:
    """The :class:`ChainTable` of ``model``'s frame ``frame_id``; None unless ``nq == nv`` and every
    joint of the model is a 1-DoF revolute or prismatic joint (the chains whose Hessian of Ψ the
    solver takes in screw form).

    Kept per model object and frame together with a copy of the model (:data:`TABLES_MAX`
    entries): a new solver of a model seen before gets the kept table when Pinocchio's own
    ``Model.__eq__`` finds the model equal to that copy (every joint, placement, frame, …; ~25 µs
    at 150 joints), so a model edited in place gets a new one. Read from the model, each list
    through one binding call (``tolist``): ~0.15 ms at 150 joints (~1 ms joint by joint). The
    table's arrays are shared by every solver of the model: read them only (writeable, so that
    the compiled functions keep one signature)."""
    key = (id(model), int(frame_id))
    with _TABLES_LOCK:
        hit = _TABLES.get(key)
    if hit is not None and hit[0] is model and model == hit[1]:
        return hit[2]
    table = _read_table(model, frame_id)
    with _TABLES_LOCK:
        _TABLES.pop(key, None)
        while len(_TABLES) >= TABLES_MAX:
            _TABLES.pop(next(iter(_TABLES)))
        _TABLES[key] = (model, pin.Model(model), table)
    return table


#: Models whose :func:`chain_table` is kept (the most recent ones).
TABLES_MAX = 8
_TABLES: dict = {}  # (id(model), frame id) -> (model, copy of the model, table or None)
_TABLES_LOCK = threading.Lock()


def _read_table(model: pin.Model, frame_id: int) -> ChainTable | None:
    """:func:`chain_table` read from the model."""
    if model.nq != model.nv:
        return None
    joints = model.joints.tolist()
    kinds = [_KINDS.get(jm.shortname()) for jm in joints[1:]]
    if None in kinds:  # (every joint of _KINDS has nq = nv = 1)
        return None
    frame = model.frames[int(frame_id)]
    path = [int(j) for j in model.supports[frame.parentJoint]][1:]  # (the universe first)
    k = len(path)
    geo = np.zeros((k + 1, GEO_COLS))
    jinfo = np.zeros((k, 2), np.int64)
    if k:
        pls = model.jointPlacements.tolist()
        hom = np.array([pls[j].homogeneous for j in path])
        geo[:k, :9] = hom[:, :3, :3].reshape(k, 9)
        geo[:k, 9:12] = hom[:, :3, 3]
        idx_v = model.idx_vs.tolist()
        sel = [kinds[j - 1] for j in path]
        geo[:k, 12:15] = [axis if axis is not None else np.asarray(joints[j].extract().axis, float).ravel()
                          for j, (_, axis) in zip(path, sel)]
        jinfo[:, 0] = [kind for kind, _ in sel]
        jinfo[:, 1] = [idx_v[j] for j in path]
    fp = frame.placement
    geo[k, :9] = np.asarray(fp.rotation, float).ravel()
    geo[k, 9:12] = np.asarray(fp.translation, float)
    return ChainTable(geo, jinfo, int(model.nv))


# --------------------------------------------------------------------------- compiled functions
def forward(x, geo, jinfo, j6, pos, rot):
    """End placement and frame Jacobian at ``x`` (nq,) from a :class:`ChainTable`'s ``geo`` and
    ``jinfo``, written into ``j6`` (6, nv; ``LOCAL_WORLD_ALIGNED``: linear rows the velocity of the
    frame origin, angular rows, world axes), ``pos`` (3,) and ``rot`` (3, 3).

    ``oMi = oMi[parent] · (jointPlacement · M_joint(q))`` joint after joint (Pinocchio's products),
    the world axes ``ω_i = R_i a_i`` and joint origins kept in ``j6`` until the end position is known;
    then the columns ``[ω × (p_f − p_i); ω]`` (revolute) or ``[ω; 0]`` (prismatic)."""
    k = jinfo.shape[0]
    nv = j6.shape[1]
    for a in range(6):
        for c in range(nv):
            j6[a, c] = 0.0
    # oMi (scalars: no temporaries)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    p0, p1, p2 = 0.0, 0.0, 0.0
    for row in range(k):
        g = geo[row]
        q = x[jinfo[row, 1]]
        ax, ay, az = g[12], g[13], g[14]
        if jinfo[row, 0] == 0:  # revolute: liMi = (Rp · Rj(q), tp)
            s = math.sin(q)
            c = math.cos(q)
            if ax == 1.0 and ay == 0.0 and az == 0.0:
                j00, j01, j02, j10, j11, j12, j20, j21, j22 = 1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c
            elif ax == 0.0 and ay == 1.0 and az == 0.0:
                j00, j01, j02, j10, j11, j12, j20, j21, j22 = c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c
            elif ax == 0.0 and ay == 0.0 and az == 1.0:
                j00, j01, j02, j10, j11, j12, j20, j21, j22 = c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0
            else:  # Rodrigues: cos q·I + sin q·[a]× + (1 − cos q)·a aᵀ
                t = 1.0 - c
                j00 = c + t * ax * ax
                j01 = t * ax * ay - s * az
                j02 = t * ax * az + s * ay
                j10 = t * ax * ay + s * az
                j11 = c + t * ay * ay
                j12 = t * ay * az - s * ax
                j20 = t * ax * az - s * ay
                j21 = t * ay * az + s * ax
                j22 = c + t * az * az
            l00 = g[0] * j00 + g[1] * j10 + g[2] * j20
            l01 = g[0] * j01 + g[1] * j11 + g[2] * j21
            l02 = g[0] * j02 + g[1] * j12 + g[2] * j22
            l10 = g[3] * j00 + g[4] * j10 + g[5] * j20
            l11 = g[3] * j01 + g[4] * j11 + g[5] * j21
            l12 = g[3] * j02 + g[4] * j12 + g[5] * j22
            l20 = g[6] * j00 + g[7] * j10 + g[8] * j20
            l21 = g[6] * j01 + g[7] * j11 + g[8] * j21
            l22 = g[6] * j02 + g[7] * j12 + g[8] * j22
            t0, t1, t2 = g[9], g[10], g[11]
        else:  # prismatic: liMi = (Rp, tp + Rp a q)
            l00, l01, l02, l10, l11, l12, l20, l21, l22 = g[0], g[1], g[2], g[3], g[4], g[5], g[6], g[7], g[8]
            t0 = g[9] + (g[0] * ax + g[1] * ay + g[2] * az) * q
            t1 = g[10] + (g[3] * ax + g[4] * ay + g[5] * az) * q
            t2 = g[11] + (g[6] * ax + g[7] * ay + g[8] * az) * q
        # oMi = oMi[parent] · liMi
        n0 = p0 + (r00 * t0 + r01 * t1 + r02 * t2)
        n1 = p1 + (r10 * t0 + r11 * t1 + r12 * t2)
        n2 = p2 + (r20 * t0 + r21 * t1 + r22 * t2)
        p0, p1, p2 = n0, n1, n2
        m00 = r00 * l00 + r01 * l10 + r02 * l20
        m01 = r00 * l01 + r01 * l11 + r02 * l21
        m02 = r00 * l02 + r01 * l12 + r02 * l22
        m10 = r10 * l00 + r11 * l10 + r12 * l20
        m11 = r10 * l01 + r11 * l11 + r12 * l21
        m12 = r10 * l02 + r11 * l12 + r12 * l22
        m20 = r20 * l00 + r21 * l10 + r22 * l20
        m21 = r20 * l01 + r21 * l11 + r22 * l21
        m22 = r20 * l02 + r21 * l12 + r22 * l22
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = m00, m01, m02, m10, m11, m12, m20, m21, m22
        col = jinfo[row, 1]  # the world axis (angular rows) and the joint origin (linear rows, for now)
        j6[3, col] = r00 * ax + r01 * ay + r02 * az
        j6[4, col] = r10 * ax + r11 * ay + r12 * az
        j6[5, col] = r20 * ax + r21 * ay + r22 * az
        j6[0, col] = p0
        j6[1, col] = p1
        j6[2, col] = p2
    g = geo[k]
    rot[0, 0] = r00 * g[0] + r01 * g[3] + r02 * g[6]
    rot[0, 1] = r00 * g[1] + r01 * g[4] + r02 * g[7]
    rot[0, 2] = r00 * g[2] + r01 * g[5] + r02 * g[8]
    rot[1, 0] = r10 * g[0] + r11 * g[3] + r12 * g[6]
    rot[1, 1] = r10 * g[1] + r11 * g[4] + r12 * g[7]
    rot[1, 2] = r10 * g[2] + r11 * g[5] + r12 * g[8]
    rot[2, 0] = r20 * g[0] + r21 * g[3] + r22 * g[6]
    rot[2, 1] = r20 * g[1] + r21 * g[4] + r22 * g[7]
    rot[2, 2] = r20 * g[2] + r21 * g[5] + r22 * g[8]
    f0 = p0 + (r00 * g[9] + r01 * g[10] + r02 * g[11])
    f1 = p1 + (r10 * g[9] + r11 * g[10] + r12 * g[11])
    f2 = p2 + (r20 * g[9] + r21 * g[10] + r22 * g[11])
    pos[0], pos[1], pos[2] = f0, f1, f2
    for row in range(k):
        col = jinfo[row, 1]
        w0, w1, w2 = j6[3, col], j6[4, col], j6[5, col]
        if jinfo[row, 0] == 0:
            d0, d1, d2 = f0 - j6[0, col], f1 - j6[1, col], f2 - j6[2, col]
            j6[0, col] = w1 * d2 - w2 * d1
            j6[1, col] = w2 * d0 - w0 * d2
            j6[2, col] = w0 * d1 - w1 * d0
        else:
            j6[0, col] = w0
            j6[1, col] = w1
            j6[2, col] = w2
            j6[3, col] = 0.0
            j6[4, col] = 0.0
            j6[5, col] = 0.0


def _theta_axis(i0, val, r, axis):
    """Pinocchio's ``internal::compute_theta_axis<i0>``: ``axis`` (3,) written, the angle returned."""
    i1 = (i0 + 1) % 3
    i2 = (i0 + 2) % 3
    sg = 1.0 if r[i2, i1] >= r[i1, i2] else -1.0
    s = math.sqrt(val + _EPS + _EPS * _EPS) * sg
    axis[i0] = s / 2.0
    axis[i1] = 1.0 / (2.0 * s) * (r[i1, i0] + r[i0, i1])
    axis[i2] = 1.0 / (2.0 * s) * (r[i2, i0] + r[i0, i2])
    w = 1.0 / (2.0 * s) * (r[i2, i1] - r[i1, i2])
    nrm = math.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2])
    angle = 2.0 * math.atan2(nrm, w)
    axis[0] /= nrm
    axis[1] /= nrm
    axis[2] /= nrm
    return angle


def log3(r, out):
    """``out`` (3,) = Pinocchio 4's ``log3(r)`` of the rotation ``r`` (3, 3): the rotation vector
    (rad, ‖·‖ ≤ π), the same branches and operations as ``src/spatial/log.hxx``."""
    # renormalize_rotation_matrix
    n0 = math.sqrt(r[0, 0] * r[0, 0] + r[1, 0] * r[1, 0] + r[2, 0] * r[2, 0])
    n1 = math.sqrt(r[0, 1] * r[0, 1] + r[1, 1] * r[1, 1] + r[2, 1] * r[2, 1])
    rn = np.empty((3, 3))
    c0 = np.empty(3)
    c1 = np.empty(3)
    for a in range(3):
        c0[a] = r[a, 0] / n0
        c1[a] = r[a, 1] / n1
    c2 = np.empty(3)
    c2[0] = c0[1] * c1[2] - c0[2] * c1[1]
    c2[1] = c0[2] * c1[0] - c0[0] * c1[2]
    c2[2] = c0[0] * c1[1] - c0[1] * c1[0]
    c0[0] = c1[1] * c2[2] - c1[2] * c2[1]
    c0[1] = c1[2] * c2[0] - c1[0] * c2[2]
    c0[2] = c1[0] * c2[1] - c1[1] * c2[0]
    for a in range(3):
        rn[a, 0] = c0[a]
        rn[a, 1] = c1[a]
        rn[a, 2] = c2[a]
    tr = rn[0, 0] + rn[1, 1] + rn[2, 2]
    cos_value = (tr - 1.0) / 2.0
    prec = _PREC2
    if cos_value >= -1.0 + prec:  # the nominal branch (Pinocchio evaluates both; the same values)
        acos_expansion = math.sqrt(2.0 * (1.0 - cos_value) + _EPS * _EPS)
        if tr <= 3.0 - prec:
            theta = math.acos(cos_value) if tr >= -1.0 + prec else math.pi - acos_expansion
        else:
            theta = acos_expansion
        a0 = 0.5 * (rn[2, 1] - rn[1, 2])
        a1 = 0.5 * (rn[0, 2] - rn[2, 0])
        a2 = 0.5 * (rn[1, 0] - rn[0, 1])
        nsq = a0 * a0 + a1 * a1 + a2 * a2
        if theta >= prec:
            t = theta / math.sin(theta)
        else:
            t = 1.0 + nsq / 6.0 + nsq * nsq * 3.0 / 40.0
        out[0] = t * a0
        out[1] = t * a1
        out[2] = t * a2
        return
    v0 = 2.0 * rn[0, 0] - tr + 1.0
    v1 = 2.0 * rn[1, 1] - tr + 1.0
    v2 = 2.0 * rn[2, 2] - tr + 1.0
    axis = np.empty(3)
    if v0 >= v1:
        i0 = 0 if v0 >= v2 else 2
    else:
        i0 = 1 if v1 >= v2 else 2
    val = v0 if i0 == 0 else (v1 if i0 == 1 else v2)
    theta = _theta_axis(i0, val, rn, axis)
    out[0] = theta * axis[0]
    out[1] = theta * axis[1]
    out[2] = theta * axis[2]


def rotation_error(rt, rot, out):
    """``out`` (3,) = ``log3(rt · rotᵀ)`` (the orientation rows of the pose error, rad)."""
    m = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            m[a, b] = rt[a, 0] * rot[b, 0] + rt[a, 1] * rot[b, 1] + rt[a, 2] * rot[b, 2]
    log3(m, out)


_compiled = None  # (forward, log3, rotation_error) compiled, False when numba is unavailable


def compiled():
    """The compiled ``(forward, log3, rotation_error)`` (numba, cached on disk), or None when numba
    cannot be imported."""
    global _compiled
    if _compiled is None:
        try:
            import numba
        except Exception:  # noqa: BLE001 - any import failure: the caller keeps Pinocchio
            _compiled = False
            return None
        opts = {"cache": True, "nogil": True}
        g = globals()
        for name in ("_theta_axis",):
            g[name] = numba.njit(**opts)(g[name])
        g["log3"] = numba.njit(**opts)(log3)
        g["forward"] = numba.njit(**opts)(forward)
        g["rotation_error"] = numba.njit(**opts)(rotation_error)
        _compiled = (g["forward"], g["log3"], g["rotation_error"])
    return _compiled or None
