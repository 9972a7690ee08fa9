"""``vjm-pin view``: the loaded robot (or its path along a force–deflection curve) in meshcat.

The library glue used by ``view`` and ``demo`` lives here too: :func:`curve_page` turns a
traced curve into an animated page, :func:`load_page` a single loaded equilibrium.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from vjm_pin.cli.common import int_range, positive_float

log = logging.getLogger(__name__)

DEFAULT_STEPS = 60

EXAMPLES = (
    "vjm-pin view paper-c-s --curve --direction -1 0 0 --max-deflection 0.05 --html curve.html",
    "vjm-pin view paper-a-s --wrench 2 0.1 0 --html loaded.html --json",
    "vjm-pin view ur5 --q shoulder_lift_joint=-1 elbow_joint=1 --wrench 0 0 -200 --open",
)

#: Keys of ``view --json`` (see ``vjm-pin schema view``). ``frames`` are the animation frames:
#: with ``--curve`` (``direction`` given) each has the scalars ``deflection`` and ``force``
#: along the direction, as the points of ``curve``; along a load path each has the 6-vectors
#: ``deflection`` and ``wrench`` of the equilibrium at ``load_factor`` × the load, as ``analyze``.
VIEW_KEYS = (
    "model", "parallel", "mode", "direction", "html", "scale", "frames", "critical",
    "critical_frame", "branches",
)
UNIT_KEYS = (
    "deflection", "force", "wrench", "stiffness_before", "stiffness_after", "direction",
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
            "a meshcat server is started and serves until Ctrl-C."
        ),
    )
    from vjm_pin.cli.analyze import add_robot_options

    add_robot_options(p)  # MODEL, --q, --pose-name, --frame, --springs (as analyze)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument(
        "--deflection", nargs="+", type=float, metavar="D", help="DX DY DZ [RX RY RZ] (m, rad)"
    )
    g.add_argument(
        "--wrench", nargs="+", type=float, metavar="W", help="FX FY FZ [MX MY MZ] (N, N·m)"
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
        "--json",
        action="store_true",
        help="with --html: one JSON object on stdout describing the page's frames (see "
        "'vjm-pin schema view')",
    )
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- curves
def trace(
    vm,
    direction: np.ndarray,
    max_deflection: float,
    steps: int = DEFAULT_STEPS,
    all_branches: bool = False,
    progress=None,
):
    """The force-deflection curve of ``vm`` along ``direction`` up to ``max_deflection`` (m);
    with ``all_branches`` also the branches that leave its critical points. ``progress(done,
    total)`` is called as points are traced (:func:`vjm_pin.analysis.curve.trace_curve`)."""
    from vjm_pin.analysis.curve import trace_curve

    return trace_curve(
        vm, direction, max_deflection, steps, all_branches=all_branches, progress=progress
    )


def _label(deflection_m: float, force_n: float, stable) -> str:
    verdict = "stable" if stable in (True, None) else "UNSTABLE"
    return f"δ = {deflection_m * 1e3:.4g} mm, |F| = {abs(force_n):.4g} N, {verdict}"


def _scene(vm, frames_x, scale):
    from vjm_pin.viz.viewer import default_scale, magnify

    if scale is None:
        scale = default_scale(vm.model, vm.reference, frames_x)
    shown = [magnify(vm.reference, x, scale) for x in frames_x]
    geom = robot_geometry(vm)
    return geom, shown, float(scale)


def robot_geometry(vm):
    """The robot's own visual meshes when its URDF has them (example-robot-data robots),
    else clean primitives for generated chains (:func:`vjm_pin.viz.viewer.chain_geometry`)."""
    from vjm_pin.viz.viewer import chain_geometry, mesh_geometry

    return mesh_geometry(vm.model, vm.urdf) or chain_geometry(vm.model, vm.roles)


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
    """

    deflection: float
    force: float
    wrench: np.ndarray
    stable: bool
    x: np.ndarray
    kind: str


