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
``branch<i>/<geometry>``
    Other equilibrium branches (:class:`Branch`, e.g. the unstable ones that leave a critical
    point): a second animated robot each, coloured by its own stability, hidden (boolean
    ``visible`` track) on frames where the branch has no equilibrium.
``force``
    The force arrow, drawn outside the robot: along the force, its length proportional to
    the force magnitude of the current frame (hidden when zero). ``arrow_style="tail"``
    starts it just beyond the load point (a pull); ``"head"`` ends it just short of the load
    point (a push seen from outside); ``"auto"`` takes ``"tail"`` unless that arrow would run
    along or through a link on some frame. Its value in N is a label in the page.
``load<i>``
    One arrow per dead load (``loads``: frame, per-frame force), laid out like ``force`` and
    at the same length scale (``arrow_length`` for the largest force of all arrows); its
    label is ``"<frame>: <|F|> N"``.
``closure<i>/a``, ``closure<i>/b``
    Loop-closure markers (``closures``): translucent unlit violet cubes, a bit larger than
    the joint spheres, at ``frame_b`` and (turned 45°, smaller) at ``frame_a``; they coincide
    where the loop is closed and follow the frames.
``ellipsoid``, ``ellipsoid/shape``
    A translucent blue ellipsoid at the end frame (``ellipsoid``: per frame its semi-axes in
    m as drawn and their axes, or None to hide it): the node carries the position and the
    principal axes, its unit sphere ``shape`` the per-frame scale.
``critical``
    A ring (unlit magenta, facing the camera, larger than whatever sits at the end point) around
    the end-frame position of the critical frame, and a pin above it carrying the label
    (``critical_label``, e.g. the critical force in N).

Per-frame stability colour
--------------------------
three.js animations can drive any property reachable from the animated object, and the
meshcat viewer (``Animator.load``) binds each clip to the object at its path. Each robot
mesh is therefore given a ``ColorKeyframeTrack`` named ``.material.color``, bound to the
mesh node ``robot/<geometry>/<object>``: the material colour is animated like a position.
Colours are keyed at every change with a second key 1e-3 frame earlier that holds
the previous colour, so the switch is sharp instead of a blend between two frames. Every
track also has keys at the first and the last frame so that all clips have the same duration
(clips loop independently in three.js). Joint markers made by :func:`chain_geometry` (names
starting with ``"joint:"``) keep their role colour; every other geometry is recoloured.
(Toggling the ``visible`` flag of two robot copies would also work, with twice the
geometry; the force arrow uses such a ``visible`` boolean track to hide zero forces.)

Which parts are red on an unstable frame: all of the robot by default. With ``modes`` (per
frame, the configuration directions in which the equilibrium is unstable, e.g. the
eigenvectors of eq. 23 on the constraint null space of a mechanism), only the bodies that
the unstable mode moves: each geometry object's displacement along the mode (largest over
its bounding-box corners, to first order, largest over the modes) is compared with the
largest one, and the objects that move at least :data:`MODE_FRACTION` of it are red, the
others green (they do not take part in the instability: the ground, a stable leg). With
``unstable_joints`` (per frame, joint indices) the caller names the red bodies itself (e.g.
the legs of a parallel robot that carry the mode); geometry attached to those joints is red.

Animation time control in the exported page
--------------------------------------------
:func:`export_html` writes its own page around meshcat's bundled viewer
(``meshcat/viewer/dist/main.min.js``, inlined, so the page works offline) instead of asking a
meshcat server for ``Visualizer.static_html()``: the same commands are replayed, but
decoded synchronously and in order (the server's page ``fetch``-es each command
asynchronously), so no server process is needed and a script can act after the scene is
complete. That script

- shows an overlay (top left) with the title and the label of the current frame
  (``frame_labels`` or: frame number, force magnitude in N, stable / UNSTABLE), labels pinned
  to scene points (the force in N at the arrow, the critical point at its pin; projected with
  the camera every frame) and a legend (bottom left); font sizes follow the viewport (vmin);
- has a load slider (bottom right) in physical units (``slider``: e.g. |F| in N, δ in mm; a
  value picks the frame whose value is nearest), a play/pause button and a "PNG" button
  that saves the picture *with* its labels and legend (the WebGL canvas composited with the
  overlay; meshcat's own image export loses them); ``window.vjmSnapshot(callback)`` does the
  same for scripts;
- reads the URL fragment: ``page.html#frame=12`` (frame index, may be fractional) or
  ``page.html#t=1.2`` (seconds) pauses the player at that time; ``hashchange`` works too;
  ``&hud=0`` hides labels, legend and controls (the scene alone);
- exposes ``window.vjmSeekFrame(k)`` and ``window.vjmSeekTime(t)`` for scripting.

Without a fragment the animation plays in a loop; meshcat's own controls ("Open Controls" →
Animations: play/pause/reset, time slider, time scale) are there as usual.

Camera
------
The direction (``camera_direction``, default :func:`auto_camera_direction`) looks across the
plane where the robot and its motion lie, from 20–65° above the floor. The points to frame
are the corners of every geometry's bounding box, the joint origins, the arrows and the
marker over all frames (and the branches and the ghost). meshcat's orbit controls look at
the world origin and commands cannot reach their target, so the scene is shifted:
``/meshcat/vjm``, ``/Grid`` and ``/Axes`` are translated by minus the centre of those points'
bounding box; the grid is the floor (z = 0, or the robot's lowest point if lower) with cells
of a 1-2-5 size near a sixth of the scene. The exported page's script then fits the camera
exactly: it aims the orbit target at the middle of the points as seen from the camera
direction and sets the distance so that they fill 85 % of the window (whatever its aspect),
again whenever the canvas changes size. The live server's page gets a bounding-sphere fit.

Live server
-----------
:func:`serve` sends the same commands to a meshcat server. The server replays its scene tree
to each browser that connects, root first. An animation stored at the root would arrive
before the meshes it binds to, so the animation command is filed under
``/meshcat/vjm/animation`` instead. That node is replayed after the robot. The served page
is meshcat's own, so it has no overlay and no ``#frame=`` control; the numbers of the current
frame (its label: force, deflection, verdict) are drawn in the scene instead
(``scene_labels``): above the robot, facing the initial camera, one textured square per line
(the viewer's ``_text`` canvas texture, black on a translucent white strip), one set per frame
switched by discrete ``visible`` tracks (frame k's text from k − ½ to k + ½). Being part of
the 3-D scene, the text turns away when the camera is orbited; meshcat's control panel cannot
show changing values (its "Animations" folder only holds the player's own controls).

Meshes and other outputs
------------------------
:func:`load_visuals` loads a URDF's own meshes (``--package-dir``, ``ROS_PACKAGE_PATH``; a
missing mesh is warned about and primitives are drawn, which ``legend_notes`` states);
``points`` adds a coloured point cloud (a stiffness map, :mod:`vjm_pin.viz.map_cloud`);
:meth:`Animation.frame_bodies` gives other renderers the drawn bodies of a frame (the
paper-style figure of :mod:`vjm_pin.viz.figures`).
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import json
import logging
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import FrameNotFound, InputError, JointNotFound, RoleError
from vjm_pin.model.task import task_vector

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
    "Branch",
    "MeshVisuals",
    "auto_camera_direction",
    "chain_geometry",
    "default_scale",
    "export_html",
    "load_visuals",
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
CRITICAL_COLOR = (0.95, 0.0, 0.95, 1.0)
"""The critical-point marker (magenta ring and pin, unlit)."""

JOINT_MARKER_PREFIX = "joint:"
"""Geometry objects whose name starts with this keep their colour in stability colouring."""
LINK_PREFIX = "link:"

_TOL = 1e-9
_CAMERA_FOV = 40.0  # (deg) vertical field of view of the camera
_EPS_FRAME = 1e-3  # (frames) offset of the key that holds the old colour before a change
_MODE_STEP = 1e-6  # (m, rad) step along an unstable mode to measure which bodies it moves
MODE_FRACTION = 0.25
"""On an unstable frame with ``modes``, a body is drawn red when it moves at least this fraction
of the largest body displacement in the unstable mode (first order), green otherwise."""
SCENE_LABEL_LINES = 4
"""Lines of scene text per frame at most (``Animation(scene_labels=True)``)."""
CLOSURE_COLOR = (0.45, 0.15, 0.95, 1.0)
"""Loop-closure markers (violet cubes at frame_a and frame_b, unlit)."""
ELLIPSOID_COLOR = (0.2, 0.45, 1.0, 0.35)
"""The compliance ellipsoid (translucent blue)."""


# ============================================================================ chain geometry
def chain_geometry(
    model: pin.Model,
    styles: Mapping[str, str],
    *,
    link_radius: float | None = None,
    link_shape: str = "cylinder",
    default_style: str = "actuated",
    extra_frames: Sequence[str] = (),
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
        segment length, at least 0.6 % of the robot's size (the diagonal of the bounding box
        of its joint origins in the neutral pose). Joint spheres have 1.7 times this radius.
    link_shape
        ``"cylinder"`` or ``"box"``.
    default_style
        Style of joints missing from ``styles``.
    extra_frames
        Frames that also get a segment from the origin of their parent joint (the world
        origin for frames on the ground) when they are not already an end of one: the
        points a mechanism is closed at (``<vjm:closure>`` frames), a task frame off the
        links, loaded frames. This draws the ground link of a loop and rigid offsets.

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

    _check_chain_options(model, styles, default_style, link_shape, extra_frames)
    segments = _chain_segments(model, extra_frames)
    if link_radius is None:
        link_radius = _default_link_radius(model, segments)
    r_link = max(float(link_radius), 1e-6)
    r_joint = 1.7 * r_link

    gmodel = pin.GeometryModel()
    ez = np.array([0.0, 0.0, 1.0])
    for parent, t, label in segments:
        length = float(np.linalg.norm(t))
        rot = pin.Quaternion.FromTwoVectors(ez, t / length).toRotationMatrix()
        placement = pin.SE3(rot, 0.5 * t)
        if link_shape == "cylinder":
            shape = coal.Cylinder(r_link, length)
        else:
            shape = coal.Box(2 * r_link, 2 * r_link, length)
        go = pin.GeometryObject(
            LINK_PREFIX + label, parent, _joint_frame(model, parent), placement, shape
        )
        go.meshColor = np.array(LINK_COLOR)
        gmodel.addGeometryObject(go)
    _add_joint_markers(gmodel, model, styles, default_style, r_joint)
    return gmodel


def _check_chain_options(model, styles, default_style, link_shape, extra_frames) -> None:
    """Validate the options of :func:`chain_geometry` (its Raises section)."""
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
    for fn in extra_frames:
        if not model.existFrame(fn):
            raise FrameNotFound(fn, [f.name for f in model.frames], "chain_geometry extra_frames")


def _joint_frame(model, j: int) -> int:
    """The JOINT frame of joint ``j`` (0 for the universe)."""
    if j == 0:
        return 0
    return int(model.getFrameId(model.names[j], pin.FrameType.JOINT))


def _chain_segments(model, extra_frames) -> list[tuple[int, np.ndarray, str]]:
    """The link segments of :func:`chain_geometry`: (parent joint, end point in the parent
    joint frame, label)."""
    names = list(model.names)
    nj = model.njoints
    children: list[list[int]] = [[] for _ in range(nj)]
    for j in range(1, nj):
        children[model.parents[j]].append(j)
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
    for fn in extra_frames:
        f = model.frames[model.getFrameId(fn)]
        j = int(f.parentJoint)
        t = np.array(f.placement.translation)
        ends = [seg_t for p_j, seg_t, _ in segments if p_j == j]
        ends += [np.array(model.jointPlacements[c].translation) for c in children[j]]
        on = [float(_segment_distances(t[None, :], np.zeros(3), e)[0]) for e in ends]
        if np.linalg.norm(t) <= _TOL or any(d <= 1e-6 for d in on):
            continue  # at the joint, or on a segment already drawn
        segments.append((j, t, f"{names[j]}->{fn}"))
    return segments


def _default_link_radius(model, segments) -> float:
    """6 % of the median segment length, at least 0.6 % of the robot's size (m)."""
    lengths = [float(np.linalg.norm(t)) for _, t, _ in segments]
    link_radius = 0.06 * float(np.median(lengths)) if lengths else 0.02
    # links cut into many short segments (beams split into sub-links) stay visible: at
    # least 0.6 % of the size of the robot (bounding box of its joints, neutral pose)
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    pts = np.array([m.translation for m in data.oMi])
    return max(link_radius, 0.006 * float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))))


