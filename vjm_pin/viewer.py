"""Meshcat scenes and animations of loaded robots (knows nothing about the solver).

Everything here works on plain Pinocchio objects: a :class:`pinocchio.Model`, a
:class:`pinocchio.GeometryModel` (the robot's own visual model, or primitives from
:func:`chain_geometry`) and a list of configuration vectors.

Scene layout (meshcat paths, all under ``/meshcat/vjm``)
-------------------------------------------------------
``robot/<geometry>``
    The animated, solid robot: one node per geometry object. Its transform is animated
    (position + quaternion tracks); the mesh itself is the child ``<object>``, which holds a
    static intrinsic transform (mesh scale, Y→Z axis fix of three.js cylinders/cones).
``ghost/<geometry>``
    A semi-transparent copy of the robot at a fixed configuration (e.g. the unloaded one).
``force``
    An arrow (shaft + cone head) at the end frame, along the applied force, whose length is
    proportional to the force magnitude of the current frame; hidden when the force is zero.
``critical``
    A sphere at the end-frame position of the critical (first unstable / bifurcation) frame.

Per-frame stability colour
--------------------------
three.js animations can drive any property reachable from the animated object, and the
meshcat viewer (``Animator.load``) binds each clip to the object at its path. Each robot
mesh is therefore given a ``ColorKeyframeTrack`` named ``.material.color``, bound to the
mesh node ``robot/<geometry>/<object>``: the material colour is animated like a position.
Colours are keyed at every stability change with a second key 1e-3 frame earlier that holds
the previous colour, so the switch is sharp instead of a blend between two frames. Every
track also has keys at the first and the last frame so that all clips have the same duration
(clips loop independently in three.js). Joint markers made by :func:`chain_geometry` (names
starting with ``"joint:"``) keep their role colour; every other geometry is recoloured.
(Toggling the ``visible`` flag of two robot copies would also work, with twice the
geometry; the force arrow uses such a ``visible`` boolean track to hide zero forces.)

Animation time control in the exported page
--------------------------------------------
:func:`export_html` writes its own page around meshcat's bundled viewer
(``meshcat/viewer/dist/main.min.js``, inlined, so the page works offline) instead of asking a
meshcat server for ``Visualizer.static_html()``: the same commands are replayed, but
decoded synchronously and in order (the server's page ``fetch``-es each command
asynchronously), so no server process is needed and a script can act after the scene is
complete. That script

- shows an overlay (top left) with the title and the label of the current frame
  (``frame_labels`` or: frame number, force magnitude in N, stable / UNSTABLE);
- reads the URL fragment: ``page.html#frame=12`` (frame index, may be fractional) or
  ``page.html#t=1.2`` (seconds) pauses the player at that time; ``hashchange`` works too;
- exposes ``window.vjmSeekFrame(k)`` and ``window.vjmSeekTime(t)`` for scripting.

Without a fragment the animation plays in a loop; meshcat's own controls ("Open Controls" →
Animations: play/pause/reset, time slider, time scale) are there as usual.

Camera
------
meshcat's orbit controls always look at the world origin, and commands cannot reach their
target. So the scene is moved instead: ``/meshcat/vjm``, ``/Grid`` and ``/Axes`` are translated
by minus the centre of the bounding box of all joint origins, end-frame positions and arrow
tips over all frames. The camera (40° field of view) is put along ``camera_direction`` at a
distance that fits that box.

Live server
-----------
:func:`serve` sends the same commands to a meshcat server. The server replays its scene tree
to each browser that connects, root first. An animation stored at the root would arrive
before the meshes it binds to, so the animation command is filed under
``/meshcat/vjm/animation`` instead. That node is replayed after the robot. The served page
is meshcat's own, so it has no overlay and no ``#frame=`` control.
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import json
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .exceptions import FrameNotFound, InputError, JointNotFound, RoleError

__all__ = [
    "CRITICAL_COLOR",
    "FORCE_COLOR",
    "GHOST_COLOR",
    "JOINT_MARKER_PREFIX",
    "LINK_COLOR",
    "STABLE_COLOR",
    "STYLE_COLORS",
    "UNSTABLE_COLOR",
    "Animation",
    "chain_geometry",
    "default_scale",
    "export_html",
    "magnify",
    "serve",
]

# ----------------------------------------------------------------------------- colours (RGBA)
STYLE_COLORS: dict[str, tuple[float, float, float, float]] = {
    "passive": (1.0, 0.55, 0.0, 1.0),  # orange
    "spring": (0.0, 0.72, 0.85, 1.0),  # cyan
    "actuated": (0.15, 0.3, 0.85, 1.0),  # blue
    "locked": (0.3, 0.3, 0.3, 1.0),  # dark grey
}
"""Joint marker colour per joint style."""
STYLE_PRIORITY: tuple[str, ...] = ("passive", "actuated", "locked", "spring")
"""Which style a marker shows when several joints are stacked at one point (first wins)."""
LINK_COLOR = (0.78, 0.78, 0.8, 1.0)
"""Link segments of :func:`chain_geometry` (light grey)."""
SPRING_HALO_ALPHA = 0.35
STABLE_COLOR = (0.25, 0.75, 0.35, 1.0)
"""Robot colour on stable frames (green)."""
UNSTABLE_COLOR = (0.9, 0.1, 0.1, 1.0)
"""Robot colour on unstable frames (red)."""
GHOST_COLOR = (0.65, 0.67, 0.75, 0.3)
"""The ghost robot (translucent grey-blue)."""
FORCE_COLOR = (1.0, 0.85, 0.0, 1.0)
"""The force arrow (yellow)."""
CRITICAL_COLOR = (0.9, 0.0, 0.9, 0.75)
"""The critical-frame marker (translucent magenta)."""

JOINT_MARKER_PREFIX = "joint:"
"""Geometry objects whose name starts with this keep their colour in stability colouring."""
LINK_PREFIX = "link:"

_TOL = 1e-9
_CAMERA_FOV = 40.0  # (deg) vertical field of view of the camera
_EPS_FRAME = 1e-3  # (frames) offset of the key that holds the old colour before a change


# ============================================================================ chain geometry
def chain_geometry(
    model: pin.Model,
    styles: Mapping[str, str],
    *,
    link_radius: float | None = None,
    link_shape: str = "cylinder",
    default_style: str = "actuated",
) -> pin.GeometryModel:
    """Primitive visual geometry for a generated chain.

    One cylinder (or square box) per link segment, from each joint origin to the origin of
    each child joint; a leaf joint gets segments to the (distinct) points of the frames it
    carries (the tool / task frame). Zero-length segments are skipped, which happens for
    massless virtual-spring frames stacked at one point. One sphere per joint location:
    joints stacked at one point (e.g. the six spring joints of a link spring and the next
    actuated joint) share one sphere coloured by the most important style among them
    (:data:`STYLE_PRIORITY`: passive > actuated > locked > spring); if spring joints are
    hidden that way, a translucent spring-coloured halo surrounds the sphere.

    Parameters
    ----------
    model
        The kinematic model.
    styles
        Joint name → ``"passive"``, ``"spring"``, ``"actuated"`` or ``"locked"`` (marker
        colours: :data:`STYLE_COLORS`). Joints not named get ``default_style``.
    link_radius
        Radius (half width for boxes) of the link segments, m. Default: 6 % of the median
        segment length. Joint spheres have 1.7 times this radius.
    link_shape
        ``"cylinder"`` or ``"box"``.
    default_style
        Style of joints missing from ``styles``.

    Returns
    -------
    pinocchio.GeometryModel
        Link objects are named ``"link:<joint>-><joint or frame>"``, joint markers
        ``"joint:<joint>"`` (and ``"joint:<joint>:springs"`` for a halo); colours are in
        ``meshColor``.

    Raises
    ------
    JointNotFound
        A key of ``styles`` is not a joint of ``model``.
    RoleError
        A style is not one of the four above, or ``link_shape`` is unknown.
    """
    import coal

    names = list(model.names)
    for jn, st in styles.items():
        if jn not in names[1:]:
            raise JointNotFound(jn, names[1:], "chain_geometry styles")
        if st not in STYLE_COLORS:
            raise RoleError(f"joint '{jn}': style '{st}' is not one of {', '.join(STYLE_COLORS)}")
    if default_style not in STYLE_COLORS:
        raise RoleError(f"default_style '{default_style}' is not one of {', '.join(STYLE_COLORS)}")
    if link_shape not in ("cylinder", "box"):
        raise RoleError(f"link_shape '{link_shape}' is not 'cylinder' or 'box'")

    nj = model.njoints
    children: list[list[int]] = [[] for _ in range(nj)]
    for j in range(1, nj):
        children[model.parents[j]].append(j)

    # --- segments: (parent joint, end point in the parent joint frame, label)
    segments: list[tuple[int, np.ndarray, str]] = []
    for j in range(1, nj):
        t = np.array(model.jointPlacements[j].translation)
        if np.linalg.norm(t) > _TOL:
            p = model.parents[j]
            segments.append((p, t, f"{names[p]}->{names[j]}"))
    for j in range(1, nj):
        if children[j]:
            continue
        points: list[np.ndarray] = []
        for f in model.frames:
            if f.parentJoint != j or f.type == pin.FrameType.JOINT:
                continue
            t = np.array(f.placement.translation)
            if np.linalg.norm(t) <= _TOL or any(np.linalg.norm(t - p) <= 1e-6 for p in points):
                continue
            points.append(t)
            segments.append((j, t, f"{names[j]}->{f.name}"))

    if link_radius is None:
        lengths = [float(np.linalg.norm(t)) for _, t, _ in segments]
        link_radius = 0.06 * float(np.median(lengths)) if lengths else 0.02
    r_link = max(float(link_radius), 1e-6)
    r_joint = 1.7 * r_link

    gmodel = pin.GeometryModel()

    def joint_frame(j: int) -> int:
        if j == 0:
            return 0
        return int(model.getFrameId(names[j], pin.FrameType.JOINT))

    ez = np.array([0.0, 0.0, 1.0])
    for parent, t, label in segments:
        length = float(np.linalg.norm(t))
        rot = pin.Quaternion.FromTwoVectors(ez, t / length).toRotationMatrix()
        placement = pin.SE3(rot, 0.5 * t)
        if link_shape == "cylinder":
            shape = coal.Cylinder(r_link, length)
        else:
            shape = coal.Box(2 * r_link, 2 * r_link, length)
        go = pin.GeometryObject(LINK_PREFIX + label, parent, joint_frame(parent), placement, shape)
        go.meshColor = np.array(LINK_COLOR)
        gmodel.addGeometryObject(go)

    # --- joint markers, one per stack of co-located joints
    stack_of = [-1] * nj
    stacks: list[list[int]] = []
    for j in range(1, nj):
        p = model.parents[j]
        if p != 0 and np.linalg.norm(model.jointPlacements[j].translation) <= _TOL:
            stack_of[j] = stack_of[p]
            stacks[stack_of[j]].append(j)
        else:
            stack_of[j] = len(stacks)
            stacks.append([j])
    for members in stacks:
        member_styles = {j: styles.get(names[j], default_style) for j in members}
        main = min(member_styles.values(), key=STYLE_PRIORITY.index)
        main_joint = next(j for j in members if member_styles[j] == main)
        attach = max(members)  # deepest joint of the stack: carries the next segment
        go = pin.GeometryObject(
            JOINT_MARKER_PREFIX + names[main_joint],
            attach,
            joint_frame(attach),
            pin.SE3.Identity(),
            coal.Sphere(r_joint),
        )
        go.meshColor = np.array(STYLE_COLORS[main])
        gmodel.addGeometryObject(go)
        if main != "spring" and "spring" in member_styles.values():
            halo = pin.GeometryObject(
                JOINT_MARKER_PREFIX + names[main_joint] + ":springs",
                attach,
                joint_frame(attach),
                pin.SE3.Identity(),
                coal.Sphere(1.35 * r_joint),
            )
            halo.meshColor = np.array(STYLE_COLORS["spring"][:3] + (SPRING_HALO_ALPHA,))
            gmodel.addGeometryObject(halo)
    return gmodel


# ============================================================================ meshcat helpers
def _import_meshcat() -> None:
    """Import meshcat without its import-time DeprecationWarning (zmq.eventloop.ioloop)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat  # noqa: F401


