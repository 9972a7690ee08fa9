"""The serial chain of §6.1 of the paper (eq. 34): ``U_p R_a R_a S_p``.

Rigid chain: a passive universal joint at the base (rotation about z, then about y; only
about z in the planar reduction), three links of length L along their x axes, two
actuated revolute joints about z between them, and the end frame ``end`` at the tip of
the third link, at the centre of the passive spherical joint. The spherical joint is
represented by constraining only the end position (task ``x y [z]``): its three
rotations are free, so the orientation rows of eq. (5) drop out.

Postures (actuated coordinates): S (0, 0), Π (−30°, −30°), Z (30°, −30°); the base joint is
set so that the unloaded end lies on the x axis.
"""

from __future__ import annotations

import math

from vjm_pin.exceptions import ArgumentError
from vjm_pin.model.generator import generate_vjm

POSTURES = {"s": (0.0, 0.0), "pi": (-30.0, -30.0), "z": (30.0, -30.0)}

#: Link beams of Models B and C (§6.1.4–6.1.5): rectangle a = 0.02 L (along z) ×
#: b = 0.05 L (along y), ν = 0.3, L = 1 m. The paper gives their forces in units of a
#: "bending coefficient" Kθ scaled "to keep similarity with model A". A chain of three
#: rigid segments with planar cantilever tip springs, pinned at both ends and straight,
#: buckles at P = (√21 − 3)·E·I/L² ≈ 1.58258·E·I/L² (closed form derived in
#: docs/paper_reproduction.md: the root of p² + 6p − 12 = 0). The paper's statement that
#: Model B in the S posture buckles at Kθ/L therefore fixes Kθ = (√21 − 3)·E·I_z/L, and E
#: is chosen so that this Kθ = 1 N·m/rad: forces of Models A, B and C then all read in
#: units of Kθ/L = 1 N (and Model C, S posture, buckles at (I_y/I_z)·Kθ/L = 0.16 Kθ/L).
PAPER_A, PAPER_B = 0.02, 0.05
#: Kθ/(E·I_z/L) of the three-link tip-spring chain (S posture, Model B).
PAPER_KTHETA_FACTOR = math.sqrt(21.0) - 3.0
PAPER_BEAM = {
    "section": "rectangle",
    "a": PAPER_A,
    "b": PAPER_B,
    "E": 12.0 / (PAPER_A * PAPER_B**3) / PAPER_KTHETA_FACTOR,
    "nu": 0.3,
}


def base_angle(qa1: float, qa2: float) -> float:
    """Base rotation (rad) that puts the end of the chain on the x axis (rad inputs)."""
    # y_end ∝ sin(q) + sin(q + qa1) + sin(q + qa1 + qa2) = A sin q + B cos q
    a = 1.0 + math.cos(qa1) + math.cos(qa1 + qa2)
    b = math.sin(qa1) + math.sin(qa1 + qa2)
    return math.atan2(-b, a)


def rigid_chain_urdf(length: float = 1.0, planar: bool = False, name: str = "upraras") -> str:
    """URDF text of the rigid ``U_p R_a R_a`` chain (links along x, joints about z)."""
    big = 1e3
    lim = f'<limit lower="{-big}" upper="{big}" effort="0" velocity="0"/>'
    parts = [f'<robot name="{name}">', '  <link name="base"/>']
    if planar:
        parts += [
            '  <joint name="base_z" type="revolute"><parent link="base"/><child link="link1"/>'
            f'<axis xyz="0 0 1"/>{lim}</joint>',
        ]
    else:
        parts += [
            '  <link name="base_u"/>',
            '  <joint name="base_z" type="revolute"><parent link="base"/><child link="base_u"/>'
            f'<axis xyz="0 0 1"/>{lim}</joint>',
            '  <joint name="base_y" type="revolute"><parent link="base_u"/><child link="link1"/>'
            f'<axis xyz="0 1 0"/>{lim}</joint>',
        ]
    parts += [
        '  <link name="link1"/>',
        '  <link name="link2"/>',
        '  <link name="link3"/>',
        '  <link name="end"/>',
        f'  <joint name="qa1" type="revolute"><parent link="link1"/><child link="link2"/>'
        f'<origin xyz="{length!r} 0 0"/><axis xyz="0 0 1"/>{lim}</joint>',
        f'  <joint name="qa2" type="revolute"><parent link="link2"/><child link="link3"/>'
        f'<origin xyz="{length!r} 0 0"/><axis xyz="0 0 1"/>{lim}</joint>',
        f'  <joint name="end_joint" type="fixed"><parent link="link3"/><child link="end"/>'
        f'<origin xyz="{length!r} 0 0"/></joint>',
        "</robot>",
    ]
    return "\n".join(parts) + "\n"


def paper_spec(model: str, posture: str, *, length: float = 1.0, k_theta: float = 1.0,
               beam: dict | None = None, subdivide: int = 1) -> dict:
    """Spring specification of Model A, B or C in posture S, Π or Z.

    Args:
        model: ``"a"`` (rigid links, 1-D actuator springs ``k_theta`` N·m/rad, planar),
            ``"b"`` (rigid actuators, planar 3×3 link springs) or ``"c"`` (rigid
            actuators, full 6×6 link springs, spatial).
        posture: ``"s"``, ``"pi"`` or ``"z"``.
        beam: Beam parameters of the links for B and C (``section``, ``a``, ``b``, ``E``,
            ``nu``); the length is the link length.
    """
    if not isinstance(model, str) or model.lower() not in ("a", "b", "c"):
        raise ArgumentError(f"unknown paper model {model!r}; choose 'a', 'b' or 'c'")
    if not isinstance(posture, str) or posture.lower() not in POSTURES:
        raise ArgumentError(f"unknown posture {posture!r}; choose one of {list(POSTURES)}")
    model = model.lower()
    posture = posture.lower()
    qa1, qa2 = (math.radians(v) for v in POSTURES[posture])
    q0 = base_angle(qa1, qa2)
    positions = {"base_z": q0, "qa1": qa1, "qa2": qa2}
    passive = ["base_z"] if model in ("a", "b") else ["base_z", "base_y"]
    spec: dict = {
        "name": f"paper-{model}-{posture}",
        "frame": "end",
        "passive": passive,
        "positions": positions,
    }
    if model == "a":
        spec.update(task=["x", "y"], actuators={"qa1": k_theta, "qa2": k_theta})
    elif model in ("b", "c"):
        if beam is None:
            raise ArgumentError("models B and C need beam parameters: beam=PAPER_BEAM or a dict like it")
        entry = {"beam": dict(beam)}
        if model == "b":
            entry["dofs"] = ["x", "y", "rz"]
        spec.update(
            task=["x", "y"] if model == "b" else ["x", "y", "z"],
            actuators={},
            links={f"link{i}": dict(entry) for i in (1, 2, 3)},
        )
        if subdivide > 1:
            spec["subdivide"] = subdivide
    return spec


def paper_model_urdf(model: str, posture: str, **kwargs) -> str:
    """VJM URDF text of a paper model (see :func:`paper_spec`)."""
    planar = isinstance(model, str) and model.lower() in ("a", "b")
    return generate_vjm(rigid_chain_urdf(kwargs.get("length", 1.0), planar=planar), paper_spec(model, posture, **kwargs))