def _frame(eq, s: float, d: np.ndarray, kind: str) -> CurveFrame:
    w = np.asarray(eq.wrench, float)
    return CurveFrame(
        float(s), float(d @ w), w, eq.stable is not False, np.asarray(eq.x, float), kind
    )


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
        solver: An :class:`~vjm_pin.solver.EquilibriumSolver` of ``vm`` (default: a new one).

    Returns:
        (frames, critical) — the :class:`CurveFrame` list in order of deflection and, per
        critical point of ``curve``, the index of its ``"critical"`` frame (or None when its
        state could not be solved).
    """
    from vjm_pin.exceptions import InputError
    from vjm_pin.solver import EquilibriumSolver

    if int(n_frames) != n_frames or n_frames < 2:
        raise InputError(f"n_frames must be an integer >= 2, got {n_frames}")
    solver = solver or EquilibriumSolver(vm)
    d = np.asarray(curve.direction, float)
    pts = list(curve.points)
    samples = [_frame(p.equilibrium, p.deflection, d, "curve") for p in pts]
    crit_samples: list[CurveFrame | None] = []
    no_split = set()  # (s_lo, s_hi) of sample pairs across a critical point
    for c in curve.critical:
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

    data = vm.model.createData()
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
    crit_arc = [arc[i] for i, f in enumerate(samples) if any(f is cs for cs in crit_samples)]
    targets = list(np.linspace(0.0, arc[-1], int(n_frames)))
    for ca in crit_arc:  # the critical states are frames themselves
        j = int(np.argmin([abs(t - ca) for t in targets]))
        targets[j] = ca
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
    crit_idx = []
    for cs in crit_samples:
        crit_idx.append(next((i for i, f in enumerate(frames) if f is cs), None))
    return frames, crit_idx


def branch_frames(vm, curve, frames, solver=None):
    """The other branches of ``curve`` (``Curve.branches``, traced with ``all_branches``)
    at the deflections of ``frames``: per branch, one configuration per frame (None where
    the branch does not reach that deflection) and one stability flag per frame.

    Each configuration is an equilibrium solved at the frame's deflection with a solver that
    does not prefer stable states, warm started from the nearest branch point, and kept
    only if it stays on the branch (within two branch steps of that point). Frames before
    the critical point a branch leaves are not shown.
    """
    from vjm_pin.solver import EquilibriumSolver
    from vjm_pin.viz.viewer import Branch

    if not curve.branches:
        return []
    d = np.asarray(curve.direction, float)
    unstable = EquilibriumSolver(vm, follow_stable=False)
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


def curve_animation(vm, curve, *, scale=None, n_frames: int = DEFAULT_FRAMES, solver=None):
    """Everything an animation of ``curve`` needs: ``(geometry, shown frames, scale, kw)``
    with ``kw`` the :class:`vjm_pin.viz.viewer.Animation` keywords (stability, forces, critical
    frame, labels, load slider in mm, other branches) and ``kw["_frames"]`` the
    :class:`CurveFrame` list (popped by the callers)."""
    from vjm_pin.viz.viewer import Branch, magnify

    frames, crit = curve_frames(vm, curve, n_frames, solver)
    if frames[0].deflection > 0:  # the unloaded robot first
        frames.insert(
            0, CurveFrame(0.0, 0.0, np.zeros(6), True, np.asarray(vm.reference, float), "curve")
        )
        crit = [None if c is None else c + 1 for c in crit]
    branches = branch_frames(vm, curve, frames, solver)
    xs = [f.x for f in frames] + [q for b in branches for q in b.frames if q is not None]
    geom, _, scale = _scene(vm, xs, scale)
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
    }
    return geom, shown, scale, kw


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
    """

    html: str
    scale: float
    frames: int
    critical_frame: int | None
    curve_frames: tuple = ()
    branches: int = 0


def curve_page(
    vm,
    curve,
    *,
    scale: float | None = None,
    path=None,
    title: str | None = None,
    fps: float = 15.0,
    n_frames: int = DEFAULT_FRAMES,
    **options,
) -> CurvePage:
    """Animated page of ``vm`` along ``curve`` (a ``vjm_pin.analysis.curve.Curve``).

    Frames from :func:`curve_frames` (dense around the critical points), the unloaded robot
    first; each coloured by its stability, with the force arrow and its value in N, the
    critical marker at the first critical point, a load slider in mm of deflection and, when
    the curve was traced with ``all_branches=True``, the other branches as second robots
    (red where unstable). ``scale`` magnifies the deformation
    (:func:`vjm_pin.viz.viewer.magnify`); None picks :func:`vjm_pin.viz.viewer.default_scale`.
    ``options`` go to :func:`vjm_pin.viz.viewer.export_html` (e.g. ``camera_direction``).
    """
    from vjm_pin.viz.viewer import export_html

    geom, shown, scale, kw = curve_animation(vm, curve, scale=scale, n_frames=n_frames)
    frames = kw.pop("_frames")
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
        page, scale, len(shown), kw["critical_index"], tuple(frames), len(kw["branches"])
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


def load_frames(vm, ts, results, scale: float | None = None, kind: str = "wrench"):
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
    geom, shown, scale = _scene(vm, xs, scale)
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
    return (
        geom,
        shown,
        scale,
        {"stable": stable, "forces": forces, "frame_labels": labels, "slider": slider},
    )


