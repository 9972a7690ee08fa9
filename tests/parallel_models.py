"""Synthetic parallel models written with the ``<vjm:leg>``/``<vjm:platform>`` shorthand (tests).

``robot_urdf``: legs of a prismatic actuator spring, a 6-D link spring and passive revolutes,
meeting at one platform point (no cross-links). ``columns_xml``: two orthogonal two-segment
columns meeting at a point (platform ``x y z``), with closed-form buckling.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .chains import random_spd


def _f(v):
    return " ".join(repr(float(x)) for x in v)


def _leg_xml(rng, name, axis, base_xyz, passive_axes=(), k6=None, rpy=(0, 0, 0), k_act=5e5):
    """A leg: prismatic actuator along ``axis`` (spring k_act N/m), a 6-D link spring (SPD k6),
    passive revolutes about ``passive_axes``, an end link ``<name>_end``."""
    k6 = random_spd(rng, 6, 1e4, 1e5) if k6 is None else k6
    j = []
    j.append(f'<link name="{name}_l1"/>')
    j.append(
        f'<joint name="{name}_act" type="prismatic"><parent link="base"/><child link="{name}_l1"/>'
        f'<origin xyz="{_f(base_xyz)}" rpy="{_f(rpy)}"/><axis xyz="{_f(axis)}"/>'
        f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
    )
    prev = f"{name}_l1"
    sj = []
    for i, c in enumerate(("tx", "ty", "tz", "rx", "ry", "rz")):
        ax = np.eye(3)[i % 3]
        kind = "prismatic" if i < 3 else "revolute"
        ln = f"{name}_s{c}"
        j.append(f'<link name="{ln}"/>')
        xyz = (0.2, 0.05, 0.0) if i == 0 else (0, 0, 0)
        j.append(
            f'<joint name="{name}_{c}" type="{kind}"><parent link="{prev}"/><child link="{ln}"/>'
            f'<origin xyz="{_f(xyz)}" rpy="0 0 0"/><axis xyz="{_f(ax)}"/>'
            f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        sj.append(f"{name}_{c}")
        prev = ln
    tags = [f'<vjm:joint name="{name}_act" role="actuated" position="0" stiffness="{k_act!r}"/>']
    tags += [f'<vjm:joint name="{n}" role="spring"/>' for n in sj]
    tags.append(
        f'<vjm:spring name="{name}_link" link="{name}_l1" joints="{" ".join(sj)}">'
        f"<vjm:stiffness>{_f(k6.ravel())}</vjm:stiffness></vjm:spring>"
    )
    for k, pax in enumerate(passive_axes):
        pn = f"{name}_pas{k}"
        j.append(f'<link name="{pn}"/>')
        j.append(
            f'<joint name="{pn}" type="revolute"><parent link="{prev}"/><child link="{pn}"/>'
            f'<origin xyz="0.1 0 0.02" rpy="0.2 0 0"/><axis xyz="{_f(pax)}"/>'
            f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
        tags.append(f'<vjm:joint name="{pn}" role="passive" position="0"/>')
        prev = pn
    j.append(f'<link name="{name}_end"/>')
    j.append(
        f'<joint name="{name}_endj" type="fixed"><parent link="{prev}"/><child link="{name}_end"/>'
        f'<origin xyz="0.05 0.1 0" rpy="0 0.3 0"/></joint>'
    )
    return j, tags


def robot_urdf(seed=0, n_legs=3, passive=True, identical=False, platform=(0.6, 0.2, 0.3)):
    """Robot of ``n_legs`` legs; the offsets put every leg's platform point at ``platform``."""
    rng = np.random.default_rng(seed)
    axes = np.eye(3)
    k6 = random_spd(rng, 6, 1e4, 1e5) if identical else None
    body, tags, legs = ['<link name="base"/>'], [], []
    for i in range(n_legs):
        name = f"leg{i + 1}"
        a = axes[0] if identical else axes[i % 3]
        rpy = (0, 0, 0) if identical else tuple(rng.uniform(-0.3, 0.3, 3))
        base = (0, 0, 0) if identical else tuple(rng.uniform(-0.2, 0.2, 3))
        b, t = _leg_xml(
            np.random.default_rng(seed + 100) if identical else rng,
            name,
            a,
            base,
            passive_axes=[axes[(i + k) % 3] for k in range(int(passive))],
            k6=k6,
            rpy=rpy,
        )
        body += b
        tags += t
        legs.append(name)
    xml = (
        '<robot name="synthetic" xmlns:vjm="urn:vjm-pin:1">'
        + "".join(body)
        + "".join(tags)
        + "</robot>"
    )
    model = pin.buildModelFromXML(xml)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    leg_tags = []
    for name in legs:
        m = data.oMf[model.getFrameId(f"{name}_end")]
        off = m.rotation.T @ (np.asarray(platform) - m.translation)
        leg_tags.append(f'<vjm:leg name="{name}" frame="{name}_end" offset="{_f(off)}"/>')
    return xml.replace(
        "</robot>", '<vjm:platform name="platform"/>' + "".join(leg_tags) + "</robot>"
    )


