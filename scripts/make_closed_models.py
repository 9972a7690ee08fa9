"""Write the bundled closed-loop models ``models/urdf/{portal-frame,portal-frame-6,four-bar}.urdf``.

Each model is one URDF tree that stock Pinocchio loads, cut open at one joint; the cut is
closed by a ``<vjm:closure>`` (docs/format.md). All of them are planar, in the world x–z
plane (z up, every joint axis along y); they are assembled at their reference configuration.

- ``portal-frame``: two rigid columns of height ``h`` on the ground, a rigid beam of span
  ``L`` on top, rotational springs ``k`` at the four corners (joints ``corner_bl``,
  ``corner_tl``, ``corner_tr``, ``corner_br``; spring role, one 1-D spring each). The tree
  runs base → left column → beam → right column → ``foot``; the closure holds ``foot`` on
  ``anchor`` (the right column's ground point) in ``x z ry``. Task frame ``top`` (beam
  middle), component ``x``; frames ``top_left`` and ``top_right`` at the column tops carry the
  vertical loads of issue 13's acceptance. One degree of freedom: the sway (columns turn by
  ``φ``: corner angles ``(φ, −φ, φ, −φ)``).
- ``portal-frame-6``: the same closed in all six components (three of them redundant).
- ``four-bar``: ground pivots A = (0, 0, 0) and D = (d, 0, 0), crank AB (actuated joint
  ``crank`` with an actuator spring), coupler BC and rocker CD (passive joints ``elbow`` and
  ``knee``), planar beam springs (``x z ry``) at the tips of the coupler and the rocker. The
  closure holds the rocker's end ``foot`` on ``anchor`` at D in ``x z`` (a pin). Task frame
  ``coupler_point`` (a point of the coupler), components ``x z``.

Springs are written by the generator (:func:`vjm_pin.generate_vjm`); this script then turns
the portal's corner "actuators" into spring-role joints, sets the task frame, and adds the
closure. ``tests/test_closures.py`` regenerates the files and fails if a committed one differs
(numbers compared with tolerances). Never edit the URDFs by hand.

Usage: ``python scripts/make_closed_models.py [--out models/urdf]``
"""

from __future__ import annotations

import argparse
import math
import xml.etree.ElementTree as ET
from pathlib import Path

from vjm_pin import generate_vjm
from vjm_pin.model.format import NS

_Q = f"{{{NS}}}"

#: Portal frame: column height h (m), beam span (m), corner spring k (N·m/rad).
PORTAL = {"height": 1.0, "span": 1.5, "k": 100.0}
PLANAR_CLOSURE = ("x", "z", "ry")
SIX = ("x", "y", "z", "rx", "ry", "rz")
CORNERS = ("corner_bl", "corner_tl", "corner_tr", "corner_br")

#: Four-bar: ground, crank, coupler, rocker lengths (m), crank angle (rad, from +x toward +z),
#: coupler point (m, in the coupler frame), crank actuator stiffness (N·m/rad), link beams.
FOUR_BAR = {
    "ground": 1.0,
    "crank": 0.4,
    "coupler": 1.0,
    "rocker": 0.8,
    "crank_angle": 1.2,
    "coupler_point": (0.5, 0.15),
    "k_crank": 200.0,
    "beam": {"section": "rectangle", "a": 0.02, "b": 0.01, "E": 2.1e11, "nu": 0.3},
}

_LIMIT = '<limit lower="-1000.0" upper="1000.0" effort="0" velocity="0"/>'


def _f(v: float) -> str:
    return repr(float(v))


def _joint(name: str, kind: str, parent: str, child: str, xyz=(0.0, 0.0, 0.0)) -> str:
    origin = f'<origin xyz="{" ".join(_f(v) for v in xyz)}" rpy="0 0 0"/>'
    if kind == "fixed":
        return f'  <joint name="{name}" type="fixed"><parent link="{parent}"/><child link="{child}"/>{origin}</joint>'
    return (
        f'  <joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>{origin}'
        f'<axis xyz="0 1 0"/>{_LIMIT}</joint>'
    )


def _robot(name: str, links: list[str], joints: list[str]) -> str:
    body = (
        [f'<robot name="{name}">']
        + [f'  <link name="{ln}"/>' for ln in links]
        + joints
        + ["</robot>"]
    )
    return "\n".join(body) + "\n"


