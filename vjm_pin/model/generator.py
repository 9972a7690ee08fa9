"""Generate VJM URDF models from a rigid URDF and a spring specification.

The specification (a YAML file or the same as a dict; schema and validation in
:mod:`vjm_pin.model.spec`) has the keys:

``name``
    Optional model name (default: the URDF robot name).
``frame`` (required)
    End (task) frame: a link name of the rigid URDF.
``task``
    Constrained task components, a list or a string from ``x y z rx ry rz``
    (default all six; ``[x, y, z]`` for a chain ending in a passive spherical joint).
``actuators``
    Mapping joint → actuator stiffness (N·m/rad for revolute, N/m for prismatic joints);
    the key ``default`` applies to every actuated joint not named. An actuated joint
    without a stiffness (no entry, no default, or ``null``) is locked (rigid).
``passive``
    List of perfect passive joints (coordinates ``q``).
``positions``
    Mapping joint → position (rad or m): commanded positions of the actuated joints
    (the rest value θ0 of their springs) and starting values of the passive joints.
    Missing joints are at 0.
``links``
    Mapping link → link spring. Each is ``{beam: {...}}`` or ``{stiffness: [[...]]}``,
    with optional ``dofs`` (a subset of ``x y z rx ry rz``, default all six; e.g.
    ``[x, y, rz]`` for planar springs) and ``rest`` (θ0, default zeros). ``dofs`` may be in
    any order: the rows/columns of ``stiffness`` and the values of ``rest`` follow it and are
    permuted to the spring joints, which are created in the order ``x y z rx ry rz``.

    - ``beam``: ``length`` (m; default: the distance from the link origin to its tip),
      ``section`` (``rectangle`` with ``a`` along the beam z axis and ``b`` along y,
      ``circle`` with ``diameter``, ``tube`` with ``outer_diameter`` and ``wall``), ``E``
      (Pa) and ``nu`` or ``G`` (Pa). The spring is the cantilever tip stiffness
      (:mod:`vjm_pin.model.beam`), restricted to ``dofs`` by inverting the matching block of the
      compliance (the other directions are rigid).
    - ``stiffness``: an n×n SPD matrix (n = number of dofs) in the link frame at the tip.

    The spring (six 1-DOF joints Tx Ty Tz Rx Ry Rz, massless frames: T_s(θ) of eq. 34)
    is inserted at the link tip: the origin of the link's child joint on the path to
    ``frame``. Its axes are those of the link frame; the beam frame has x from the link
    origin to the tip and z closest to the link's z axis (y if z is along the beam).
``subdivide``
    Split every beam link into k sub-links, each with its own tip spring of a beam of
    length L/k (default 1).
"""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET

import numpy as np

from vjm_pin.exceptions import FrameNotFound, JointNotFound, SpecError, UrdfParseError
from vjm_pin.model.beam import Beam
from vjm_pin.model.format import COMPONENTS, NS, _read_root, build_pin_model, check_stiffness_matrix
from vjm_pin.model.spec import LINK_KEYS as _LINK_KEYS
from vjm_pin.model.spec import SPEC_KEYS, read_spec  # noqa: F401 - SPEC_KEYS re-exported

_Q = f"{{{NS}}}"
LINK_KEYS = set(_LINK_KEYS)  # the fields of spec.LinkSpec (built lazily: no pydantic at import)
SPRING_SUFFIX = ("tx", "ty", "tz", "rx", "ry", "rz")


def load_spec(spec) -> dict:
    """Read a spec from a dict, a YAML path or YAML text and validate the whole document
    (:func:`vjm_pin.model.spec.read_spec`; ``frame`` required).

    Raises:
        SpecProblems: a :class:`SpecError` listing every problem with its YAML path.
    """
    return read_spec(spec, require_frame=True)


def _components(value, what: str) -> list[str]:
    comps = value.split() if isinstance(value, str) else list(value)
    for c in comps:
        if c not in COMPONENTS:
            raise SpecError(f"{what}: '{c}' is not one of {list(COMPONENTS)}")
    if len(set(comps)) != len(comps) or not comps:
        raise SpecError(f"{what}: components {comps} must be distinct and non-empty")
    return comps


def _fmt(v: float) -> str:
    return repr(float(v))


def _fmt_vec(v) -> str:
    return " ".join(_fmt(x) for x in np.asarray(v, dtype=float).ravel())


