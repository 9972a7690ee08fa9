"""Real robots: any rigid URDF, or a robot of ``example-robot-data`` by name, as a VJM model.

Defaults (when no spring specification is given):

- every movable joint on the path from the root to the end frame is *actuated* with a 1-D
  actuator spring of stiffness :data:`DEFAULT_REVOLUTE_STIFFNESS` (N·m/rad, revolute and
  continuous joints) or :data:`DEFAULT_PRISMATIC_STIFFNESS` (N/m, prismatic joints);
- movable joints off that path (fingers, other arms, legs) are *locked* at their pose;
- links are rigid.

The default 1e5 N·m/rad is an order of magnitude, not a measured value: the torsional
stiffness of the strain-wave (harmonic-drive) gearboxes of 5–10 kg payload arms in the
manufacturers' catalogues is of order 1e4–1e5 N·m/rad, and identified joint stiffnesses of
heavy industrial robots are of order 1e5–1e7 N·m/rad (e.g. Dumas, Caro, Garnier, Furet,
"Joint stiffness identification of six-revolute industrial serial robots", RCIM 2011).
Give the measured values of your robot with a spec (``actuators:`` key of the spring
specification, see :mod:`vjm_pin.model.generator`).

The end frame defaults to the last frame of the kinematic chain (see
:func:`default_frame`); a tree with several branches needs an explicit frame, unless its
SRDF names an end effector, and :class:`~vjm_pin.exceptions.FrameNotFound` lists the
candidates. The pose comes from ``NAME=VALUE`` pairs (:func:`parse_q`) and/or a named SRDF
state (:func:`srdf_states`).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import (  # UnknownRobot, AmbiguousFrame: raised here, importable from here
    AmbiguousFrame,
    ArgumentError,
    FrameNotFound,
    InputError,
    JointNotFound,
    ModelError,
    SpecError,
    UnknownRobot,
    UrdfParseError,
)
from vjm_pin.model.format import VjmModel, _read_root, load_vjm

#: Default actuator stiffness of revolute joints (N·m/rad); see the module docstring.
DEFAULT_REVOLUTE_STIFFNESS = 1.0e5
#: Default actuator stiffness of prismatic joints (N/m).
DEFAULT_PRISMATIC_STIFFNESS = 1.0e7


@dataclass(frozen=True)
class RobotSource:
    """Where a robot's description lives.

    Attributes:
        name: Robot name (``example-robot-data`` key or the URDF file stem).
        urdf: Path of the rigid URDF.
        srdf: Path of its SRDF (named states, end effector), or None.
        ref_posture: Name of the loader's reference SRDF state, or None.
        free_flyer: Whether ``example-robot-data`` mounts it on a free-flyer (legged robots,
            humanoids, drones): vjm_pin analyses it with a fixed base.
    """

    name: str
    urdf: Path
    srdf: Path | None = None
    ref_posture: str | None = None
    free_flyer: bool = False


# ----------------------------------------------------------------------------- sources
def robot_names() -> list[str]:
    """Names of the ``example-robot-data`` robots (``vjm-pin models --robots``)."""
    try:
        import example_robot_data as erd
    except ImportError:  # pragma: no cover - a declared dependency
        return []
    return sorted(erd.ROBOTS)


def robot_source(name: str) -> RobotSource:
    """Locate the URDF/SRDF of an ``example-robot-data`` robot.

    Raises:
        UnknownRobot: ``name`` is not a robot of ``example-robot-data`` (lists them).
    """
    import example_robot_data as erd

    if name not in erd.ROBOTS:
        raise UnknownRobot(name, robot_names())
    loader = erd.ROBOTS[name]
    sub = os.path.join(loader.path, loader.urdf_subpath, loader.urdf_filename)
    if not loader.urdf_filename:
        raise ModelError(f"robot '{name}' of example-robot-data has no URDF file (only SDF)")
    try:
        base = Path(erd.getModelPath(sub))
    except OSError as e:
        raise ModelError(f"robot '{name}': URDF not found ({e})") from None
    urdf = base / sub
    srdf = None
    if loader.srdf_filename:
        cand = base / loader.path / loader.srdf_subpath / loader.srdf_filename
        srdf = cand if cand.is_file() else None
    return RobotSource(name, urdf, srdf, loader.ref_posture, bool(loader.free_flyer))


# ----------------------------------------------------------------------------- URDF tree
@dataclass(frozen=True)
class UrdfTree:
    """The joint tree of a rigid URDF.

    Attributes:
        root: Root link. joints: name → (type, parent link, child link).
        children: link → child joint names (document order).
        limits: joint → (lower, upper) for revolute/prismatic joints with a ``<limit>``.
        origins: joint → (3,) origin translation in the parent link frame (m).
    """

    root: str
    joints: dict
    children: dict
    limits: dict
    origins: dict

    @property
    def movable(self) -> list[str]:
        return [n for n, (t, _, _) in self.joints.items() if t != "fixed"]

    def has_movable_below(self, link: str) -> bool:
        return any(
            self.joints[j][0] != "fixed" or self.has_movable_below(self.joints[j][2])
            for j in self.children.get(link, [])
        )

    def path_joints(self, link: str) -> list[str]:
        """Joint names from the root to ``link``."""
        by_child = {c: j for j, (_, _, c) in self.joints.items()}
        out = []
        while link in by_child:
            out.append(by_child[link])
            link = self.joints[by_child[link]][1]
        return out[::-1]

    def leaves(self) -> list[str]:
        return [ln for ln in self.links if not self.children.get(ln)]

    @property
    def links(self) -> list[str]:
        return [self.root] + [c for (_, _, c) in self.joints.values()]


def urdf_tree(source) -> UrdfTree:
    """Parse the joint tree of a URDF (path or text)."""
    root, _, label = _read_root(source)
    joints, children, limits, origins = {}, {}, {}, {}
    childs = set()
    for j in root.findall("joint"):
        name, t = j.get("name"), j.get("type")
        p, c = j.find("parent"), j.find("child")
        if p is None or c is None:
            raise ModelError(f"{label}: joint '{name}' lacks <parent> or <child>")
        joints[name] = (t, p.get("link"), c.get("link"))
        children.setdefault(p.get("link"), []).append(name)
        childs.add(c.get("link"))
        lim = j.find("limit")
        if t in ("revolute", "prismatic") and lim is not None and lim.get("lower") is not None:
            limits[name] = (
                _urdf_float(lim.get("lower"), label, f"joint '{name}' limit lower"),
                _urdf_float(lim.get("upper", "0"), label, f"joint '{name}' limit upper"),
            )
        o = j.find("origin")
        xyz = ((o.get("xyz") if o is not None else None) or "0 0 0").split()
        if len(xyz) != 3:
            raise UrdfParseError(f"{label}: joint '{name}' origin xyz needs 3 numbers, got {' '.join(xyz)!r}")
        origins[name] = np.array([_urdf_float(v, label, f"joint '{name}' origin xyz") for v in xyz])
    roots = [ln.get("name") for ln in root.findall("link") if ln.get("name") not in childs]
    if len(roots) != 1:
        raise ModelError(f"{label}: expected one root link, found {roots}")
    return UrdfTree(roots[0], joints, children, limits, origins)


def _urdf_float(text, label: str, what: str) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        raise UrdfParseError(f"{label}: {what}: expected a number, got {text!r}") from None


def beam_length(source, link: str) -> float:
    """Length (m) of ``link`` as a beam: the distance between the origin of the joint that
    carries it and the origin of its child joint on the chain (the only child joint, or the
    child joint leading to movable joints). Used by a spec that gives only the section and
    material of a link (``beam: {section: ..., E: ...}``)."""
    tree = urdf_tree(source)
    if link not in tree.links:
        raise FrameNotFound(link, tree.links, "beam length")
    kids = tree.children.get(link, [])
    if not kids:
        raise SpecError(f"link '{link}' has no child joint, so its beam length is not defined")
    onward = [
        j for j in kids if tree.joints[j][0] != "fixed" or tree.has_movable_below(tree.joints[j][2])
    ]
    pick = onward if onward else kids
    if len(pick) > 1:
        raise SpecError(
            f"link '{link}' branches into joints {pick}: give the beam 'length' explicitly"
        )
    return float(np.linalg.norm(tree.origins[pick[0]]))


def frame_candidates(source) -> list[str]:
    """Leaf links with at least one movable joint on their path: the possible end frames of
    a branched robot (``source``: URDF path, text or :class:`UrdfTree`)."""
    tree = source if isinstance(source, UrdfTree) else urdf_tree(source)
    return [
        ln
        for ln in tree.leaves()
        if any(tree.joints[j][0] != "fixed" for j in tree.path_joints(ln))
    ]


def default_frame(source, srdf: Path | None = None) -> str:
    """The end frame when none is given.

    For a single chain (the movable joints form one path): the last link of the chain
    below the last movable joint, following fixed joints, and the last one in document
    order where fixed joints branch (``tool0`` for the UR arms). For a branched tree: the
    SRDF's ``<end_effector parent_link=...>`` if there is one, otherwise
    :class:`FrameNotFound` listing the leaf links.
    """
    tree = urdf_tree(source)
    link = tree.root
    while True:
        onward = [
            j
            for j in tree.children.get(link, [])
            if tree.joints[j][0] != "fixed" or tree.has_movable_below(tree.joints[j][2])
        ]
        if len(onward) > 1:
            ee = srdf_end_effector(srdf) if srdf is not None else None
            if ee and ee in tree.links:
                return ee
            raise AmbiguousFrame(link, onward, frame_candidates(tree))
        if not onward:
            break
        link = tree.joints[onward[0]][2]
    # below the last movable joint: follow fixed joints to the last leaf (document order)
    while tree.children.get(link):
        link = tree.joints[tree.children[link][-1]][2]
    return link


# ----------------------------------------------------------------------------- SRDF
def srdf_states(srdf, urdf_text: str) -> dict[str, dict[str, float]]:
    """Named states ``<group_state name=...>`` of an SRDF: name → {joint: value (rad, m)} for
    every 1-DOF joint of the URDF (joints a state does not list at Pinocchio's neutral value).

    Read by Pinocchio's own SRDF reader (``pin.loadReferenceConfigurations``), so a state
    means here what it means in every Pinocchio tool; a continuous joint (``cos, sin`` in
    Pinocchio) is returned as its angle.

    Raises:
        ModelError: the SRDF cannot be read.
    """
    if srdf is None:
        return {}
    import pinocchio as pin

    model = pin.buildModelFromXML(urdf_text)
    try:
        pin.loadReferenceConfigurations(model, str(srdf), False)
    except (RuntimeError, OSError, ValueError) as e:
        raise ModelError(f"SRDF {srdf}: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
    out: dict[str, dict[str, float]] = {}
    for entry in model.referenceConfigurations:
        q = np.asarray(entry.data(), dtype=float)
        state = out.setdefault(entry.key(), {})
        for j in range(1, model.njoints):
            jm = model.joints[j]
            if jm.nq == 1:
                state[model.names[j]] = float(q[jm.idx_q])
            elif jm.nq == 2 and jm.nv == 1:  # continuous: (cos, sin)
                state[model.names[j]] = float(np.arctan2(q[jm.idx_q + 1], q[jm.idx_q]))
    return out


def srdf_end_effector(srdf) -> str | None:
    if srdf is None:
        return None
    try:
        root = ET.parse(str(srdf)).getroot()
    except (ET.ParseError, OSError):
        return None
    ee = root.find("end_effector")
    return None if ee is None else ee.get("parent_link")


# ----------------------------------------------------------------------------- pose
def parse_q(items) -> dict[str, float]:
    """``["NAME=VALUE", ...]`` → {name: value} (rad or m); :class:`InputError` on bad items."""
    if isinstance(items, (str, bytes)) or not isinstance(items, (list, tuple, type(None))):
        raise ArgumentError(f"parse_q expects a list of 'NAME=VALUE' strings, got {type(items).__name__} {items!r}")
    out = {}
    for it in items or []:
        if not isinstance(it, str) or "=" not in it:
            raise InputError(f"a joint position is NAME=VALUE, got '{it}'")
        name, val = it.split("=", 1)
        if not name.strip():
            raise InputError(f"a joint position is NAME=VALUE, got '{it}' (no joint name)")
        try:
            v = float(val)
        except ValueError:
            raise InputError(f"joint position {name}: '{val}' is not a number") from None
        if not math.isfinite(v):
            raise InputError(f"joint position {name}: value must be finite, got {val}")
        out[name.strip()] = v
    return out


def check_pose(tree: UrdfTree, pose: dict[str, float]) -> None:
    """Unknown joints → :class:`JointNotFound`; values outside the URDF limits or not finite →
    :class:`InputError` (the pose is unreachable)."""
    for name, v in pose.items():
        if name not in tree.joints or tree.joints[name][0] == "fixed":
            raise JointNotFound(name, tree.movable, "pose")
        if not math.isfinite(v):
            raise InputError(f"joint '{name}': position must be finite, got {v}")
        if name in tree.limits:
            lo, hi = tree.limits[name]
            if lo < hi and not (lo - 1e-9 <= v <= hi + 1e-9):
                raise InputError(
                    f"joint '{name}' = {v:g} is outside its limits [{lo:g}, {hi:g}]: pose unreachable"
                )


# ----------------------------------------------------------------------------- build
def default_spec(source, frame: str, pose: dict | None = None, springs: dict | None = None) -> dict:
    """The spring spec of the defaults (module docstring), merged with ``springs`` (a spec
    dict whose ``actuators`` override the defaults per joint and whose ``links`` add link
    flexibility; a link beam without ``length`` gets :func:`beam_length`)."""
    tree = urdf_tree(source)
    if frame not in tree.links:
        raise FrameNotFound(frame, tree.links, "end frame")
    path = [j for j in tree.path_joints(frame) if tree.joints[j][0] != "fixed"]
    user = dict(springs or {})
    user_act = dict(user.get("actuators") or {})
    default_k = user_act.pop("default", None)
    passive = list(user.get("passive") or [])
    act = {}
    for j in path:
        if j in passive:
            continue
        if j in user_act:
            act[j] = user_act[j]
        elif default_k is not None:
            act[j] = default_k
        else:
            act[j] = (
                DEFAULT_PRISMATIC_STIFFNESS
                if tree.joints[j][0] == "prismatic"
                else DEFAULT_REVOLUTE_STIFFNESS
            )
    for j in user_act:
        if j not in tree.joints:
            raise JointNotFound(j, tree.movable, "spec 'actuators'")
    positions = {j: 0.0 for j in tree.movable}
    positions.update(user.get("positions") or {})
    positions.update(pose or {})
    links = {}
    for ln, entry in (user.get("links") or {}).items():
        entry = dict(entry) if isinstance(entry, dict) else entry
        if (
            isinstance(entry, dict)
            and isinstance(entry.get("beam"), dict)
            and "length" not in entry["beam"]
        ):
            entry["beam"] = dict(entry["beam"], length=beam_length(source, ln))
        links[ln] = entry
    spec = {k: v for k, v in user.items() if k not in ("actuators", "positions", "links", "frame")}
    spec.update(frame=frame, actuators=act, positions=positions, links=links)
    return spec


@dataclass(frozen=True)
class RobotModel:
    """A VJM model built from a rigid robot description.

    Attributes:
        vm: The :class:`~vjm_pin.model.format.VjmModel`.
        source: Where it came from. spec: The spring spec used (defaults included).
        pose: The joint positions applied (rad, m). pose_name: SRDF state used, if any
            (with ``+0.3 rad (singular)`` when the default pose was moved off a singularity).
        rigid_urdf: The rigid URDF text (for gravity: inertials).
    """

    vm: VjmModel
    source: RobotSource
    spec: dict
    pose: dict
    pose_name: str | None
    rigid_urdf: str


def _strip_transmissions(path) -> str:
    """The URDF at ``path`` with only its links and joints (no transmissions, Gazebo tags)."""
    root, _, _ = _read_root(Path(path))
    for el in list(root):
        if el.tag not in ("link", "joint"):
            root.remove(el)
    return ET.tostring(root, encoding="unicode")


def build_robot(
    source: RobotSource | str | Path,
    *,
    frame: str | None = None,
    q: dict | None = None,
    pose_name: str | None = None,
    springs=None,
) -> RobotModel:
    """Build the VJM model of a rigid robot.

    Args:
        source: A :class:`RobotSource`, an ``example-robot-data`` name or a URDF path.
        frame: End frame (default :func:`default_frame`).
        q: Joint positions {name: value} (rad, m), applied over ``pose_name``.
        pose_name: Named SRDF state; default the loader's reference state when the robot has
            one and no ``q`` is given, otherwise zeros.
        springs: Spring spec (dict or YAML path/text) overriding/adding to the defaults.

    Raises:
        UnknownRobot, FrameNotFound, JointNotFound, InputError (pose outside the limits),
        SpecError, UrdfParseError.
    """
    from vjm_pin.model.generator import generate_vjm, load_spec

    _check_robot_options(source, frame, q, pose_name)
    src = _resolve_source(source)
    text = _strip_transmissions(src.urdf)
    tree = urdf_tree(text)
    pose, used = _initial_pose(src, text, tree, pose_name, q)
    user_q = dict(q or {})
    check_pose(tree, user_q)
    pose.update(user_q)
    spec_data = None
    if springs is not None:
        spec_data = _read_spec(springs)
    if frame is None and spec_data and spec_data.get("frame"):
        frame = str(spec_data["frame"])  # the spec's end frame when no frame is given
    if frame is None:
        frame = default_frame(text, src.srdf)
    elif frame not in tree.links:
        raise FrameNotFound(frame, tree.links, "the end frame must be a link of the URDF")
    chain = [j for j in tree.path_joints(frame) if tree.joints[j][0] != "fixed"]
    if not chain:
        raise ModelError(
            f"robot '{src.name}': no movable joint between the root and frame '{frame}': nothing to analyse"
        )
    if pose_name is None and not user_q:
        nudged = _nudge_if_singular(text, tree, frame, chain, pose)
        if nudged is not pose:
            used = f"{used or 'zeros'}+{SINGULAR_NUDGE:g} rad (singular)"
        pose = nudged
    spec_user = None if spec_data is None else load_spec(dict(spec_data, frame=frame))
    spec = default_spec(text, frame, pose, spec_user)
    if "task" not in spec:
        spec["task"] = default_task(text, frame, spec["positions"])
    spec.setdefault("name", src.name)
    vm = load_vjm(generate_vjm(text, spec))
    return RobotModel(vm, src, spec, pose, used, text)


def _resolve_source(source) -> RobotSource:
    """The :class:`RobotSource` of ``source`` (a source, a catalogue name or a URDF path)."""
    if isinstance(source, (str, Path)) and not (
        isinstance(source, str) and source in robot_names()
    ):
        p = Path(source)
        if not p.is_file():
            if p.suffix == ".urdf":
                raise ModelError(f"URDF file not found: {p}")
            raise UnknownRobot(str(source), robot_names())
        return RobotSource(p.stem, p, None, None, False)
    if isinstance(source, str):
        return robot_source(source)
    return source


def _initial_pose(src, text, tree, pose_name, q) -> tuple[dict[str, float], str | None]:
    """The pose before the user's ``q``: the named SRDF state ``pose_name``, else the loader's
    reference state when no ``q`` is given, else empty (zeros); with the state's name (or None)."""
    states = srdf_states(src.srdf, text)
    pose: dict[str, float] = {}
    used = None
    if pose_name is not None:
        if pose_name not in states:
            raise InputError(
                f"robot '{src.name}' has no named pose '{pose_name}'; named poses: {sorted(states) or 'none'}"
            )
        used = pose_name
    elif not q and src.ref_posture in states:
        used = src.ref_posture
    if used is not None:
        pose.update(
            _wrap_into_limits(
                tree,
                {
                    k: v
                    for k, v in states[used].items()
                    if k in tree.joints and tree.joints[k][0] != "fixed"
                },
            )
        )
    return pose, used


def _check_robot_options(source, frame, q, pose_name) -> None:
    """Types of the arguments of :func:`build_robot` (:class:`ArgumentError` naming them)."""
    if not isinstance(source, (RobotSource, str, Path)):
        raise ArgumentError(
            f"source must be a robot name, a URDF path or a RobotSource, got {type(source).__name__} {source!r}"
        )
    for arg, value in (("frame", frame), ("pose_name", pose_name)):
        if value is not None and not isinstance(value, str):
            raise ArgumentError(f"{arg} must be a name (str) or None, got {type(value).__name__} {value!r}")
    if q is not None:
        if not isinstance(q, dict):
            raise ArgumentError(f"q must be a dict {{joint name: value (rad or m)}}, got {type(q).__name__} {q!r}")
        for name, v in q.items():
            if not isinstance(name, str) or isinstance(v, bool) or not isinstance(
                v, (int, float, np.integer, np.floating)
            ):
                raise ArgumentError(f"q: joint '{name}' position must be a number (rad or m), got {v!r}")


def _wrap_into_limits(tree: UrdfTree, pose: dict) -> dict:
    """SRDF values of revolute joints moved by ±2π into the URDF limits where that helps
    (some SRDF states use another branch of the angle, e.g. kinova's ``arm_up``)."""
    out = {}
    for k, v in pose.items():
        if k in tree.limits and tree.joints[k][0] == "revolute":
            lo, hi = tree.limits[k]
            for c in (v, v + 2 * math.pi, v - 2 * math.pi):
                if lo - 1e-9 <= c <= hi + 1e-9:
                    v = c
                    break
        out[k] = v
    return out


def _rigid_jacobian(text: str, frame: str, pose: dict) -> np.ndarray:
    """(6, nv) LOCAL_WORLD_ALIGNED Jacobian of ``frame`` of the rigid URDF at ``pose``."""
    import pinocchio as pin

    from vjm_pin.model.format import build_pin_model

    model = build_pin_model(text)
    data = model.createData()
    x = pin.neutral(model)
    for j in range(1, model.njoints):
        name = model.names[j]
        if name in pose and model.joints[j].nq == 1:
            x[model.joints[j].idx_q] = pose[name]
    fid = model.getFrameId(frame)
    pin.computeJointJacobians(model, data, x)
    pin.updateFramePlacements(model, data)
    return np.asarray(pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)).reshape(
        6, model.nv
    )