def _rgb_int(rgba: Sequence[float]) -> int:
    r, g, b = (round(255 * min(max(float(c), 0.0), 1.0)) for c in rgba[:3])
    return (r << 16) + (g << 8) + b


def _material(rgba: Sequence[float]):
    import meshcat.geometry as mg

    alpha = float(rgba[3]) if len(rgba) > 3 else 1.0
    if alpha < 1.0:
        # depthWrite off: translucent objects do not hide what is behind them; polygon
        # offset: where a translucent surface coincides with a solid one (the ghost at the
        # pose of the animated robot) the solid one wins instead of z-fighting stripes
        return mg.MeshPhongMaterial(
            color=_rgb_int(rgba),
            opacity=alpha,
            transparent=True,
            depthWrite=False,
            polygonOffset=True,
            polygonOffsetFactor=1.0,
            polygonOffsetUnits=4.0,
        )
    return mg.MeshPhongMaterial(color=_rgb_int(rgba))


_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


def _meshcat_geometry(go: pin.GeometryObject) -> tuple[Any, np.ndarray] | None:
    """Meshcat geometry of a Pinocchio geometry object and its intrinsic 4×4 transform
    (mesh scale, axis fix), or None (with a warning) if it cannot be shown."""
    import coal
    import meshcat.geometry as mg

    geom = go.geometry
    scale = np.diag(np.r_[np.asarray(go.meshScale, dtype=float).ravel(), 1.0])
    obj = None
    intrinsic = np.eye(4)
    mesh_path = str(go.meshPath)
    ext = Path(mesh_path).suffix.lower() if mesh_path else ""
    try:
        if isinstance(geom, coal.Capsule):
            from pinocchio.visualize.meshcat_visualizer import createCapsule

            obj = createCapsule(2.0 * geom.halfLength, geom.radius)
        elif isinstance(geom, coal.Cylinder):
            obj, intrinsic = mg.Cylinder(2.0 * geom.halfLength, geom.radius), _Y_TO_Z
        elif isinstance(geom, coal.Cone):
            obj = mg.Cylinder(2.0 * geom.halfLength, radiusTop=0.0, radiusBottom=geom.radius)
            intrinsic = _Y_TO_Z
        elif isinstance(geom, coal.Box):
            obj = mg.Box([float(x) for x in 2.0 * np.asarray(geom.halfSide)])
        elif isinstance(geom, coal.Sphere):
            obj = mg.Sphere(geom.radius)
        elif isinstance(geom, coal.Ellipsoid):
            obj = mg.Sphere(1.0)
            intrinsic = np.diag(np.r_[np.asarray(geom.radii, dtype=float), 1.0])
        elif ext in (".dae", ".obj", ".stl") and os.path.isfile(mesh_path):
            # as geometry (not "_meshfile_object") so that one Phong material, whose colour
            # can be animated, applies to the whole mesh
            cls = {
                ".dae": mg.DaeMeshGeometry,
                ".obj": mg.ObjMeshGeometry,
                ".stl": mg.StlMeshGeometry,
            }[ext]
            obj = cls.from_file(mesh_path)
        elif isinstance(geom, (coal.BVHModelBase, coal.ConvexBase)):
            from pinocchio.visualize.meshcat_visualizer import loadMesh

            obj = loadMesh(geom)
    except Exception as exc:  # noqa: BLE001 - a broken mesh must not stop the rest of the scene
        warnings.warn(f"geometry '{go.name}' not shown: {exc}", stacklevel=3)
        return None
    if obj is None:
        warnings.warn(
            f"geometry '{go.name}' ({type(geom).__name__}) not shown: unsupported", stacklevel=3
        )
        return None
    return obj, scale @ intrinsic