def _finish(
    text: str, *, task_frame: str, task: tuple[str, ...], closures: list[dict], joint_springs=()
) -> str:
    """Set the task, turn ``joint_springs`` (actuated joints with a stiffness) into spring-role
    joints with one 1-D spring each, and append the closures."""
    root = ET.fromstring(text)
    tags = [el for el in root if el.tag.startswith(_Q)]
    for el in tags:
        root.remove(el)
    out = []
    for el in tags:
        name = el.get("name")
        if el.tag == f"{_Q}task":
            el.set("frame", task_frame)
            el.set("components", " ".join(task))
        elif el.tag == f"{_Q}joint" and name in joint_springs:
            k = el.get("stiffness")
            rest = el.get("position")
            el.attrib.clear()
            el.set("name", name)
            el.set("role", "spring")
            sp = ET.Element(f"{_Q}spring", name=name, joints=name)
            ET.SubElement(sp, f"{_Q}stiffness").text = k
            ET.SubElement(sp, f"{_Q}rest").text = rest
            out.append(el)
            out.append(sp)
            continue
        out.append(el)
    out += [
        ET.Element(
            f"{_Q}closure", {k: (" ".join(v) if k == "components" else v) for k, v in c.items()}
        )
        for c in closures
    ]
    for el in out:
        root.append(el)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def portal_frame_urdf(
    height: float = PORTAL["height"],
    span: float = PORTAL["span"],
    k: float = PORTAL["k"],
    components: tuple[str, ...] = PLANAR_CLOSURE,
    name: str = "portal-frame",
) -> str:
    """The planar portal frame (module docstring) with its closure in ``components``."""
    h, s = float(height), float(span)
    rigid = _robot(
        name,
        [
            "base",
            "column_left",
            "beam",
            "column_right",
            "foot",
            "anchor",
            "top",
            "top_left",
            "top_right",
        ],
        [
            _joint("corner_bl", "revolute", "base", "column_left"),
            _joint("corner_tl", "revolute", "column_left", "beam", (0.0, 0.0, h)),
            _joint("corner_tr", "revolute", "beam", "column_right", (s, 0.0, 0.0)),
            _joint("corner_br", "revolute", "column_right", "foot", (0.0, 0.0, -h)),
            _joint("anchor_joint", "fixed", "base", "anchor", (s, 0.0, 0.0)),
            _joint("top_joint", "fixed", "beam", "top", (0.5 * s, 0.0, 0.0)),
            _joint("top_left_joint", "fixed", "beam", "top_left"),
            _joint("top_right_joint", "fixed", "beam", "top_right", (s, 0.0, 0.0)),
        ],
    )
    text = generate_vjm(
        rigid, {"frame": "top", "task": ["x"], "actuators": {c: float(k) for c in CORNERS}}
    )
    closure = {
        "name": "right_foot",
        "frame_a": "foot",
        "frame_b": "anchor",
        "components": tuple(components),
    }
    return _finish(text, task_frame="top", task=("x",), closures=[closure], joint_springs=CORNERS)


def four_bar_angles(p: dict = FOUR_BAR) -> tuple[float, float, float]:
    """Direction angles (rad, from +x toward +z) of crank, coupler and rocker (C → D) in the
    assembled reference configuration (the branch with C above the ground line)."""
    a, b, c, d = p["crank"], p["coupler"], p["rocker"], p["ground"]
    al = p["crank_angle"]
    bx, bz = a * math.cos(al), a * math.sin(al)
    ex, ez = d - bx, -bz  # B -> D
    e = math.hypot(ex, ez)
    # C = B + b (cos, sin)(phi): |C - D| = c; angle at B between BD and BC by the law of cosines
    gamma = math.acos((b * b + e * e - c * c) / (2 * b * e))
    phi_bd = math.atan2(ez, ex)
    phi_bc = phi_bd + gamma
    cx, cz = bx + b * math.cos(phi_bc), bz + b * math.sin(phi_bc)
    phi_cd = math.atan2(0.0 - cz, d - cx)
    return al, phi_bc, phi_cd


def four_bar_urdf(p: dict = FOUR_BAR, name: str = "four-bar") -> str:
    """The planar four-bar linkage (module docstring)."""
    a, b, c, d = p["crank"], p["coupler"], p["rocker"], p["ground"]
    u, v = p["coupler_point"]
    rigid = _robot(
        name,
        ["base", "crank_link", "coupler_link", "rocker_link", "foot", "anchor", "coupler_point"],
        [
            _joint("crank", "revolute", "base", "crank_link"),
            _joint("elbow", "revolute", "crank_link", "coupler_link", (a, 0.0, 0.0)),
            _joint("knee", "revolute", "coupler_link", "rocker_link", (b, 0.0, 0.0)),
            _joint("foot_joint", "fixed", "rocker_link", "foot", (c, 0.0, 0.0)),
            _joint("anchor_joint", "fixed", "base", "anchor", (d, 0.0, 0.0)),
            _joint("coupler_point_joint", "fixed", "coupler_link", "coupler_point", (u, 0.0, v)),
        ],
    )
    phi_ab, phi_bc, phi_cd = four_bar_angles(p)
    # a positive turn about +y takes +x toward −z: joint value = −(change of direction angle)
    positions = {"crank": -phi_ab, "elbow": -(phi_bc - phi_ab), "knee": -(phi_cd - phi_bc)}
    beam = {"beam": dict(p["beam"]), "dofs": ["x", "z", "ry"]}
    spec = {
        "frame": "foot",
        "actuators": {"crank": float(p["k_crank"])},
        "passive": ["elbow", "knee"],
        "positions": positions,
        "links": {"coupler_link": beam, "rocker_link": beam},
    }
    text = generate_vjm(rigid, spec)
    closure = {
        "name": "rocker_pivot",
        "frame_a": "foot",
        "frame_b": "anchor",
        "components": ("x", "z"),
    }
    return _finish(text, task_frame="coupler_point", task=("x", "z"), closures=[closure])


def closed_models() -> dict[str, str]:
    """File name → URDF text of every bundled closed-loop model."""
    return {
        "portal-frame.urdf": portal_frame_urdf(),
        "portal-frame-6.urdf": portal_frame_urdf(components=SIX, name="portal-frame-6"),
        "four-bar.urdf": four_bar_urdf(),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", default=str(Path(__file__).resolve().parent.parent / "models" / "urdf")
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in closed_models().items():
        (out / name).write_text(text)
        print(out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