# ----------------------------------------------------------------------------- command
def run(args) -> int:
    from vjm_pin.exceptions import InputError
    from vjm_pin.outputs import HTML_EXTENSIONS
    from vjm_pin.solver import EquilibriumSolver
    from vjm_pin.cli.analyze import load_from_args
    from vjm_pin.cli.common import check_output_option, direction_vector, finite_vector
    from vjm_pin.cli.parallel_cmds import is_parallel_model

    check_output_option(args, "--html", HTML_EXTENSIONS)  # before any work
    if getattr(args, "json", False) and args.html is None:
        raise InputError("--json describes the page written by --html: give --html FILE.html")
    if is_parallel_model(args.model):
        raise InputError(
            f"'{args.model}' is a parallel model (<vjm:leg> tags); 'vjm-pin view' shows serial "
            "chains only (use 'vjm-pin analyze' or 'vjm-pin curve' for it)"
        )
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
    vm, _ = load_from_args(args)
    if args.scale is not None and not (np.isfinite(args.scale) and args.scale > 0):
        raise InputError(f"--scale must be a positive number, got {args.scale}")
    if args.curve:
        if args.direction is None or args.max_deflection is None:
            raise InputError("--curve needs --direction DX DY DZ [RX RY RZ] and --max-deflection M")
        if not (np.isfinite(args.max_deflection) and args.max_deflection > 0):
            raise InputError(
                f"--max-deflection must be a positive length in m, got {args.max_deflection}"
            )
        if args.steps < 2:
            raise InputError(f"--steps must be at least 2, got {args.steps}")
        direction = direction_vector(args.direction, "--direction")
        from vjm_pin.cli.common import Progress, summary

        with Progress(args, args.steps + 1, f"curve {vm.name}") as bar:
            curve = trace(
                vm, direction, args.max_deflection, args.steps, args.all_branches, bar.update
            )
        if args.html is not None:
            cp = curve_page(vm, curve, scale=args.scale, path=args.html)
            summary(args, f"{vm.name}: wrote {args.html}, {cp.frames} frames, {len(curve.critical)} critical points")
            if args.json:
                print(_dump_view(_curve_view_dict(vm, curve, cp, args.html)))
            else:
                print(f"wrote {args.html}: {cp.frames} frames, deformation ×{cp.scale:g}")
            _maybe_open(args)
            return 0
        geom, shown, scale, kw = curve_animation(vm, curve, scale=args.scale)
        kw.pop("_frames")
        return _serve(vm, geom, shown, scale, args, kw)
    solver = EquilibriumSolver(vm)
    # true equilibria along the load path t·load (warm started), not an interpolation
    if args.deflection is not None:
        kind, load = "deflection", finite_vector(args.deflection, "--deflection")
    else:
        kind, load = "wrench", finite_vector(args.wrench, "--wrench")
    ts, path = load_path(vm, load, kind, solver=solver)
    res = path[-1]
    geom, shown, scale, kw = load_frames(vm, ts, path, args.scale, kind)
    title = f"{vm.name}: loaded equilibrium — deformation ×{scale:g}"
    if args.html is not None:
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
        from vjm_pin.cli.common import summary

        verdict = "stable" if res.stable is not False else "UNSTABLE"
        summary(args, f"{vm.name}: wrote {args.html}, {len(shown)} frames, {verdict} equilibrium")
        if args.json:
            print(_dump_view(_load_view_dict(vm, kind, ts, path, scale, args.html)))
        else:
            print(f"wrote {args.html}: deformation ×{scale:g}; {verdict} equilibrium")
        _maybe_open(args)
        return 0
    kw.pop("frame_labels")
    return _serve(vm, geom, shown, scale, args, kw)


def _dump_view(body: dict) -> str:
    from vjm_pin.cli.common import dump_json, envelope

    return dump_json(envelope("view", {k: body.get(k) for k in VIEW_KEYS}, UNIT_KEYS))


def _curve_view_dict(vm, curve, cp, html) -> dict:
    """The ``view --curve --json`` body: the frames of the page ``cp`` (:class:`CurvePage`)."""
    from vjm_pin.cli.curve import CRITICAL_KEYS, critical_dict

    return {
        "model": vm.name,
        "parallel": False,
        "mode": "curve",
        "direction": curve.direction,
        "html": str(html),
        "scale": cp.scale,
        "frames": [
            {
                "deflection": f.deflection,
                "force": f.force,
                "wrench": f.wrench,
                "stable": f.stable,
                "kind": f.kind,
            }
            for f in cp.curve_frames
        ],
        "critical": [{k: critical_dict(c).get(k) for k in CRITICAL_KEYS} for c in curve.critical],
        "critical_frame": cp.critical_frame,
        "branches": cp.branches,
    }


def _load_view_dict(vm, kind, ts, results, scale, html) -> dict:
    """The ``view --deflection/--wrench --json`` body: one frame per equilibrium of the load
    path (the unloaded robot at load factor 0, as drawn)."""
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
    return {
        "model": vm.name,
        "parallel": False,
        "mode": kind,
        "direction": None,
        "html": str(html),
        "scale": scale,
        "frames": frames,
        "critical": [],
        "critical_frame": None,
        "branches": 0,
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