def _node_names(gmodel: pin.GeometryModel) -> list[str]:
    out: list[str] = []
    seen: set[str] = set()
    for go in gmodel.geometryObjects:
        base = go.name.replace("/", "_") or "geom"
        name, i = base, 1
        while name in seen:
            i += 1
            name = f"{base}_{i}"
        seen.add(name)
        out.append(name)
    return out


def _translation(p: Sequence[float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = np.asarray(p, dtype=float)
    return m


# ============================================================================ the animation
class Animation:
    """A meshcat scene with an animated robot, built from plain Pinocchio objects.

    Parameters
    ----------
    model
        Kinematic model.
    visual_model
        Geometry to show (the robot's visual model, or :func:`chain_geometry`).
    frames
        Configurations to animate, each an (nq,) vector (m, rad).
    ghost_q
        (nq,) configuration of the translucent ghost robot, or None for no ghost.
    stable
        Per-frame stability (colour :data:`STABLE_COLOR` / :data:`UNSTABLE_COLOR`), or None
        to keep the geometry colours.
    forces
        Per-frame force at ``frame_name``, each a 3-vector in world axes (N) (a 6-vector is
        read as a wrench, linear part first), or None for no arrow.
    frame_name
        End frame: where the force arrow starts and the critical marker sits. Required with
        ``forces`` or ``critical_index``.
    critical_index
        Index into ``frames`` of the critical frame, or None.
    fps
        Playback rate, frames per second.
    title_text
        Title shown in the page (and its ``<title>``).
    frame_labels
        One overlay text per frame, or None for an automatic one.
    arrow_length
        Length of the arrow for the largest force magnitude, m. Default: 30 % of the size of
        the robot's bounding box over all frames.
    camera_direction
        Direction from the look-at point to the camera, world axes (any length).
    recolor
        Predicate on geometry-object names: which objects take the stability colour.
        Default: all but the joint markers of :func:`chain_geometry`.
    loop
        Play the animation in a loop (else once, then back to the start).

    Raises
    ------
    InputError
        Wrong sizes, non-finite values, an index out of range, ``fps <= 0``.
    FrameNotFound
        ``frame_name`` is not a frame of the model.
    """

    def __init__(
        self,
        model: pin.Model,
        visual_model: pin.GeometryModel,
        frames: Sequence[np.ndarray],
        *,
        ghost_q: np.ndarray | None = None,
        stable: Sequence[bool] | None = None,
        forces: Sequence[np.ndarray] | None = None,
        frame_name: str | None = None,
        critical_index: int | None = None,
        fps: float = 10.0,
        title_text: str = "",
        frame_labels: Sequence[str] | None = None,
        arrow_length: float | None = None,
        camera_direction: Sequence[float] = (0.45, -1.0, 0.45),
        recolor: Callable[[str], bool] | None = None,
        loop: bool = True,
    ) -> None:
        self.model = model
        self.visual_model = visual_model
        self.frames = [self._check_q(q, f"frames[{k}]") for k, q in enumerate(frames)]
        n = len(self.frames)
        if n == 0:
            raise InputError("frames is empty: at least one configuration is needed")
        self.ghost_q = None if ghost_q is None else self._check_q(ghost_q, "ghost_q")
        if stable is not None:
            stable = [bool(s) for s in stable]
            if len(stable) != n:
                raise InputError(f"stable has {len(stable)} entries, expected {n} (one per frame)")
        self.stable = stable
        if forces is not None:
            fl = []
            for k, f in enumerate(forces):
                f = np.asarray(f, dtype=float).ravel()
                if f.size not in (3, 6) or not np.all(np.isfinite(f)):
                    raise InputError(
                        f"forces[{k}] must be a finite 3-vector (N), got shape {f.shape}"
                    )
                fl.append(f[:3].copy())
            if len(fl) != n:
                raise InputError(f"forces has {len(fl)} entries, expected {n} (one per frame)")
            forces = fl
        self.forces = forces
        if critical_index is not None:
            ci = int(critical_index)
            if not 0 <= ci < n:
                raise InputError(f"critical_index {critical_index} is outside 0..{n - 1}")
            critical_index = ci
        self.critical_index = critical_index
        if (forces is not None or critical_index is not None) and frame_name is None:
            raise InputError("frame_name is required with forces or critical_index")
        self.frame_id: int | None = None
        if frame_name is not None:
            if not model.existFrame(frame_name):
                raise FrameNotFound(frame_name, [f.name for f in model.frames], "viewer frame_name")
            self.frame_id = int(model.getFrameId(frame_name))
        self.frame_name = frame_name
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f"fps must be positive, got {fps}")
        self.fps = float(fps)
        self.title_text = str(title_text)
        if frame_labels is not None:
            frame_labels = [str(s) for s in frame_labels]
            if len(frame_labels) != n:
                raise InputError(f"frame_labels has {len(frame_labels)} entries, expected {n}")
        self.frame_labels = frame_labels if frame_labels is not None else self._default_labels()
        cam = np.asarray(camera_direction, dtype=float).ravel()
        if cam.size != 3 or not np.all(np.isfinite(cam)) or np.linalg.norm(cam) < _TOL:
            raise InputError("camera_direction must be a non-zero 3-vector")
        self.camera_direction = cam / np.linalg.norm(cam)
        self.recolor = (
            recolor
            if recolor is not None
            else (lambda name: not name.startswith(JOINT_MARKER_PREFIX))
        )
        self.loop = bool(loop)
        self.arrow_length = arrow_length
        self._compute_kinematics()

    # ------------------------------------------------------------------ inputs & kinematics
    def _check_q(self, q, what: str) -> np.ndarray:
        q = np.asarray(q, dtype=float).ravel()
        if q.shape != (self.model.nq,):
            raise InputError(f"{what} has shape {q.shape}, expected ({self.model.nq},)")
        if not np.all(np.isfinite(q)):
            raise InputError(f"{what} contains NaN or infinite values")
        return q.copy()

    def _default_labels(self) -> list[str]:
        n = len(self.frames)
        out = []
        for k in range(n):
            parts = [f"frame {k}/{n - 1}"]
            if self.forces is not None:
                parts.append(f"|F| = {np.linalg.norm(self.forces[k]):.4g} N")
            if self.stable is not None:
                parts.append("stable" if self.stable[k] else "UNSTABLE")
            if self.critical_index == k:
                parts.append("critical")
            out.append(" | ".join(parts))
        return out

    def _placements(self, q: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, np.ndarray | None]:
        """Geometry placements (4×4), joint origins (njoints, 3), end-frame pose (4×4)."""
        pin.forwardKinematics(self.model, self._data, q)
        pin.updateGeometryPlacements(self.model, self._data, self.visual_model, self._gdata)
        oMg = [np.array(m.homogeneous) for m in self._gdata.oMg]
        joints = np.array([m.translation for m in self._data.oMi])
        oMf = None
        if self.frame_id is not None:
            oMf = np.array(
                pin.updateFramePlacement(self.model, self._data, self.frame_id).homogeneous
            )
        return oMg, joints, oMf

    def _compute_kinematics(self) -> None:
        self._data = self.model.createData()
        self._gdata = pin.GeometryData(self.visual_model)
        self._frame_oMg: list[list[np.ndarray]] = []
        self._frame_oMf: list[np.ndarray | None] = []
        pts = []
        for q in self.frames:
            oMg, joints, oMf = self._placements(q)
            self._frame_oMg.append(oMg)
            self._frame_oMf.append(oMf)
            pts.append(joints)
            pts.extend(m[None, :3, 3] for m in oMg)
            if oMf is not None:
                pts.append(oMf[None, :3, 3])
        self._ghost_oMg = None
        if self.ghost_q is not None:
            oMg, joints, oMf = self._placements(self.ghost_q)
            self._ghost_oMg = oMg
            pts.append(joints)
            if oMf is not None:
                pts.append(oMf[None, :3, 3])
        pts_arr = np.vstack(pts)
        lo, hi = pts_arr.min(axis=0), pts_arr.max(axis=0)
        self.scene_size = max(float(np.linalg.norm(hi - lo)), 1e-3)
        if self.arrow_length is None:
            self.arrow_length = 0.3 * self.scene_size
        # arrow tips also need to be in view
        if self.forces is not None:
            fmax = max(float(np.linalg.norm(f)) for f in self.forces)
            if fmax > 0:
                tips = [
                    oMf[:3, 3] + self.arrow_length * f / fmax
                    for oMf, f in zip(self._frame_oMf, self.forces)
                ]
                pts_arr = np.vstack([pts_arr, np.array(tips)])
        lo, hi = pts_arr.min(axis=0), pts_arr.max(axis=0)
        self.bbox = (lo, hi)

    # ------------------------------------------------------------------ commands
    def commands(self) -> list[Any]:
        """The meshcat commands that build the scene and set the animation.

        Returns
        -------
        list
            ``meshcat.commands`` objects (``SetObject``, ``SetTransform``, ``SetProperty``,
            ``SetAnimation``) in the order they must be applied.
        """
        _import_meshcat()
        import meshcat.animation as ma
        import meshcat.geometry as mg
        from meshcat.commands import Delete, SetObject, SetProperty, SetTransform
        from meshcat.path import Path as MPath

        root = MPath(("meshcat", "vjm"))
        cmds: list[Any] = [Delete(root)]
        anim = ma.Animation(default_framerate=self.fps)
        n = len(self.frames)
        last = n - 1

        def node(*parts: str) -> MPath:
            return MPath(root.entries + tuple(parts))

        def track_transform(path: MPath, mats: list[np.ndarray]) -> None:
            frame = ma.AnimationFrameVisualizer(anim, path, 0)
            for k, m in enumerate(mats):
                frame.current_frame = k
                frame.set_transform(m)

        def prop(path: MPath, k: float, name: str, jstype: str, value) -> None:
            ma.AnimationFrameVisualizer(anim, path, k).set_property(name, jstype, value)

        def col(is_stable: bool) -> list[float]:
            return list((STABLE_COLOR if is_stable else UNSTABLE_COLOR)[:3])

        # --- robot (animated) and ghost (static)
        names = _node_names(self.visual_model)
        for gi, go in enumerate(self.visual_model.geometryObjects):
            conv = _meshcat_geometry(go)
            if conv is None:
                continue
            geom, intrinsic = conv
            base_rgba = tuple(float(c) for c in go.meshColor)
            recol = self.stable is not None and self.recolor(go.name)
            rgba = (STABLE_COLOR if self.stable[0] else UNSTABLE_COLOR) if recol else base_rgba
            path = node("robot", names[gi])
            cmds.append(SetObject(geom, _material(rgba), path))
            obj_path = MPath(path.entries + ("<object>",))
            cmds.append(SetTransform(intrinsic, obj_path))
            mats = [self._frame_oMg[k][gi] for k in range(n)]
            cmds.append(SetTransform(mats[0], path))
            if any(not np.allclose(m, mats[0], atol=1e-12) for m in mats[1:]):
                track_transform(path, mats)
            if recol and len(set(self.stable)) > 1:
                prop(obj_path, 0, "material.color", "color", col(self.stable[0]))
                for k in range(1, n):
                    if self.stable[k] != self.stable[k - 1]:
                        prop(
                            obj_path,
                            k - _EPS_FRAME,
                            "material.color",
                            "color",
                            col(self.stable[k - 1]),
                        )
                        prop(obj_path, k, "material.color", "color", col(self.stable[k]))
                prop(obj_path, last, "material.color", "color", col(self.stable[last]))
            if self._ghost_oMg is not None:
                gpath = node("ghost", names[gi])
                ghost_geom = _meshcat_geometry(go)[0]  # fresh uuids: no shared three.js objects
                cmds.append(SetObject(ghost_geom, _material(GHOST_COLOR), gpath))
                cmds.append(SetTransform(intrinsic, MPath(gpath.entries + ("<object>",))))
                cmds.append(SetTransform(self._ghost_oMg[gi], gpath))

        # --- force arrow: node "force" at the end frame with +y along F, shaft scaled along y
        if self.forces is not None:
            mags = [float(np.linalg.norm(f)) for f in self.forces]
            fmax = max(mags)
            L = float(self.arrow_length)
            head_len, head_r, shaft_r = 0.2 * L, 0.07 * L, 0.025 * L
            fpath, spath, hpath = node("force"), node("force", "shaft"), node("force", "head")
            cmds.append(SetObject(mg.Cylinder(1.0, shaft_r), _material(FORCE_COLOR), spath))
            cmds.append(
                SetTransform(_translation([0, 0.5, 0]), MPath(spath.entries + ("<object>",)))
            )
            cmds.append(
                SetObject(
                    mg.Cylinder(head_len, radiusTop=0.0, radiusBottom=head_r),
                    _material(FORCE_COLOR),
                    hpath,
                )
            )
            cmds.append(
                SetTransform(
                    _translation([0, 0.5 * head_len, 0]), MPath(hpath.entries + ("<object>",))
                )
            )
            ey = np.array([0.0, 1.0, 0.0])
            mats, shaft_scale, head_scale, visible = [], [], [], []
            prev_dir = ey
            for k in range(n):
                m = np.eye(4)
                m[:3, 3] = self._frame_oMf[k][:3, 3]
                d = self.forces[k] / mags[k] if mags[k] > 0 else prev_dir
                prev_dir = d
                m[:3, :3] = pin.Quaternion.FromTwoVectors(ey, d).toRotationMatrix()
                mats.append(m)
                length = L * mags[k] / fmax if fmax > 0 else 0.0
                hs = min(1.0, length / (2.0 * head_len)) if head_len > 0 else 1.0
                shaft_scale.append(max(length - hs * head_len, 1e-6))
                head_scale.append(max(hs, 1e-6))
                visible.append(bool(mags[k] > 0))
            cmds.append(SetTransform(mats[0], fpath))
            track_transform(fpath, mats)
            for k in range(n):
                prop(spath, k, "scale", "vector3", [1.0, shaft_scale[k], 1.0])
                prop(hpath, k, "position", "vector3", [0.0, shaft_scale[k], 0.0])
                prop(hpath, k, "scale", "vector3", [head_scale[k]] * 3)
                prop(fpath, k, "visible", "boolean", visible[k])
            cmds.append(SetProperty("scale", [1.0, shaft_scale[0], 1.0], spath))
            cmds.append(SetTransform(_translation([0.0, shaft_scale[0], 0.0]), hpath))
            cmds.append(SetProperty("scale", [head_scale[0]] * 3, hpath))
            cmds.append(SetProperty("visible", visible[0], fpath))

        # --- critical marker
        if self.critical_index is not None:
            p = self._frame_oMf[self.critical_index][:3, 3]
            cpath = node("critical")
            cmds.append(
                SetObject(mg.Sphere(0.03 * self.scene_size), _material(CRITICAL_COLOR), cpath)
            )
            cmds.append(SetTransform(_translation(p), cpath))

        # --- camera. meshcat's orbit controls always look at the world origin (their target
        # is not reachable by commands), so the scene is shifted instead: the robot, the grid
        # and the axes are translated by -centre of the bounding box, and the camera sits at
        # camera_direction * distance from the origin, with a 40° field of view.
        lo, hi = self.bbox
        center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.05)
        dist = 1.1 * radius / math.sin(math.radians(_CAMERA_FOV) / 2.0)
        off = dist * self.camera_direction
        shift = _translation(-center)
        cmds.append(SetTransform(shift, root))
        cmds.append(SetTransform(shift, MPath(("Grid",))))
        cmds.append(SetTransform(shift, MPath(("Axes",))))
        cam = MPath(("Cameras", "default", "rotated", "<object>"))
        cmds.append(SetProperty("fov", _CAMERA_FOV, cam))
        # the camera lives in the frame "rotated" (y up): world (x, y, z) -> (x, z, -y)
        cmds.append(SetProperty("position", [float(off[0]), float(off[2]), float(-off[1])], cam))

        if n > 1:
            cmds.append(
                _SetAnimationAt(anim, node("animation"), repetitions=(math.inf if self.loop else 1))
            )
        return cmds

    # ------------------------------------------------------------------ outputs
    def to_html(self) -> str:
        """Self-contained HTML page (about 1 MB plus meshes) that plays offline.

        Returns
        -------
        str
            The page; see the module docstring for the overlay and the ``#frame=`` /
            ``#t=`` controls.
        """
        _import_meshcat()
        import meshcat
        import umsgpack

        js_path = os.path.join(os.path.dirname(meshcat.__file__), "viewer", "dist", "main.min.js")
        with open(js_path, encoding="utf-8") as fh:
            main_js = fh.read()
        blobs = [
            base64.b64encode(umsgpack.packb(_plain(c.lower()))).decode("ascii")
            for c in self.commands()
        ]
        setup = {
            "fps": self.fps,
            "nframes": len(self.frames),
            "labels": self.frame_labels,
            "title": self.title_text,
        }
        return _PAGE.format(
            title=html.escape(self.title_text or "vjm_pin"),
            main_js=main_js,
            commands=_js_json(blobs),
            setup=_js_json(setup),
        )

    def send(self, vis) -> None:
        """Draw the scene and set the animation in a live ``meshcat.Visualizer``.

        Parameters
        ----------
        vis
            A ``meshcat.Visualizer`` (any path; the scene goes to its window's root).
        """
        for cmd in self.commands():
            vis.window.send(cmd)


