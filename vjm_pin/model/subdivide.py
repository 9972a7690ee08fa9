"""Link subdivision of a VJM URDF (beyond the paper).

A link spring derived from beam parameters (a ``<vjm:beam>`` element inside its
``<vjm:spring>``) lumps the whole flexibility of the link into one tip spring (the
cantilever tip stiffness, :mod:`vjm_pin.model.beam`). :func:`subdivide_vjm` splits each such
link into ``k`` sub-links of length L/k along the original tip vector, each ending in its
own spring: the tip stiffness of a beam of length L/k, restricted to the same degrees of
freedom. As k grows the VJM chain converges to the continuous beam (e.g. Euler's column
load π²EI/(ℓL)² for buckling). The generator's ``subdivide`` spec key produces the same
model from a rigid URDF; this works on any VJM URDF that kept its beam parameters.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import ModelError, SpecError
from vjm_pin.model.format import COMPONENTS, NS, _read_root, load_vjm
from vjm_pin.model.generator import link_spring_matrix, spring_chain

_Q = f"{{{NS}}}"


def _fmt(v: float) -> str:
    return repr(float(v))


def _fmt_vec(v) -> str:
    return " ".join(_fmt(x) for x in np.asarray(v, dtype=float).ravel())


def _beam_entry(beam_el: ET.Element, spring: str) -> tuple[dict, list[str], int]:
    attrs = dict(beam_el.attrib)
    dofs = attrs.pop("dofs", " ".join(COMPONENTS)).split()
    done = int(float(attrs.pop("subdivide", "1")))
    beam = {k: (v if k == "section" else float(v)) for k, v in attrs.items()}
    if "length" not in beam:
        raise ModelError(f"spring '{spring}': <vjm:beam> has no 'length'")
    return beam, dofs, done


def _subdivide_spring(root, sp, k, joints, links, role_tags) -> None:
    """Replace the lumped beam spring ``sp`` of ``root`` (in place) by a chain of ``k``
    sub-springs of length ``L/k``, re-attaching the joints downstream of it."""
    name = sp.get("name")
    beam, dofs, done = _beam_entry(sp.find(f"{_Q}beam"), name)
    if done != 1:
        raise ModelError(
            f"spring '{name}' was already subdivided ({done} sub-links); subdivide the original model"
        )
    rest = np.array([float(v) for v in (sp.findtext(f"{_Q}rest") or "").split()] or [0.0])
    if np.any(rest != 0):
        raise ModelError(
            f"spring '{name}' has a preload (non-zero rest): subdivision would not preserve it"
        )
    jnames = sp.get("joints").split()
    first = joints[jnames[0]]
    parent = first.find("parent").get("link")
    o = first.find("origin")
    tip = np.array([float(v) for v in (o.get("xyz") if o is not None else "0 0 0").split()])
    if np.linalg.norm(tip) < 1e-12:
        raise ModelError(
            f"spring '{name}': the beam tip coincides with the link origin; cannot subdivide"
        )
    last_frame = joints[jnames[-1]].find("child").get("link")
    downstream = [
        j for j in root.findall("joint") if j.find("parent").get("link") == last_frame
    ]
    # remove the lumped spring
    for jn in jnames:
        child = joints[jn].find("child").get("link")
        root.remove(joints[jn])
        root.remove(links[child])
        root.remove(role_tags[jn])
    pos = list(root).index(sp)
    root.remove(sp)
    sub_beam = dict(beam, length=beam["length"] / k)
    kmat, dofs_out, rest_out, beam_dict = link_spring_matrix(
        {"beam": sub_beam, "dofs": dofs}, name, tip / k
    )
    new_elems, tags, parent = spring_chain(
        [f"{name}_s{s + 1}" for s in range(k)], sp.get("link"), parent, dofs_out, tip / k,
        kmat, rest_out, beam_dict, k, joints, links, ModelError,
    )
    for j in downstream:
        j.find("parent").set("link", parent)
    for i, el in enumerate(tags):
        root.insert(pos + i, el)
    for el in new_elems:
        root.append(el)


def subdivide_vjm(source: str | Path, k: int) -> str:
    """VJM URDF text with every beam link split into ``k`` sub-links.

    Args:
        source: VJM URDF path or text whose link springs carry ``<vjm:beam>`` parameters.
        k: Number of sub-links per beam link (≥ 1; 1 returns an equivalent model).

    Raises:
        SpecError: ``k`` is not a positive integer.
        ModelError: no spring has beam parameters, a beam link was already subdivided, or
            a beam spring has a preload (non-zero rest).
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise SpecError(f"subdivide must be a positive integer, got {k!r}")
    k = int(k)
    root, text, label = _read_root(source)
    load_vjm(text)  # validates the input (numbers, roles, matrices) before it is taken apart
    root = copy.deepcopy(root)
    springs = [el for el in root.findall(f"{_Q}spring") if el.find(f"{_Q}beam") is not None]
    if not springs:
        raise ModelError(
            f"{label}: no link spring carries <vjm:beam> parameters, so there is nothing to subdivide "
            "(generate the model from beam parameters to keep them)"
        )
    if k == 1:
        return ET.tostring(root, encoding="unicode") + "\n"
    joints = {j.get("name"): j for j in root.findall("joint")}
    links = {ln.get("name"): ln for ln in root.findall("link")}
    role_tags = {t.get("name"): t for t in root.findall(f"{_Q}joint")}
    for sp in springs:
        _subdivide_spring(root, sp, k, joints, links, role_tags)
    # keep robot elements before the vjm tags (cosmetic; URDF order does not matter)
    robot = [el for el in root if not el.tag.startswith(_Q)]
    vjm = [el for el in root if el.tag.startswith(_Q)]
    for el in list(root):
        root.remove(el)
    for el in robot + vjm:
        root.append(el)
    ET.indent(root, space="  ")
    text = ET.tostring(root, encoding="unicode") + "\n"
    load_vjm(text)  # validates the result
    return text


def subdivide_model(vm_source: str | Path, k: int):
    """:func:`subdivide_vjm` then :func:`~vjm_pin.model.format.load_vjm`."""
    return load_vjm(subdivide_vjm(vm_source, k))
