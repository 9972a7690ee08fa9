"""The legs of a parallel model as serial chains (model layer).

A model written with the ``<vjm:leg>``/``<vjm:platform>`` shorthand loads as one mechanism
(:func:`~vjm_pin.model.format.load_vjm`: the platform is the task frame on the first leg,
every other leg is held on it by a closure). :func:`split_legs` gives each leg alone as a
serial :class:`~vjm_pin.model.format.VjmModel`: the joints on the path from the root to the
leg's link, its role and spring tags, the closures inside the leg, and a fixed joint to a link
``<leg>__platform`` placed exactly as the mechanism's frame of that name (the platform point,
world-aligned at the file's reference configuration) as the task frame, in the platform's
components. With no cross-links (every joint on some leg, no spring or closure spanning two
legs) the mechanism's loaded stiffness is the sum of the legs' (paper §5, ``K_C = Σ K_C⁽ⁱ⁾``),
each leg solved at the same platform location.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from pathlib import Path

from vjm_pin.exceptions import ModelError
from vjm_pin.model.format import COMPONENTS, NS, Leg, VjmModel, load_vjm
from vjm_pin.model.generator import _path_joints

_Q = f"{{{NS}}}"


def _leg_text(root: ET.Element, vm: VjmModel, leg: Leg) -> str:
    """URDF text of one leg (path joints, its links, offset link, its VJM tags)."""
    import pinocchio as pin

    path = _path_joints(root, leg.frame)
    names = set(leg.joints)
    keep_links = {j.find("child").get("link") for j in path}
    keep_links |= {j.find("parent").get("link") for j in path[:1]} if path else {leg.frame}
    out = ET.Element("robot", {"name": f"{vm.name}__{leg.name}"})
    for el in root.findall("link"):
        if el.get("name") in keep_links:
            out.append(copy.deepcopy(el))
    for j in path:
        out.append(copy.deepcopy(j))
    # the platform link placed as the mechanism's frame <leg>__platform relative to the leg's link
    model = vm.model
    link_m = model.frames[model.getFrameId(leg.frame)].placement
    plat_m = model.frames[model.getFrameId(leg.platform_frame)].placement
    rel = link_m.inverse() * plat_m
    ET.SubElement(out, "link", {"name": leg.platform_frame})
    pj = ET.SubElement(out, "joint", {"name": f"{leg.platform_frame}_joint", "type": "fixed"})
    ET.SubElement(pj, "parent", {"link": leg.frame})
    ET.SubElement(pj, "child", {"link": leg.platform_frame})
    xyz = " ".join(repr(float(v)) for v in rel.translation)
    rpy = " ".join(repr(float(v)) for v in pin.rpy.matrixToRpy(rel.rotation))
    ET.SubElement(pj, "origin", {"xyz": xyz, "rpy": rpy})
    comps = " ".join(COMPONENTS[i] for i in vm.task)
    ET.SubElement(out, f"{_Q}task", {"frame": leg.platform_frame, "components": comps})
    for el in root.findall(f"{_Q}joint"):
        if el.get("name") in names:
            out.append(copy.deepcopy(el))
    for el in root.findall(f"{_Q}spring"):
        js = (el.get("joints") or "").split()
        inside = [jn in names for jn in js]
        if js and all(inside):
            out.append(copy.deepcopy(el))
        elif any(inside):
            raise ModelError(
                f"spring '{el.get('name')}' is split between leg '{leg.name}' and another part of the model"
            )
    for el in root.findall(f"{_Q}closure"):
        ends = [el.get("frame_a"), el.get("frame_b")]
        inside = [_frame_link(model, f) in keep_links for f in ends]
        if all(inside):
            out.append(copy.deepcopy(el))
        elif any(inside):
            raise ModelError(
                f"closure '{el.get('name')}' links leg '{leg.name}' with another part of the model (a cross-link): "
                "the legs cannot be split"
            )
    return ET.tostring(out, encoding="unicode")


def _frame_link(model, frame: str) -> str:
    """The link a Pinocchio frame belongs to (itself for a link; the parent link of a URDF
    frame on a fixed joint)."""
    import pinocchio as pin

    fid = int(model.getFrameId(frame))
    for _ in range(model.nframes):
        f = model.frames[fid]
        if f.type == pin.FrameType.BODY or fid == 0:
            break
        fid = int(f.parentFrame)
    return model.frames[fid].name


def split_legs(model: VjmModel | str | Path) -> dict[str, VjmModel]:
    """Each leg of a ``<vjm:leg>`` model as a serial model (module docstring).

    Args:
        model: A :class:`~vjm_pin.model.format.VjmModel` from :func:`load_vjm`, or a URDF path
            or text. The legs' actuated and passive joints take the model's reference values
            (:meth:`~vjm_pin.model.format.VjmModel.with_positions`).

    Returns:
        Leg name → its :class:`VjmModel` (task frame ``<leg>__platform``, the platform
        components), file order.

    Raises:
        ModelError: the model has no legs, a joint is on no leg, or a spring or a closure spans a
            leg and another part of the model.
    """
    vm = model if isinstance(model, VjmModel) else load_vjm(model)
    if not vm.legs:
        raise ModelError(
            f"model '{vm.name}' is not a parallel model: no <vjm:leg name=... frame=... offset=.../> element"
        )
    root = ET.fromstring(vm.urdf)
    used = {j for lg in vm.legs for j in lg.joints}
    orphans = [j for j in vm.joint_names if j not in used]
    if orphans:
        raise ModelError(
            f"model '{vm.name}': joint(s) {orphans} belong to no leg (every joint must be on a leg's path)"
        )
    out = {}
    for leg in vm.legs:
        lv = load_vjm(_leg_text(root, vm, leg))
        pos = {
            j: float(vm.reference[vm.joint_index(j)])
            for j in lv.joint_names
            if lv.roles[j] != "spring"
        }
        out[leg.name] = lv.with_positions(pos) if pos else lv
    return out


__all__ = ["split_legs"]