class _SetAnimationAt:
    """``meshcat.commands.SetAnimation`` filed under a scene path instead of the root.

    The viewer ignores the command's path, but a meshcat server replays its scene tree to a
    newly connected browser depth first, root first: an animation stored at the root arrives
    before the objects, and tracks that bind to a mesh (``.material.color`` on
    ``<object>``) would find only an empty placeholder. Stored at ``vjm/animation`` (created
    after all other ``vjm`` nodes), it is replayed after them.
    """

    def __init__(self, animation, path, play: bool = True, repetitions: float = 1) -> None:
        from meshcat.commands import SetAnimation

        self._cmd = SetAnimation(animation, play=play, repetitions=repetitions)
        self.path = path

    def lower(self) -> dict:
        data = self._cmd.lower()
        data["path"] = self.path.lower()
        return data


def _plain(x):
    """Lowered command with numpy scalars/arrays turned into Python types (msgpack)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x


def _js_json(x) -> str:
    """JSON safe to embed in a <script> element."""
    return json.dumps(x).replace("</", "<\\/").replace("<!--", "<\\!--")


_PAGE = """<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
  body {{ margin: 0; }}
  #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
  #vjm-overlay {{ position: absolute; left: 8px; top: 8px; padding: 4px 8px;
    font: 14px/1.35 sans-serif; color: #fff; background: rgba(0, 0, 0, 0.45);
    border-radius: 4px; pointer-events: none; white-space: pre-wrap;
    max-width: calc(100vw - 270px); }}  /* keep clear of meshcat's controls bar (top right) */
  #vjm-title {{ font-weight: bold; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="vjm-overlay"><div id="vjm-title"></div><div id="vjm-label"></div></div>