def _rank(a: np.ndarray) -> int:
    s = np.linalg.svd(a, compute_uv=False) if a.size else np.zeros(0)
    return int(np.sum(s > 1e-9 * max(s.max() if s.size else 0.0, 1e-300)))


def default_task(source, frame: str, pose: dict) -> list[str]:
    """Task components when the spec gives none: all six when at least six joints drive the
    end frame; otherwise the components (greedily in the order x, y, z, rx, ry, rz) that the
    joints move independently at ``pose`` — a 3-joint leg gets x y z, a planar 2-link arm
    the two in-plane translations. The other directions are rigid and left unconstrained."""
    from vjm_pin.model.format import COMPONENTS

    text = source if isinstance(source, str) and "<" in source else Path(source).read_text()
    jac = _rigid_jacobian(text, frame, pose)
    if _rank(jac) >= 6:
        return list(COMPONENTS)
    rows: list[int] = []
    for i in range(6):
        if _rank(jac[rows + [i]]) > len(rows):
            rows.append(i)
    return [COMPONENTS[i] for i in rows]


#: Offset (rad) added to every chain joint when the default pose is singular.
SINGULAR_NUDGE = 0.3


def _nudge_if_singular(text, tree: UrdfTree, frame: str, chain: list[str], pose: dict) -> dict:
    """The default pose (SRDF reference state or zeros) moved by :data:`SINGULAR_NUDGE` rad on
    every chain joint (kept in the limits) when the end frame is singular there (the joints
    cannot move it in min(6, n) independent directions, e.g. the stretched UR arm at zero).
    Explicit poses (``q``, ``pose_name``) are never changed."""
    full = {j: 0.0 for j in tree.movable}
    full.update(pose)
    jac = _rigid_jacobian(text, frame, full)
    if _rank(jac) >= min(6, len(chain)):
        return pose
    out = dict(full)
    for j in chain:
        v = full[j] + SINGULAR_NUDGE
        if j in tree.limits:
            lo, hi = tree.limits[j]
            if lo < hi and not (lo <= v <= hi):
                v = full[j] - SINGULAR_NUDGE
                if not (lo <= v <= hi):
                    v = 0.5 * (lo + hi)
        out[j] = v
    return out


def _read_spec(springs) -> dict:
    """A validated spring spec from a dict, a YAML path or YAML text (its 'frame' is
    optional here); see :func:`vjm_pin.model.spec.read_spec`."""
    from vjm_pin.model.spec import read_spec

    return read_spec(springs, require_frame=False)


def load_robot(name_or_path, **kwargs) -> VjmModel:
    """:func:`build_robot` and return only the VJM model."""
    return build_robot(name_or_path, **kwargs).vm