def single_leg_urdf(seed=0):
    """Leg 1 of the identical-legs robot alone, as a parallel model of one leg."""
    return robot_urdf(seed, n_legs=1, passive=False, identical=True)


def _column_leg(name, axis, out_axis, base, length, k_bend, k_axial):
    """A two-segment column along ``axis`` in the plane normal to z: bending springs k_r about z at
    the base and at mid-length, an out-of-plane bending spring about ``out_axis`` at the base, an
    axial prismatic spring k_a at the base; the end (tip) is the platform point."""
    a = np.asarray(axis, float)
    lim = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    xml = [f'<link name="{name}_{n}"/>' for n in ("b1", "b2", "ax", "mid", "end")]
    xml += [
        (
            f'<joint name="{name}_r1" type="revolute"><parent link="base"/><child link="{name}_b1"/>'
            f'<origin xyz="{_f(base)}"/><axis xyz="0 0 1"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_r3" type="revolute"><parent link="{name}_b1"/><child link="{name}_b2"/>'
            f'<axis xyz="{_f(out_axis)}"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_s" type="prismatic"><parent link="{name}_b2"/><child link="{name}_ax"/>'
            f'<axis xyz="{_f(a)}"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_r2" type="revolute"><parent link="{name}_ax"/><child link="{name}_mid"/>'
            f'<origin xyz="{_f(length / 2 * a)}"/><axis xyz="0 0 1"/>{lim}</joint>'
        ),
        (
            f'<joint name="{name}_tip" type="fixed"><parent link="{name}_mid"/><child link="{name}_end"/>'
            f'<origin xyz="{_f(length / 2 * a)}"/></joint>'
        ),
    ]
    tags = [
        f'<vjm:joint name="{name}_{j}" role="actuated" position="0" stiffness="{k!r}"/>'
        for j, k in (("r1", k_bend), ("r2", k_bend), ("r3", k_bend), ("s", k_axial))
    ]
    tags.append(f'<vjm:leg name="{name}" frame="{name}_end" offset="0 0 0"/>')
    return xml, tags


def columns_xml(L=1.0, kr=100.0, ka=1e5):
    xa, ta = _column_leg("A", (1, 0, 0), (0, 1, 0), (0, 0, 0), L, kr, ka)
    xb, tb = _column_leg("B", (0, 1, 0), (1, 0, 0), (L, -L, 0), L, kr, ka)
    return (
        '<robot name="columns" xmlns:vjm="urn:vjm-pin:1"><link name="base"/>'
        + "".join(xa + xb)
        + '<vjm:platform name="p" components="x y z"/>'
        + "".join(ta + tb)
        + "</robot>"
    )


def mechanism_fd_stiffness(ms, res, h: float) -> np.ndarray:
    """Central differences (6, 6) of the task wrench of re-solved mechanism equilibria
    (``MechanismSolver``, every task component held) around ``res``, the task frame displaced
    by ±h along each component (m, world rotation vector rad)."""
    from vjm_pin.kinematics.chain import deflection, displace

    fd = np.zeros((6, 6))
    for j in range(6):
        dt = np.zeros(6)
        dt[j] = h
        out = []
        for sign in (1.0, -1.0):
            p, r = displace(res.position, res.rotation, sign * dt)
            out.append(ms.solve(deflection=deflection(ms.p0, ms.r0, p, r), x0=res.x).wrench)
        fd[:, j] = (out[0] - out[1]) / (2 * h)
    return fd