def _origin(el: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    o = el.find("origin")
    if o is None:
        return np.zeros(3), np.zeros(3)
    xyz = np.array([float(v) for v in (o.get("xyz") or "0 0 0").split()])
    rpy = np.array([float(v) for v in (o.get("rpy") or "0 0 0").split()])
    return xyz, rpy


def _set_origin(el: ET.Element, xyz, rpy) -> None:
    o = el.find("origin")
    if o is None:
        o = ET.SubElement(el, "origin")
    o.set("xyz", _fmt_vec(xyz))
    o.set("rpy", _fmt_vec(rpy))


def beam_frame(tip: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) whose columns are the beam axes in the link frame: x along
    ``tip``, z closest to the link z axis (y if ``tip`` is along z)."""
    x = np.asarray(tip, float) / np.linalg.norm(tip)
    ref = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    z = ref - x * (x @ ref)
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def link_spring_matrix(entry: dict, link: str, tip: np.ndarray, length: float | None = None):
    """Stiffness (n, n), dofs, rest and beam dict of one link spring entry.

    ``dofs`` may be given in any order: a ``stiffness`` matrix and ``rest`` are read in the
    order given and returned permuted to the canonical order ``x y z rx ry rz`` of the
    generated spring joints (``P K Pᵀ`` with the permutation ``P``)."""
    unknown = set(entry) - LINK_KEYS
    if unknown:
        raise SpecError(f"link '{link}': unknown key(s) {sorted(unknown)}; known: {sorted(LINK_KEYS)}")
    if ("beam" in entry) == ("stiffness" in entry):
        raise SpecError(f"link '{link}': give exactly one of 'beam' or 'stiffness'")
    given = _components(entry.get("dofs", list(COMPONENTS)), f"link '{link}' dofs")
    dofs = [c for c in COMPONENTS if c in given]
    perm = [given.index(c) for c in dofs]  # canonical position i <- given position perm[i]
    idx = [COMPONENTS.index(c) for c in dofs]
    n = len(dofs)
    beam_dict = None
    if "beam" in entry:
        b = entry["beam"]
        if not isinstance(b, dict):
            raise SpecError(f"link '{link}': 'beam' must be a mapping")
        default_len = length if length is not None else float(np.linalg.norm(tip))
        try:
            beam = Beam.from_dict(b, length=default_len if default_len > 0 else None)
        except SpecError as e:
            raise SpecError(f"link '{link}': {e}") from None
        if np.linalg.norm(tip) < 1e-12:
            rot = np.eye(3)
        else:
            rot = beam_frame(tip)
        T = np.zeros((6, 6))
        T[:3, :3] = rot
        T[3:, 3:] = rot
        c_link = T @ beam.compliance() @ T.T
        k = np.linalg.inv(c_link[np.ix_(idx, idx)])
        k = 0.5 * (k + k.T)
        beam_dict = beam.to_dict()
    else:
        k = np.asarray(entry["stiffness"], dtype=float) if _is_matrix(entry["stiffness"]) else None
        if k is None:
            raise SpecError(f"link '{link}': 'stiffness' must be a {n}x{n} matrix (list of rows)")
        k = check_stiffness_matrix(k, n, link)[np.ix_(perm, perm)]
    k = check_stiffness_matrix(k, n, link)
    try:
        rest = np.asarray(entry.get("rest", np.zeros(n)), dtype=float).ravel()
    except (TypeError, ValueError):
        rest = np.zeros(0)
    if rest.size != n or not np.all(np.isfinite(rest)):
        raise SpecError(f"link '{link}': 'rest' must have {n} finite values (one per dof, in the order of 'dofs')")
    return k, dofs, rest[perm], beam_dict


def _is_matrix(v) -> bool:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        return False
    return a.ndim == 2


def _path_joints(root: ET.Element, frame: str) -> list[ET.Element]:
    """Joints from the root link to link ``frame``, in order."""
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    path = []
    link = frame
    seen = set()
    while link in by_child:
        if link in seen:
            raise UrdfParseError(f"the URDF has a kinematic loop through link '{link}'")
        seen.add(link)
        j = by_child[link]
        path.append(j)
        link = j.find("parent").get("link")
    return path[::-1]


def generate_vjm(rigid_urdf, spec) -> str:
    """Turn a rigid URDF (path or text) and a spring spec (dict, YAML path or text) into
    VJM URDF text (see :mod:`vjm_pin.model.format` for the format).

    Raises:
        SpecError: unknown keys, wrong shapes, bad values.
        JointNotFound, FrameNotFound: names the URDF does not have.
        UrdfParseError: a malformed URDF.
    """
    spec = load_spec(spec)
    root, _text, label = _read_root(rigid_urdf)
    root = copy.deepcopy(root)
    for el in list(root):
        if el.tag.startswith(_Q):
            root.remove(el)
    build_pin_model(ET.tostring(root, encoding="unicode"), label)  # validates the rigid URDF
    links = [ln.get("name") for ln in root.findall("link")]
    joints = {j.get("name"): j for j in root.findall("joint")}
    movable = [n for n, j in joints.items() if j.get("type") != "fixed"]

    frame = spec["frame"]
    if frame not in links:
        raise FrameNotFound(frame, links, "spec 'frame' must be a link of the URDF")
    task = _components(spec.get("task", list(COMPONENTS)), "spec 'task'")
    if "name" in spec:
        root.set("name", str(spec["name"]))
    passive, actuators, default_k, positions, subdivide = _check_roles(spec, joints, movable)
    _one_dof_joints(joints)

    tags: list[ET.Element] = [ET.Element(f"{_Q}task", frame=frame, components=" ".join(task))]
    for n in movable:
        tags.append(_role_tag(n, passive, actuators, default_k, positions))

    path_links = {j.find("parent").get("link"): j for j in _path_joints(root, frame)}
    link_specs = spec.get("links") or {}
    if not isinstance(link_specs, dict):
        raise SpecError("spec 'links' must be a mapping link -> spring")
    for link, entry in link_specs.items():
        if link not in links:
            raise FrameNotFound(link, links, "spec 'links'")
        if link not in path_links:
            raise SpecError(
                f"link '{link}' has no child joint on the path to frame '{frame}', so its tip is not defined"
            )
        if not isinstance(entry, dict):
            raise SpecError(f"link '{link}': expected a mapping with 'beam' or 'stiffness'")
        tags += _insert_link_spring(root, joints, links, link, entry, path_links[link], subdivide)

    for t in tags:
        root.append(t)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _check_roles(spec: dict, joints: dict, movable: list):
    """The spec's passive joints, actuator stiffnesses, positions and subdivision, checked."""
    passive = list(spec.get("passive") or [])
    for n in passive:
        if n not in joints:
            raise JointNotFound(n, movable, "spec 'passive'")
        if joints[n].get("type") == "fixed":
            raise SpecError(f"spec 'passive': joint '{n}' is fixed")
    actuators = dict(spec.get("actuators") or {})
    default_k = actuators.pop("default", None)
    for n in actuators:
        if n not in joints:
            raise JointNotFound(n, movable, "spec 'actuators'")
        if n in passive:
            raise SpecError(f"joint '{n}' is both passive and in 'actuators'")
    positions = dict(spec.get("positions") or {})
    for n, v in positions.items():
        if n not in joints or joints[n].get("type") == "fixed":
            raise JointNotFound(n, movable, "spec 'positions'")
        if not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise SpecError(f"spec 'positions': joint '{n}' position must be a finite number, got {v!r}")
    subdivide = spec.get("subdivide", 1)
    if not isinstance(subdivide, int) or subdivide < 1:
        raise SpecError(f"spec 'subdivide' must be a positive integer, got {subdivide!r}")
    return passive, actuators, default_k, positions, subdivide


def _one_dof_joints(joints: dict) -> None:
    """Continuous joints become revolute (wide limits); floating/planar are refused."""
    for n, j in joints.items():
        t = j.get("type")
        if t == "continuous":
            j.set("type", "revolute")
            lim = j.find("limit")
            if lim is None:
                lim = ET.SubElement(j, "limit", effort="0", velocity="0")
            lim.set("lower", _fmt(-1e3))
            lim.set("upper", _fmt(1e3))
        elif t in ("floating", "planar"):
            raise SpecError(
                f"joint '{n}' is {t}: build it from 1-DOF joints (a floating joint is a quaternion "
                "free-flyer in Pinocchio, which the VJM coordinates cannot use)"
            )


def _role_tag(n: str, passive, actuators: dict, default_k, positions: dict) -> ET.Element:
    """The ``<vjm:joint>`` tag of movable joint ``n`` (passive, or actuated with its stiffness)."""
    attrs = {"name": n}
    if n in passive:
        attrs["role"] = "passive"
    else:
        attrs["role"] = "actuated"
        k = actuators.get(n, default_k)
        if k is not None:
            try:
                kf = float(k)
            except (TypeError, ValueError):
                raise SpecError(f"actuator stiffness of '{n}' must be a number, got {k!r}") from None
            if not math.isfinite(kf) or kf <= 0:
                raise SpecError(f"actuator stiffness of '{n}' must be positive, got {k!r}")
            attrs["stiffness"] = _fmt(kf)
    attrs["position"] = _fmt(positions.get(n, 0.0))
    return ET.Element(f"{_Q}joint", attrs)


def _insert_link_spring(root, joints: dict, links: list, link: str, entry: dict, child, subdivide: int):
    """Insert the spring joints of ``link`` (``subdivide`` sub-links for a beam) between the
    link and its child joint on the path; return the ``vjm:`` tags to append."""
    tags: list[ET.Element] = []
    xyz, rpy = _origin(child)
    k_sub = subdivide if "beam" in entry else 1
    full_len = None
    if "beam" in entry and isinstance(entry["beam"], dict) and "length" in entry["beam"]:
        full_len = float(entry["beam"]["length"])
    sub_entry = dict(entry)
    if k_sub > 1:
        b = dict(entry["beam"])
        b["length"] = (full_len if full_len is not None else float(np.linalg.norm(xyz))) / k_sub
        sub_entry["beam"] = b
    k_mat, dofs, rest, beam_dict = link_spring_matrix(sub_entry, link, xyz)
    names = [link if k_sub == 1 else f"{link}_s{s + 1}" for s in range(k_sub)]
    elems, tags, parent = spring_chain(
        names, link, link, dofs, xyz / k_sub, k_mat, rest, beam_dict, k_sub, joints, links, SpecError
    )
    for el in elems:
        root.append(el)
    child.find("parent").set("link", parent)
    _set_origin(child, np.zeros(3), rpy)
    return tags


def spring_chain(names, link: str, parent: str, dofs, tip, k_mat, rest, beam_dict, k_sub, joints, links, error):
    """URDF elements of the spring sub-links ``names`` of ``link`` in series from ``parent``:
    per sub-link one prismatic/revolute joint per spring dof (the first carrying the offset
    ``tip`` of one sub-link) and a ``<vjm:spring>`` tag with ``k_mat``/``rest`` (and the beam
    parameters when given). Used by the generator and by subdivision.

    Returns:
        ``(link and joint elements, vjm tags, last frame)``.

    Raises:
        ``error``: a generated name clashes with a joint or link of the URDF.
    """
    elems: list[ET.Element] = []
    tags: list[ET.Element] = []
    for sname in names:
        jnames = []
        for d_i, dof in enumerate(dofs):
            c = COMPONENTS.index(dof)
            jn = f"{sname}_vjm_{SPRING_SUFFIX[c]}"
            cn = f"{jn}_frame"
            if jn in joints or cn in links:
                raise error(f"generated name '{jn}' clashes with an element of the URDF")
            axis = np.zeros(3)
            axis[c % 3] = 1.0
            je = ET.Element("joint", name=jn, type="prismatic" if c < 3 else "revolute")
            ET.SubElement(je, "parent", link=parent)
            ET.SubElement(je, "child", link=cn)
            ET.SubElement(je, "origin", xyz=_fmt_vec(tip if d_i == 0 else np.zeros(3)), rpy="0 0 0")
            ET.SubElement(je, "axis", xyz=_fmt_vec(axis))
            ET.SubElement(je, "limit", lower=_fmt(-1e3), upper=_fmt(1e3), effort="0", velocity="0")
            elems += [ET.Element("link", name=cn), je]
            tags.append(ET.Element(f"{_Q}joint", name=jn, role="spring"))
            jnames.append(jn)
            parent = cn
        sp = ET.Element(f"{_Q}spring", name=sname, link=link, joints=" ".join(jnames))
        ET.SubElement(sp, f"{_Q}stiffness").text = _fmt_vec(k_mat)
        ET.SubElement(sp, f"{_Q}rest").text = _fmt_vec(rest)
        if beam_dict is not None:
            ET.SubElement(
                sp,
                f"{_Q}beam",
                {k: (v if k == "section" else _fmt(v)) for k, v in beam_dict.items()},
                dofs=" ".join(dofs),
                subdivide=str(k_sub),
            )
        tags.append(sp)
    return elems, tags, parent
