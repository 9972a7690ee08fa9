"""The VJM model: a URDF that stock Pinocchio loads, plus tags for roles and springs.

Format (see ``docs/format.md``): ordinary URDF, and in the namespace
``urn:vjm-pin:1`` (prefix ``vjm``), children of ``<robot>``::

    <vjm:task frame="tool0" components="x y z rx ry rz"/>
    <vjm:joint name="j1" role="passive" position="0.0"/>
    <vjm:joint name="j2" role="actuated" position="0.3" stiffness="1e5"/>
    <vjm:joint name="j3" role="actuated" position="0.0"/>            <!-- locked -->
    <vjm:joint name="link1_tx" role="spring"/>
    <vjm:spring name="link1" link="link1" joints="link1_tx ... link1_rz">
      <vjm:stiffness>36 numbers, row-major, SI</vjm:stiffness>
      <vjm:rest>6 numbers (θ0)</vjm:rest>
      <vjm:beam length="1" section="rectangle" a="0.02" b="0.05" E="2e11" G="7.7e10"/>
    </vjm:spring>

Pinocchio's URDF parser ignores the namespaced elements.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import (
    ArgumentError,
    ClosureViolated,
    FrameNotFound,
    InputError,
    JointNotFound,
    ModelError,
    RoleError,
    StiffnessMatrixError,
    UnknownVjmTag,
    UrdfParseError,
)

NS = "urn:vjm-pin:1"
ROLES = ("passive", "spring", "actuated")
COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
_Q = f"{{{NS}}}"

ET.register_namespace("vjm", NS)


@dataclass(frozen=True)
class VjmTag:
    """One element of the ``vjm`` namespace.

    Attributes:
        parent: Where it may appear: ``"robot"`` (a child of the root) or ``"vjm:spring"``.
        attributes: Its attribute names (no other attribute is accepted).
        meaning: What it says (rendered into ``docs/format.md``).
        text: Whether its text content carries data (numbers).
    """

    parent: str
    attributes: tuple[str, ...]
    meaning: str
    text: bool = False


#: Every element of the ``vjm`` namespace, its place and its attributes: the one table that
#: :func:`check_vjm_tags` (the loader) enforces and that ``docs/format.md`` shows
#: (:func:`vjm_tags_markdown`; a test keeps the two equal). No attribute of the ``vjm``
#: namespace is defined on other elements.
VJM_TAGS: dict[str, VjmTag] = {
    "task": VjmTag(
        "robot",
        ("frame", "components"),
        "Exactly one. End (task) frame and the constrained components among `x y z rx ry rz` "
        "(default all six). A chain ending in a passive spherical joint constrains `x y z` only; "
        "a planar chain `x y`.",
    ),
    "joint": VjmTag(
        "robot",
        ("name", "role", "position", "stiffness"),
        "One per non-fixed joint. `role` is `passive` (perfect passive joint, coordinate in `q`), "
        "`spring` (virtual spring or preloaded passive joint, coordinate in `θ`) or `actuated`. An "
        "actuated joint with `stiffness` (N·m/rad or N/m) is a 1-D spring whose rest value θ₀ is its "
        "`position` (the commanded value); without `stiffness` it is locked at `position`. For "
        "passive joints `position` is the unloaded value (one number, m or rad).",
    ),
    "spring": VjmTag(
        "robot",
        ("name", "joints", "link"),
        "One spring group (unique `name`): its joints (role `spring`) in matrix order, the link "
        "whose flexibility it models.",
    ),
    "stiffness": VjmTag(
        "vjm:spring",
        (),
        "The n×n symmetric positive-definite stiffness (N/m, N·m/rad, N/rad), in the order of the "
        "spring's `joints`, row-major.",
        text=True,
    ),
    "rest": VjmTag("vjm:spring", (), "Rest values θ₀ (preload) in the order of `joints`, default zeros.", text=True),
    "beam": VjmTag(
        "vjm:spring",
        ("length", "section", "a", "b", "diameter", "outer_diameter", "wall", "E", "G", "nu", "dofs", "subdivide"),
        "Provenance: the beam the matrix was computed from (kept so that results can be read in SI "
        "and links can be subdivided).",
    ),
    "platform": VjmTag(
        "robot",
        ("name", "components"),
        "Parallel robots (docs/parallel.md), optional: platform name (the task frame, on the first leg) and "
        "constrained components (the task; the legs are joined to the platform in these components).",
    ),
    "leg": VjmTag(
        "robot",
        ("name", "frame", "offset"),
        "Parallel robots (docs/parallel.md): one leg, the link where it meets the platform and the "
        "platform point in that link's frame (m). Every leg but the first is held on the platform by a "
        "closure named after the leg.",
    ),
    "closure": VjmTag(
        "robot",
        ("name", "frame_a", "frame_b", "components"),
        "A loop closure (unique `name`): the placement of `frame_a` relative to `frame_b` (the "
        "translation of the origins and `log3` of the relative rotation, both in `frame_b`'s axes; "
        "m, rad) is held at zero in the listed `components` (a non-empty subset of `x y z rx ry rz` "
        "without repeats, default all six; kept in the order written, which is the order of the "
        "constraint rows and reactions). Frames are links or URDF frames. The file is assembled at "
        "its reference configuration: each listed component is zero there to 1e-9 (m, rad). "
        "Redundant components (a planar loop closed in all six) are allowed.",
    ),
}


def vjm_tags_markdown() -> str:
    """The table of :data:`VJM_TAGS` as Markdown (the one in ``docs/format.md``)."""
    rows = ["| element | inside | attributes | meaning |", "|---|---|---|---|"]
    for name, tag in VJM_TAGS.items():
        attrs = " ".join(f"`{a}`" for a in tag.attributes) or ("text (numbers)" if tag.text else "—")
        rows.append(f"| `vjm:{name}` | `<{tag.parent}>` | {attrs} | {tag.meaning} |")
    return "\n".join(rows) + "\n"


def _did_you_mean(name: str, known) -> str:
    import difflib

    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'? " if close else ""


def check_vjm_tags(text: str, label: str = "<urdf string>") -> None:
    """Refuse what the loader would otherwise ignore: an element or attribute of the ``vjm``
    namespace that :data:`VJM_TAGS` does not define, a ``vjm`` element out of its place, an
    un-prefixed element inside a ``vjm`` element (``<rest>`` for ``<vjm:rest>``) and an
    element of another version of the format (``urn:vjm-pin:N``).

    Raises:
        UnknownVjmTag: naming the element or attribute, its parent element and line, and the
            known names (with a close match when there is one).
    """
    if "urn:vjm-pin" not in text:
        return
    from xml.parsers import expat

    parser = expat.ParserCreate(namespace_separator="}")
    stack: list[str] = []

    def fail(what: str, name: str, parent: str, known, hint_name: str | None = None) -> None:
        line = parser.CurrentLineNumber
        hint = _did_you_mean(hint_name or name, known)
        listed = f"; {hint}known: {', '.join(known)}" if known else (f"; {hint}" if hint else "")
        raise UnknownVjmTag(f"{label}, line {line}: {what}{listed}", name, parent, line, known)

    def start(name: str, attrs: dict) -> None:
        uri, _, local = name.rpartition("}")
        parent = stack[-1] if stack else ""
        shown = f"vjm:{local}" if uri == NS else local
        if uri == NS:
            here = [f"vjm:{n}" for n, t in VJM_TAGS.items() if t.parent == parent]
            tag = VJM_TAGS.get(local)
            if tag is None:
                fail(f"unknown element <vjm:{local}> inside <{parent}>", shown, parent, here)
            if tag.parent != parent:
                fail(f"element <vjm:{local}> inside <{parent}> is out of place: it belongs inside <{tag.parent}>",
                     shown, parent, [])
            for a in attrs:
                a_uri, _, a_local = a.rpartition("}")
                if a_uri or a_local not in tag.attributes:
                    fail(f"unknown attribute '{a_local}' of <vjm:{local}>", a_local, shown, tag.attributes)
        elif uri.startswith("urn:vjm-pin:"):
            raise UnknownVjmTag(
                f"{label}, line {parser.CurrentLineNumber}: element <{local}> is in namespace '{uri}'; this "
                f"version of vjm_pin reads '{NS}'",
                local,
                parent,
                parser.CurrentLineNumber,
                [],
            )
        else:
            if parent.startswith("vjm:"):
                inner = [f"vjm:{n}" for n, t in VJM_TAGS.items() if t.parent == parent]
                fail(f"element <{local}> inside <{parent}> has no vjm: prefix", local, parent, inner, f"vjm:{local}")
            for a in attrs:
                a_uri, _, a_local = a.rpartition("}")
                if a_uri == NS:
                    fail(f"unknown attribute 'vjm:{a_local}' of <{local}>: the vjm namespace defines no attributes "
                         "on URDF elements (roles and springs are <vjm:joint>/<vjm:spring> elements)",
                         a_local, shown, [])
        stack.append(shown)

    def end(name: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as e:  # pragma: no cover - ElementTree parsed the same text first
        raise UrdfParseError(f"{label}: malformed XML: {e}") from None


def _parse_numbers(text: str | None, what: str) -> np.ndarray:
    try:
        vals = np.array([float(v) for v in (text or "").replace(",", " ").split()], dtype=float)
    except ValueError as e:
        raise ModelError(f"{what}: not a list of numbers ({e})") from None
    if not np.all(np.isfinite(vals)):
        raise ModelError(f"{what}: contains NaN or infinite values")
    return vals


def _parse_number(text: str | None, what: str) -> float:
    """Exactly one finite number from an attribute value; :class:`ModelError` otherwise."""
    vals = _parse_numbers(text, what)
    if vals.size != 1:
        raise ModelError(f"{what}: expected one number, got '{text}'")
    return float(vals[0])


def check_stiffness_matrix(k: np.ndarray, n: int, name: str) -> np.ndarray:
    """Return ``k`` as an (n, n) float array after checking that it is symmetric
    positive definite; raise :class:`StiffnessMatrixError` naming ``name`` otherwise."""
    k = np.asarray(k, dtype=float)
    if k.ndim == 0 and n == 1:
        k = k.reshape(1, 1)
    if k.shape != (n, n):
        raise StiffnessMatrixError(
            f"spring '{name}': stiffness matrix has shape {k.shape}, expected ({n}, {n}) for its {n} joint(s)"
        )
    if not np.all(np.isfinite(k)):
        raise StiffnessMatrixError(f"spring '{name}': stiffness matrix contains NaN or infinite values")
    scale = max(np.abs(k).max(), 1e-300)
    if np.abs(k - k.T).max() > 1e-9 * scale:
        raise StiffnessMatrixError(f"spring '{name}': stiffness matrix is not symmetric")
    ev = np.linalg.eigvalsh(0.5 * (k + k.T))
    if ev.min() <= 1e-12 * ev.max() or ev.max() <= 0.0:
        raise StiffnessMatrixError(
            f"spring '{name}': stiffness matrix is not positive definite (eigenvalues {ev.min():.3g} … {ev.max():.3g})"
        )
    return 0.5 * (k + k.T)


@dataclass(frozen=True)
class SpringGroup:
    """One (possibly multidimensional, coupled) virtual spring.

    Attributes:
        name: Spring name.
        joints: Names of its joints, in the order of the matrix rows.
        stiffness: (k, k) SPD stiffness matrix in SI (N/m, N·m/rad, N/rad), joint coordinates.
        rest: (k,) rest values θ0 of the joints (m or rad): the preload.
        link: The link whose flexibility the spring models (None for actuator springs).
        beam: Beam parameters it was derived from (``vjm_pin.model.beam.Beam.to_dict()`` keys), if any.
    """

    name: str
    joints: tuple[str, ...]
    stiffness: np.ndarray
    rest: np.ndarray
    link: str | None = None
    beam: dict | None = None


#: Largest violation (m or rad) of a closure component at the reference configuration
#: that the loader accepts: the file must be assembled there.
ASSEMBLY_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Closure:
    """One loop closure (``<vjm:closure>``): frame_a is held on frame_b.

    The relative placement of ``frame_a`` with respect to ``frame_b`` is
    ``s = (R_bᵀ(p_a − p_b), log3(R_bᵀ R_a))`` (m, rad; both parts in ``frame_b``'s axes,
    :func:`relative_placement`); the closure holds ``s`` at zero in ``components``.

    Attributes:
        name: Unique closure name.
        frame_a, frame_b: Pinocchio frame names (links or URDF frames), distinct.
        components: Held components among ``x y z rx ry rz``, non-empty, no repeats, in the
            order written in the file: the order of the constraint rows and multipliers.
    """

    name: str
    frame_a: str
    frame_b: str
    components: tuple[str, ...]

    def __post_init__(self):
        comps = tuple(self.components.split() if isinstance(self.components, str) else self.components)
        bad = [c for c in comps if c not in COMPONENTS]
        if bad:
            raise ModelError(f"closure '{self.name}': component '{bad[0]}' is not one of {list(COMPONENTS)}")
        if not comps or len(set(comps)) != len(comps):
            raise ModelError(f"closure '{self.name}': components {list(comps)} must be distinct and non-empty")
        if self.frame_a == self.frame_b:
            raise ModelError(f"closure '{self.name}': frame_a and frame_b are the same frame '{self.frame_a}'")
        object.__setattr__(self, "components", comps)

    @property
    def indices(self) -> tuple[int, ...]:
        """Indices of :attr:`components` in ``(x, y, z, rx, ry, rz)``, in the order written."""
        return tuple(COMPONENTS.index(c) for c in self.components)


def relative_placement(p_a, r_a, p_b, r_b) -> np.ndarray:
    """The 6-D placement of frame a relative to frame b: ``(R_bᵀ(p_a − p_b), log3(R_bᵀ R_a))``.

    Args:
        p_a, p_b: (3,) frame origins, world (m). r_a, r_b: (3, 3) orientations in world.

    Returns:
        (6,): translation (m) and rotation vector (rad), in frame b's axes.
    """
    import pinocchio as pin

    r_b = np.asarray(r_b, float)
    return np.concatenate([r_b.T @ (np.asarray(p_a, float) - p_b), pin.log3(r_b.T @ np.asarray(r_a, float))])


def _read_closures(root: ET.Element, model, label: str, reference: np.ndarray) -> tuple[Closure, ...]:
    """The ``<vjm:closure>`` elements, validated and checked for assembly at ``reference``.

    Raises:
        ModelError: a missing attribute, a repeated name, bad components.
        FrameNotFound: an unknown frame.
        ClosureViolated: a listed component is not zero to :data:`ASSEMBLY_TOLERANCE` at
            the reference configuration.
    """
    from vjm_pin.model.placements import frame_placements

    frame_names = [f.name for f in model.frames]
    closures: list[Closure] = []
    for el in root.findall(f"{_Q}closure"):
        name = el.get("name")
        if not name:
            raise ModelError(f"{label}: <vjm:closure> without 'name'")
        if any(c.name == name for c in closures):
            raise ModelError(f"{label}: two <vjm:closure> elements named '{name}'")
        frames = []
        for attr in ("frame_a", "frame_b"):
            f = el.get(attr)
            if not f:
                raise ModelError(f"{label}: closure '{name}' has no '{attr}' attribute")
            if not model.existFrame(f):
                raise FrameNotFound(f, frame_names, f"closure '{name}' {attr}")
            frames.append(f)
        comps = el.get("components")
        comps = " ".join(COMPONENTS) if comps is None else comps
        closures.append(Closure(name, frames[0], frames[1], tuple(comps.split())))
    if not closures:
        return ()
    omf = frame_placements(model, reference)  # no pin.Data: model/placements.py
    for c in closures:
        ma, mb = omf[model.getFrameId(c.frame_a)], omf[model.getFrameId(c.frame_b)]
        s = relative_placement(ma.translation, ma.rotation, mb.translation, mb.rotation)
        for i in c.indices:
            if not abs(s[i]) <= ASSEMBLY_TOLERANCE:
                unit = "m" if i < 3 else "rad"
                raise ClosureViolated(
                    f"{label}: closure '{c.name}' is violated at the reference configuration: component "
                    f"'{COMPONENTS[i]}' is {s[i]:.3g} {unit} (tolerance {ASSEMBLY_TOLERANCE:g}); the file must be "
                    "assembled at its reference configuration",
                    c.name,
                    COMPONENTS[i],
                    float(s[i]),
                )
    return tuple(closures)


#: Suffix of the Pinocchio frame added at each leg's platform point (``<leg>__platform``).
LEG_FRAME_SUFFIX = "__platform"


@dataclass(frozen=True)
class Leg:
    """One leg of a model written with the ``<vjm:leg>``/``<vjm:platform>`` shorthand.

    Attributes:
        name: Leg name.
        frame: The link where the leg meets the platform.
        offset: (3,) the platform point in ``frame``'s axes (m).
        platform_frame: Name of the Pinocchio frame the loader adds at the platform point, on
            ``frame``'s joint, world-aligned at the file's reference configuration
            (``"<leg>__platform"``).
        joints: Names of the non-fixed joints on the path from the root to ``frame``, root first.
    """

    name: str
    frame: str
    offset: np.ndarray
    platform_frame: str
    joints: tuple[str, ...]


def _read_platform(root: ET.Element, label: str) -> tuple[str, tuple[int, ...]]:
    """Name and task components of ``<vjm:platform>`` (defaults ``platform``, all six)."""
    plats = root.findall(f"{_Q}platform")
    if len(plats) > 1:
        raise ModelError(f"{label}: more than one <vjm:platform> element")
    plat = plats[0] if plats else None
    name = (plat.get("name") if plat is not None else None) or "platform"
    comps = ((plat.get("components") if plat is not None else None) or " ".join(COMPONENTS)).split()
    if any(c not in COMPONENTS for c in comps) or not comps or len(set(comps)) != len(comps):
        raise ModelError(f"{label}: platform components {comps} must be distinct names from {list(COMPONENTS)}")
    return name, tuple(sorted(COMPONENTS.index(c) for c in comps))


def _read_legs(root: ET.Element, model, label: str, reference: np.ndarray):
    """The ``<vjm:leg>``/``<vjm:platform>`` shorthand as frames and closures (docs/parallel.md).

    Adds to ``model`` one frame per leg at its platform point (``frame`` + ``offset``,
    world-aligned at ``reference``) and the task frame named after the platform (on the first
    leg, same placement); every other leg's frame is held on the task frame by a closure named
    after the leg in the platform components (all six: a rigid platform; ``x y z``: the legs
    meet at a point).

    Returns:
        (legs, task frame name, task components, closures).

    Raises:
        ModelError: a leg without ``name``/``frame``, a repeated leg name, a bad offset, a frame
            name already used, or legs whose platform points do not coincide at ``reference``.
        FrameNotFound: a leg's ``frame`` is not a link.
    """
    import pinocchio as pin

    pname, task = _read_platform(root, label)
    links = sorted(f.name for f in model.frames if f.type == pin.FrameType.BODY)
    from vjm_pin.model.placements import frame_placements

    omf = frame_placements(model, reference)  # no pin.Data: model/placements.py
    legs: list[Leg] = []
    points = []
    for el in root.findall(f"{_Q}leg"):
        name, frame = el.get("name"), el.get("frame")
        if not name or not frame:
            raise ModelError(f"{label}: <vjm:leg> needs 'name' and 'frame' attributes")
        if any(lg.name == name for lg in legs):
            raise ModelError(f"{label}: two legs named '{name}'")
        if frame not in links:
            raise FrameNotFound(frame, links, f"vjm:leg '{name}'")
        off = _parse_numbers(el.get("offset") or "0 0 0", f"leg '{name}' offset")
        if off.size != 3:
            raise ModelError(f"leg '{name}': offset needs 3 numbers (m), got {off.size}")
        fid = model.getFrameId(frame)
        link = model.frames[fid]
        world = omf[fid]
        # platform point on the link, its axes turned back to world at the reference
        placement = link.placement * pin.SE3(world.rotation.T, off)
        joints, j = [], link.parentJoint
        while j > 0:
            joints.append(model.names[j])
            j = model.parents[j]
        fnames = [f"{name}{LEG_FRAME_SUFFIX}"] + ([pname] if not legs else [])
        for fname in fnames:
            if model.existFrame(fname):
                raise ModelError(f"{label}: leg '{name}': the model already has a frame named '{fname}'")
            model.addFrame(pin.Frame(fname, link.parentJoint, fid, placement, pin.FrameType.OP_FRAME))
        legs.append(Leg(name, frame, off, fnames[0], tuple(joints[::-1])))
        points.append(world.act(off))
    scale = max(max(np.linalg.norm(p) for p in points), 1.0)
    for lg, p in zip(legs, points):
        if np.linalg.norm(p - points[0]) > 1e-9 * scale:
            raise ModelError(
                f"{label}: leg '{lg.name}' puts the platform point at {np.round(p, 9).tolist()} but leg "
                f"'{legs[0].name}' at {np.round(points[0], 9).tolist()} (reference configuration): check its offset"
            )
    comps = tuple(COMPONENTS[i] for i in task)
    closures = tuple(Closure(lg.name, lg.platform_frame, pname, comps) for lg in legs[1:])
    return tuple(legs), pname, task, closures


@dataclass(frozen=True)
class VjmModel:
    """A manipulator in the VJM form, ready for the solver.

    Attributes:
        model: The Pinocchio model (every joint 1-DOF revolute or prismatic, nq = nv).
        name: Model name.
        frame: End (task) frame name.
        frame_id: Its Pinocchio frame index.
        task: Indices of the constrained task components in (x, y, z, rx, ry, rz).
        roles: Joint name → ``"passive"``, ``"spring"``, ``"actuated"`` (with a stiffness: a
            1-D spring) or ``"locked"`` (actuated without a stiffness).
        springs: The spring groups (actuator springs included, as 1-D groups).
        reference: (nq,) unloaded configuration: commanded actuator positions, spring rest
            values θ0, passive joints at their given positions (m, rad).
        theta_idx: Indices (into the configuration) of the spring coordinates θ, group order.
        q_idx: Indices of the perfect passive coordinates q.
        K_theta: (nθ, nθ) block-diagonal stiffness of all springs, in ``theta_idx`` order.
        theta0: (nθ,) rest values θ0.
        urdf: The URDF text the model was read from.
        closures: The loop closures (``<vjm:closure>``), file order; empty for a tree. The
            file's reference configuration satisfies them (to 1e-9); one changed by
            :meth:`with_positions` need not (the solver re-assembles the mechanism).
            A model written with ``<vjm:leg>`` holds every leg but the first on the platform
            (closures named after the legs, :attr:`legs`).
        legs: The legs of a model written with the ``<vjm:leg>``/``<vjm:platform>`` shorthand
            (:class:`Leg`, file order; the task frame is the platform, on the first leg);
            empty otherwise. :func:`vjm_pin.model.legs.split_legs` gives each as a serial model.
    """

    model: object
    name: str
    frame: str
    frame_id: int
    task: tuple[int, ...]
    roles: dict
    springs: tuple[SpringGroup, ...]
    reference: np.ndarray
    theta_idx: np.ndarray
    q_idx: np.ndarray
    K_theta: np.ndarray
    theta0: np.ndarray
    urdf: str = field(repr=False, default="")
    closures: tuple[Closure, ...] = ()
    legs: tuple[Leg, ...] = ()

    # ------------------------------------------------------------------ names
    @property
    def joint_names(self) -> list[str]:
        """Names of the configuration coordinates, index order."""
        return list(self.model.names[1:])

    @property
    def theta_names(self) -> list[str]:
        names = self.joint_names
        return [names[i] for i in self.theta_idx]

    @property
    def q_names(self) -> list[str]:
        names = self.joint_names
        return [names[i] for i in self.q_idx]

    @property
    def task_names(self) -> list[str]:
        return [COMPONENTS[i] for i in self.task]

    @property
    def n_theta(self) -> int:
        return len(self.theta_idx)

    @property
    def n_q(self) -> int:
        return len(self.q_idx)

    def joint_index(self, name: str) -> int:
        """Configuration index of joint ``name``; :class:`JointNotFound` if unknown."""
        names = self.joint_names
        if not isinstance(name, str) or name not in names:
            raise JointNotFound(str(name), names)
        return names.index(name)

    def with_positions(self, positions: dict) -> VjmModel:
        """A copy whose reference configuration has the given joint values (m, rad).

        Actuated/locked joints: the commanded position (θ0 of an actuator spring);
        passive joints: the starting value; virtual spring joints cannot be set (their
        reference is the rest value of their spring)."""
        ref = self.reference.copy()
        theta0 = self.theta0.copy()
        springs = list(self.springs)
        if not isinstance(positions, dict):
            raise ArgumentError(
                f"positions must be a dict {{joint name: value (m or rad)}}, got {type(positions).__name__}"
            )
        for name, value in positions.items():
            i = self.joint_index(name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ArgumentError(f"joint '{name}': position must be a number (m or rad), got {value!r}")
            v = float(value)
            if not math.isfinite(v):
                raise InputError(f"joint '{name}': position must be finite, got {value}")
            role = self.roles[name]
            if role == "spring":
                raise RoleError(f"joint '{name}' is a virtual spring joint; its position is its rest value")
            ref[i] = v
            if role == "actuated":
                pos = list(self.theta_idx).index(i)
                theta0[pos] = v
                for g, grp in enumerate(springs):
                    if grp.joints == (name,):
                        springs[g] = replace(grp, rest=np.array([v]))
        return replace(self, reference=ref, theta0=theta0, springs=tuple(springs))


def _read_text(path: Path, what: str = "URDF") -> str:
    """The text of the file at ``path``; :class:`UrdfParseError` (missing file, folder,
    unreadable or not UTF-8 text) otherwise."""
    if path.is_dir():
        raise UrdfParseError(f"{path}: is a folder, not a {what} file")
    if not path.is_file():
        raise UrdfParseError(f"{what} file not found: {path}")
    try:
        data = path.read_bytes()
    except OSError as e:
        raise UrdfParseError(f"{path}: cannot read the {what} file ({e.strerror or e})") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise UrdfParseError(
            f"{path}: not a {what} text file (not UTF-8: byte 0x{data[e.start]:02x} at offset {e.start})"
        ) from None


def _read_root(source: str | Path) -> tuple[ET.Element, str, str]:
    """Parse URDF text or a path; return (root element, text, display name).

    A ``str`` containing ``<`` is XML text, any other ``str`` or a :class:`~pathlib.Path` a
    file name. The ``vjm`` tags are checked (:func:`check_vjm_tags`)."""
    text: str
    label: str
    if isinstance(source, Path) or (isinstance(source, str) and "<" not in source):
        if not str(source).strip():
            raise ArgumentError("URDF source is empty: give a file path or URDF (XML) text")
        p = Path(source)
        text = _read_text(p)
        label = str(p)
    elif isinstance(source, str):
        text = source
        label = "<urdf string>"
    else:
        raise ArgumentError(
            f"URDF source must be a file path (str or pathlib.Path) or URDF text (str), got {type(source).__name__}"
        )
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise UrdfParseError(f"{label}: malformed XML: {e}") from None
    if root.tag != "robot":
        raise UrdfParseError(f"{label}: root element is <{root.tag}>, expected <robot> (not a URDF)")
    check_vjm_tags(text, label)
    return root, text, label


def build_pin_model(text: str, label: str = "<urdf string>"):
    """Build a Pinocchio model from URDF text, re-raising its errors as :class:`UrdfParseError`."""
    import pinocchio as pin

    try:
        return pin.buildModelFromXML(text)
    except (ValueError, RuntimeError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise UrdfParseError(f"{label}: Pinocchio could not load the URDF: {first}") from None


def load_vjm(source: str | Path) -> VjmModel:
    """Load and validate a VJM URDF (path or XML text).

    Raises:
        UrdfParseError: malformed XML or a URDF Pinocchio rejects.
        RoleError: a non-fixed joint without a role, with two roles, or a spring joint
            outside (or in two) spring groups; an unsupported joint type.
        JointNotFound, FrameNotFound: a tag names a joint/frame the URDF does not have.
        StiffnessMatrixError: a matrix of the wrong size, not symmetric or not SPD.
        ModelError: a ``<vjm:leg>``/``<vjm:platform>`` shorthand that does not assemble (legs
            whose platform points differ, a ``<vjm:task>`` next to legs; see :func:`_read_legs`).

    A model written with ``<vjm:leg>`` loads as a mechanism: the platform is the task frame on
    the first leg and every other leg is held on it by a closure (docs/parallel.md).
    """
    root, text, label = _read_root(source)
    model = build_pin_model(text, label)
    joint_names = list(model.names[1:])
    frame_names = [f.name for f in model.frames]

    for j, jm in enumerate(model.joints[1:], start=1):
        if jm.nq != 1 or jm.nv != 1:
            raise RoleError(
                f"joint '{model.names[j]}' is a {jm.shortname()} (nq={jm.nq}, nv={jm.nv}); the VJM format needs "
                "1-DOF revolute or prismatic joints (the generator turns 'continuous' into 'revolute' and "
                "'floating'/'planar' into chains of 1-DOF joints)"
            )

    frame, task, has_legs = _read_task(root, model, label, frame_names)
    roles, positions, act_stiff = _read_roles(root, label, joint_names)
    springs = _read_springs(root, label, joint_names, roles, positions, act_stiff)
    full_roles, reference, theta_idx, theta0, K, q_idx = _assemble_springs(
        label, model, joint_names, roles, positions, act_stiff, springs
    )
    legs, leg_closures = (), ()
    if has_legs:
        legs, frame, task, leg_closures = _read_legs(root, model, label, reference)
    closures = _read_closures(root, model, label, reference)
    clash = sorted({c.name for c in closures} & {c.name for c in leg_closures})
    if clash:
        raise ModelError(f"{label}: closure name(s) {clash} are also leg names (the legs' closures)")
    closures = leg_closures + closures
    return VjmModel(
        model=model,
        name=root.get("name", "robot"),
        frame=frame,
        frame_id=int(model.getFrameId(frame)),
        task=task,
        roles=full_roles,
        springs=tuple(springs),
        reference=reference,
        theta_idx=np.array(theta_idx, dtype=int),
        q_idx=np.array(q_idx, dtype=int),
        K_theta=np.asarray(K, dtype=float),
        theta0=np.array(theta0, dtype=float),
        urdf=text,
        closures=closures,
        legs=legs,
    )


def _read_task(root, model, label: str, frame_names):
    """``(frame, task, has_legs)`` of ``<vjm:task>`` (or, with legs, empty: the platform
    gives them once the reference is known, :func:`_read_legs`)."""
    tasks = root.findall(f"{_Q}task")
    has_legs = bool(root.findall(f"{_Q}leg"))
    if has_legs and tasks:
        raise ModelError(
            f"{label}: a model with <vjm:leg> elements takes its task from <vjm:platform>; remove <vjm:task>"
        )
    if not has_legs and root.findall(f"{_Q}platform"):
        raise ModelError(f"{label}: <vjm:platform> without <vjm:leg name=... frame=... offset=.../> elements")
    if has_legs:
        frame, task = "", ()  # from the platform (_read_legs, once the reference is known)
    elif len(tasks) != 1:
        raise ModelError(f"{label}: expected exactly one <vjm:task frame=... /> element, found {len(tasks)}")
    else:
        frame = tasks[0].get("frame")
        if not frame:
            raise ModelError(f"{label}: <vjm:task> has no 'frame' attribute")
        if not model.existFrame(frame):
            raise FrameNotFound(frame, frame_names, "vjm:task")
        comps = (tasks[0].get("components") or " ".join(COMPONENTS)).split()
        for c in comps:
            if c not in COMPONENTS:
                raise ModelError(f"{label}: task component '{c}' is not one of {list(COMPONENTS)}")
        if len(set(comps)) != len(comps) or not comps:
            raise ModelError(f"{label}: task components {comps} must be distinct and non-empty")
        task = tuple(sorted(COMPONENTS.index(c) for c in comps))

    return frame, task, has_legs


def _read_roles(root, label: str, joint_names):
    """``(roles, positions, actuator stiffnesses)`` of the ``<vjm:joint>`` tags."""
    roles: dict[str, str] = {}
    positions: dict[str, float] = {}
    act_stiff: dict[str, float] = {}
    for el in root.findall(f"{_Q}joint"):
        name = el.get("name")
        if name is None:
            raise RoleError(f"{label}: <vjm:joint> without 'name'")
        if name not in joint_names:
            raise JointNotFound(name, joint_names, "vjm:joint; fixed joints take no role")
        if name in roles:
            raise RoleError(f"joint '{name}' has more than one <vjm:joint> role tag")
        role = el.get("role")
        if role not in ROLES:
            raise RoleError(f"joint '{name}': role '{role}' is not one of {list(ROLES)}")
        if el.get("position") is not None:
            positions[name] = _parse_number(el.get("position"), f"joint '{name}' position")
        if el.get("stiffness") is not None:
            if role != "actuated":
                raise RoleError(f"joint '{name}': 'stiffness' is only for actuated joints (springs use <vjm:spring>)")
            k = _parse_number(el.get("stiffness"), f"joint '{name}' stiffness")
            check_stiffness_matrix(np.array([[k]]), 1, name)
            act_stiff[name] = float(k)
        roles[name] = role
    missing = [n for n in joint_names if n not in roles]
    if missing:
        raise RoleError(f"joint(s) {missing} have no role: add <vjm:joint name=... role=\"passive|spring|actuated\"/>")

    return roles, positions, act_stiff


def _read_springs(root, label: str, joint_names, roles, positions, act_stiff) -> list:
    """The :class:`SpringGroup` s of ``<vjm:spring>`` tags, then one per stiff actuator."""
    springs: list[SpringGroup] = []
    owner: dict[str, str] = {}
    for el in root.findall(f"{_Q}spring"):
        sname = el.get("name")
        if not sname:
            raise ModelError(f"{label}: <vjm:spring> without 'name'")
        if any(g.name == sname for g in springs):
            raise ModelError(f"{label}: two <vjm:spring> elements named '{sname}'")
        joints = tuple((el.get("joints") or "").split())
        if not joints:
            raise ModelError(f"spring '{sname}' lists no joints")
        for jn in joints:
            if jn not in joint_names:
                raise JointNotFound(jn, joint_names, f"spring '{sname}'")
            if roles.get(jn) != "spring":
                raise RoleError(f"joint '{jn}' is in spring '{sname}' but its role is '{roles.get(jn)}', not 'spring'")
            if jn in owner:
                raise RoleError(f"joint '{jn}' is in two springs: '{owner[jn]}' and '{sname}'")
            owner[jn] = sname
        n = len(joints)
        st = el.find(f"{_Q}stiffness")
        if st is None:
            raise StiffnessMatrixError(f"spring '{sname}' has no <vjm:stiffness> matrix")
        vals = _parse_numbers(st.text, f"spring '{sname}' stiffness")
        if vals.size != n * n:
            raise StiffnessMatrixError(
                f"spring '{sname}': stiffness has {vals.size} numbers, expected {n * n} ({n}x{n} for its {n} joints)"
            )
        k = check_stiffness_matrix(vals.reshape(n, n), n, sname)
        rest_el = el.find(f"{_Q}rest")
        rest = np.zeros(n) if rest_el is None else _parse_numbers(rest_el.text, f"spring '{sname}' rest")
        if rest.size != n:
            raise ModelError(f"spring '{sname}': rest has {rest.size} values, expected {n}")
        beam_el = el.find(f"{_Q}beam")
        beam = None
        if beam_el is not None:
            beam = {}
            for key, v in beam_el.attrib.items():
                beam[key] = v if key in ("section", "dofs") else _parse_number(v, f"spring '{sname}' beam '{key}'")
        springs.append(SpringGroup(sname, joints, k, rest, el.get("link"), beam))
    orphans = [n for n, r in roles.items() if r == "spring" and n not in owner]
    if orphans:
        raise RoleError(f"spring joint(s) {orphans} belong to no <vjm:spring> group")
    for name, k in act_stiff.items():
        springs.append(SpringGroup(name, (name,), np.array([[k]]), np.array([positions.get(name, 0.0)])))

    return springs


def _assemble_springs(label: str, model, joint_names, roles, positions, act_stiff, springs):
    """``(roles with 'locked' actuators, reference, θ indices, θ₀, K_θ, q indices)``."""
    full_roles = {n: ("locked" if r == "actuated" and n not in act_stiff else r) for n, r in roles.items()}
    reference = np.zeros(model.nq)
    for n, v in positions.items():
        reference[joint_names.index(n)] = v
    theta_idx, blocks, theta0 = [], [], []
    for g in springs:
        for jn, r in zip(g.joints, g.rest):
            theta_idx.append(joint_names.index(jn))
            reference[joint_names.index(jn)] = r
        blocks.append(g.stiffness)
        theta0.extend(g.rest)
    # block-diagonal K_θ (numpy only: importing scipy.linalg would dominate a one-shot CLI run)
    K = np.zeros((len(theta0), len(theta0)))
    at = 0
    for blk in blocks:
        k = len(blk)
        K[at : at + k, at : at + k] = blk
        at += k
    q_idx = [i for i, n in enumerate(joint_names) if full_roles[n] == "passive"]
    for i, r in enumerate(reference):
        if not math.isfinite(r):
            raise InputError(f"joint '{joint_names[i]}': position is not finite")
    if not springs:
        raise RoleError(f"{label}: the model has no spring (no <vjm:spring> and no actuated joint with a stiffness)")
    return full_roles, reference, theta_idx, theta0, K, q_idx
