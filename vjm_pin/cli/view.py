"""``vjm-pin view``: the loaded robot (or its path along a force–deflection curve) in meshcat.

The library glue used by ``view`` and ``demo`` lives here too: :func:`curve_page` turns a
traced curve into an animated page, :func:`load_path`/:func:`load_frames` a serial chain's
load path, :func:`mechanism_load_path`/:func:`mechanism_frames` that of any model through
the mechanism solver (loop closures, the Orthoglide's legs, ``--load`` dead loads).

Every model kind is shown. A chain under an end deflection or wrench alone uses the serial
solver; a model with loop closures or dead loads the mechanism solver (every task component
held for ``--deflection``, loaded for ``--wrench``, free for ``--load`` alone), a curve of a
mechanism :func:`vjm_pin.analysis.curve.trace_curve` on it, with the branch left at each
critical point drawn by :func:`continued_branches` (``--all-branches``).

What is red on an unstable frame of a mechanism ("its own stability" of each part): the
verdict is that of the whole mechanism (eq. 23 on the null space of the closure and held
rows); its unstable mode (:meth:`~vjm_pin.solver.MechanismSolver.unstable_modes`) says which
parts take part. A parallel robot's legs are coloured whole: red when they carry the mode
(:func:`unstable_legs`); other mechanisms body by body: red when the mode moves the body
(:data:`vjm_pin.viz.viewer.MODE_FRACTION`). Closure frames are marked, every dead load has
its arrow, and ``--ellipsoid`` draws the translational compliance ellipsoid of the task frame
(:func:`compliance_ellipsoid`, scale in the legend).

Other outputs: ``--png`` a snapshot figure of the page's frames (:func:`write_snapshots`,
:mod:`vjm_pin.viz.figures`); ``--map`` a stiffness map as points over the robot
(:func:`_run_map`, :mod:`vjm_pin.viz.map_cloud`). Meshes: :func:`robot_visuals` with the
folders of ``--package-dir`` (:class:`MeshSearch`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from vjm_pin.cli.common import int_range, positive_float

log = logging.getLogger(__name__)

DEFAULT_STEPS = 60
DEFAULT_SNAPSHOTS = 6

EXAMPLES = (
    "vjm-pin view paper-c-s --curve --direction -1 0 0 --max-deflection 0.05 --all-branches --html curve.html",
    "vjm-pin view orthoglide-q3 --wrench -2300 -2300 -2300 --ellipsoid --html q3.html --json",
    "vjm-pin view portal-frame --load top_left 0 0 -300 --load top_right 0 0 -300 --html sway.html",
)

#: Keys of ``view --json`` (see ``vjm-pin schema view``). ``frames`` are the animation frames:
#: with ``--curve`` (``direction`` given) each has the scalars ``deflection`` and ``force``
#: along the direction, as the points of ``curve``; along a load path each has the 6-vectors
#: ``deflection`` and ``wrench`` of the equilibrium at ``load_factor`` × the load, as ``analyze``.
VIEW_KEYS = (
    "model", "parallel", "mode", "direction", "html", "scale", "frames", "critical",
    "critical_frame", "branches", "closures", "loads", "ellipsoid", "meshes", "snapshots", "map",
)
UNIT_KEYS = (
    "deflection", "force", "wrench", "stiffness_before", "stiffness_after", "direction",
    "compliance_eigenvalues",
)


def add_parser(sub):
    p = sub.add_parser(
        "view",
        help="show the loaded robot, or animate it along a force-deflection curve, in meshcat",
        description=(
            "Show MODEL in meshcat: the unloaded robot ghosted, the loaded one solid (green: stable, "
            "red: unstable), the force arrow (value in N) at the end frame. With --deflection/--wrench "
            "the animation runs through true equilibria along the load path (each solved at its share "
            "of the load, labelled with its force in N and deflection in mm); with --curve it follows "
            "the traced force-deflection path, with frames dense around the critical points, a ring "
            "marking the critical point and, with --all-branches, the other (unstable) branches in "
            "red. Deformations (spring deflections θ-θ0 and passive joint motion) are magnified by "
            "--scale for display; the page states the scale. With --html the page is written to a "
            "file that plays offline, with a legend, a load slider (N or mm) and a PNG button (append "
            "#frame=K to its URL to pause at frame K, &hud=0 to hide labels and controls); without it "
            "a meshcat server is started and serves until Ctrl-C. "
            "Mechanisms with loop closures (<vjm:closure>, the Orthoglide's legs) and any model "
            "with --load dead loads are solved by the mechanism solver: --deflection holds every "
            "task component, --wrench loads them, --load alone leaves the task frame free; the "
            "closure frames are marked (violet cubes), every load has its arrow, and on an "
            "unstable frame the bodies that move in the unstable mode (eigenvector of eq. 23 on "
            "the constraint null space, the control as run) are red, the others green (parallel "
            "robots: the legs that carry the mode). With --curve a mechanism's --all-branches "
            "draws the branch left at each critical point, continued past it. "
            "--png FILE writes a paper-style snapshot figure (as the paper's Fig. 6) of the same "
            "frames; --map MAP draws a stiffness map ('vjm-pin map --out') as coloured points over "
            "the robot. The robot's own meshes are drawn when found (--package-dir, "
            "ROS_PACKAGE_PATH); a missing one is named in a warning and primitives are drawn. The "
            "served page shows the current frame's numbers as text in the scene."
        ),
    )
    from vjm_pin.cli.analyze import add_robot_options

    add_robot_options(p)  # MODEL, --q, --pose-name, --frame, --springs (as analyze)
    g = p.add_mutually_exclusive_group(required=False)
    g.add_argument(
        "--deflection", nargs="+", type=float, metavar="D",
        help="DX DY DZ [RX RY RZ] (m, rad), or one number per task component"
    )
    g.add_argument(
        "--wrench", nargs="+", type=float, metavar="W",
        help="FX FY FZ [MX MY MZ] (N, N·m), or one number per task component"
    )
    g.add_argument(
        "--curve", action="store_true", help="trace and animate the force-deflection curve"
    )
    p.add_argument(
        "--direction",
        nargs="+",
        type=float,
        metavar="D",
        help="with --curve: deflection direction DX DY DZ [RX RY RZ]",
    )
    p.add_argument(
        "--max-deflection",
        type=positive_float,
        metavar="M",
        help="with --curve: largest deflection along the direction (m)",
    )
    p.add_argument(
        "--steps",
        type=int_range(2),
        default=DEFAULT_STEPS,
        help=f"with --curve: number of curve steps (default {DEFAULT_STEPS})",
    )
    p.add_argument(
        "--all-branches",
        action="store_true",
        help="with --curve: also trace the branches that leave each critical point and show "
        "them as second robots (red where unstable)",
    )
    _add_display_options(p)
    p.set_defaults(func=run)


def _add_display_options(p) -> None:
    """``--scale``, ``--html``, ``--open``, ``--load``, ``--ellipsoid``, ``--json``."""
    p.add_argument(
        "--scale",
        type=positive_float,
        default=None,
        metavar="S",
        help="deformation magnification (default: chosen so the deformation is visible)",
    )
    p.add_argument(
        "--html",
        metavar="FILE.html",
        help="write a self-contained HTML page instead of serving; never the model or springs "
        "file; checked before the work starts, written atomically; an existing file is replaced",
    )
    p.add_argument(
        "--open",
        action="store_true",
        help="open the page (or the served viewer) in the web browser",
    )
    p.add_argument(
        "--png",
        metavar="FILE",
        help="also write a paper-style snapshot figure (as the paper's Fig. 6): the robot at "
        "--snapshots frames side by side, 2-D projection in mm, unstable parts red, the "
        "critical frame ringed in magenta; PNG, PDF, SVG... by extension; checked before the "
        "work, written atomically; without --html nothing is served",
    )
    p.add_argument(
        "--map",
        metavar="MAP",
        help="show a stiffness map written by 'vjm-pin map --out' (.npz or .csv) as points over "
        "the robot at its reference: each pose's unloaded end position, coloured by --color-by "
        "(legend: the colour of five values; grey: poses not solved)",
    )
    p.add_argument(
        "--color-by",
        choices=("k_min", "deflection"),
        default="k_min",
        help="with --map: the weakest translational stiffness k_min (N/m, log scale; default) "
        "or the end deflection under the map's load (mm)",
    )
    p.add_argument(
        "--snapshots",
        type=int_range(1),
        default=DEFAULT_SNAPSHOTS,
        metavar="N",
        help=f"with --png: number of panels (default {DEFAULT_SNAPSHOTS}; the critical frame is one)",
    )
    from vjm_pin.cli.common import add_load_option

    add_load_option(p)
    p.add_argument(
        "--package-dir",
        action="append",
        default=[],
        metavar="DIR",
        help="folder where package:// mesh names resolve (repeatable; ROS_PACKAGE_PATH, the "
        "URDF's folder and example-robot-data are searched too); a mesh not found is named in "
        "a warning and the robot is drawn with primitives",
    )
    p.add_argument(
        "--ellipsoid",
        action="store_true",
        help="draw the translational compliance ellipsoid of the task frame from the loaded "
        "stiffness K_C at every frame (semi-axes: displacement under the force stated in the "
        "legend, true scale; hidden where K_C is singular or not positive definite)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="with --html: one JSON object on stdout describing the page's frames (see "
        "'vjm-pin schema view')",
    )


# ----------------------------------------------------------------------------- curves
def trace(
    vm,
    direction: np.ndarray,
    max_deflection: float,
    steps: int = DEFAULT_STEPS,
    all_branches: bool = False,
    progress=None,
    loads=(),
):
    """The force-deflection curve of ``vm`` along ``direction`` up to ``max_deflection`` (m);
    with ``all_branches`` also the branches that leave its critical points (serial chains;
    for mechanisms :func:`continued_branches` draws them). ``progress(done, total)`` is
    called as points are traced (:func:`vjm_pin.analysis.curve.trace_curve`); ``loads`` are
    dead loads kept constant along the curve."""
    from vjm_pin.analysis.curve import trace_curve

    mechanism = bool(getattr(vm, "closures", ())) or bool(loads)
    return trace_curve(
        vm,
        direction,
        max_deflection,
        steps,
        all_branches=all_branches and not mechanism,
        progress=progress,
        **({"loads": tuple(loads)} if loads else {}),
    )


def continued_branches(vm, curve, frames, crit, solver):
    """For a mechanism's curve: at each critical point, the branch the followed path left —
    continued past the critical deflection from the pre-critical state, at the deflections
    of ``frames`` (``crit``: the frame index of each critical point, or None), by a solver
    that does not prefer stable states (warm started from the previous state) — as
    :class:`vjm_pin.viz.viewer.Branch` (one configuration per frame, None where it is not
    shown: before the critical point, where it coincides with the followed branch within
    1e-6, or where it could not be solved) with its stability."""
    from vjm_pin.viz.viewer import Branch

    if not isinstance(solver, MechanismCurveSolver):
        return []
    d = np.asarray(curve.direction, float)
    free = solver.mechanism.sibling(follow_stable=False)
    out = []
    for ci, start in enumerate(crit):
        if start is None or frames[start].equilibrium is None:
            continue
        prev = frames[start].equilibrium
        qs, flags = [None] * len(frames), [False] * len(frames)
        for k in range(start + 1, len(frames)):
            r = free.solve(deflection=frames[k].deflection * d, x0=prev.x, raise_on_failure=False)
            if not r.converged:
                break
            prev = r
            if np.linalg.norm(r.x - frames[k].x) > 1e-6:
                qs[k], flags[k] = np.asarray(r.x, float), r.stable is not False
        if any(q is not None for q in qs):
            out.append(Branch(tuple(qs), tuple(flags), f"continued branch {ci + 1}"))
    return out


def _label(deflection_m: float, force_n: float, stable) -> str:
    verdict = "stable" if stable in (True, None) else "UNSTABLE"
    return f"δ = {deflection_m * 1e3:.4g} mm, |F| = {abs(force_n):.4g} N, {verdict}"


@dataclass(frozen=True)
class MeshSearch:
    """Where the robot's mesh files are looked for (besides ``ROS_PACKAGE_PATH`` and
    example-robot-data; :func:`vjm_pin.model.meshes.resolve_meshes`).

    Attributes:
        package_dirs: Folders given by ``--package-dir`` (``package://`` roots).
        urdf_dir: Folder of the URDF file the model was read from (relative mesh names), or None.
    """

    package_dirs: tuple = ()
    urdf_dir: str | None = None


def mesh_search_from_args(args) -> MeshSearch:
    """:class:`MeshSearch` of ``--package-dir`` and of MODEL when it is a file."""
    from pathlib import Path

    from vjm_pin.exceptions import InputError

    dirs = tuple(getattr(args, "package_dir", None) or ())
    for d in dirs:
        if not Path(d).is_dir():
            raise InputError(f"--package-dir: '{d}' is not a folder")
    model = Path(str(getattr(args, "model", "")))
    return MeshSearch(dirs, str(model.resolve().parent) if model.is_file() else None)


def _scene(vm, frames_x, scale, extra_frames=(), meshes=None):
    """``(geometry, shown frames, scale, MeshVisuals)`` of the configurations ``frames_x``."""
    from vjm_pin.viz.viewer import default_scale, magnify

    if scale is None:
        scale = default_scale(vm.model, vm.reference, frames_x)
    shown = [magnify(vm.reference, x, scale) for x in frames_x]
    geom, vis = robot_visuals(vm, extra_frames, meshes)
    return geom, shown, float(scale), vis


def robot_visuals(vm, extra_frames=(), meshes: MeshSearch | None = None):
    """``(geometry, MeshVisuals)``: the robot's own visual meshes when its URDF has them and
    they are all found (example-robot-data robots, ``--package-dir``, ``ROS_PACKAGE_PATH``;
    each missing one is warned about), else clean primitives
    (:func:`vjm_pin.viz.viewer.chain_geometry`; ``extra_frames`` get segments of their own:
    closure frames, the task frame, loaded frames)."""
    from vjm_pin.viz.viewer import chain_geometry, load_visuals

    m = meshes or MeshSearch()
    vis = load_visuals(vm.model, vm.urdf, m.package_dirs, m.urdf_dir)
    geom = vis.geometry or chain_geometry(vm.model, vm.roles, extra_frames=extra_frames)
    return geom, vis


def robot_geometry(vm, extra_frames=(), meshes: MeshSearch | None = None):
    """The geometry of :func:`robot_visuals` alone."""
    return robot_visuals(vm, extra_frames, meshes)[0]


def _add_mesh_kw(kw: dict, vis) -> None:
    """The legend note (primitives replace missing meshes) and ``kw["_meshes"]`` (popped by
    the callers: the ``meshes`` key of the JSON, :func:`_meshes_dict`)."""
    if vis.note:
        kw["legend_notes"] = [vis.note]
    kw["_meshes"] = vis


def _meshes_dict(vis) -> dict | None:
    """The ``meshes`` key of ``view --json``: None for a robot without visuals; else what
    is drawn (``"meshes"`` or ``"primitives"``), the mesh names not found and the note."""
    if vis is None or (vis.geometry is None and not vis.missing and not vis.error):
        return None
    return {
        "drawn": "meshes" if vis.geometry is not None else "primitives",
        "missing": list(vis.missing),
        "note": vis.note,
    }


# ----------------------------------------------------------------------------- curve frames
DEFAULT_FRAMES = 91
"""Animation frames of a curve page (about 6 s at 15 frames per second)."""
W_DEFLECTION, W_FORCE = 0.5, 0.6
"""Weights of the normalised deflection and force in the frame arc length (shape: 1)."""


@dataclass(frozen=True, eq=False)  # identity: frames are looked up by object
class CurveFrame:
    """One animation frame of a curve: an equilibrium on the followed branch.

    Attributes:
        deflection: Deflection along the curve direction (m, or rad for a rotation).
        force: Force along the direction, ``dᵀF`` (N or N·m).
        wrench: (6,) external wrench at the end (N, N·m), world axes.
        stable: Stability verdict (eq. 23) of the equilibrium.
        x: (nq,) configuration (m, rad).
        kind: ``"curve"`` (a point of the traced curve), ``"refined"`` (solved here, warm
            started from a neighbouring point) or ``"critical"`` (the pre-critical state at
            a critical point's deflection).
        equilibrium: The solver's result (serial ``EquilibriumResult`` or
            ``MechanismResult``), None for the unloaded robot added in front.
    """

    deflection: float
    force: float
    wrench: np.ndarray
    stable: bool
    x: np.ndarray
    kind: str
    equilibrium: object = None


def _frame(eq, s: float, d: np.ndarray, kind: str) -> CurveFrame:
    w = np.asarray(eq.wrench, float)
    return CurveFrame(
        float(s), float(d @ w), w, eq.stable is not False, np.asarray(eq.x, float), kind, eq
    )


class MechanismCurveSolver:
    """The ``solve`` interface of the serial :class:`~vjm_pin.solver.EquilibriumSolver` (every
    task component held at a deflection) over :class:`~vjm_pin.solver.MechanismSolver`, for
    the frames of a curve of a mechanism with loop closures. ``wrench0`` and ``fast_fail``
    are accepted and not used (the mechanism solver starts with a plain Newton attempt)."""

    def __init__(self, vm, follow_stable: bool = True, loads=()):
        from vjm_pin.solver import MechanismSolver

        self.mechanism = MechanismSolver(vm, loads, follow_stable=follow_stable)

    def solve(self, deflection, x0=None, wrench0=None, raise_on_failure=True, fast_fail=False):
        return self.mechanism.solve(deflection=deflection, x0=x0, raise_on_failure=raise_on_failure)


def curve_solver(vm, follow_stable: bool = True, loads=()):
    """The solver for curve frames of ``vm``: the serial one for chains, the mechanism one
    (:class:`MechanismCurveSolver`) for models with loop closures or dead ``loads``."""
    from vjm_pin.solver import EquilibriumSolver

    if getattr(vm, "closures", ()) or loads:
        return MechanismCurveSolver(vm, follow_stable, loads)
    return EquilibriumSolver(vm, follow_stable=follow_stable)


def _warm_solve(solver, s, d, start):
    """Equilibrium at deflection ``s·d`` from the state ``start`` (one Newton attempt
    first, the full solver if it fails), or None."""
    from vjm_pin.exceptions import NoEquilibrium

    for fast in (True, False):
        try:
            eq = solver.solve(
                s * d, x0=start.x, wrench0=start.wrench, raise_on_failure=False, fast_fail=fast
            )
        except NoEquilibrium:
            eq = None
        if eq is not None and eq.converged:
            return eq
    return None


def _joint_positions(vm, data, x) -> np.ndarray:
    import pinocchio as pin

    pin.forwardKinematics(vm.model, data, np.asarray(x, float))
    return np.array([m.translation for m in data.oMi[1:]])


def curve_frames(vm, curve, n_frames: int = DEFAULT_FRAMES, solver=None):
    """Animation frames along ``curve``, dense where something happens.

    The frames are true equilibria, spaced uniformly in the arc length of the path
    (deflection, force, shape) with each coordinate normalised by its range over the curve
    (shape: the largest joint displacement between neighbours over the largest joint
    displacement from the start). A steep pre-critical rise of the force and the fast
    change of shape just past a critical point thus get as many frames as the long
    post-critical plateau. Around each critical point the bracket is sampled first
    (pre-critical states up to the critical deflection, post-critical ones solved backwards
    from the first point after it), and the pre-critical state at the critical deflection is
    always a frame (``kind="critical"``).

    Args:
        vm: The model.
        curve: A :class:`vjm_pin.analysis.curve.Curve` of ``vm``.
        n_frames: Number of frames wanted (at least the number of critical points + 2).
        solver: A solver with the serial solver's ``solve`` (default: :func:`curve_solver`).

    Returns:
        (frames, critical) — the :class:`CurveFrame` list in order of deflection and, per
        critical point of ``curve``, the index of its ``"critical"`` frame (or None when its
        state could not be solved).
    """
    from vjm_pin.exceptions import InputError

    if int(n_frames) != n_frames or n_frames < 2:
        raise InputError(f"n_frames must be an integer >= 2, got {n_frames}")
    solver = solver or curve_solver(vm)
    d = np.asarray(curve.direction, float)
    pts = list(curve.points)
    samples = [_frame(p.equilibrium, p.deflection, d, "curve") for p in pts]
    extra, crit_samples, no_split = _critical_brackets(solver, pts, curve.critical, d)
    samples += extra
    samples.sort(key=lambda f: f.deflection)
    dedup = [samples[0]]
    for f in samples[1:]:
        if f.deflection - dedup[-1].deflection > 1e-12 * max(1.0, abs(f.deflection)):
            dedup.append(f)
        elif f.kind == "critical":
            dedup[-1] = f
    samples = dedup
    m = len(samples)
    if m == 1:
        return samples, [0 if cs is not None else None for cs in crit_samples]

    seg, arc = _arc_lengths(vm, samples)
    crit_arc = [arc[i] for i, f in enumerate(samples) if any(f is cs for cs in crit_samples)]
    targets = list(np.linspace(0.0, arc[-1], int(n_frames)))
    for ca in crit_arc:  # the critical states are frames themselves
        j = int(np.argmin([abs(t - ca) for t in targets]))
        targets[j] = ca
    frames = _resample(samples, targets, arc, seg, no_split, solver, d)
    crit_idx = []
    for cs in crit_samples:
        crit_idx.append(next((i for i, f in enumerate(frames) if f is cs), None))
    return frames, crit_idx


def _critical_brackets(solver, pts, critical, d):
    """Samples around each critical point for :func:`curve_frames`: ``(samples, crit_samples,
    no_split)`` — pre-critical states up to the critical deflection and post-critical ones
    solved backwards from the point after it; per critical point its ``"critical"`` frame
    (or None); the ``(s_lo, s_hi)`` brackets not to interpolate across."""
    samples: list[CurveFrame] = []
    crit_samples: list[CurveFrame | None] = []
    no_split = set()  # (s_lo, s_hi) of sample pairs across a critical point
    for c in critical:
        i = int(c.index)
        if not 1 <= i < len(pts):
            crit_samples.append(None)
            continue
        a, b = pts[i - 1], pts[i]
        s_cr = float(c.deflection)
        prev, pre = a.equilibrium, []
        for u in (0.5, 0.8, 0.95, 1.0 - 1e-4):
            s = a.deflection + (s_cr - a.deflection) * u
            eq = _warm_solve(solver, s, d, prev)
            if eq is None:
                break
            pre.append(_frame(eq, s, d, "refined"))
            prev = eq
        cs = None
        if pre and abs(pre[-1].deflection - s_cr) <= 1e-3 * max(
            abs(s_cr), abs(b.deflection - a.deflection)
        ):
            cs = CurveFrame(
                *[getattr(pre[-1], f) for f in ("deflection", "force", "wrench", "stable", "x")],
                "critical",
                pre[-1].equilibrium,
            )
            pre[-1] = cs
        crit_samples.append(cs)
        prev, post = b.equilibrium, []
        for u in (0.7, 0.45, 0.25, 0.12, 0.05, 0.02, 0.005):
            s = s_cr + (b.deflection - s_cr) * u
            eq = _warm_solve(solver, s, d, prev)
            if eq is None or (eq.stable is not False) != (b.stable is not False):
                break
            post.append(_frame(eq, s, d, "refined"))
            prev = eq
        samples += pre + post
        lo = pre[-1].deflection if pre else a.deflection
        hi = min([p.deflection for p in post], default=b.deflection)
        no_split.add((lo, hi))
    return samples, crit_samples, no_split


def _arc_lengths(vm, samples):
    """``(seg, arc)``: the normalised (deflection, force, shape) length of each sample
    interval and their running sum from 0 (:func:`curve_frames`)."""
    from vjm_pin.kinematics.shared import data_for

    m = len(samples)
    data = data_for(vm.model)
    joints = [_joint_positions(vm, data, f.x) for f in samples]
    s_arr = np.array([f.deflection for f in samples])
    f_arr = np.array([f.force for f in samples])
    rs = max(float(np.ptp(s_arr)), 1e-300)
    rf = float(np.ptp(f_arr)) or 1.0
    disp = max(float(np.linalg.norm(j - joints[0], axis=1).max()) for j in joints) or 1.0
    seg = np.array(
        [
            np.sqrt(
                (W_DEFLECTION * (s_arr[k + 1] - s_arr[k]) / rs) ** 2
                + (W_FORCE * (f_arr[k + 1] - f_arr[k]) / rf) ** 2
                + (float(np.linalg.norm(joints[k + 1] - joints[k], axis=1).max()) / disp) ** 2
            )
            for k in range(m - 1)
        ]
    )
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    return seg, arc


def _resample(samples, targets, arc, seg, no_split, solver, d) -> list[CurveFrame]:
    """One frame per arc-length target: a sample, or an equilibrium solved between two
    (never across a critical bracket or a change of stability), :func:`curve_frames`."""
    m = len(samples)
    frames: list[CurveFrame] = []
    for t in targets:
        k = int(min(np.searchsorted(arc, t, side="right") - 1, m - 2))
        u = (t - arc[k]) / seg[k] if seg[k] > 0 else 0.0
        lo, hi = samples[k], samples[k + 1]
        across = any(lo.deflection >= a and hi.deflection <= b for a, b in no_split) or (
            lo.stable != hi.stable
        )
        if u <= 0.02 or u >= 0.98 or across:
            f = lo if u < 0.5 else hi
        else:
            s = lo.deflection + u * (hi.deflection - lo.deflection)
            eq = _warm_solve(solver, s, d, lo)
            step = float(np.linalg.norm(hi.x - lo.x))
            x_lin = lo.x + u * (hi.x - lo.x)
            if (
                eq is not None
                and (eq.stable is not False) == lo.stable
                and (np.linalg.norm(eq.x - x_lin) <= 2.0 * step + 1e-12)
            ):
                f = _frame(eq, s, d, "refined")
            else:
                f = lo if u < 0.5 else hi
        if not frames or f.deflection != frames[-1].deflection:
            frames.append(f)
        elif f.kind == "critical":
            frames[-1] = f
    return frames


def branch_frames(vm, curve, frames, solver=None):
    """The other branches of ``curve`` (``Curve.branches``, traced with ``all_branches``)
    at the deflections of ``frames``: per branch, one configuration per frame (None where
    the branch does not reach that deflection) and one stability flag per frame.

    Each configuration is an equilibrium solved at the frame's deflection with a solver that
    does not prefer stable states, warm started from the nearest branch point, and kept
    only if it stays on the branch (within two branch steps of that point). Frames before
    the critical point a branch leaves are not shown.
    """
    from vjm_pin.viz.viewer import Branch

    if not curve.branches:
        return []
    d = np.asarray(curve.direction, float)
    unstable = curve_solver(vm, follow_stable=False)
    crit_s = sorted(float(c.deflection) for c in curve.critical)
    out = []
    for bi, br in enumerate(curve.branches):
        bs = np.array([p.deflection for p in br])
        if bs.size == 0:
            continue
        start = max([s for s in crit_s if s <= bs[0] + 1e-15], default=bs[0])
        step = max(
            [
                float(np.linalg.norm(br[k + 1].equilibrium.x - br[k].equilibrium.x))
                for k in range(len(br) - 1)
            ],
            default=0.0,
        )
        qs, flags = [], []
        for f in frames:
            s = f.deflection
            if s < start or s > bs[-1] * (1 + 1e-12) + 1e-15:
                qs.append(None)
                flags.append(False)
                continue
            k = int(np.argmin(np.abs(bs - s)))
            near = br[k]
            if abs(near.deflection - s) <= 1e-12 * max(1.0, abs(s)):
                qs.append(np.asarray(near.equilibrium.x, float))
                flags.append(near.stable is not False)
                continue
            eq = _warm_solve(unstable, s, d, near.equilibrium)
            if eq is None or np.linalg.norm(eq.x - near.equilibrium.x) > 2.0 * step + 1e-9:
                qs.append(None)
                flags.append(False)
                continue
            qs.append(np.asarray(eq.x, float))
            flags.append(eq.stable is not False)
        if any(q is not None for q in qs):
            out.append(Branch(tuple(qs), tuple(flags), f"branch {bi + 1}"))
    return out


def curve_animation(
    vm,
    curve,
    *,
    scale=None,
    n_frames: int = DEFAULT_FRAMES,
    solver=None,
    ellipsoid=False,
    all_branches=False,
    meshes: MeshSearch | None = None,
):
    """Everything an animation of ``curve`` needs: ``(geometry, shown frames, scale, kw)``
    with ``kw`` the :class:`vjm_pin.viz.viewer.Animation` keywords (stability, forces, critical
    frame, labels, load slider in mm, other branches; for mechanisms the closure markers and
    the unstable modes; with ``ellipsoid`` the compliance ellipsoid) and ``kw["_frames"]``
    the :class:`CurveFrame` list and ``kw["_ellipsoid"]`` (force scale, per-frame data) or
    None (popped by the callers). For a mechanism the other branches are drawn with
    ``all_branches`` (:func:`continued_branches`); for a chain when the curve has them."""
    from vjm_pin.viz.viewer import Branch, magnify

    loads = tuple(getattr(curve, "loads", ()) or ())
    solver = solver or curve_solver(vm, loads=loads)
    frames, crit = curve_frames(vm, curve, n_frames, solver)
    if frames[0].deflection > 0:  # the unloaded robot first
        frames.insert(
            0, CurveFrame(0.0, 0.0, np.zeros(6), True, np.asarray(vm.reference, float), "curve")
        )
        crit = [None if c is None else c + 1 for c in crit]
    branches = branch_frames(vm, curve, frames, solver)
    if all_branches and isinstance(solver, MechanismCurveSolver):
        branches = continued_branches(vm, curve, frames, crit, solver)
    xs = [f.x for f in frames] + [q for b in branches for q in b.frames if q is not None]
    marked = _marked_frames(vm, loads) if vm.closures or loads else ()
    geom, _, scale, vis = _scene(vm, xs, scale, marked, meshes)
    shown = [magnify(vm.reference, f.x, scale) for f in frames]
    branches = [
        Branch(
            tuple(None if q is None else magnify(vm.reference, q, scale) for q in b.frames),
            b.stable,
            b.name,
        )
        for b in branches
    ]
    labels = [_label(f.deflection, f.force, f.stable) for f in frames]
    critical = next((c for c in crit if c is not None), None)
    crit_text = None
    if critical is not None:
        c = curve.critical[crit.index(critical)]
        labels[critical] = (
            f"CRITICAL POINT: F_cr = {abs(c.force):.4g} N at δ = {c.deflection * 1e3:.4g} mm "
            f"(stiffness {c.stiffness_before:.4g} → {c.stiffness_after:.4g} N/m)"
        )
        if critical + 1 < len(frames):
            labels[critical + 1] += (
                f" — first frame past the critical point F_cr = {abs(c.force):.4g} N at δ = {c.deflection * 1e3:.4g} mm"
            )
        crit_text = f"critical: F_cr = {abs(c.force):.4g} N, δ = {c.deflection * 1e3:.4g} mm"
    for k, f in enumerate(frames):
        alt = [b for b in branches if b.frames[k] is not None]
        if alt:
            labels[k] += (
                f"; {len(alt)} other equilibri{'um' if len(alt) == 1 else 'a'} shown ({sum(not b.stable[k] for b in alt)} unstable)"
            )
    kw = {
        "stable": [f.stable for f in frames],
        "forces": [f.wrench[:3] for f in frames],
        "critical_index": critical,
        "critical_label": crit_text,
        "frame_labels": labels,
        "branches": branches,
        "slider": {"name": "δ", "unit": "mm", "values": [f.deflection * 1e3 for f in frames]},
        "_frames": frames,
        "_ellipsoid": None,
    }
    _mechanism_curve_kw(vm, kw, frames, solver, loads, ellipsoid)
    _add_mesh_kw(kw, vis)
    return geom, shown, scale, kw


def _mechanism_curve_kw(vm, kw, frames, solver, loads, ellipsoid) -> None:
    """Add to the keywords ``kw`` of :func:`curve_animation` the dead-load arrows, the
    closure markers and the unstable modes (and legs) of a mechanism's curve frames, and the
    compliance ellipsoid with ``ellipsoid``."""
    if loads:
        kw["loads"] = [(ld.frame, [ld.wrench[:3]] * len(frames)) for ld in loads]
    if vm.closures or loads:
        mech = solver.mechanism if isinstance(solver, MechanismCurveSolver) else None
        kw["closures"] = closure_triples(vm)
        if mech is not None:
            kw["modes"] = [
                mech.unstable_modes(f.equilibrium)[1]
                if f.equilibrium is not None and f.stable is False
                else None
                for f in frames
            ]
            if getattr(vm, "legs", ()):
                kw["unstable_joints"] = [
                    None if m is None else leg_joint_ids(vm, unstable_legs(vm, m))
                    for m in kw["modes"]
                ]
    if ellipsoid:
        drawn, force, data = ellipsoid_frames(vm, _curve_stiffness(vm, frames, solver))
        if force is not None:
            kw["ellipsoid"], kw["ellipsoid_label"] = drawn, ellipsoid_label(vm, force)
        kw["_ellipsoid"] = (force, data)


def _curve_stiffness(vm, frames, solver) -> list:
    """K_C (6, 6) at each curve frame (None where singular or unknown); the unloaded robot's
    for the frame added in front."""
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
    from vjm_pin.solver import loaded_stiffness, unloaded_stiffness

    out = []
    for f in frames:
        try:
            if isinstance(solver, MechanismCurveSolver):
                eq = f.equilibrium or solver.solve(np.zeros(6))
                out.append(solver.mechanism.stiffness(eq).stiffness)
            elif f.equilibrium is None:
                out.append(unloaded_stiffness(vm).stiffness)
            else:
                out.append(loaded_stiffness(vm, f.equilibrium).stiffness)
        except (SingularStiffness, NoEquilibrium):
            out.append(None)
    return out


@dataclass(frozen=True)
class CurvePage:
    """An exported curve animation.

    Attributes:
        html: The page.
        scale: Deformation magnification used (dimensionless).
        frames: Number of animation frames.
        critical_frame: Frame index of the first critical point (the pre-critical state at
            the critical deflection), or None.
        curve_frames: The :class:`CurveFrame` of every animation frame.
        branches: Number of other branches drawn.
        ellipsoid: (force scale N, per-frame data) of the compliance ellipsoid
            (:func:`ellipsoid_frames`), or None when not drawn.
    """

    html: str
    scale: float
    frames: int
    critical_frame: int | None
    curve_frames: tuple = ()
    branches: int = 0
    ellipsoid: tuple | None = None
    meshes: object = None


def curve_page(
    vm,
    curve,
    *,
    scale: float | None = None,
    path=None,
    title: str | None = None,
    fps: float = 15.0,
    n_frames: int = DEFAULT_FRAMES,
    ellipsoid: bool = False,
    all_branches: bool = False,
    meshes: MeshSearch | None = None,
    animation=None,
    **options,
) -> CurvePage:
    """Animated page of ``vm`` along ``curve`` (a ``vjm_pin.analysis.curve.Curve``).

    Frames from :func:`curve_frames` (dense around the critical points), the unloaded robot
    first; each coloured by its stability, with the force arrow and its value in N, the
    critical marker at the first critical point, a load slider in mm of deflection and, when
    the curve was traced with ``all_branches=True``, the other branches as second robots
    (red where unstable). ``scale`` magnifies the deformation
    (:func:`vjm_pin.viz.viewer.magnify`); None picks :func:`vjm_pin.viz.viewer.default_scale`.
    ``ellipsoid`` adds the compliance ellipsoid (:func:`ellipsoid_frames`).
    ``options`` go to :func:`vjm_pin.viz.viewer.export_html` (e.g. ``camera_direction``).
    ``animation``: the result of :func:`curve_animation` for these arguments when already
    computed (not computed again; its keywords are not modified).
    """
    from vjm_pin.viz.viewer import export_html

    if animation is not None:
        geom, shown, scale, kw = animation
        kw = dict(kw)
    else:
        geom, shown, scale, kw = curve_animation(
            vm,
            curve,
            scale=scale,
            n_frames=n_frames,
            ellipsoid=ellipsoid,
            all_branches=all_branches,
            meshes=meshes,
        )
    frames = kw.pop("_frames")
    vis = kw.pop("_meshes")
    ell = kw.pop("_ellipsoid")
    d = np.asarray(curve.direction, float)
    text = (
        title or f"{vm.name}: path along deflection direction {np.array2string(d[:3], precision=3)}"
    )
    text += f" — deformation ×{scale:g}"
    if kw["branches"]:
        text += f" — {len(kw['branches'])} other branch{'es' if len(kw['branches']) > 1 else ''}"
    kw.update(options)
    page = export_html(
        vm.model,
        geom,
        shown,
        ghost_q=vm.reference,
        frame_name=vm.frame,
        fps=fps,
        title_text=text,
        path=path,
        **kw,
    )
    return CurvePage(
        page, scale, len(shown), kw["critical_index"], tuple(frames), len(kw["branches"]), ell, vis
    )


# ----------------------------------------------------------------------------- load path
DEFAULT_LOAD_FRAMES = 21


def load_path(vm, load, kind: str, n: int = DEFAULT_LOAD_FRAMES, solver=None):
    """Equilibria along the straight load path ``t·load``, ``t = 0 … 1`` in ``n`` steps.

    Each is solved at its own load factor, warm started from the previous one (so the path
    is followed continuously); ``kind`` is ``"deflection"`` (``load`` prescribes the end
    deflection, m and rad) or ``"wrench"`` (``load`` is the end wrench, N and N·m).

    Returns:
        (load factors (n,), list of :class:`~vjm_pin.solver.EquilibriumResult`).

    Raises:
        NoEquilibrium: no equilibrium at some load factor (the message names it).
    """
    from vjm_pin.exceptions import InputError, NoEquilibrium
    from vjm_pin.solver import EquilibriumSolver

    if kind not in ("deflection", "wrench"):
        raise InputError(f"kind must be 'deflection' or 'wrench', got {kind!r}")
    if int(n) != n or n < 2:
        raise InputError(f"n must be an integer >= 2, got {n}")
    solver = solver or EquilibriumSolver(vm)
    load = np.asarray(load, float).ravel()
    ts = np.linspace(0.0, 1.0, int(n))
    out = []
    prev = None
    for t in ts:
        try:
            if kind == "deflection":
                eq = solver.solve(
                    t * load,
                    x0=None if prev is None else prev.x,
                    wrench0=None if prev is None else prev.wrench,
                )
            else:
                eq = solver.solve_wrench(t * load, x0=None if prev is None else prev.x)
        except NoEquilibrium as e:
            raise NoEquilibrium(
                f"no equilibrium at {t:.0%} of the {kind} on the load path: {e}",
                e.result,
                e.residual,
            ) from None
        out.append(eq)
        prev = eq
    return ts, out


def load_frames(vm, ts, results, scale: float | None = None, kind: str = "wrench", meshes=None):
    """Animation of the equilibria ``results`` of :func:`load_path`: ``(geometry, shown
    frames, scale, kw)`` with ``kw`` the :class:`vjm_pin.viz.viewer.Animation` keywords; each
    frame is labelled with its own force (N) and deflection (mm), and the page's slider is
    in N (``kind="wrench"``) or mm (``kind="deflection"``)."""
    xs = [np.asarray(r.x, float) for r in results]
    forces = [np.asarray(r.wrench, float)[:3] for r in results]
    stable = [r.stable is not False for r in results]
    unloaded = [t == 0 for t in ts]
    for k, u in enumerate(unloaded):
        # at zero load the unloaded robot is the equilibrium (the solver's start at a singular
        # configuration, e.g. a straight chain, may report an arbitrary indeterminate force)
        if u:
            xs[k], forces[k], stable[k] = np.asarray(vm.reference, float), np.zeros(3), True
    geom, shown, scale, vis = _scene(vm, xs, scale, meshes=meshes)
    labels = []
    for t, r, u in zip(ts, results, unloaded):
        if u:
            labels.append("load ×0.00: unloaded robot, |F| = 0 N, |δ| = 0 mm")
            continue
        f = float(np.linalg.norm(np.asarray(r.wrench, float)[:3]))
        dmm = float(np.linalg.norm(np.asarray(r.deflection, float)[:3])) * 1e3
        labels.append(
            f"load ×{t:.2f}: |F| = {f:.4g} N, |δ| = {dmm:.4g} mm, "
            + ("stable" if r.stable is not False else "UNSTABLE")
        )
    if kind == "wrench":
        slider = {"name": "|F|", "unit": "N", "values": [float(np.linalg.norm(f)) for f in forces]}
    else:
        slider = {
            "name": "|δ|",
            "unit": "mm",
            "values": [
                0.0 if u else float(np.linalg.norm(np.asarray(r.deflection, float)[:3])) * 1e3
                for r, u in zip(results, unloaded)
            ],
        }
    kw = {"stable": stable, "forces": forces, "frame_labels": labels, "slider": slider}
    _add_mesh_kw(kw, vis)
    return geom, shown, scale, kw


# ----------------------------------------------------------------------------- mechanisms
#: Drawn size of the ellipsoid: the median over the frames of its largest semi-axis is this
#: fraction of the robot's size; no semi-axis is drawn longer than :data:`ELLIPSOID_CAP`
#: times the size (the frame is then marked ``clipped``); a semi-axis of zero length (a
#: translation outside the task) is drawn :data:`ELLIPSOID_FLAT` times the size thick.
ELLIPSOID_SIZE, ELLIPSOID_CAP, ELLIPSOID_FLAT = 0.2, 0.6, 0.01


@dataclass(frozen=True)
class MechanismFrame:
    """One equilibrium on the load path of a mechanism (:func:`mechanism_load_path`).

    Attributes:
        load_factor: ``t`` (the task load and every dead load at ``t`` times their value).
        result: The :class:`~vjm_pin.solver.MechanismResult`.
        modes: (nq, k) directions in which it is unstable under the control as run
            (:meth:`~vjm_pin.solver.MechanismSolver.unstable_modes`; k = 0 when stable).
        stiffness: (6, 6) loaded Cartesian stiffness K_C (N/m, N/rad, N·m/rad; world axes),
            or None when it was not asked for or is singular (a critical point).
    """

    load_factor: float
    result: object
    modes: np.ndarray
    stiffness: np.ndarray | None = None


def mechanism_load_path(
    vm, kind: str, load=None, loads=(), n: int = DEFAULT_LOAD_FRAMES, stiffness: bool = False
) -> list[MechanismFrame]:
    """Equilibria of ``vm`` (loop closures or not) along the straight load path ``t·(load,
    loads)``, ``t = 0 … 1`` in ``n`` steps, through :class:`~vjm_pin.solver.MechanismSolver`.

    ``kind``: ``"deflection"`` (every task component held at ``t·load``, m and rad),
    ``"wrench"`` (every task component loaded by the dead wrench ``t·load``, N and N·m) or
    ``"loads"`` (the task frame free: no task load, ``load`` ignored). ``loads`` are dead
    loads (:class:`~vjm_pin.kinematics.dead_loads.Load`) scaled by ``t`` too. Each
    equilibrium is warm started from the previous one (the path is followed continuously;
    first by a solver that does not prefer stable states, so that past a critical load the
    path stays on its branch and is shown unstable instead of jumping to a distant stable
    state; the stable-seeking solver when that fails). With ``stiffness`` K_C is evaluated
    too.

    Raises:
        NoEquilibrium: no equilibrium at some load factor (the message names it).
    """
    from vjm_pin.exceptions import InputError, NoEquilibrium, SingularStiffness
    from vjm_pin.kinematics.dead_loads import Load
    from vjm_pin.solver import MechanismSolver

    if kind not in ("deflection", "wrench", "loads"):
        raise InputError(f"kind must be 'deflection', 'wrench' or 'loads', got {kind!r}")
    if int(n) != n or n < 2:
        raise InputError(f"n must be an integer >= 2, got {n}")
    load = np.zeros(6) if load is None else np.asarray(load, float).ravel()
    out: list[MechanismFrame] = []
    prev = None
    for t in np.linspace(0.0, 1.0, int(n)):
        scaled = [Load(ld.frame, t * ld.wrench) for ld in loads]
        x0 = None if prev is None else prev.x
        task = {"deflection": t * load} if kind == "deflection" else {
            "wrench": t * load if kind == "wrench" else np.zeros(6)
        }
        try:
            solver = MechanismSolver(vm, scaled, follow_stable=prev is None)
            res = solver.solve(**task, x0=x0, raise_on_failure=prev is None)
            if not res.converged:
                solver = MechanismSolver(vm, scaled)
                res = solver.solve(**task, x0=x0)
        except NoEquilibrium as e:
            raise NoEquilibrium(
                f"no equilibrium at {t:.0%} of the load on the load path: {e}", e.result, e.residual
            ) from None
        _, modes = solver.unstable_modes(res) if res.stable is False else (None, None)
        k6 = None
        if stiffness:
            try:
                k6 = solver.stiffness(res).stiffness
            except SingularStiffness:
                k6 = None
        out.append(
            MechanismFrame(float(t), res, np.zeros((vm.model.nq, 0)) if modes is None else modes, k6)
        )
        prev = res
    return out


def compliance_ellipsoid(stiffness, task) -> tuple[np.ndarray, np.ndarray] | None:
    """The translational compliance ellipsoid of the task frame from K_C.

    ``C = K⁻¹`` with ``K`` the loaded stiffness K_C restricted to the task components (the
    other rows are not defined), and its translational block ``C_tt`` (m/N): the task frame
    moves by ``C_tt f`` under a force ``f`` (moments zero, every task component loaded), so
    the forces of unit magnitude map onto the ellipsoid with semi-axes the eigenvalues of
    ``C_tt`` along its eigenvectors. Translations outside the task get a zero semi-axis.

    Returns:
        (semi-axes (3,) in m/N, descending; axes (3, 3), one unit column per semi-axis,
        world axes), or None when K_C is singular or ``C_tt`` is not positive definite
        (past a critical point, or under a load the mechanism cannot carry stably).
    """
    task = [int(c) for c in task]
    trans = [i for i, c in enumerate(task) if c < 3]
    if stiffness is None or not trans:
        return None
    k = np.asarray(stiffness, float)[np.ix_(task, task)]
    try:
        c = np.linalg.inv(k)
    except np.linalg.LinAlgError:
        return None
    sub = 0.5 * (c[np.ix_(trans, trans)] + c[np.ix_(trans, trans)].T)
    ev_s, vec_s = np.linalg.eigh(sub)
    if not np.all(np.isfinite(ev_s)) or ev_s.min() <= 0:
        return None
    idx = [task[i] for i in trans]
    ev, vec = np.zeros(3), np.zeros((3, 3))
    ev[: len(idx)] = ev_s
    vec[np.ix_(idx, range(len(idx)))] = vec_s
    for j, axis in enumerate(i for i in range(3) if i not in idx):
        vec[axis, len(idx) + j] = 1.0  # translations outside the task: zero semi-axes
    order = np.argsort(ev, kind="stable")[::-1]
    return ev[order], vec[:, order]


def robot_size(vm) -> float:
    """Diagonal of the bounding box of the joint origins and frames of the unloaded robot (m)."""
    import pinocchio as pin

    from vjm_pin.kinematics.shared import data_for

    data = data_for(vm.model)
    pin.framesForwardKinematics(vm.model, data, np.asarray(vm.reference, float))
    pts = np.array([m.translation for m in data.oMi] + [m.translation for m in data.oMf])
    return max(float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))), 1e-3)


def ellipsoid_frames(vm, stiffnesses):
    """Drawn ellipsoids for :class:`vjm_pin.viz.viewer.Animation` from one K_C (or None) per
    frame: ``(drawn, force, data)``; ``drawn`` per frame (semi-axes as drawn, m; axes) or
    None; the semi-axes as drawn are the displacements under a force of ``force`` N (true
    scale, :data:`ELLIPSOID_SIZE`, :data:`ELLIPSOID_CAP`, :data:`ELLIPSOID_FLAT`); ``data``
    per frame the JSON entry (``compliance_eigenvalues`` m/N, ``axes``, ``clipped``) or None."""
    size = robot_size(vm)
    ells = [compliance_ellipsoid(k, vm.task) for k in stiffnesses]
    tops = [float(e[0][0]) for e in ells if e is not None]
    if not tops:
        return [None] * len(ells), None, [None] * len(ells)
    force = ELLIPSOID_SIZE * size / float(np.median(tops))
    drawn, data = [], []
    for e in ells:
        if e is None:
            drawn.append(None)
            data.append(None)
            continue
        a = e[0] * force
        clipped = bool(np.any(a > ELLIPSOID_CAP * size))
        a = np.clip(a, ELLIPSOID_FLAT * size, ELLIPSOID_CAP * size)
        drawn.append((a, e[1]))
        data.append({"compliance_eigenvalues": e[0], "axes": e[1].T, "clipped": clipped})
    return drawn, force, data


def ellipsoid_label(vm, force: float) -> str:
    """Legend text of the compliance ellipsoid (what it is and its scale)."""
    return (
        f"translational compliance ellipsoid at {vm.frame} (K_C⁻¹): semi-axes = displacement "
        f"under a {force:.3g} N force, true scale"
    )


#: A leg takes part in an unstable mode when its coordinates carry at least this fraction of
#: the share of the leg that carries most (:func:`unstable_legs`).
LEG_SHARE = 0.5


def unstable_legs(vm, modes) -> list[str]:
    """The legs of a parallel robot (``vm.legs``) that take part in the unstable ``modes``
    ((nq, k) configuration directions, :meth:`~vjm_pin.solver.MechanismSolver.unstable_modes`).

    A leg's share of a mode ``v`` is ``‖v_leg‖² / ‖v‖²`` over the coordinates of its joints
    (m and rad as they come); its share of several modes is the largest one. The legs whose
    share is at least :data:`LEG_SHARE` times the largest leg share are unstable: at the
    Orthoglide's Q3 under a load along −u past the critical force, the leg whose bars buckle
    carries about 60 % of the mode and the two others about 20 % each (they follow the
    platform). Empty for a stable equilibrium or a model without legs.
    """
    legs = list(getattr(vm, "legs", ()))
    m = np.asarray(modes, float) if modes is not None else np.zeros((0, 0))
    if not legs or m.ndim != 2 or m.shape[1] == 0:
        return []
    shares = []
    for leg in legs:
        idx = [vm.joint_index(j) for j in leg.joints]
        shares.append(
            max(float(np.sum(v[idx] ** 2) / max(float(v @ v), 1e-300)) for v in m.T)
        )
    top = max(shares)
    return [leg.name for leg, sh in zip(legs, shares) if top > 0 and sh >= LEG_SHARE * top]


def leg_joint_ids(vm, names) -> list[int]:
    """Pinocchio joint indices (1…) of the joints of the legs ``names``."""
    by = {leg.name: leg for leg in getattr(vm, "legs", ())}
    return [vm.joint_index(j) + 1 for n in names for j in by[n].joints]


def closure_triples(vm) -> list[tuple[str, str, str]]:
    """``(name, frame_a, frame_b)`` of each loop closure of ``vm`` (viewer markers)."""
    return [(c.name, c.frame_a, c.frame_b) for c in getattr(vm, "closures", ())]


def mechanism_frames(
    vm, path, kind: str, loads=(), scale=None, ellipsoid: bool = False, meshes=None
):
    """Animation of the equilibria ``path`` of :func:`mechanism_load_path`: ``(geometry,
    shown frames, scale, kw)`` with ``kw`` the :class:`vjm_pin.viz.viewer.Animation`
    keywords: per-frame stability and unstable modes (the bodies that move in the unstable
    mode drawn red), the end force (not for ``kind="loads"``), an arrow per dead load, the
    closure markers, labels with the force (N) and deflection (mm), a load slider (|F| in N
    of the end force, the end deflection in mm, or the largest dead load in N) and, with
    ``ellipsoid``, the compliance ellipsoid (:func:`ellipsoid_frames`; ``kw["_ellipsoid"]``
    holds the force scale and the per-frame data, popped by the callers)."""
    xs = [np.asarray(f.result.x, float) for f in path]
    geom, shown, scale, vis = _scene(vm, xs, scale, _marked_frames(vm, loads), meshes)
    stable = [f.result.stable is not False for f in path]
    lmax = max([float(np.linalg.norm(ld.wrench[:3])) for ld in loads], default=0.0)
    labels = []
    for f in path:
        r = f.result
        fn = float(np.linalg.norm(np.asarray(r.wrench, float)[:3]))
        dmm = float(np.linalg.norm(np.asarray(r.deflection, float)[:3])) * 1e3
        if kind == "loads":
            text = f"load ×{f.load_factor:.2f}: {vm.frame} free, |δ| = {dmm:.4g} mm"
        else:
            text = f"load ×{f.load_factor:.2f}: |F| = {fn:.4g} N, |δ| = {dmm:.4g} mm"
        if loads:
            text += f", dead loads up to {f.load_factor * lmax:.4g} N"
        if r.stable is False:
            k = f.modes.shape[1]
            text += f", UNSTABLE ({k} unstable mode{'s' if k != 1 else ''}; red: the parts that take part)"
        else:
            text += ", stable"
        labels.append(text)
    if kind == "wrench":
        slider = {
            "name": "|F|",
            "unit": "N",
            "values": [float(np.linalg.norm(np.asarray(f.result.wrench, float)[:3])) for f in path],
        }
    elif kind == "deflection":
        slider = {
            "name": "|δ|",
            "unit": "mm",
            "values": [
                float(np.linalg.norm(np.asarray(f.result.deflection, float)[:3])) * 1e3 for f in path
            ],
        }
    else:
        slider = {"name": "dead load", "unit": "N", "values": [f.load_factor * lmax for f in path]}
    kw = {
        "stable": stable,
        "frame_labels": labels,
        "slider": slider,
        "modes": [f.modes if f.modes.size else None for f in path],
        "closures": closure_triples(vm),
        "loads": [(ld.frame, [f.load_factor * ld.wrench[:3] for f in path]) for ld in loads],
    }
    if getattr(vm, "legs", ()):  # parallel robots: whole legs coloured (unstable_legs)
        kw["unstable_joints"] = [
            leg_joint_ids(vm, unstable_legs(vm, f.modes)) if f.result.stable is False else None
            for f in path
        ]
    if kind != "loads":
        kw["forces"] = [np.asarray(f.result.wrench, float)[:3] for f in path]
    if ellipsoid:
        drawn, force, data = ellipsoid_frames(vm, [f.stiffness for f in path])
        if force is not None:
            kw["ellipsoid"] = drawn
            kw["ellipsoid_label"] = ellipsoid_label(vm, force)
        kw["_ellipsoid"] = (force, data)
    _add_mesh_kw(kw, vis)
    return geom, shown, scale, kw


def _marked_frames(vm, loads=()) -> list[str]:
    """Frames that get a segment of their own in a chain drawing: closure frames, the task
    frame, loaded frames (:func:`vjm_pin.viz.viewer.chain_geometry` ``extra_frames``)."""
    names = [f for c in getattr(vm, "closures", ()) for f in (c.frame_a, c.frame_b)]
    names += [vm.frame] + [ld.frame for ld in loads]
    return list(dict.fromkeys(names))


# ----------------------------------------------------------------------------- command
def run(args) -> int:
    from vjm_pin.cli.analyze import load_from_args
    from vjm_pin.cli.common import check_output_option, loads_from_args
    from vjm_pin.exceptions import InputError
    from vjm_pin.outputs import HTML_EXTENSIONS, PLOT_EXTENSIONS

    check_output_option(args, "--html", HTML_EXTENSIONS)  # before any work
    check_output_option(args, "--png", PLOT_EXTENSIONS)
    if args.snapshots != DEFAULT_SNAPSHOTS and args.png is None:
        raise InputError("--snapshots applies with --png only")
    if getattr(args, "json", False) and args.html is None:
        raise InputError("--json describes the page written by --html: give --html FILE.html")
    if not args.curve:
        extra = [
            flag
            for flag, given in (
                ("--direction", args.direction is not None),
                ("--max-deflection", args.max_deflection is not None),
                ("--steps", args.steps != DEFAULT_STEPS),
                ("--all-branches", args.all_branches),
            )
            if given
        ]
        if extra:
            verb = "apply" if len(extra) > 1 else "applies"
            raise InputError(f"{', '.join(extra)} {verb} with --curve only")
    loads = loads_from_args(args)
    cloud = _map_from_args(args, loads)
    if cloud is None and not (
        args.curve or loads or args.deflection is not None or args.wrench is not None
    ):
        raise InputError("nothing to show: give --deflection, --wrench, --load, --curve or --map")
    if args.scale is not None and not (np.isfinite(args.scale) and args.scale > 0):
        raise InputError(f"--scale must be a positive number, got {args.scale}")
    vm, _ = load_from_args(args)
    args.meshes = mesh_search_from_args(args)
    if cloud is not None:
        return _run_map(args, vm, cloud)
    if args.curve:
        return _run_curve(args, vm, loads)
    if vm.closures or loads:
        return _run_mechanism(args, vm, loads)
    return _run_serial(args, vm)


def _map_from_args(args, loads):
    """The ``--map`` file read (:func:`vjm_pin.viz.map_cloud.read_map`) before any work, or
    None; ``--map`` shows the robot at its reference, so no load options go with it."""
    from vjm_pin.exceptions import InputError

    if args.map is None:
        if args.color_by != "k_min":
            raise InputError("--color-by applies with --map only")
        return None
    other = [
        flag
        for flag, given in (
            ("--curve", args.curve),
            ("--deflection", args.deflection is not None),
            ("--wrench", args.wrench is not None),
            ("--load", bool(loads)),
            ("--ellipsoid", args.ellipsoid),
            ("--png", args.png is not None),
        )
        if given
    ]
    if other:
        raise InputError(f"--map shows the robot at its reference: not with {', '.join(other)}")
    from vjm_pin.viz.map_cloud import read_map

    try:
        return read_map(args.map)
    except InputError as e:
        raise InputError(f"--map: {e}") from None


def _run_map(args, vm, cloud) -> int:
    """The map ``cloud`` as coloured points over the robot at its reference (``--map``)."""
    import warnings
    from pathlib import Path

    from vjm_pin.cli.common import summary
    from vjm_pin.viz.map_cloud import COLOR_BY, map_points
    from vjm_pin.viz.viewer import export_html, serve

    if cloud.model is not None and cloud.model != vm.name:
        warnings.warn(f"the map was computed for model '{cloud.model}', it is drawn over '{vm.name}'")
    if cloud.frame is not None and cloud.frame != vm.frame:
        warnings.warn(f"the map's end frame is '{cloud.frame}', the model's '{vm.frame}'")
    pts = map_points(cloud, args.color_by)
    label, unit, factor, _ = COLOR_BY[args.color_by]
    geom, vis = robot_visuals(vm, (), args.meshes)
    n = len(cloud.p0)
    text = f"{n} poses: end positions (unloaded) coloured by {label}"
    if pts["range"] is not None:
        lo, hi = (v * factor for v in pts["range"])
        text += f" from {lo:.3g} to {hi:.3g} {unit}"
    kw = {"points": pts, "frame_labels": [text], "legend_notes": [vis.note] if vis.note else []}
    title = f"{vm.name}: map {Path(cloud.path).name}, robot at its reference"
    if args.html is None:
        url = serve(vm.model, geom, [vm.reference], open_browser=args.open, title_text=title, **kw)
        print(f"meshcat viewer at {url}; Ctrl-C to stop")
        while True:
            time.sleep(1.0)
    export_html(vm.model, geom, [vm.reference], title_text=title, path=args.html, **kw)
    summary(args, f"{vm.name}: wrote {args.html}, {n} map points")
    if args.json:
        body = {
            "model": vm.name, "parallel": _is_parallel(vm), "mode": "map", "direction": None,
            "html": str(args.html), "scale": 1.0, "frames": [], "critical": [],
            "critical_frame": None, "branches": 0, "closures": [c.name for c in vm.closures],
            "loads": [], "ellipsoid": None, "meshes": _meshes_dict(vis),
            "map": {
                "path": cloud.path, "points": n, "color_by": args.color_by,
                "range": None if pts["range"] is None else list(pts["range"]),
                "not_solved": pts["not_solved"],
            },
        }  # fmt: skip
        print(_dump_view(body))
    else:
        print(f"wrote {args.html}: {text}")
    _maybe_open(args)
    return 0


def _run_curve(args, vm, loads=()) -> int:
    from vjm_pin.cli.common import Progress, direction_vector, summary
    from vjm_pin.exceptions import InputError

    if args.direction is None or args.max_deflection is None:
        raise InputError("--curve needs --direction DX DY DZ [RX RY RZ] and --max-deflection M")
    if not (np.isfinite(args.max_deflection) and args.max_deflection > 0):
        raise InputError(
            f"--max-deflection must be a positive length in m, got {args.max_deflection}"
        )
    if args.steps < 2:
        raise InputError(f"--steps must be at least 2, got {args.steps}")
    direction = direction_vector(args.direction, "--direction")
    with Progress(args, args.steps + 1, f"curve {vm.name}") as bar:
        curve = trace(
            vm, direction, args.max_deflection, args.steps, args.all_branches, bar.update, loads
        )
    anim = None
    if args.png is not None or args.html is None:
        anim = curve_animation(
            vm,
            curve,
            scale=args.scale,
            ellipsoid=args.ellipsoid,
            all_branches=args.all_branches,
            meshes=args.meshes,
        )
    snaps = None
    if args.png is not None:
        loads = tuple(getattr(curve, "loads", ()) or ())
        snaps = write_snapshots(args, vm, anim[1], anim[2], anim[3], loads)
        if args.html is None:
            return 0
    if args.html is not None:
        cp = curve_page(
            vm,
            curve,
            scale=args.scale,
            path=args.html,
            ellipsoid=args.ellipsoid,
            all_branches=args.all_branches,
            meshes=args.meshes,
            animation=anim,
        )
        summary(
            args,
            f"{vm.name}: wrote {args.html}, {cp.frames} frames, {len(curve.critical)} critical points",
        )
        if args.json:
            body = _curve_view_dict(vm, curve, cp, args.html)
            body["snapshots"] = _snapshots_dict(snaps)
            print(_dump_view(body))
        else:
            print(f"wrote {args.html}: {cp.frames} frames, deformation ×{cp.scale:g}")
        _maybe_open(args)
        return 0
    geom, shown, scale, kw = anim
    for k in ("_frames", "_ellipsoid", "_meshes"):
        kw.pop(k, None)
    return _serve(vm, geom, shown, scale, args, kw)


def _run_serial(args, vm) -> int:
    """A serial chain under an end deflection or wrench (:class:`~vjm_pin.solver.EquilibriumSolver`)."""
    from vjm_pin.cli.common import finite_vector
    from vjm_pin.solver import EquilibriumSolver

    solver = EquilibriumSolver(vm)
    # true equilibria along the load path t·load (warm started), not an interpolation
    if args.deflection is not None:
        kind, load = "deflection", finite_vector(args.deflection, "--deflection")
    else:
        kind, load = "wrench", finite_vector(args.wrench, "--wrench")
    ts, path = load_path(vm, load, kind, solver=solver)
    geom, shown, scale, kw = load_frames(vm, ts, path, args.scale, kind, meshes=args.meshes)
    ell = None
    if args.ellipsoid:
        drawn, force, data = ellipsoid_frames(vm, _serial_stiffness(vm, ts, path))
        if force is not None:
            kw["ellipsoid"], kw["ellipsoid_label"] = drawn, ellipsoid_label(vm, force)
        ell = (force, data)
    body = _load_view_dict(vm, kind, ts, path, scale, args.html, ell, kw.pop("_meshes"))
    return _finish_load_page(args, vm, geom, shown, scale, kw, path[-1].stable, body)


def _serial_stiffness(vm, ts, path) -> list:
    """K_C (6, 6) per equilibrium of a serial load path (None where singular; the unloaded
    robot's at load factor 0, as drawn)."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import loaded_stiffness, unloaded_stiffness

    out = []
    for t, r in zip(ts, path):
        try:
            out.append((unloaded_stiffness(vm) if t == 0 else loaded_stiffness(vm, r)).stiffness)
        except SingularStiffness:
            out.append(None)
    return out


def _run_mechanism(args, vm, loads) -> int:
    """A mechanism (loop closures) or any model with dead loads, through
    :class:`~vjm_pin.solver.MechanismSolver`: every task component held (``--deflection``),
    loaded (``--wrench``) or free (``--load`` alone)."""
    from vjm_pin.cli.common import finite_vector

    sizes = tuple(sorted({3, 6, len(vm.task)}))  # or one number per task component
    if args.deflection is not None:
        kind, load = "deflection", finite_vector(args.deflection, "--deflection", sizes)
    elif args.wrench is not None:
        kind, load = "wrench", finite_vector(args.wrench, "--wrench", sizes)
    else:
        kind, load = "loads", None
    path = mechanism_load_path(vm, kind, load, loads, stiffness=args.ellipsoid)
    geom, shown, scale, kw = mechanism_frames(
        vm, path, kind, loads, args.scale, args.ellipsoid, meshes=args.meshes
    )
    ell = kw.pop("_ellipsoid", None)
    body = _mechanism_view_dict(vm, kind, path, scale, args.html, loads, ell, kw.pop("_meshes"))
    return _finish_load_page(args, vm, geom, shown, scale, kw, path[-1].result.stable, body)


def _finish_load_page(args, vm, geom, shown, scale, kw, stable_last, body) -> int:
    """Write (``--html``) or serve the page of a load path and report it."""
    from vjm_pin.cli.common import summary

    title = f"{vm.name}: loaded equilibrium — deformation ×{scale:g}"
    if args.png is not None:
        body["snapshots"] = _snapshots_dict(
            write_snapshots(args, vm, shown, scale, kw, loads_of(args))
        )
        if args.html is None:
            return 0
    if args.html is None:  # the served page shows the frame labels as scene text
        return _serve(vm, geom, shown, scale, args, kw)
    from vjm_pin.viz.viewer import export_html

    export_html(
        vm.model,
        geom,
        shown,
        ghost_q=vm.reference,
        frame_name=vm.frame,
        title_text=title,
        path=args.html,
        **kw,
    )
    verdict = "stable" if stable_last is not False else "UNSTABLE"
    summary(args, f"{vm.name}: wrote {args.html}, {len(shown)} frames, {verdict} equilibrium")
    if args.json:
        print(_dump_view(body))
    else:
        print(f"wrote {args.html}: deformation ×{scale:g}; {verdict} equilibrium")
    _maybe_open(args)
    return 0


def loads_of(args) -> tuple:
    """The ``--load`` dead loads of ``args`` (:func:`vjm_pin.cli.common.loads_from_args`)."""
    from vjm_pin.cli.common import loads_from_args

    return tuple(loads_from_args(args))


def write_snapshots(args, vm, shown, scale, kw, loads=()):
    """Write the ``--png`` snapshot figure of the animation ``(shown, kw)`` (the page's
    frames and keywords) drawn on :func:`vjm_pin.viz.viewer.chain_geometry`; report it on
    stdout (stderr with ``--json``); return the :class:`vjm_pin.viz.figures.SnapshotFigure`."""
    import sys

    from vjm_pin.viz.figures import save_snapshots
    from vjm_pin.viz.viewer import Animation, chain_geometry

    marked = _marked_frames(vm, loads) if (vm.closures or loads) else ()
    geom = chain_geometry(vm.model, vm.roles, extra_frames=marked)
    opts = {k: v for k, v in kw.items() if not k.startswith("_") and k != "legend_notes"}
    anim = Animation(vm.model, geom, shown, ghost_q=vm.reference, frame_name=vm.frame, **opts)
    fig = save_snapshots(
        anim, args.png, count=args.snapshots, title=f"{vm.name} — deformation ×{scale:g}"
    )
    crit = "" if fig.critical_frame is None else f", critical frame {fig.critical_frame}"
    text = (
        f"wrote {args.png}: {len(fig.frames)} snapshots (frames "
        f"{', '.join(map(str, fig.frames))}{crit}), {fig.plane} plane"
    )
    if not args.json:
        print(text)
    elif not getattr(args, "quiet", False):
        print(text, file=sys.stderr)
    return fig


def _snapshots_dict(fig) -> dict | None:
    """The ``snapshots`` key of ``view --json``: the ``--png`` figure, or None."""
    if fig is None:
        return None
    return {
        "path": fig.path,
        "frames": list(fig.frames),
        "critical_frame": fig.critical_frame,
        "plane": fig.plane,
    }


def _dump_view(body: dict) -> str:
    from vjm_pin.cli.common import dump_json, envelope

    return dump_json(envelope("view", {k: body.get(k) for k in VIEW_KEYS}, UNIT_KEYS))


def _view_body(
    vm,
    mode,
    html,
    scale,
    frames,
    *,
    parallel,
    loads=(),
    direction=None,
    critical=(),
    critical_frame=None,
    branches=0,
    ellipsoid=None,
    meshes=None,
) -> dict:
    """The ``view --json`` body (keys :data:`VIEW_KEYS` but ``snapshots``), one builder for
    every page: ``frames`` are the JSON frames already built, ``loads`` the dead loads
    (:class:`~vjm_pin.kinematics.dead_loads.Load` s), ``ellipsoid`` the ``(force, per-frame data)``
    of :func:`ellipsoid_frames` or None, ``meshes`` the scene's visuals (:func:`_meshes_dict`)."""
    return {
        "model": vm.name,
        "parallel": parallel,
        "mode": mode,
        "direction": direction,
        "html": str(html),
        "scale": scale,
        "frames": frames,
        "critical": list(critical),
        "critical_frame": critical_frame,
        "branches": branches,
        "closures": [c.name for c in vm.closures],
        "loads": [{"frame": ld.frame, "wrench": ld.wrench} for ld in loads],
        "ellipsoid": _ellipsoid_dict(vm, ellipsoid),
        "meshes": _meshes_dict(meshes),
    }


def _curve_view_dict(vm, curve, cp, html) -> dict:
    """The ``view --curve --json`` body: the frames of the page ``cp`` (:class:`CurvePage`)."""
    from vjm_pin.cli.curve import CRITICAL_KEYS, critical_dict

    frames = [
        {
            "deflection": f.deflection,
            "force": f.force,
            "wrench": f.wrench,
            "stable": f.stable,
            "kind": f.kind,
        }
        for f in cp.curve_frames
    ]
    return _view_body(
        vm,
        "curve",
        html,
        cp.scale,
        frames,
        parallel=_is_parallel(vm),
        loads=getattr(curve, "loads", ()) or (),
        direction=curve.direction,
        critical=[{k: critical_dict(c).get(k) for k in CRITICAL_KEYS} for c in curve.critical],
        critical_frame=cp.critical_frame,
        branches=cp.branches,
        ellipsoid=cp.ellipsoid,
        meshes=cp.meshes,
    )


def _load_view_dict(vm, kind, ts, results, scale, html, ellipsoid, meshes) -> dict:
    """The ``view --deflection/--wrench --json`` body of a serial chain: one frame per
    equilibrium of the load path (the unloaded robot at load factor 0, as drawn)."""
    frames = []
    for t, r in zip(ts, results):
        zero = t == 0
        frames.append(
            {
                "load_factor": float(t),
                "deflection": np.zeros(6) if zero else r.deflection,
                "wrench": np.zeros(6) if zero else r.wrench,
                "stable": True if zero else r.stable is not False,
                "kind": "load",
            }
        )
    return _view_body(
        vm, kind, html, scale, frames, parallel=False, ellipsoid=ellipsoid, meshes=meshes
    )


def _is_parallel(vm) -> bool:
    """A parallel robot: a model whose legs are declared (``<vjm:leg>``)."""
    return bool(getattr(vm, "legs", ()))


def _mechanism_view_dict(vm, kind, path, scale, html, loads, ellipsoid, meshes) -> dict:
    """The ``view --json`` body of a mechanism load path (:func:`mechanism_load_path`): one
    frame per equilibrium with both verdicts and the number of unstable modes."""
    frames = [
        {
            "load_factor": f.load_factor,
            "deflection": f.result.deflection,
            "wrench": f.result.wrench,
            "stable": f.result.stable is not False,
            "stable_end_held": f.result.stable_end_held,
            "unstable_modes": int(f.modes.shape[1]),
            "unstable_legs": unstable_legs(vm, f.modes),
            "kind": "load",
        }
        for f in path
    ]
    return _view_body(
        vm,
        kind,
        html,
        scale,
        frames,
        parallel=_is_parallel(vm),
        loads=loads,
        ellipsoid=ellipsoid,
        meshes=meshes,
    )


def _ellipsoid_dict(vm, ell):
    """The ``ellipsoid`` key: None without ``--ellipsoid``; else what was drawn
    (:func:`ellipsoid_frames`): per frame the compliance eigenvalues (m/N), their axes
    (rows, world axes) and whether the drawing was clipped, or None where K_C is singular or
    not positive definite."""
    if ell is None:
        return None
    force, data = ell
    return {
        "quantity": "translational compliance (K_C restricted to the task, inverted)",
        "frame": vm.frame,
        "force": force,
        "frames": data,
    }


def _maybe_open(args) -> None:
    if args.open:
        import webbrowser
        from pathlib import Path

        webbrowser.open(Path(args.html).resolve().as_uri())


def _serve(vm, geom, shown, scale, args, kw) -> int:
    from vjm_pin.viz.viewer import serve

    url = serve(
        vm.model,
        geom,
        shown,
        ghost_q=vm.reference,
        frame_name=vm.frame,
        open_browser=args.open,
        **kw,
    )
    print(f"meshcat viewer at {url} (deformation ×{scale:g}); Ctrl-C to stop")
    while True:
        time.sleep(1.0)