def _add_joint_markers(gmodel, model, styles, default_style, r_joint) -> None:
    """One sphere per stack of co-located joints (and a spring halo), :func:`chain_geometry`."""
    import coal

    names = list(model.names)
    stack_of = [-1] * model.njoints
    stacks: list[list[int]] = []
    for j in range(1, model.njoints):
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
            _joint_frame(model, attach),
            pin.SE3.Identity(),
            coal.Sphere(r_joint),
        )
        go.meshColor = np.array(STYLE_COLORS[main])
        gmodel.addGeometryObject(go)
        if main != "spring" and "spring" in member_styles.values():
            halo = pin.GeometryObject(
                JOINT_MARKER_PREFIX + names[main_joint] + ":springs",
                attach,
                _joint_frame(model, attach),
                pin.SE3.Identity(),
                coal.Sphere(1.35 * r_joint),
            )
            halo.meshColor = np.array(STYLE_COLORS["spring"][:3] + (SPRING_HALO_ALPHA,))
            gmodel.addGeometryObject(halo)


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


def _local_box(go: pin.GeometryObject) -> np.ndarray:
    """(8, 3) corners of the local bounding box of a geometry object (its own frame, m);
    the origin alone when the shape gives none."""
    try:
        g = go.geometry
        g.computeLocalAABB()
        lo = np.asarray(g.aabb_local.min_, float)
        hi = np.asarray(g.aabb_local.max_, float)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError
    except Exception:  # noqa: BLE001 - a shape without a box is shown by its origin
        return np.zeros((1, 3))
    return np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )


def _segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each of ``points`` (m, 3) to the segment a–b."""
    ab = b - a
    L2 = float(ab @ ab)
    if L2 <= 0:
        return np.linalg.norm(points - a, axis=1)
    t = np.clip((points - a) @ ab / L2, 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def _distances_to_links(
    points: np.ndarray,
    joints: np.ndarray,
    model: pin.Model,
    end: tuple[int, np.ndarray] | None = None,
) -> np.ndarray:
    """Distance from each of ``points`` to the polyline of the kinematic tree (joint
    origins ``joints``, parent to child, and ``end`` = (parent joint, position) of the end
    frame), m."""
    segments = [(joints[model.parents[j]], joints[j]) for j in range(1, model.njoints)]
    if end is not None:
        segments.append((joints[end[0]], np.asarray(end[1], float)))
    best = np.full(len(points), math.inf)
    for a, b in segments:
        best = np.minimum(best, _segment_distances(points, a, b))
    return best


def _thin_points(pts: np.ndarray, voxel: float, cap: int = 3000) -> np.ndarray:
    """One point per ``voxel``-sized cell; at most ``cap`` points, always keeping the
    extreme points along the axes and the diagonals (what the camera must frame)."""
    keys = np.round(pts / max(voxel, 1e-12))
    _, idx = np.unique(keys, axis=0, return_index=True)
    out = pts[np.sort(idx)]
    if len(out) > cap:
        dirs = np.array(
            [
                [x, y, z]
                for x in (-1, 0, 1)
                for y in (-1, 0, 1)
                for z in (-1, 0, 1)
                if (x, y, z) != (0, 0, 0)
            ],
            float,
        )
        proj = out @ dirs.T
        keep = set(np.argmax(proj, axis=0).tolist())
        keep.update(np.linspace(0, len(out) - 1, cap - len(keep)).astype(int).tolist())
        out = out[sorted(keep)]
    return out


def auto_camera_direction(
    frame_joints: Sequence[np.ndarray],
    points: np.ndarray,
    min_elevation: float = 20.0,
    max_elevation: float = 65.0,
) -> np.ndarray:
    """A camera direction (unit 3-vector, from the look-at point to the camera) that sees
    both the robot and its motion broadside, from above the floor.

    The direction of least spread of ``points`` (the robot over all frames) plus the least
    spread of the joint motion (displacements from the first frame), each normalised by its
    trace, is the normal of the plane where things happen; it is then tilted to an
    elevation between ``min_elevation`` and ``max_elevation`` degrees above the floor, on the
    side of the (0.45, −1, 0.45) default view.
    """
    pts = np.asarray(points, float)
    c = np.cov((pts - pts.mean(axis=0)).T) if len(pts) > 1 else np.zeros((3, 3))
    total = np.trace(c)
    cov = c / total if total > 0 else np.zeros((3, 3))
    if len(frame_joints) > 1:
        d = np.vstack([np.asarray(j) - np.asarray(frame_joints[0]) for j in frame_joints[1:]])
        m = d.T @ d
        if np.trace(m) > 0:
            cov = cov + m / np.trace(m)
    ref = np.array([0.45, -1.0, 0.45])
    if not np.any(cov):
        v = ref
    else:
        _, vecs = np.linalg.eigh(cov)
        v = vecs[:, 0]
    v = v / np.linalg.norm(v)
    if v @ ref < 0:
        v = -v
    h = v[:2].copy()
    if np.linalg.norm(h) < 0.05:
        h = ref[:2]
    h = h / np.linalg.norm(h)
    elev = math.degrees(math.asin(max(-1.0, min(1.0, abs(v[2])))))
    elev = math.radians(min(max(elev, min_elevation), max_elevation))
    return np.array([math.cos(elev) * h[0], math.cos(elev) * h[1], math.sin(elev)])


def _torus(R: float, r: float, nu: int = 48, nv: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a torus of radii R, r in the xy plane (normal z)."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    verts = np.stack(
        [(R + r * np.cos(vv)) * np.cos(uu), (R + r * np.cos(vv)) * np.sin(uu), r * np.sin(vv)],
        axis=-1,
    ).reshape(-1, 3)
    faces = []
    for i in range(nu):
        for j in range(nv):
            a, b = i * nv + j, ((i + 1) % nu) * nv + j
            c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
            faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces)


def _flat_material(rgba: Sequence[float]):
    """Unlit material: a marker in one flat colour, whatever the light."""
    import meshcat.geometry as mg

    return mg.MeshBasicMaterial(color=_rgb_int(rgba))


def _closure_material():
    """Unlit translucent violet: the closure cubes, with the joint inside them visible."""
    import meshcat.geometry as mg

    return mg.MeshBasicMaterial(
        color=_rgb_int(CLOSURE_COLOR), opacity=0.6, transparent=True, depthWrite=False
    )


def _css(rgba: Sequence[float]) -> str:
    r, g, b = (round(255 * min(max(float(c), 0.0), 1.0)) for c in rgba[:3])
    a = float(rgba[3]) if len(rgba) > 3 else 1.0
    return f"rgba({r}, {g}, {b}, {a:g})"


def _nice(x: float) -> float:
    """Largest 1-2-5 number not above ``x`` (> 0)."""
    exp = math.floor(math.log10(x))
    mant = x / 10**exp
    return max(m for m in (1.0, 2.0, 5.0) if m <= mant + 1e-12) * 10**exp


# ============================================================================ the animation
@dataclass(frozen=True)
class Branch:
    """Another equilibrium branch, shown as a second robot that follows the animation.

    Attributes:
        frames: One entry per animation frame: the (nq,) configuration on this branch at
            that frame's load, or None where the branch has no equilibrium (hidden).
        stable: One stability flag per frame (green / red); ignored where hidden.
        name: Short text for the legend and the labels (e.g. ``"branch 1"``).
    """

    frames: tuple
    stable: tuple
    name: str = ""


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
        End frame: where the force acts and the critical marker sits. Required with
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
        Direction from the look-at point to the camera, world axes (any length), or None
        for :func:`auto_camera_direction` (from above the floor, across the motion).
    recolor
        Predicate on geometry-object names: which objects take the stability colour.
        Default: all but the joint markers of :func:`chain_geometry`.
    loop
        Play the animation in a loop (else once, then back to the start).
    branches
        Other equilibrium branches (:class:`Branch`), each drawn as a second robot coloured
        by its own stability, visible on the frames where it exists.
    critical_label
        Text of the label pinned to the critical marker (default ``"critical point"``).
    arrow_style
        ``"tail"``: the arrow starts at the load point and points along the force (a pull);
        ``"head"``: it ends at the load point (a push, drawn from outside); ``"auto"``
        (default): ``"tail"`` unless that arrow would run through the robot on some frame.
    slider
        ``{"name": "|F|", "unit": "N", "values": [...]}``: one value per frame of a
        quantity to scrub the animation with in the exported page (a range input in those
        units; a value picks the frame whose value is nearest). Default: the force
        magnitude in N when ``forces`` are given.
    legend
        Show the legend (stable / unstable / critical / force / unloaded) in the page.
    loads
        Dead loads: ``(frame name, per-frame forces)`` pairs, each force a 3-vector (N,
        world axes); one arrow each, same length scale as the end force.
    modes
        Per frame None or an (nq, k) array of unstable directions: on an unstable frame only
        the bodies they move are red (module docstring, :data:`MODE_FRACTION`).
    closures
        ``(name, frame_a, frame_b)`` of each loop closure: markers at both frames.
    ellipsoid
        Per frame None or ``(semi-axes (3,) m as drawn, axes (3, 3) unit columns)``: an
        ellipsoid centred at the end frame (``frame_name`` required).
    ellipsoid_label
        Its legend text (say what it is and its scale).
    unstable_joints
        Per frame None or the joint indices whose bodies are red on an unstable frame
        (overrides ``modes`` on that frame).
    legend_notes
        Lines of text added at the end of the legend (e.g. that primitives replace missing
        meshes, :attr:`MeshVisuals.note`).
    scene_labels
        Draw the current frame's label (``frame_labels``, split at ", " into at most
        :data:`SCENE_LABEL_LINES` lines) as text in the 3-D scene above the robot, facing the
        camera, switched per frame by ``visible`` tracks: the numbers for meshcat's own page
        (:func:`serve`), which has no overlay.
    points
        A static coloured point cloud (e.g. a stiffness map, :mod:`vjm_pin.viz.map_cloud`):
        ``{"positions": (N, 3) m, "colors": (N, 3) RGB in 0..1, "size": point size in m,
        "legend": [(rgba, text), ...]}``; the legend rows are added to the page's legend.

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
        camera_direction: Sequence[float] | None = None,
        recolor: Callable[[str], bool] | None = None,
        loop: bool = True,
        branches: Sequence[Branch] | None = None,
        critical_label: str | None = None,
        arrow_style: str = "auto",
        slider: Mapping[str, Any] | None = None,
        legend: bool = True,
        loads: Sequence[tuple[str, Sequence[np.ndarray]]] | None = None,
        modes: Sequence[np.ndarray | None] | None = None,
        closures: Sequence[tuple[str, str, str]] | None = None,
        ellipsoid: Sequence[tuple[np.ndarray, np.ndarray] | None] | None = None,
        ellipsoid_label: str | None = None,
        unstable_joints: Sequence[Sequence[int] | None] | None = None,
        legend_notes: Sequence[str] = (),
        points: Mapping[str, Any] | None = None,
        scene_labels: bool = False,
    ) -> None:
        self.model = model
        self.legend_notes = [str(t) for t in legend_notes]
        self.points = self._check_points(points)
        self.scene_labels = bool(scene_labels)
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
        self.forces = forces = self._check_forces(forces, n)
        self._set_end_frame(critical_index, frame_name)
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f"fps must be positive, got {fps}")
        self.fps = float(fps)
        self.title_text = str(title_text)
        if frame_labels is not None:
            frame_labels = [str(s) for s in frame_labels]
            if len(frame_labels) != n:
                raise InputError(f"frame_labels has {len(frame_labels)} entries, expected {n}")
        self.frame_labels = frame_labels if frame_labels is not None else self._default_labels()
        self._camera_given = camera_direction
        if camera_direction is not None:
            cam = np.asarray(camera_direction, dtype=float).ravel()
            if cam.size != 3 or not np.all(np.isfinite(cam)) or np.linalg.norm(cam) < _TOL:
                raise InputError("camera_direction must be a non-zero 3-vector")
        self.recolor = (
            recolor
            if recolor is not None
            else (lambda name: not name.startswith(JOINT_MARKER_PREFIX))
        )
        self.loop = bool(loop)
        self.arrow_length = arrow_length
        self.branches: list[Branch] = self._check_branches(branches, n)
        self.critical_label = "critical point" if critical_label is None else str(critical_label)
        if arrow_style not in ("auto", "tail", "head"):
            raise InputError(f"arrow_style must be 'auto', 'tail' or 'head', got {arrow_style!r}")
        self._arrow_style_opt = arrow_style
        self.slider = self._check_slider(slider, forces, n)
        self.legend = bool(legend)
        self._check_extras(loads, modes, closures, ellipsoid, ellipsoid_label)
        self.unstable_joints = self._check_unstable_joints(unstable_joints, n)
        self._compute_kinematics()

    def _set_end_frame(self, critical_index, frame_name) -> None:
        """Validate and set ``critical_index``, ``frame_name`` and ``frame_id`` (after
        ``frames`` and ``forces``)."""
        n, model = len(self.frames), self.model
        if critical_index is not None:
            ci = int(critical_index)
            if not 0 <= ci < n:
                raise InputError(f"critical_index {critical_index} is outside 0..{n - 1}")
            critical_index = ci
        self.critical_index = critical_index
        if (self.forces is not None or critical_index is not None) and frame_name is None:
            raise InputError("frame_name is required with forces or critical_index")
        self.frame_id: int | None = None
        if frame_name is not None:
            if not model.existFrame(frame_name):
                raise FrameNotFound(frame_name, [f.name for f in model.frames], "viewer frame_name")
            self.frame_id = int(model.getFrameId(frame_name))
        self.frame_name = frame_name

    def _check_unstable_joints(self, unstable_joints, n: int) -> list[frozenset | None] | None:
        """Validate ``unstable_joints``: ``n`` joint index sets (or None)."""
        if unstable_joints is None:
            return None
        nj = self.model.njoints
        uj = [None if u is None else frozenset(int(j) for j in u) for u in unstable_joints]
        if len(uj) != n or any(u is not None and not all(0 <= j < nj for j in u) for u in uj):
            raise InputError(
                f"unstable_joints needs {n} entries (joint index sets 0..{nj - 1} or None)"
            )
        return uj

    @staticmethod
    def _check_forces(forces, n: int) -> list[np.ndarray] | None:
        """Validate ``forces``: ``n`` finite 3-vectors (a 6-vector's linear part), N
        (:func:`vjm_pin.model.task.task_vector`, the one "3 or 6 numbers" check)."""
        if forces is None:
            return None
        fl = [task_vector(f, name=f"forces[{k}]", unit="N")[:3] for k, f in enumerate(forces)]
        if len(fl) != n:
            raise InputError(f"forces has {len(fl)} entries, expected {n} (one per frame)")
        return fl

    def _check_branches(self, branches, n: int) -> list[Branch]:
        """Validate ``branches``: ``n`` configurations (or None) and flags each."""
        out = []
        for bi, br in enumerate(branches or ()):
            bf, bs = list(br.frames), [bool(s) for s in br.stable]
            if len(bf) != n or len(bs) != n:
                raise InputError(
                    f"branches[{bi}] has {len(bf)} frames and {len(bs)} flags, expected {n} each"
                )
            bf = [
                None if q is None else self._check_q(q, f"branches[{bi}].frames[{k}]")
                for k, q in enumerate(bf)
            ]
            out.append(Branch(tuple(bf), tuple(bs), br.name or f"branch {bi + 1}"))
        return out

    @staticmethod
    def _check_slider(slider, forces, n: int) -> dict | None:
        """Validate ``slider`` (default: |F| in N when ``forces`` are given)."""
        if slider is None and forces is not None and n > 1:
            slider = {
                "name": "|F|",
                "unit": "N",
                "values": [float(np.linalg.norm(f)) for f in forces],
            }
        if slider is None:
            return None
        vals = [float(v) for v in slider["values"]]
        if len(vals) != n or not all(math.isfinite(v) for v in vals):
            raise InputError(f"slider values must be {n} finite numbers (one per frame)")
        return {
            "name": str(slider.get("name", "")),
            "unit": str(slider.get("unit", "")),
            "values": vals,
        }

    @staticmethod
    def _check_points(points) -> dict | None:
        """Validate the point cloud option (see the class docstring)."""
        if points is None:
            return None
        pos = np.asarray(points.get("positions"), dtype=float)
        col = np.asarray(points.get("colors"), dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 3 or not len(pos) or not np.all(np.isfinite(pos)):
            raise InputError("points: positions must be a non-empty (N, 3) array of finite m")
        if col.shape != pos.shape or not np.all((col >= 0) & (col <= 1)):
            raise InputError(f"points: colors must be ({len(pos)}, 3) RGB values in 0..1")
        size = float(points.get("size", 0.01))
        if not (math.isfinite(size) and size > 0):
            raise InputError(f"points: size must be a positive length in m, got {size}")
        legend = [(tuple(float(c) for c in rgba), str(t)) for rgba, t in points.get("legend", ())]
        return {"positions": pos, "colors": col, "size": size, "legend": legend}

    def _frame_index(self, name: str, what: str) -> int:
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise FrameNotFound(str(name), [f.name for f in self.model.frames], what)
        return int(self.model.getFrameId(name))

    def _check_extras(self, loads, modes, closures, ellipsoid, ellipsoid_label) -> None:
        """Validate the dead-load arrows, unstable modes, closure markers and ellipsoid."""
        n, nq = len(self.frames), self.model.nq
        self.loads: list[tuple[str, int, list[np.ndarray]]] = []
        for i, item in enumerate(loads or ()):
            name, fl = item
            fid = self._frame_index(name, f"loads[{i}] frame")
            fl = [np.asarray(f, dtype=float).ravel()[:3] for f in fl]
            if len(fl) != n or any(f.size != 3 or not np.all(np.isfinite(f)) for f in fl):
                raise InputError(f"loads[{i}] ('{name}') needs {n} finite force 3-vectors (N), one per frame")
            self.loads.append((str(name), fid, fl))
        self.modes: list[np.ndarray | None] | None = None
        if modes is not None:
            ml = []
            for k, m in enumerate(modes):
                if m is None:
                    ml.append(None)
                    continue
                m = np.asarray(m, dtype=float)
                m = m.reshape(nq, -1) if m.size % nq == 0 and m.size else m
                if m.ndim != 2 or m.shape[0] != nq or not np.all(np.isfinite(m)):
                    raise InputError(f"modes[{k}] must be a finite ({nq}, k) array or None")
                ml.append(m)
            if len(ml) != n:
                raise InputError(f"modes has {len(ml)} entries, expected {n} (one per frame)")
            self.modes = ml
        self.closures: list[tuple[str, int, int]] = []
        for i, item in enumerate(closures or ()):
            cname, fa, fb = item
            self.closures.append(
                (str(cname), self._frame_index(fa, f"closure '{cname}' frame_a"),
                 self._frame_index(fb, f"closure '{cname}' frame_b"))
            )
        self.ellipsoid: list[tuple[np.ndarray, np.ndarray] | None] | None = None
        if ellipsoid is not None:
            if self.frame_id is None:
                raise InputError("frame_name is required with ellipsoid")
            el = []
            for k, e in enumerate(ellipsoid):
                if e is None:
                    el.append(None)
                    continue
                a = np.asarray(e[0], dtype=float).ravel()
                r = np.asarray(e[1], dtype=float)
                if a.shape != (3,) or r.shape != (3, 3) or not (np.all(np.isfinite(a)) and np.all(np.isfinite(r))):
                    raise InputError(f"ellipsoid[{k}] must be (semi-axes (3,), axes (3, 3)), finite")
                if np.any(a < 0):
                    raise InputError(f"ellipsoid[{k}] has a negative semi-axis: {a.tolist()}")
                if np.linalg.det(r) < 0:
                    r = r.copy()
                    r[:, 2] *= -1.0
                el.append((a, r))
            if len(el) != n:
                raise InputError(f"ellipsoid has {len(el)} entries, expected {n} (one per frame)")
            self.ellipsoid = el
        self.ellipsoid_label = (
            "compliance ellipsoid" if ellipsoid_label is None else str(ellipsoid_label)
        )

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

    def _frame_positions(self, fids) -> list[np.ndarray]:
        """Positions (3,) of frames ``fids`` after :meth:`_placements` (m, world)."""
        return [
            np.array(pin.updateFramePlacement(self.model, self._data, f).translation) for f in fids
        ]

    def _placements(self, q: np.ndarray):
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

    def _box_points(self, oMg: list[np.ndarray]) -> np.ndarray:
        """Corners of every geometry's local bounding box, world axes (m)."""
        pts = []
        for m, box in zip(oMg, self._local_boxes):
            pts.append(box @ m[:3, :3].T + m[:3, 3])
        return np.vstack(pts) if pts else np.zeros((0, 3))

    def _compute_kinematics(self) -> None:
        self._data = self.model.createData()
        self._gdata = pin.GeometryData(self.visual_model)
        self._local_boxes = [_local_box(go) for go in self.visual_model.geometryObjects]
        self._frame_oMg: list[list[np.ndarray]] = []
        self._frame_oMf: list[np.ndarray | None] = []
        self._frame_joints: list[np.ndarray] = []
        # positions per frame of the dead-load frames and of the closure frames (a, b)
        extra_fids = [fid for _, fid, _ in self.loads] + [
            f for _, fa, fb in self.closures for f in (fa, fb)
        ]
        self._extra_pos: list[list[np.ndarray]] = []
        pts = []
        for q in self.frames:
            oMg, joints, oMf = self._placements(q)
            self._frame_oMg.append(oMg)
            self._frame_oMf.append(oMf)
            self._frame_joints.append(joints)
            self._extra_pos.append(self._frame_positions(extra_fids))
            pts.append(joints)
            pts.append(self._box_points(oMg))
            if oMf is not None:
                pts.append(oMf[None, :3, 3])
            pts += [p[None, :] for p in self._extra_pos[-1]]
        self._branch_oMg: list[list[list[np.ndarray] | None]] = []
        for br in self.branches:
            rows = []
            for q in br.frames:
                if q is None:
                    rows.append(None)
                    continue
                oMg, joints, _ = self._placements(q)
                rows.append(oMg)
                pts.append(joints)
                pts.append(self._box_points(oMg))
            self._branch_oMg.append(rows)
        self._ghost_oMg = None
        if self.ghost_q is not None:
            oMg, joints, oMf = self._placements(self.ghost_q)
            self._ghost_oMg = oMg
            pts.append(joints)
            pts.append(self._box_points(oMg))
            if oMf is not None:
                pts.append(oMf[None, :3, 3])
        if self.points is not None:
            pts.append(self.points["positions"])
        pts_arr = np.vstack(pts)
        lo, hi = pts_arr.min(axis=0), pts_arr.max(axis=0)
        self.scene_size = max(float(np.linalg.norm(hi - lo)), 1e-3)
        if self.arrow_length is None:
            self.arrow_length = 0.3 * self.scene_size
        self.camera_direction = (
            auto_camera_direction(self._frame_joints, pts_arr)
            if self._camera_given is None
            else np.asarray(self._camera_given, float).ravel()
            / np.linalg.norm(np.asarray(self._camera_given, float))
        )
        self._geom_stable = self._geometry_stability()
        self._layout_arrow()
        self._layout_marker()
        extra = [a[None, :] for a in self._arrow_ends] + [m[None, :] for m in self._marker_points]
        if self.ellipsoid is not None:
            for k, e in enumerate(self.ellipsoid):
                if e is not None:
                    c = self._frame_oMf[k][:3, 3]
                    extra += [(c + s * a * e[1][:, i])[None, :] for i, a in enumerate(e[0]) for s in (-1, 1)]
        pts_arr = np.vstack([pts_arr, *extra]) if extra else pts_arr
        lo, hi = pts_arr.min(axis=0), pts_arr.max(axis=0)
        self._text_box = None
        if self.scene_labels:
            self._text_box = self._layout_text(lo, hi)
            pts_arr = np.vstack([pts_arr, self._text_box["corners"]])
            lo, hi = pts_arr.min(axis=0), pts_arr.max(axis=0)
        self.bbox = (lo, hi)
        self._view_points = _thin_points(pts_arr, 0.02 * self.scene_size)

    # ------------------------------------------------------------------ scene text
    def label_lines(self, k: int) -> list[str]:
        """The lines of text drawn in the scene at frame ``k`` (``scene_labels``)."""
        parts = [t.strip() for t in self.frame_labels[int(k)].split(", ") if t.strip()]
        if len(parts) > SCENE_LABEL_LINES:
            parts = parts[: SCENE_LABEL_LINES - 1] + [", ".join(parts[SCENE_LABEL_LINES - 1 :])]
        return parts

    def _layout_text(self, lo: np.ndarray, hi: np.ndarray) -> dict:
        """Where the scene text goes: above the bounding box ``lo``–``hi`` (m), its plane
        facing the camera with the text's x axis horizontal."""
        cam = self.camera_direction / np.linalg.norm(self.camera_direction)
        x = np.cross(np.array([0.0, 0.0, 1.0]), cam)
        if np.linalg.norm(x) < 1e-6:  # looking straight down: text along world x
            x = np.array([1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        y = np.cross(cam, x)
        rot = np.column_stack([x, y, cam])
        width = 0.45 * self.scene_size
        step = 0.16 * width  # line spacing (the text is a strip across the middle of its square)
        nl = max(len(self.label_lines(k)) for k in range(len(self.frames)))
        top = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2]]) + (
            0.08 * self.scene_size + nl * step
        ) * np.array([0.0, 0.0, 1.0])
        centres = [top - (i + 0.5) * step * y for i in range(nl)]
        half = 0.5 * width * x
        mid = 0.5 * (centres[0] + centres[-1])
        corners = np.array([c + s * half + t * 0.6 * step * y for c in (centres[0], centres[-1])
                            for s in (-1, 1) for t in (-1, 1)])
        return {"rot": rot, "width": width, "centres": centres, "step": step, "mid": mid,
                "lines": nl, "corners": corners}

    def _text_commands(self, cmds, node, prop) -> None:
        """The scene text of ``scene_labels``: per frame and line a square textured with the
        line (meshcat's ``_text`` canvas texture), visible on its frame only; a translucent
        white strip behind them."""
        import meshcat.geometry as mg
        from meshcat.commands import SetObject, SetProperty, SetTransform

        tb = self._text_box
        w, n, last = tb["width"], len(self.frames), len(self.frames) - 1
        back = np.eye(4)
        back[:3, :3], back[:3, 3] = tb["rot"], tb["mid"] - 0.01 * w * tb["rot"][:, 2]
        h = tb["lines"] * tb["step"] + 0.4 * tb["step"]
        cmds.append(SetObject(mg.Box([w, h, 1e-4 * w]),
                              mg.MeshBasicMaterial(color=0xFFFFFF, opacity=0.75), node("text", "back")))
        cmds.append(SetTransform(back, node("text", "back")))
        for k in range(n):
            for li, line in enumerate(self.label_lines(k)):
                tex = mg.GenericTexture(
                    {"type": "_text", "text": line, "font_size": 34, "font_face": "sans-serif"}
                )
                mat = mg.MeshBasicMaterial(color=0xFFFFFF, map=tex, transparent=True, side=0)  # front only
                path = node("text", f"f{k}", f"l{li}")
                cmds.append(SetObject(mg.Box([w, w, 1e-4 * w]), mat, path))
                m = np.eye(4)
                m[:3, :3], m[:3, 3] = tb["rot"], tb["centres"][li]
                cmds.append(SetTransform(m, path))
            fnode = node("text", f"f{k}")
            cmds.append(SetProperty("visible", k == 0, fnode))
            if n > 1:  # discrete keys: shown from k - 1/2 to k + 1/2 (the nearest frame)
                keys = {0: k == 0, last: k == last}
                if k > 0:
                    keys[k - 0.5] = True
                if k < last:
                    keys[k + 0.5] = False
                for t in sorted(keys):
                    prop(fnode, t, "visible", "boolean", keys[t])

    # ------------------------------------------------------------------ stability colours
    def _geometry_stability(self) -> list[list[bool]] | None:
        """Per frame, per geometry object: the colour flag (True green, False red).

        Without ``modes`` every object takes the frame's verdict. With ``modes``, on an
        unstable frame the objects that move in the unstable mode are red and the others
        green: each object's displacement (largest over its bounding-box corners, to first
        order, largest over the mode's columns) is compared with the largest one; at least
        :data:`MODE_FRACTION` of it is red (:data:`MODE_FRACTION` module docs).
        """
        if self.stable is None:
            return None
        ng = len(self.visual_model.geometryObjects)
        out = []
        for k, q in enumerate(self.frames):
            if not self.stable[k] and self.unstable_joints and self.unstable_joints[k] is not None:
                red = self.unstable_joints[k]
                out.append([go.parentJoint not in red for go in self.visual_model.geometryObjects])
                continue
            if self.stable[k] or self.modes is None or self.modes[k] is None or not self.modes[k].size:
                out.append([self.stable[k]] * ng)
                continue
            base = [box @ m[:3, :3].T + m[:3, 3] for m, box in zip(self._frame_oMg[k], self._local_boxes)]
            disp = np.zeros(ng)
            for v in self.modes[k].T:
                nv = float(np.linalg.norm(v))
                if nv == 0:
                    continue
                oMg, _, _ = self._placements(q + (_MODE_STEP / nv) * v)
                moved = [box @ m[:3, :3].T + m[:3, 3] for m, box in zip(oMg, self._local_boxes)]
                disp = np.maximum(
                    disp, [float(np.linalg.norm(b - a, axis=1).max()) for a, b in zip(base, moved)]
                )
            top = float(disp.max()) if ng else 0.0
            if top <= 0:
                out.append([False] * ng)
            else:
                out.append([bool(d < MODE_FRACTION * top) for d in disp])
        return out

    # ------------------------------------------------------------------ arrow & marker layout
    def _layout_arrow(self) -> None:
        """Arrow placement per frame for the end force and each dead load: base point, unit
        direction, length (one length scale for all: ``arrow_length`` for the largest
        magnitude); style chosen per arrow so it stays outside the robot (``arrow_style``)."""
        self._arrow_ends: list[np.ndarray] = []
        self._arrows: list[dict] = []
        self.arrow_style = None
        n = len(self.frames)
        specs = []
        if self.forces is not None:
            pos = [self._frame_oMf[k][:3, 3] for k in range(n)]
            specs.append(("force", self.frame_id, pos, self.forces, "force", "F = {:.3g} N"))
        for i, (name, fid, fl) in enumerate(self.loads):
            pos = [self._extra_pos[k][i] for k in range(n)]
            specs.append((f"load{i}", fid, pos, fl, "load", name + ": {:.3g} N"))
        if not specs:
            return
        fmax = max(float(np.linalg.norm(f)) for spec in specs for f in spec[3])
        L = float(self.arrow_length)
        self._arrow_gap = 0.025 * self.scene_size
        for node_name, fid, pos, forces, cls, fmt in specs:
            mags = [float(np.linalg.norm(f)) for f in forces]
            dirs, prev = [], np.array([0.0, 0.0, -1.0])
            for k in range(n):
                d = forces[k] / mags[k] if mags[k] > 0 else prev
                prev = d
                dirs.append(d)
            lengths = [L * m / fmax if fmax > 0 else 0.0 for m in mags]
            style = self._arrow_style_opt
            parent = int(self.model.frames[fid].parentJoint)
            if style == "auto":
                style = "tail"
                clear = 0.04 * self.scene_size
                for k in range(n):
                    if lengths[k] <= 0:
                        continue
                    along = np.linspace(0.2, 1.0, 9) * (lengths[k] + self._arrow_gap)
                    samples = pos[k] + np.outer(along, dirs[k])
                    dist = _distances_to_links(
                        samples, self._frame_joints[k], self.model, (parent, pos[k])
                    )
                    # through the robot: closer to a link than to the load point, and close
                    if np.any(dist < np.minimum(clear, 0.5 * along)):
                        style = "head"
                        break
            tails = []  # tail (start) of the drawn arrow, per frame
            for k in range(n):
                if style == "tail":
                    tails.append(pos[k] + self._arrow_gap * dirs[k])
                else:
                    tails.append(pos[k] - (self._arrow_gap + lengths[k]) * dirs[k])
            for k in range(n):
                if lengths[k] > 0:
                    self._arrow_ends += [tails[k], tails[k] + lengths[k] * dirs[k]]
            self._arrows.append(
                {
                    "node": node_name,
                    "cls": cls,
                    "style": style,
                    "tails": tails,
                    "dirs": dirs,
                    "lengths": lengths,
                    # where the label sits: on the middle of the arrow (the page lifts it above)
                    "label_points": [t + 0.5 * lengths[k] * dirs[k] for k, t in enumerate(tails)],
                    "texts": [fmt.format(m) if m > 0 else "" for m in mags],
                }
            )
        if self.forces is not None:
            self.arrow_style = self._arrows[0]["style"]

    def _layout_marker(self) -> None:
        """The critical marker: a ring around the end point (larger than whatever sits
        there) facing the camera, and a pin rising from it that carries the label."""
        self._marker_points: list[np.ndarray] = []
        if self.critical_index is None:
            return
        k = self.critical_index
        p = self._frame_oMf[k][:3, 3]
        r_end = 0.0
        for m, box in zip(self._frame_oMg[k], self._local_boxes):
            if np.linalg.norm(m[:3, 3] - p) < 1e-6 * self.scene_size + 1e-9:
                r_end = max(r_end, 0.5 * float(np.max(box.max(axis=0) - box.min(axis=0))))
        R = max(0.05 * self.scene_size, 1.8 * r_end)
        self._ring = (p.copy(), R)
        up = np.array([0.0, 0.0, 1.0])
        self._pin_base = p + R * up
        self._pin_top = p + (R + 0.12 * self.scene_size) * up
        self._marker_points = [p + R * up, p - R * up, self._pin_top]
        for ax in (np.array([1.0, 0, 0]), np.array([0, 1.0, 0])):
            self._marker_points += [p + R * ax, p - R * ax]

    def frame_bodies(self, k: int) -> list[tuple[pin.GeometryObject, np.ndarray, bool | None]]:
        """What frame ``k`` draws, for other renderers (:mod:`vjm_pin.viz.figures`): per
        geometry object, ``(object, (4, 4) world placement (m), colour flag)`` with the flag
        True (stable, green), False (red: unstable, or a part of the unstable mode) or None
        (no stability given, or a joint marker that keeps its colour)."""
        if not 0 <= int(k) < len(self.frames):
            raise InputError(f"frame {k} is outside 0..{len(self.frames) - 1}")
        out = []
        for gi, go in enumerate(self.visual_model.geometryObjects):
            flag = None
            if self._geom_stable is not None and self.recolor(go.name):
                flag = bool(self._geom_stable[k][gi])
            out.append((go, self._frame_oMg[k][gi], flag))
        return out

    def ghost_bodies(self) -> list[tuple[pin.GeometryObject, np.ndarray]] | None:
        """Per geometry object of the ghost robot ``(object, (4, 4) placement)``, or None."""
        if self._ghost_oMg is None:
            return None
        return list(zip(self.visual_model.geometryObjects, self._ghost_oMg))

    def end_position(self, k: int) -> np.ndarray | None:
        """(3,) world position (m) of ``frame_name`` at frame ``k``, or None without it."""
        m = self._frame_oMf[int(k)]
        return None if m is None else np.array(m[:3, 3])

    def _center(self) -> np.ndarray:
        lo, hi = self.bbox
        return 0.5 * (lo + hi)

    def floor_height(self) -> float:
        """Height of the grid (m, world z): the world floor z = 0, or lower when the robot
        reaches below it."""
        return min(0.0, float(self.bbox[0][2]))

    def _legend(self) -> list[dict]:
        """The legend rows of the page (shape, CSS colour, text); empty without ``legend``."""
        legend: list[dict] = []
        if not self.legend:
            return legend
        any_unstable = (self.stable is not None and not all(self.stable)) or any(
            not s for br in self.branches for q, s in zip(br.frames, br.stable) if q is not None
        )
        if self.stable is not None or self.branches:
            legend.append(
                {"shape": "box", "color": _css(STABLE_COLOR), "text": "stable equilibrium"}
            )
            if any_unstable or self.branches:
                legend.append(
                    {
                        "shape": "box",
                        "color": _css(UNSTABLE_COLOR),
                        "text": "unstable equilibrium"
                        + (
                            " (red: the parts that take part in its unstable mode)"
                            if (
                                self.modes is not None
                                and any(m is not None and m.size for m in self.modes)
                            )
                            or self.unstable_joints
                            else ""
                        ),
                    }
                )
        if self.critical_index is not None:
            legend.append(
                {"shape": "ring", "color": _css(CRITICAL_COLOR), "text": "critical point"}
            )
        if self._arrows:
            what = (["force on the end"] if self.forces is not None else []) + (
                ["dead loads"] if self.loads else []
            )
            legend.append(
                {
                    "shape": "arrow",
                    "color": _css(FORCE_COLOR),
                    "text": f"{' and '.join(what)} (length ∝ |F|)",
                }
            )
        if self.closures:
            legend.append(
                {
                    "shape": "box",
                    "color": _css(CLOSURE_COLOR),
                    "text": "loop closure (frame_a, frame_b)",
                }
            )
        if self.ellipsoid is not None:
            legend.append(
                {
                    "shape": "box",
                    "color": _css(ELLIPSOID_COLOR[:3] + (0.6,)),
                    "text": self.ellipsoid_label,
                }
            )
        if self.ghost_q is not None:
            legend.append(
                {
                    "shape": "box",
                    "color": _css(GHOST_COLOR[:3] + (0.6,)),
                    "text": "unloaded robot",
                }
            )
        if self.points is not None:
            legend += [
                {"shape": "box", "color": _css(rgba), "text": t}
                for rgba, t in self.points["legend"]
            ]
        legend += [{"shape": "note", "color": "transparent", "text": t} for t in self.legend_notes]
        return legend

    def page_setup(self) -> dict:
        """What the exported page's script needs: labels, anchored labels, camera, legend."""
        c = self._center()

        def sh(p):
            return [float(v) for v in (np.asarray(p, float) - c)]

        anchors = []
        n = len(self.frames)
        for arrow in self._arrows:
            anchors.append(
                {
                    "cls": arrow["cls"],
                    "pos": [sh(p) for p in arrow["label_points"]],
                    "text": arrow["texts"],
                }
            )
        if self.critical_index is not None:
            anchors.append(
                {
                    "cls": "critical",
                    "pos": [sh(self._pin_top)] * n,
                    "text": [self.critical_label] * n,
                }
            )
        legend = self._legend()
        return {
            "fps": self.fps,
            "nframes": n,
            "labels": self.frame_labels,
            "title": self.title_text,
            "anchors": anchors,
            "legend": legend,
            "slider": self.slider,
            "camera": {
                "direction": [float(v) for v in self.camera_direction],
                "fov": _CAMERA_FOV,
                "points": [sh(p) for p in self._view_points],
                "fill": 0.85,
            },
        }

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
        from meshcat.commands import Delete
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

        def color_track(obj_path: MPath, flags: list[bool]) -> None:
            """Sharp colour switches (a key 1e-3 frame before each change holds the old one)."""
            prop(obj_path, 0, "material.color", "color", col(flags[0]))
            for k in range(1, n):
                if flags[k] != flags[k - 1]:
                    prop(obj_path, k - _EPS_FRAME, "material.color", "color", col(flags[k - 1]))
                    prop(obj_path, k, "material.color", "color", col(flags[k]))
            prop(obj_path, last, "material.color", "color", col(flags[last]))

        def bool_track(path: MPath, name: str, flags: list[bool]) -> None:
            for k in range(n):
                prop(path, k, name, "boolean", bool(flags[k]))

        self._robot_commands(cmds, node, track_transform, color_track, bool_track)
        self._overlay_commands(cmds, node, prop, track_transform, bool_track)
        if self._text_box is not None:
            self._text_commands(cmds, node, prop)

        self._critical_commands(cmds, node)
        self._camera_commands(cmds, root)
        if n > 1:
            cmds.append(
                _SetAnimationAt(anim, node("animation"), repetitions=(math.inf if self.loop else 1))
            )
        return cmds


    def _robot_commands(self, cmds, node, track_transform, color_track, bool_track) -> None:
        """The robot (animated, stability colours), the other branches (animated, shown where
        they exist) and the ghost (static); helpers of :meth:`commands`."""
        from meshcat.commands import SetObject, SetProperty, SetTransform
        from meshcat.path import Path as MPath

        n = len(self.frames)
        # --- robot (animated), other branches (animated) and ghost (static)
        names = _node_names(self.visual_model)
        for gi, go in enumerate(self.visual_model.geometryObjects):
            conv = _meshcat_geometry(go)
            if conv is None:
                continue
            geom, intrinsic = conv
            base_rgba = tuple(float(c) for c in go.meshColor)
            recol = self.stable is not None and self.recolor(go.name)
            gflags = [self._geom_stable[k][gi] for k in range(n)] if recol else []
            rgba = (STABLE_COLOR if gflags[0] else UNSTABLE_COLOR) if recol else base_rgba
            path = node("robot", names[gi])
            cmds.append(SetObject(geom, _material(rgba), path))
            obj_path = MPath(path.entries + ("<object>",))
            cmds.append(SetTransform(intrinsic, obj_path))
            mats = [self._frame_oMg[k][gi] for k in range(n)]
            cmds.append(SetTransform(mats[0], path))
            if any(not np.allclose(m, mats[0], atol=1e-12) for m in mats[1:]):
                track_transform(path, mats)
            if recol and len(set(gflags)) > 1:
                color_track(obj_path, gflags)
            for bi, br in enumerate(self.branches):
                shown = [q is not None for q in br.frames]
                first = shown.index(True) if any(shown) else 0
                # hidden frames hold the nearest shown pose (no flying in from elsewhere)
                bm, prev = [], None
                for k in range(n):
                    m = self._branch_oMg[bi][k]
                    if m is None:
                        m = prev if prev is not None else self._branch_oMg[bi][first]
                    if m is None:
                        m = self._frame_oMg[k]
                    bm.append(m[gi])
                    prev = self._branch_oMg[bi][k] or prev
                flags = [br.stable[k] if shown[k] else br.stable[first] for k in range(n)]
                bpath = node(f"branch{bi}", names[gi])
                b_rgba = (
                    (STABLE_COLOR if flags[0] else UNSTABLE_COLOR)
                    if self.recolor(go.name)
                    else base_rgba
                )
                cmds.append(SetObject(_meshcat_geometry(go)[0], _material(b_rgba), bpath))
                b_obj = MPath(bpath.entries + ("<object>",))
                cmds.append(SetTransform(intrinsic, b_obj))
                cmds.append(SetTransform(bm[0], bpath))
                track_transform(bpath, bm)
                if self.recolor(go.name) and len(set(flags)) > 1:
                    color_track(b_obj, flags)
            if self._ghost_oMg is not None:
                gpath = node("ghost", names[gi])
                ghost_geom = _meshcat_geometry(go)[0]  # fresh uuids: no shared three.js objects
                cmds.append(SetObject(ghost_geom, _material(GHOST_COLOR), gpath))
                cmds.append(SetTransform(intrinsic, MPath(gpath.entries + ("<object>",))))
                cmds.append(SetTransform(self._ghost_oMg[gi], gpath))
        for bi, br in enumerate(self.branches):
            shown = [q is not None for q in br.frames]
            cmds.append(SetProperty("visible", shown[0], node(f"branch{bi}")))
            if len(set(shown)) > 1:
                bool_track(node(f"branch{bi}"), "visible", shown)

    def _critical_commands(self, cmds, node) -> None:
        """The critical marker (:meth:`commands`)."""
        import meshcat.geometry as mg
        from meshcat.commands import SetObject, SetTransform

        # --- critical marker: a ring (facing the camera) around the end point of the
        # critical frame, larger than the end sphere, and a pin above it for the label
        if self.critical_index is not None:
            p, R = self._ring
            mat = _flat_material(CRITICAL_COLOR)
            verts, faces = _torus(R, 0.14 * R)
            rot = pin.Quaternion.FromTwoVectors(
                np.array([0.0, 0.0, 1.0]), self.camera_direction
            ).toRotationMatrix()
            ring = np.eye(4)
            ring[:3, :3], ring[:3, 3] = rot, p
            cmds.append(
                SetObject(mg.TriangularMeshGeometry(verts, faces), mat, node("critical", "ring"))
            )
            cmds.append(SetTransform(ring, node("critical", "ring")))
            h = float(np.linalg.norm(self._pin_top - self._pin_base))
            stick = np.eye(4)
            stick[:3, :3] = _Y_TO_Z[:3, :3]
            stick[:3, 3] = 0.5 * (self._pin_base + self._pin_top)
            cmds.append(
                SetObject(
                    mg.Cylinder(h, 0.05 * R),
                    _flat_material(CRITICAL_COLOR),
                    node("critical", "pin"),
                )
            )
            cmds.append(SetTransform(stick, node("critical", "pin")))
            cmds.append(
                SetObject(
                    mg.Sphere(0.3 * R), _flat_material(CRITICAL_COLOR), node("critical", "head")
                )
            )
            cmds.append(SetTransform(_translation(self._pin_top), node("critical", "head")))

    def _camera_commands(self, cmds, root) -> None:
        """Scene shift, grid, axes and camera (:meth:`commands`)."""
        from meshcat.commands import SetProperty, SetTransform
        from meshcat.path import Path as MPath

        # --- camera. meshcat's orbit controls look at the world origin (their target is not
        # reachable by commands; the exported page's script sets it), so the scene is shifted
        # instead: the robot, the grid and the axes are translated by -centre of the bounding
        # box, and the camera sits at camera_direction * distance, with a 40° field of view.
        # The grid is the floor (z = 0, or the robot's lowest point when it reaches below),
        # with cells of a 1-2-5 size near a sixth of the scene.
        lo, hi = self.bbox
        center = self._center()
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.05)
        dist = 1.05 * radius / math.sin(math.radians(_CAMERA_FOV) / 2.0)
        off = dist * self.camera_direction
        shift = _translation(-center)
        cmds.append(SetTransform(shift, root))
        cell = _nice(self.scene_size / 6.0)
        grid = _translation(-center + np.array([0.0, 0.0, self.floor_height()]))
        grid[:3, :3] *= cell / 0.5  # meshcat's grid: 20 m, 40 cells of 0.5 m
        cmds.append(SetTransform(grid, MPath(("Grid",))))
        axes = _translation(-center)
        axes[:3, :3] *= 0.25 * self.scene_size  # meshcat's axes are 1 m long
        cmds.append(SetTransform(axes, MPath(("Axes",))))
        cam = MPath(("Cameras", "default", "rotated", "<object>"))
        cmds.append(SetProperty("fov", _CAMERA_FOV, cam))
        # the camera lives in the frame "rotated" (y up): world (x, y, z) -> (x, z, -y)
        cmds.append(SetProperty("position", [float(off[0]), float(off[2]), float(-off[1])], cam))

    def _overlay_commands(self, cmds, node, prop, track_transform, bool_track) -> None:
        """Append the commands of the force and dead-load arrows, the closure markers and the
        ellipsoid (helpers of :meth:`commands`: ``node`` makes a path under the root, ``prop``
        keys a property, ``track_transform``/``bool_track`` animate a node)."""
        for part in (self._arrow_commands, self._closure_commands, self._ellipsoid_commands):
            part(cmds, node, prop, track_transform, bool_track)
        if self.points is not None:
            import meshcat.geometry as mg
            from meshcat.commands import SetObject

            pc = self.points
            cmds.append(
                SetObject(
                    mg.PointsGeometry(pc["positions"].T, pc["colors"].T),
                    mg.PointsMaterial(size=pc["size"]),
                    node("points"),
                )
            )

    def _arrow_commands(self, cmds, node, prop, track_transform, bool_track) -> None:
        """Force and dead-load arrows (:meth:`_overlay_commands`)."""
        import meshcat.geometry as mg
        from meshcat.commands import SetObject, SetProperty, SetTransform
        from meshcat.path import Path as MPath

        n = len(self.frames)
        # --- force arrows (end force, dead loads): node at the arrow's tail with +y along F,
        # the shaft scaled along y
        L = float(self.arrow_length)
        head_len, head_r, shaft_r = 0.2 * L, 0.07 * L, 0.025 * L
        ey = np.array([0.0, 1.0, 0.0])
        for arrow in self._arrows:
            fpath = node(arrow["node"])
            spath, hpath = node(arrow["node"], "shaft"), node(arrow["node"], "head")
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
            mats, shaft_scale, head_scale, visible = [], [], [], []
            for k in range(n):
                m = np.eye(4)
                m[:3, 3] = arrow["tails"][k]
                m[:3, :3] = pin.Quaternion.FromTwoVectors(ey, arrow["dirs"][k]).toRotationMatrix()
                mats.append(m)
                length = arrow["lengths"][k]
                hs = min(1.0, length / (2.0 * head_len)) if head_len > 0 else 1.0
                shaft_scale.append(max(length - hs * head_len, 1e-6))
                head_scale.append(max(hs, 1e-6))
                visible.append(bool(length > 0))
            cmds.append(SetTransform(mats[0], fpath))
            if n > 1:
                track_transform(fpath, mats)
                for k in range(n):
                    prop(spath, k, "scale", "vector3", [1.0, shaft_scale[k], 1.0])
                    prop(hpath, k, "position", "vector3", [0.0, shaft_scale[k], 0.0])
                    prop(hpath, k, "scale", "vector3", [head_scale[k]] * 3)
                bool_track(fpath, "visible", visible)
            cmds.append(SetProperty("scale", [1.0, shaft_scale[0], 1.0], spath))
            cmds.append(SetTransform(_translation([0.0, shaft_scale[0], 0.0]), hpath))
            cmds.append(SetProperty("scale", [head_scale[0]] * 3, hpath))
            cmds.append(SetProperty("visible", visible[0], fpath))

    def _closure_commands(self, cmds, node, prop, track_transform, bool_track) -> None:
        """Loop-closure markers (:meth:`_overlay_commands`)."""
        import meshcat.geometry as mg
        from meshcat.commands import SetObject, SetTransform
        from meshcat.path import Path as MPath

        n = len(self.frames)
        # --- loop closures: a violet cube at frame_b and one turned 45° at frame_a (they
        # coincide where the loop is closed), following the frames
        # larger than the joint spheres there, translucent: the joint stays visible inside
        joint_size = max(
            [
                float(np.max(box.max(axis=0) - box.min(axis=0)))
                for go, box in zip(self.visual_model.geometryObjects, self._local_boxes)
                if go.name.startswith(JOINT_MARKER_PREFIX) and not go.name.endswith(":springs")
            ],
            default=0.0,
        )
        edge = max(0.025 * self.scene_size, 1.2 * joint_size)
        nl = len(self.loads)
        turn = np.eye(4)
        turn[:3, :3] = pin.utils.rotate("z", math.pi / 4) @ pin.utils.rotate("x", math.pi / 4)
        for ci, (_, _, _) in enumerate(self.closures):
            for j, (part, size, rot) in enumerate((("b", edge, np.eye(4)), ("a", 0.8 * edge, turn))):
                path = node(f"closure{ci}", part)
                cmds.append(SetObject(mg.Box([size] * 3), _closure_material(), path))
                cmds.append(SetTransform(rot, MPath(path.entries + ("<object>",))))
                mats = [_translation(self._extra_pos[k][nl + 2 * ci + (1 - j)]) for k in range(n)]
                cmds.append(SetTransform(mats[0], path))
                if any(not np.allclose(m, mats[0], atol=1e-12) for m in mats[1:]):
                    track_transform(path, mats)

    def _ellipsoid_commands(self, cmds, node, prop, track_transform, bool_track) -> None:
        """The compliance ellipsoid (:meth:`_overlay_commands`)."""
        import meshcat.geometry as mg
        from meshcat.commands import SetObject, SetProperty, SetTransform

        n = len(self.frames)
        # --- compliance ellipsoid at the end frame: node "ellipsoid" (position, principal
        # axes) and its unit sphere "ellipsoid/shape" scaled by the semi-axes
        if self.ellipsoid is not None:
            epath, shape = node("ellipsoid"), node("ellipsoid", "shape")
            cmds.append(SetObject(mg.Sphere(1.0), _material(ELLIPSOID_COLOR), shape))
            first = next((e for e in self.ellipsoid if e is not None), None)
            mats, scales, visible = [], [], []
            for k in range(n):
                e = self.ellipsoid[k] or first
                m = np.eye(4)
                m[:3, 3] = self._frame_oMf[k][:3, 3]
                if e is not None:
                    m[:3, :3] = e[1]
                mats.append(m)
                scales.append([max(float(a), 1e-9) for a in (e[0] if e is not None else np.ones(3))])
                visible.append(self.ellipsoid[k] is not None)
            cmds.append(SetTransform(mats[0], epath))
            cmds.append(SetProperty("scale", scales[0], shape))
            cmds.append(SetProperty("visible", visible[0], epath))
            if n > 1:
                track_transform(epath, mats)
                for k in range(n):
                    prop(shape, k, "scale", "vector3", scales[k])
                if len(set(visible)) > 1:
                    bool_track(epath, "visible", visible)

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
        setup = self.page_setup()
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
  body {{ margin: 0; font-family: sans-serif; overflow: hidden; }}
  #vjm-anchors {{ position: fixed; left: 0; top: 0; width: 100vw; height: 100vh; overflow: hidden;
    pointer-events: none; }}
  #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
  .vjm-box {{ position: absolute; padding: 0.3em 0.6em; color: #fff;
    background: rgba(0, 0, 0, 0.5); border-radius: 0.3em; line-height: 1.35;
    font-size: clamp(11px, 2.3vmin, 30px); }}
  #vjm-overlay {{ left: 8px; top: 8px; pointer-events: none; white-space: pre-wrap;
    max-width: calc(100vw - 270px); }}  /* keep clear of meshcat's controls bar (top right) */
  #vjm-title {{ font-weight: bold; }}
  #vjm-legend {{ left: 8px; bottom: 8px; pointer-events: none; font-size: clamp(10px, 2vmin, 26px); }}
  .vjm-key {{ display: inline-block; width: 1.6em; height: 0.75em; margin-right: 0.5em;
    vertical-align: middle; box-sizing: border-box; }}
  #vjm-controls {{ right: 8px; bottom: 8px; display: flex; align-items: center; gap: 0.5em;
    font-size: clamp(10px, 2vmin, 26px); }}
  #vjm-controls button {{ font-size: inherit; }}
  #vjm-slider {{ width: 28vw; }}
  .vjm-anchor {{ position: absolute; transform: translate(-50%, -50%); pointer-events: none;
    white-space: nowrap; font-size: clamp(10px, 2.1vmin, 28px); padding: 0.1em 0.4em;
    border-radius: 0.3em; background: rgba(255, 255, 255, 0.88); color: #222;
    border: 2px solid #888; display: none; }}
  .vjm-anchor.critical {{ color: #90009a; border-color: #e000e0; font-weight: bold; }}
  .vjm-anchor.force {{ color: #5a4a00; border-color: #e6c200; transform: translate(-50%, -160%); }}
  .vjm-anchor.critical {{ transform: translate(-50%, -140%); }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="vjm-overlay" class="vjm-box"><div id="vjm-title" class="vjm-t"></div><div id="vjm-label" class="vjm-t"></div></div>
<div id="vjm-anchors"></div>
<div id="vjm-legend" class="vjm-box"></div>
<div id="vjm-controls" class="vjm-box"><button id="vjm-play" title="play / pause">&#9199;</button>
<input id="vjm-slider" type="range"><span id="vjm-value" class="vjm-t"></span>
<button id="vjm-png" title="save the picture with its labels as PNG">PNG</button></div>
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
  var pane = document.getElementById("meshcat-pane");
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

  // --- camera: look at the middle of the robot (all frames) and fill the window with it
  function dot(a, b) {{ return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }}
  function cross(a, b) {{
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  }}
  function unit(a) {{ var l = Math.sqrt(dot(a, a)); return [a[0] / l, a[1] / l, a[2] / l]; }}
  function size() {{  // of the WebGL canvas (what the camera's aspect must match)
    var el = viewer.renderer.domElement;
    return [el.clientWidth || window.innerWidth, el.clientHeight || window.innerHeight];
  }}
  function fit() {{
    var c = setup.camera, d = c.direction, pts = c.points;
    var cam = viewer.camera, ctl = viewer.controls;
    var sz = size(), w = sz[0], h = sz[1];
    var f = [-d[0], -d[1], -d[2]];
    var r = cross(f, [0, 0, 1]);
    if (dot(r, r) < 1e-12) r = cross(f, [0, 1, 0]);
    r = unit(r);
    var u = cross(r, f);
    var lr = Infinity, hr = -Infinity, lu = Infinity, hu = -Infinity;
    for (var i = 0; i < pts.length; i++) {{
      var pr = dot(pts[i], r), pu = dot(pts[i], u);
      lr = Math.min(lr, pr); hr = Math.max(hr, pr); lu = Math.min(lu, pu); hu = Math.max(hu, pu);
    }}
    var cr = 0.5 * (lr + hr), cu = 0.5 * (lu + hu);
    var ctr = [cr * r[0] + cu * u[0], cr * r[1] + cu * u[1], cr * r[2] + cu * u[2]];
    var tv = Math.tan(c.fov * Math.PI / 360) * c.fill, th = tv * w / h;
    var D = 1e-6;
    for (var i = 0; i < pts.length; i++) {{
      var q = [pts[i][0] - ctr[0], pts[i][1] - ctr[1], pts[i][2] - ctr[2]];
      var qd = dot(q, d);
      D = Math.max(D, qd + Math.abs(dot(q, r)) / th, qd + Math.abs(dot(q, u)) / tv);
    }}
    var p = [ctr[0] + D * d[0], ctr[1] + D * d[1], ctr[2] + D * d[2]];
    // the camera and the orbit target live in the frame "rotated" (y up)
    cam.position.set(p[0], p[2], -p[1]);
    ctl.target.set(ctr[0], ctr[2], -ctr[1]);
    cam.fov = c.fov; cam.aspect = w / h; cam.near = D / 200; cam.far = D * 200;
    cam.updateProjectionMatrix();
    ctl.update();
    viewer.set_dirty();
  }}
  var fitted = "", anchors = null;
  function refit() {{  // at start and whenever the canvas changes size
    var sz = size().join("x");
    if (sz !== fitted) {{ fitted = sz; fit(); }}
  }}
  refit();
  window.vjmFitCamera = fit;
  // refit inside meshcat's own render call, so no frame is drawn with a stale camera
  var render = viewer.render.bind(viewer);
  viewer.render = function () {{
    refit();
    render();
    if (anchors) placeAnchors(frameAt(viewer.animator.time || 0));
  }};

  // --- legend
  var legend = document.getElementById("vjm-legend");
  if (!setup.legend.length) legend.style.display = "none";
  setup.legend.forEach(function (e) {{
    var row = document.createElement("div");
    var key = document.createElement("span");
    key.className = "vjm-key";
    key.dataset.shape = e.shape; key.dataset.color = e.color;
    if (e.shape === "ring") {{
      key.style.border = "0.2em solid " + e.color; key.style.borderRadius = "50%";
      key.style.width = "0.95em"; key.style.height = "0.95em"; key.style.margin = "0 1.15em 0 0.3em";
    }} else if (e.shape === "arrow") {{
      key.style.background = "linear-gradient(to right, " + e.color + " 70%, transparent 70%)";
      key.style.height = "0.3em";
      key.style.clipPath = "none";
    }} else {{
      key.style.background = e.color;
    }}
    var t = document.createElement("span");
    t.className = "vjm-t"; t.textContent = e.text;
    row.appendChild(key); row.appendChild(t); legend.appendChild(row);
  }});

  // --- labels pinned to points of the scene (force, critical point)
  anchors = setup.anchors.map(function (a) {{
    var el = document.createElement("div");
    el.className = "vjm-anchor vjm-t " + a.cls;
    document.getElementById("vjm-anchors").appendChild(el);
    return {{ a: a, el: el }};
  }});
  var v3 = viewer.camera.position.clone();
  function placeAnchors(k) {{
    var cam = viewer.camera;
    if (cam.updateWorldMatrix) cam.updateWorldMatrix(true, false); else cam.updateMatrixWorld(true);
    var sz = size(), w = sz[0], h = sz[1];
    anchors.forEach(function (o) {{
      var p = o.a.pos[k], text = o.a.text[k];
      v3.set(p[0], p[2], -p[1]);  // meshcat's z-up scene in three.js' y-up world
      v3.project(cam);
      if (!text || v3.z > 1) {{ o.el.style.display = "none"; return; }}
      o.el.style.display = "block";
      o.el.textContent = text;
      o.el.style.left = ((v3.x + 1) / 2 * w) + "px";
      o.el.style.top = ((1 - v3.y) / 2 * h) + "px";
    }});
  }}

  // --- load slider (in the units of setup.slider) and play / pause
  var slider = document.getElementById("vjm-slider"), value = document.getElementById("vjm-value");
  var sl = setup.slider, dragging = false;
  function fmt(x) {{ return parseFloat(x.toPrecision(4)).toString(); }}
  if (sl && n > 1) {{
    var lo = Math.min.apply(null, sl.values), hi = Math.max.apply(null, sl.values);
    slider.min = lo; slider.max = hi; slider.step = (hi > lo) ? (hi - lo) / 1000 : 1;
    slider.addEventListener("input", function () {{
      dragging = true;
      var x = parseFloat(slider.value), best = 0;
      for (var k = 1; k < n; k++)
        if (Math.abs(sl.values[k] - x) < Math.abs(sl.values[best] - x)) best = k;
      window.vjmSeekFrame(best);
    }});
    slider.addEventListener("change", function () {{ dragging = false; }});
  }} else {{
    slider.style.display = "none";
  }}
  var play = document.getElementById("vjm-play");
  if (n < 2) play.style.display = "none";
  play.addEventListener("click", function () {{
    var a = viewer.animator;
    if (a.playing) a.pause(); else a.play();
  }});

  // --- PNG of the picture with its labels (the WebGL canvas alone would lose them)
  function snapshot(done) {{
    var img = new Image();
    img.onload = function () {{
      var cv = document.createElement("canvas");
      cv.width = img.width; cv.height = img.height;
      var s = img.width / size()[0], ctx = cv.getContext("2d");
      ctx.drawImage(img, 0, 0);
      var boxes = document.querySelectorAll(".vjm-box:not(#vjm-controls), .vjm-anchor, .vjm-key");
      boxes.forEach(function (el) {{
        var st = getComputedStyle(el);
        if (st.display === "none" || st.visibility === "hidden") return;
        var b = el.getBoundingClientRect();
        if (el.dataset.shape === "ring" || el.dataset.shape === "arrow") {{
          ctx.strokeStyle = el.dataset.color; ctx.fillStyle = el.dataset.color;
          if (el.dataset.shape === "ring") {{
            ctx.lineWidth = 0.2 * b.height * s; ctx.beginPath();
            ctx.arc((b.left + b.width / 2) * s, (b.top + b.height / 2) * s, 0.4 * b.height * s, 0, 2 * Math.PI);
            ctx.stroke();
          }} else {{
            ctx.fillRect(b.left * s, b.top * s, 0.7 * b.width * s, b.height * s);
          }}
          return;
        }}
        ctx.fillStyle = st.backgroundColor;
        ctx.fillRect(b.left * s, b.top * s, b.width * s, b.height * s);
        var bw = parseFloat(st.borderTopWidth);
        if (bw > 0) {{
          ctx.strokeStyle = st.borderTopColor; ctx.lineWidth = bw * s;
          ctx.strokeRect(b.left * s, b.top * s, b.width * s, b.height * s);
        }}
      }});
      document.querySelectorAll(".vjm-t").forEach(function (el) {{
        var st = getComputedStyle(el);
        if (st.display === "none" || st.visibility === "hidden" || !el.textContent) return;
        if (el.closest("#vjm-controls")) return;
        var b = el.getBoundingClientRect(), fs = parseFloat(st.fontSize);
        var lh = parseFloat(st.lineHeight) || 1.35 * fs;
        ctx.font = st.fontWeight + " " + fs * s + "px " + st.fontFamily;
        ctx.fillStyle = st.color; ctx.textBaseline = "middle";
        var pad = parseFloat(st.paddingLeft) || 0, pt = parseFloat(st.paddingTop) || 0;
        el.innerText.split("\\n").forEach(function (line, i) {{
          ctx.fillText(line, (b.left + pad) * s, (b.top + pt + (i + 0.5) * lh) * s);
        }});
      }});
      done(cv.toDataURL("image/png"));
    }};
    img.src = viewer.capture_image();
  }}
  window.vjmSnapshot = snapshot;
  document.getElementById("vjm-png").addEventListener("click", function () {{
    snapshot(function (url) {{
      var a = document.createElement("a");
      a.href = url; a.download = "vjm-view.png"; document.body.appendChild(a); a.click(); a.remove();
    }});
  }});

  function fromHash() {{
    var h = new URLSearchParams(window.location.hash.replace(/^#/, ""));
    var k = parseFloat(h.get("frame")), t = parseFloat(h.get("t"));
    var hud = h.get("hud") !== "0";  // #hud=0: the scene alone (no labels, legend, controls)
    ["vjm-overlay", "vjm-legend", "vjm-controls", "vjm-anchors"].forEach(function (id) {{
      document.getElementById(id).style.visibility = hud ? "" : "hidden";
    }});
    if (isFinite(k)) window.vjmSeekFrame(k);
    else if (isFinite(t)) seekTime(t);
  }}
  window.addEventListener("hashchange", fromHash);
  fromHash();
  function update() {{
    refit();
    var k = frameAt(viewer.animator.time || 0);
    label.textContent = labels[k];
    placeAnchors(k);
    if (sl && n > 1) {{
      if (!dragging) slider.value = sl.values[k];
      value.textContent = sl.name + " = " + fmt(sl.values[k]) + " " + sl.unit;
    }}
    play.innerHTML = viewer.animator.playing ? "&#10074;&#10074;" : "&#9654;";
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
        If given, the page is also written to this file (UTF-8), atomically (a temporary
        file renamed over ``path``); check it first with :func:`vjm_pin.outputs.check_output`.
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
        from vjm_pin.outputs import atomic_output

        with atomic_output(path, "w") as fh:  # no half page if interrupted
            fh.write(page)
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

    kwargs.setdefault("scene_labels", True)
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


@dataclass(frozen=True)
class MeshVisuals:
    """The robot's own visual geometry as loaded by :func:`load_visuals`.

    Attributes:
        geometry: The visual :class:`pinocchio.GeometryModel`, or None when the URDF has no
            ``<visual>`` or its meshes could not all be loaded (draw primitives instead).
        missing: Mesh names that no folder of the search path holds
            (:func:`vjm_pin.model.meshes.resolve_meshes`), in file order.
        error: Why the meshes could not be loaded although all were found, or None.
    """

    geometry: pin.GeometryModel | None
    missing: tuple[str, ...] = ()
    error: str | None = None

    @property
    def note(self) -> str | None:
        """One line saying that primitives replace the meshes (None when nothing is missing)."""
        if self.missing:
            k = len(self.missing)
            return f"{k} mesh file{'s' if k > 1 else ''} not found: drawn as primitives"
        if self.error:
            return "meshes could not be loaded: drawn as primitives"
        return None


def load_visuals(
    model: pin.Model,
    urdf_text: str,
    package_dirs: Sequence[str | os.PathLike] = (),
    urdf_dir: str | os.PathLike | None = None,
) -> MeshVisuals:
    """Visual geometry of a URDF with ``<visual>`` meshes or primitives.

    Mesh names (``package://``, ``file://``, relative) are resolved by
    :func:`vjm_pin.model.meshes.resolve_meshes` over ``package_dirs``, ``ROS_PACKAGE_PATH``,
    ``urdf_dir`` and example-robot-data. Each mesh that is not found is named in one warning
    (``warnings.warn``) and the whole robot is then left to primitives (``geometry`` None): a
    robot with some links missing would look like a different mechanism. A mesh that is found
    but cannot be read is warned about too.
    """
    from vjm_pin.model.meshes import resolve_meshes

    if "<visual" not in urdf_text:
        return MeshVisuals(None)
    quiet = logging.getLogger("yourdfpy.urdf")  # it logs every folder a name is not in
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        res = resolve_meshes(urdf_text, package_dirs, urdf_dir)
    finally:
        quiet.setLevel(level)
    if res.missing:
        where = ", ".join(res.search_path) or "no folder"
        for name in res.missing:
            warnings.warn(
                f"mesh '{name}' not found (searched {where}; pass its package folder in package_dirs "
                "(CLI: --package-dir) or set ROS_PACKAGE_PATH); the robot is drawn with primitives",
                stacklevel=2,
            )
        return MeshVisuals(None, tuple(res.missing))
    try:
        geom = pin.buildGeomFromUrdfString(model, res.urdf, pin.GeometryType.VISUAL)
    except (ValueError, RuntimeError, OSError) as e:
        msg = " ".join(str(e).split()) or type(e).__name__
        warnings.warn(f"could not load the robot's meshes ({msg}); drawn with primitives", stacklevel=2)
        return MeshVisuals(None, (), msg)
    return MeshVisuals(geom if geom.ngeoms else None)


def mesh_geometry(
    model: pin.Model, urdf_text: str, extra_dirs=(), urdf_dir=None
) -> pin.GeometryModel | None:
    """Visual geometry of a URDF that has ``<visual>`` meshes or primitives (e.g. the robots
    of ``example-robot-data``, whose visuals the VJM generator keeps), or None when it has
    none or they cannot be loaded (then use :func:`chain_geometry`); missing meshes are
    warned about (:func:`load_visuals`)."""
    return load_visuals(model, urdf_text, extra_dirs, urdf_dir).geometry
