"""Random closed-loop mechanisms for the tests: VJM URDF text written here, every loop closed
exactly at the reference configuration.

Each model is one URDF tree; a loop is cut at a fixed joint whose child is the closure's
``frame_b``. The builder first loads the tree with plain Pinocchio at the chosen joint values
(passive positions, actuator commands, spring rest values), then sets the cut joint's origin to
the placement of ``frame_a`` relative to the cut's parent, so that all six components of the
closure are zero there (to round-off) whatever components the closure holds.

- :func:`planar_loop`: planar four-bar (``n_bars=4``) or five-bar (``n_bars=5``) linkage in the
  x–z plane (joint axes along y), cut at the last ground pivot (``cut="pin"``, closure ``x z``)
  or inside a ground piece behind an extra passive pivot (``cut="rigid"``, closure ``x z ry`` or
  all six: three redundant rows). Springs: the crank actuator (1-D), a coupled 2-D spring
  (axial + bending) in the coupler before the task point, a coupled 3-D spring in the last
  link; the other pivots passive or 1-D springs.
- :func:`spatial_rssr`: a spatial R–S–S–R loop of revolute joints: crank on a random axis, a
  compliant spherical joint (three revolutes with a coupled 3-D spring), a coupler with a
  coupled 6-D spring, and a second branch with a passive revolute on a random axis; the
  loop is closed at the second spherical joint (closure ``x y z``: a perfect spherical joint),
  or (``weld``) that joint is three more revolutes in the tree (passive, or with a coupled 3-D
  spring) and the loop is welded behind it (all six components).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from vjm_pin import load_vjm

NS = "urn:vjm-pin:1"


def _v(a) -> str:
    return " ".join(repr(float(x)) for x in a)


def random_spd(rng, scales) -> np.ndarray:
    """A coupled SPD matrix ``D^½ C D^½`` with the diagonal ``scales`` (units per row) and a
    random correlation ``C`` (eigenvalues 0.3–1.7 of a rotated identity)."""
    n = len(scales)
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    c = q @ np.diag(rng.uniform(0.3, 1.7, n)) @ q.T
    d = np.sqrt(np.asarray(scales, float) / np.diag(c))
    return d[:, None] * c * d[None, :]


class Tree:
    """A URDF tree with VJM roles, springs, closures and a task, written as text."""

    def __init__(self, name: str):
        self.name = name
        self.links: dict[str, tuple[float, tuple]] = {"base": (0.0, (0.0, 0.0, 0.0))}
        self.joints: list[dict] = []
        self.values: dict[str, float] = {}
        self.roles: dict[str, tuple] = {}
        self.springs: list[tuple] = []
        self.closures: list[dict] = []
        self.task: tuple[str, tuple[str, ...]] = ("", ())

    def joint(self, name, kind, parent, child, xyz=(0, 0, 0), rpy=(0, 0, 0), axis=(0, 1, 0), value=0.0, mass=0.0,
              com=(0, 0, 0)):
        self.links.setdefault(child, (float(mass), tuple(com)))
        self.joints.append({"name": name, "kind": kind, "parent": parent, "child": child, "xyz": tuple(xyz),
                            "rpy": tuple(rpy), "axis": tuple(np.asarray(axis, float) / np.linalg.norm(axis))})
        if kind != "fixed":
            self.values[name] = float(value)

    def urdf(self, vjm: bool = True) -> str:
        out = [f'<robot name="{self.name}" xmlns:vjm="{NS}">']
        for ln, (m, com) in self.links.items():
            if m > 0:
                out.append(
                    f'  <link name="{ln}"><inertial><origin xyz="{_v(com)}" rpy="0 0 0"/><mass value="{m!r}"/>'
                    f'<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
                )
            else:
                out.append(f'  <link name="{ln}"/>')
        for j in self.joints:
            body = (f'<parent link="{j["parent"]}"/><child link="{j["child"]}"/>'
                    f'<origin xyz="{_v(j["xyz"])}" rpy="{_v(j["rpy"])}"/>')
            if j["kind"] != "fixed":
                body += f'<axis xyz="{_v(j["axis"])}"/><limit lower="-10" upper="10" effort="0" velocity="0"/>'
            out.append(f'  <joint name="{j["name"]}" type="{j["kind"]}">{body}</joint>')
        if vjm:
            frame, comps = self.task
            out.append(f'  <vjm:task frame="{frame}" components="{" ".join(comps)}"/>')
            for name, role in self.roles.items():
                if role[0] == "actuated":
                    out.append(f'  <vjm:joint name="{name}" role="actuated" position="{self.values[name]!r}" '
                               f'stiffness="{role[1]!r}"/>')
                elif role[0] == "passive":
                    out.append(f'  <vjm:joint name="{name}" role="passive" position="{self.values[name]!r}"/>')
                else:
                    out.append(f'  <vjm:joint name="{name}" role="spring"/>')
            for sname, joints, k in self.springs:
                rest = [self.values[j] for j in joints]
                out.append(f'  <vjm:spring name="{sname}" joints="{" ".join(joints)}">'
                           f"<vjm:stiffness>{_v(np.ravel(k))}</vjm:stiffness><vjm:rest>{_v(rest)}</vjm:rest>"
                           "</vjm:spring>")
            for c in self.closures:
                out.append(f'  <vjm:closure name="{c["name"]}" frame_a="{c["frame_a"]}" frame_b="{c["frame_b"]}" '
                           f'components="{" ".join(c["components"])}"/>')
        out.append("</robot>")
        return "\n".join(out) + "\n"

    def spring(self, name, joints, k):
        for j in joints:
            self.roles[j] = ("spring",)
        self.springs.append((name, tuple(joints), np.asarray(k, float)))

    def close(self, name, frame_a, cut_joint, components):
        """Set the origin of the fixed joint ``cut_joint`` (child: frame b) so that frame b
        coincides with ``frame_a`` at the joint values, and add the closure."""
        model = pin.buildModelFromXML(self.urdf(vjm=False))
        data = model.createData()
        q = np.zeros(model.nq)
        for jn, v in self.values.items():
            q[model.joints[model.getJointId(jn)].idx_q] = v
        pin.framesForwardKinematics(model, data, q)
        cut = next(j for j in self.joints if j["name"] == cut_joint)
        rel = data.oMf[model.getFrameId(cut["parent"])].inverse() * data.oMf[model.getFrameId(frame_a)]
        cut["xyz"] = tuple(rel.translation)
        cut["rpy"] = tuple(pin.rpy.matrixToRpy(rel.rotation))
        self.closures.append({"name": name, "frame_a": frame_a, "frame_b": cut["child"], "components": tuple(components)})


def _angle(rng, lo=0.5, hi=2.2) -> float:
    """A relative joint angle away from 0 and ±π (no folded or stretched link pairs)."""
    return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


def planar_loop(seed: int, n_bars: int = 4, cut: str = "pin", closure=None, n_passive: int = 2,
                task=("x", "z"), masses: bool = True) -> tuple[Tree, object]:
    """A random planar n-bar linkage (module docstring); returns (tree, VjmModel)."""
    rng = np.random.default_rng(seed)
    n = n_bars - 1  # moving links: crank, coupler(s), last link
    closure = closure or (("x", "z") if cut == "pin" else ("x", "z", "ry"))
    t = Tree(f"planar-{n_bars}-bar-{seed}")
    lengths = rng.uniform(0.4, 1.0, n)
    parent, prev_rest = "base", 0.0
    for i in range(n):
        ln, li = f"b{i + 1}", lengths[i]
        xyz = (0.0, 0.0, 0.0) if i == 0 else (float(prev_rest), 0.0, 0.0)
        value = float(rng.uniform(-np.pi, np.pi)) if i == 0 else _angle(rng)
        t.joint(f"r{i + 1}", "revolute", parent, ln, xyz, value=value,
                mass=rng.uniform(0.5, 3.0) if masses else 0.0, com=(0.5 * li, 0.0, 0.0))
        prev_rest = li
        parent = ln
        if i == 1:  # coupler: a coupled 2-D spring (axial x, bending ry) at 0.3 l, task point after it
            t.joint("f2x", "prismatic", ln, "b2m", (0.3 * li, 0.0, 0.0), axis=(1, 0, 0), value=rng.uniform(-1e-3, 1e-3))
            t.joint("f2r", "revolute", "b2m", "b2b", value=rng.uniform(-0.1, 0.1))
            t.spring("coupler_flex", ["f2x", "f2r"], random_spd(rng, [rng.uniform(2e4, 1e5), rng.uniform(200, 1000)]))
            t.joint("tool_joint", "fixed", "b2b", "tool", (rng.uniform(0.05, 0.6) * li, 0.0, rng.uniform(-0.2, 0.2)))
            parent, prev_rest = "b2b", 0.7 * li
        if i == n - 1:  # last link: coupled 3-D spring at mid-length
            t.joint(f"f{i + 1}x", "prismatic", ln, f"b{i + 1}m", (0.5 * li, 0.0, 0.0), axis=(1, 0, 0),
                    value=rng.uniform(-1e-3, 1e-3))
            t.joint(f"f{i + 1}z", "prismatic", f"b{i + 1}m", f"b{i + 1}n", axis=(0, 0, 1), value=rng.uniform(-1e-3, 1e-3))
            t.joint(f"f{i + 1}r", "revolute", f"b{i + 1}n", f"b{i + 1}b", value=rng.uniform(-0.1, 0.1))
            t.spring("last_flex", [f"f{i + 1}x", f"f{i + 1}z", f"f{i + 1}r"],
                     random_spd(rng, [rng.uniform(2e4, 1e5), rng.uniform(2e4, 1e5), rng.uniform(200, 1000)]))
            parent, prev_rest = f"b{i + 1}b", 0.5 * li
    pivots = [f"r{i + 1}" for i in range(1, n)]
    if cut == "rigid":
        t.joint("rg", "revolute", parent, "ground_piece", (float(prev_rest), 0.0, 0.0), value=_angle(rng))
        t.joint("foot_joint", "fixed", "ground_piece", "foot", (0.2, 0.0, 0.0))
        pivots.append("rg")
    else:
        t.joint("foot_joint", "fixed", parent, "foot", (float(prev_rest), 0.0, 0.0))
    t.joint("anchor_joint", "fixed", "base", "anchor")
    t.roles["r1"] = ("actuated", float(rng.uniform(50, 300)))
    passive = list(rng.choice(pivots, size=min(n_passive, len(pivots)), replace=False))
    if cut == "rigid" and "rg" not in passive:
        passive[-1] = "rg"
    for j in pivots:
        if j in passive:
            t.roles[j] = ("passive",)
        else:
            t.spring(f"{j}_spring", [j], [[rng.uniform(50, 300)]])
    t.task = ("tool", tuple(task))
    t.close("loop", "foot", "anchor_joint", closure)
    return t, load_vjm(t.urdf())


def _six_spring(t, rng, name, parent, child, offset, m):
    """A coupled 6-D spring (three prismatic, three revolute joints) from ``parent`` at ``offset``."""
    names = []
    kinds = [("prismatic", (1, 0, 0)), ("prismatic", (0, 1, 0)), ("prismatic", (0, 0, 1)),
             ("revolute", (1, 0, 0)), ("revolute", (0, 1, 0)), ("revolute", (0, 0, 1))]
    for k, (kind, axis) in enumerate(kinds):
        small = 1e-3 if kind == "prismatic" else 0.05
        nxt = child if k == 5 else f"{name}{k}"
        t.joint(f"{name}_{k}", kind, parent, nxt, offset if k == 0 else (0, 0, 0), axis=axis,
                value=rng.uniform(-small, small), mass=m if k == 5 else 0.0, com=(0.2, 0, 0))
        names.append(f"{name}_{k}")
        parent = nxt
    t.spring(name, names, random_spd(rng, [*rng.uniform(5e4, 2e5, 3), *rng.uniform(300, 2000, 3)]))


def spatial_rssr(seed: int, weld: bool = False, task=("x", "y", "z"), masses: bool = True, passive_ball: bool = True,
                 tool_on_coupler_root: bool = False):
    """A random spatial R–S–S–R loop (module docstring); returns (tree, VjmModel).
    ``tool_on_coupler_root``: the task frame before the coupler spring, with a coupled 6-D
    spring in the crank (so that the springs alone move it in six directions)."""
    rng = np.random.default_rng(seed)
    t = Tree(f"rssr-{seed}")
    l1, l2 = rng.uniform(0.3, 0.6), rng.uniform(0.6, 1.0)
    m = (lambda: rng.uniform(0.5, 2.0)) if masses else (lambda: 0.0)
    t.joint("ra", "revolute", "base", "link1", axis=rng.standard_normal(3), value=rng.uniform(-np.pi, np.pi),
            mass=m(), com=(0.5 * l1, 0, 0))
    crank = "link1"
    if tool_on_coupler_root:
        _six_spring(t, rng, "crank_flex", "link1", "link1b", (0.5 * l1, 0, 0), m())
        crank, l1 = "link1b", 0.5 * l1
    t.joint("sb1", "revolute", crank, "s1", (l1, 0, 0), axis=(1, 0, 0), value=rng.uniform(-0.5, 0.5))
    t.joint("sb2", "revolute", "s1", "s2", axis=(0, 1, 0), value=rng.uniform(-0.5, 0.5))
    t.joint("sb3", "revolute", "s2", "link2", axis=(0, 0, 1), value=rng.uniform(-0.5, 0.5), mass=m(),
            com=(0.3 * l2, 0, 0))
    t.spring("ball_b", ["sb1", "sb2", "sb3"], random_spd(rng, rng.uniform(100, 500, 3)))
    _six_spring(t, rng, "coupler", "link2", "link2b", (0.4 * l2, 0, 0), m())
    xyz = (rng.uniform(0.0, 0.4) * l2, *rng.uniform(-0.1, 0.1, 2))
    t.joint("tool_joint", "fixed", "link2" if tool_on_coupler_root else "link2b", "tool", xyz)
    if weld:  # the second spherical joint in the tree (three revolutes), the loop welded behind it
        for k, axis in enumerate([(1, 0, 0), (0, 1, 0), (0, 0, 1)]):
            t.joint(f"sc{k + 1}", "revolute", "link2b" if k == 0 else f"t{k}", "link2c" if k == 2 else f"t{k + 1}",
                    (0.6 * l2, 0, 0) if k == 0 else (0, 0, 0), axis=axis, value=rng.uniform(-0.5, 0.5))
        if passive_ball:
            for k in range(3):
                t.roles[f"sc{k + 1}"] = ("passive",)
        else:
            t.spring("ball_c", ["sc1", "sc2", "sc3"], random_spd(rng, rng.uniform(100, 500, 3)))
        t.joint("ca_joint", "fixed", "link2c", "c_a")
    else:
        t.joint("ca_joint", "fixed", "link2b", "c_a", (0.6 * l2, 0, 0))
    d = np.array([rng.uniform(0.6, 1.0), rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4)])
    t.joint("rd", "revolute", "base", "link3", d, rng.uniform(-1, 1, 3), axis=rng.standard_normal(3),
            value=rng.uniform(-np.pi, np.pi), mass=m(), com=(0.2, 0, 0))
    t.joint("cb_joint", "fixed", "link3", "c_b")
    t.roles["ra"] = ("actuated", float(rng.uniform(100, 500)))
    t.roles["rd"] = ("passive",)
    t.task = ("tool", tuple(task))
    t.close("loop_c", "c_a", "cb_joint", ("x", "y", "z", "rx", "ry", "rz") if weld else ("x", "y", "z"))
    return t, load_vjm(t.urdf())


def planar_frames(vm) -> list[str]:
    """Frames of a planar model that can carry loads (its links)."""
    return [f.name for f in vm.model.frames if f.type == pin.FrameType.BODY and f.name not in ("base", "anchor")]