<script>
{main_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  var commands = {commands};
  for (var i = 0; i < commands.length; i++) {{
    var s = atob(commands[i]);
    var bytes = new Uint8Array(s.length);
    for (var j = 0; j < s.length; j++) bytes[j] = s.charCodeAt(j);
    viewer.handle_command_bytearray(bytes);
  }}
}})();
</script>
<script>
(function () {{
  var setup = {setup};
  var fps = setup.fps, n = setup.nframes, labels = setup.labels;
  document.getElementById("vjm-title").textContent = setup.title;
  if (!setup.title) document.getElementById("vjm-title").style.display = "none";
  var label = document.getElementById("vjm-label");
  function frameAt(t) {{
    var k = Math.floor(t * fps + 1e-3);
    return Math.max(0, Math.min(n - 1, k));
  }}
  function seekTime(t) {{
    var a = viewer.animator;
    a.pause();
    a.seek(t);
    a.display_progress(t);
    viewer.set_dirty();
  }}
  window.vjmSeekTime = seekTime;
  window.vjmSeekFrame = function (k) {{ seekTime(k / fps); }};
  function fromHash() {{
    var h = new URLSearchParams(window.location.hash.replace(/^#/, ""));
    var k = parseFloat(h.get("frame")), t = parseFloat(h.get("t"));
    if (isFinite(k)) window.vjmSeekFrame(k);
    else if (isFinite(t)) seekTime(t);
  }}
  window.addEventListener("hashchange", fromHash);
  fromHash();
  function update() {{
    label.textContent = labels[frameAt(viewer.animator.time || 0)];
    requestAnimationFrame(update);
  }}
  update();
}})();
</script>
</body>
</html>
"""


# ============================================================================ functions
def export_html(
    model: pin.Model,
    visual_model: pin.GeometryModel,
    frames: Sequence[np.ndarray],
    *,
    ghost_q: np.ndarray | None = None,
    stable: Sequence[bool] | None = None,
    forces: Sequence[np.ndarray] | None = None,
    frame_name: str | None = None,
    critical_index: int | None = None,
    fps: float = 10.0,
    title_text: str = "",
    path: str | os.PathLike | None = None,
    **options: Any,
) -> str:
    """Self-contained HTML page with the animated robot; plays offline.

    Shows the ghost robot at ``ghost_q``, the solid robot along ``frames`` coloured by
    stability, the force arrow at ``frame_name`` scaled to the current load and a marker at
    the end-frame position of the critical frame. The module docstring describes the page's
    controls (``page.html#frame=12``).

    Parameters
    ----------
    model
        Kinematic model.
    visual_model
        Geometry to show: the robot's own visual model (meshes) or :func:`chain_geometry`.
    frames
        Configurations to animate, each an (nq,) vector (m, rad).
    ghost_q
        (nq,) configuration of the translucent ghost, or None.
    stable
        Per-frame stability flags (green / red robot), or None.
    forces
        Per-frame force at ``frame_name``, 3-vectors in world axes (N), or None.
    frame_name
        End frame of the force arrow and the critical marker.
    critical_index
        Index into ``frames`` of the critical frame, or None.
    fps
        Playback rate, frames per second.
    title_text
        Title of the page and of its overlay.
    path
        If given, the page is also written to this file (UTF-8).
    **options
        More :class:`Animation` keywords: ``frame_labels``, ``arrow_length`` (m),
        ``camera_direction``, ``recolor``, ``loop``.

    Returns
    -------
    str
        The HTML page.
    """
    anim = Animation(
        model,
        visual_model,
        frames,
        ghost_q=ghost_q,
        stable=stable,
        forces=forces,
        frame_name=frame_name,
        critical_index=critical_index,
        fps=fps,
        title_text=title_text,
        **options,
    )
    page = anim.to_html()
    if path is not None:
        Path(path).write_text(page, encoding="utf-8")
    return page


_LIVE: list[Any] = []  # keeps the visualizers (and their server processes' sockets) alive


def serve(
    model: pin.Model,
    visual_model: pin.GeometryModel,
    frames: Sequence[np.ndarray],
    *,
    zmq_url: str | None = None,
    open_browser: bool = False,
    **kwargs: Any,
) -> str:
    """Show the animation in a meshcat server and return its URL; the caller blocks.

    The scene and animation are those of :func:`export_html` (same keyword arguments),
    without the HTML overlay and the ``#frame=`` control (the served page is meshcat's own);
    use meshcat's "Animations" controls instead.

    Parameters
    ----------
    zmq_url
        Existing meshcat server (``tcp://127.0.0.1:6000``), or None to start one in a
        subprocess (it lives until this Python process exits).
    open_browser
        Also open the page in the default web browser.
    **kwargs
        Passed to :class:`Animation`.

    Returns
    -------
    str
        The viewer URL (e.g. ``http://127.0.0.1:7000/static/``).
    """
    _import_meshcat()
    import meshcat

    anim = Animation(model, visual_model, frames, **kwargs)
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints the URL itself
        vis = meshcat.Visualizer(zmq_url=zmq_url)
    anim.send(vis)
    _LIVE.append(vis)
    if open_browser:
        vis.open()
    return vis.url()


# ============================================================================ magnification
def magnify(reference: np.ndarray, x: np.ndarray, scale: float) -> np.ndarray:
    """Configuration shown for ``x`` with its deformation magnified ``scale`` times.

    ``reference + scale · (x − reference)``: with ``reference`` the unloaded configuration
    (spring coordinates at their rest values θ₀, passive joints at their unloaded values,
    actuators at their commands), this multiplies the spring deflections θ − θ₀ and the
    passive joints' motion by ``scale``; joints that did not move stay put. Vectors (nq,),
    m and rad.
    """
    ref = np.asarray(reference, dtype=float)
    x = np.asarray(x, dtype=float)
    if ref.shape != x.shape:
        raise InputError(f"configuration has shape {x.shape}, reference has {ref.shape}")
    if not (math.isfinite(scale) and scale > 0):
        raise InputError(f"deformation scale must be a positive finite number, got {scale}")
    return ref + float(scale) * (x - ref)


def _joint_points(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    pts = [data.oMi[j].translation for j in range(1, model.njoints)]
    pts += [f.translation for f in data.oMf]
    return np.array(pts)


def default_scale(
    model: pin.Model,
    reference: np.ndarray,
    frames: Sequence[np.ndarray],
    *,
    visible_fraction: float = 0.08,
    max_scale: float = 1e4,
) -> float:
    """Deformation magnification that makes the largest displacement visible.

    The largest displacement of any joint origin or frame, over all ``frames``, from its
    unloaded position (``reference``) is compared with the size of the unloaded robot (the
    diagonal of the bounding box of its joint origins and frames, m). If it is below
    ``visible_fraction`` of that size, the scale is the 1-2-5 number that brings it there
    (at most ``max_scale``); otherwise 1 (deformations already visible are never shrunk).
    """
    data = model.createData()
    ref_pts = _joint_points(model, data, np.asarray(reference, float))
    size = float(np.linalg.norm(ref_pts.max(axis=0) - ref_pts.min(axis=0)))
    disp = 0.0
    for q in frames:
        disp = max(
            disp,
            float(
                np.linalg.norm(
                    _joint_points(model, data, np.asarray(q, float)) - ref_pts, axis=1
                ).max()
            ),
        )
    if size <= _TOL or disp <= _TOL * size:
        return 1.0
    want = visible_fraction * size / disp
    if want <= 1.0:
        return 1.0
    exp = math.floor(math.log10(want))
    mant = want / 10**exp
    nice = max(m for m in (1.0, 2.0, 5.0, 10.0) if m <= mant + 1e-12)
    return float(min(nice * 10**exp, max_scale))


def package_dirs() -> list[str]:
    """Folders where ``package://`` mesh URIs of ``example-robot-data`` robots resolve."""
    dirs = []
    try:
        import example_robot_data as erd

        robots = Path(erd.getModelPath("ur_description/urdf/ur5_robot.urdf")).resolve()
        dirs += [str(robots.parent.parent), str(robots.parent), str(robots)]
    except (ImportError, OSError):  # pragma: no cover - a declared dependency
        pass
    return dirs


def mesh_geometry(model: pin.Model, urdf_text: str, extra_dirs=()) -> pin.GeometryModel | None:
    """Visual geometry of a URDF that has ``<visual>`` meshes or primitives (e.g. the robots
    of ``example-robot-data``, whose visuals the VJM generator keeps), or None when it has
    none or they cannot be loaded (then use :func:`chain_geometry`)."""
    if "<visual" not in urdf_text:
        return None
    try:
        geom = pin.buildGeomFromUrdfString(
            model, urdf_text, pin.GeometryType.VISUAL, package_dirs=[*extra_dirs, *package_dirs()]
        )
    except (ValueError, RuntimeError, OSError):
        return None
    return geom if geom.ngeoms else None
