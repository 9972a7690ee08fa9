"""``vjm-pin view``: the loaded robot (or its path along a force–deflection curve) in meshcat.

The library glue used by ``view`` and ``demo`` lives here too: :func:`curve_page` turns a
traced curve into an animated page, :func:`load_page` a single loaded equilibrium.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

DEFAULT_STEPS = 60


def add_parser(sub):
    p = sub.add_parser(
        "view",
        help="show the loaded robot, or animate it along a force-deflection curve, in meshcat",
        description=(
            "Show MODEL in meshcat: the unloaded robot ghosted, the loaded one solid (green: stable, "
            "red: unstable), the force arrow at the end frame and, with --curve, an animation along the "
            "traced force-deflection path with a marker at the critical point. Deformations (spring "
            "deflections θ-θ0 and passive joint motion) are magnified by --scale for display; the page "
            "states the scale. With --html the page is written to a file that plays offline "
            "(append #frame=K to its URL to pause at frame K); without it a meshcat server is started "
            "and serves until Ctrl-C."
        ),
    )
    from .analyze import add_robot_options

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
        type=float,
        metavar="M",
        help="with --curve: largest deflection along the direction (m)",
    )
    p.add_argument(
        "--steps",
        type=int,
        default=DEFAULT_STEPS,
        help=f"with --curve: number of curve steps (default {DEFAULT_STEPS})",
    )
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="deformation magnification (default: chosen so the deformation is visible)",
    )
    p.add_argument(
        "--html", metavar="FILE", help="write a self-contained HTML page instead of serving"
    )
    p.add_argument(
        "--open",
        action="store_true",
        help="open the page (or the served viewer) in the web browser",
    )
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- curves
def trace(vm, direction: np.ndarray, max_deflection: float, steps: int = DEFAULT_STEPS):
    """The force-deflection curve of ``vm`` along ``direction`` up to ``max_deflection`` (m)."""
    from ..solver.curve import trace_curve

    return trace_curve(vm, direction, max_deflection, steps)


@dataclass(frozen=True)
class CurvePage:
    """An exported curve animation.

    Attributes:
        html: The page.
        scale: Deformation magnification used (dimensionless).
        frames: Number of animation frames.
        critical_frame: Frame index of the first critical point, or None.
    """

    html: str
    scale: float
    frames: int
    critical_frame: int | None


def _label(deflection_m: float, force_n: float, stable) -> str:
    verdict = "stable" if stable in (True, None) else "UNSTABLE"
    return f"δ = {deflection_m * 1e3:.3f} mm, |F| = {abs(force_n):.4g} N, {verdict}"


def _scene(vm, frames_x, scale):
    from ..viewer import default_scale, magnify

    if scale is None:
        scale = default_scale(vm.model, vm.reference, frames_x)
    shown = [magnify(vm.reference, x, scale) for x in frames_x]
    geom = robot_geometry(vm)
    return geom, shown, float(scale)


def robot_geometry(vm):
    """The robot's own visual meshes when its URDF has them (example-robot-data robots),
    else clean primitives for generated chains (:func:`vjm_pin.viewer.chain_geometry`)."""
    from ..viewer import chain_geometry, mesh_geometry

    return mesh_geometry(vm.model, vm.urdf) or chain_geometry(vm.model, vm.roles)


def curve_page(
    vm,
    curve,
    *,
    scale: float | None = None,
    path=None,
    title: str | None = None,
    fps: float = 10.0,
    **options,
) -> CurvePage:
    """Animated page of ``vm`` along ``curve`` (a ``vjm_pin.solver.curve.Curve``).

    Frame 0 is the unloaded robot unless the curve starts at zero deflection; then one frame
    per curve point, coloured by its stability, with the force arrow scaled to its load and
    the critical marker at the first critical point. ``scale`` magnifies the deformation
    (:func:`vjm_pin.viewer.magnify`); None picks :func:`vjm_pin.viewer.default_scale`.
    ``options`` go to :func:`vjm_pin.viewer.export_html` (e.g. ``camera_direction``).
    """
    from ..viewer import export_html

    points = list(curve.points)
    xs, stable, forces, labels = [], [], [], []
    offset = 0
    if not points or abs(points[0].deflection) > 0:
        xs.append(vm.reference.copy())
        stable.append(True)
        forces.append(np.zeros(3))
        labels.append(_label(0.0, 0.0, True))
        offset = 1
    for pt in points:
        xs.append(np.asarray(pt.equilibrium.x, float))
        stable.append(bool(pt.stable) if pt.stable is not None else True)
        forces.append(np.asarray(pt.wrench, float)[:3])
        labels.append(_label(pt.deflection, pt.force, pt.stable))
    critical = curve.critical[0].index + offset if curve.critical else None
    geom, shown, scale = _scene(vm, xs, scale)
    d = np.asarray(curve.direction, float)
    text = (
        title or f"{vm.name}: path along deflection direction {np.array2string(d[:3], precision=3)}"
    )
    text += f" — deformation ×{scale:g}"
    if critical is not None:
        c = curve.critical[0]
        labels[critical] += f" — first frame past the critical point F_cr = {abs(c.force):.4g} N at δ = {c.deflection * 1e3:.4g} mm"
    page = export_html(
        vm.model,
        geom,
        shown,
        ghost_q=vm.reference,
        stable=stable,
        forces=forces,
        frame_name=vm.frame,
        critical_index=critical,
        fps=fps,
        title_text=text,
        frame_labels=labels,
        path=path,
        **options,
    )
    return CurvePage(page, scale, len(shown), critical)


def load_frames(vm, res, scale: float | None = None, n: int = 11):
    """Frames growing the equilibrium ``res`` from the unloaded robot (display only):
    the deformation and the force are interpolated linearly, n frames."""
    ts = np.linspace(0.0, 1.0, n)
    xs = [vm.reference + t * (res.x - vm.reference) for t in ts]
    geom, shown, scale = _scene(vm, xs, scale)
    forces = [t * np.asarray(res.wrench, float)[:3] for t in ts]
    stable = [True] * (n - 1) + [res.stable is not False]
    labels = [f"load ×{t:.1f}" for t in ts[:-1]] + [
        _label(
            float(np.linalg.norm(res.deflection[:3])),
            float(np.linalg.norm(res.wrench[:3])),
            res.stable,
        )
    ]
    return geom, shown, scale, {"stable": stable, "forces": forces, "frame_labels": labels}


# ----------------------------------------------------------------------------- command
def run(args) -> int:
    from ..exceptions import InputError
    from ..solver import EquilibriumSolver
    from .common import finite_vector

    from .analyze import load_from_args

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
        direction = finite_vector(args.direction, "--direction")
        curve = trace(vm, direction, args.max_deflection, args.steps)
        if args.html:
            cp = curve_page(vm, curve, scale=args.scale, path=args.html)
            print(f"wrote {args.html}: {cp.frames} frames, deformation ×{cp.scale:g}")
            _maybe_open(args)
            return 0
        from ..viewer import default_scale, magnify

        xs = [vm.reference] + [np.asarray(p.equilibrium.x, float) for p in curve.points]
        scale = args.scale or default_scale(vm.model, vm.reference, xs)
        kw = {
            "stable": [True] + [p.stable is not False for p in curve.points],
            "forces": [np.zeros(3)] + [np.asarray(p.wrench, float)[:3] for p in curve.points],
            "critical_index": curve.critical[0].index + 1 if curve.critical else None,
        }
        return _serve(
            vm,
            robot_geometry(vm),
            [magnify(vm.reference, x, scale) for x in xs],
            scale,
            args,
            kw,
        )
    solver = EquilibriumSolver(vm)
    if args.deflection is not None:
        res = solver.solve(finite_vector(args.deflection, "--deflection"))
    else:
        res = solver.solve_wrench(finite_vector(args.wrench, "--wrench"))
    geom, shown, scale, kw = load_frames(vm, res, args.scale)
    title = f"{vm.name}: loaded equilibrium — deformation ×{scale:g}"
    if args.html:
        from ..viewer import export_html

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
        print(
            f"wrote {args.html}: deformation ×{scale:g}; {'stable' if res.stable is not False else 'UNSTABLE'} equilibrium"
        )
        _maybe_open(args)
        return 0
    kw.pop("frame_labels")
    return _serve(vm, geom, shown, scale, args, kw)


def _maybe_open(args) -> None:
    if args.open:
        import webbrowser
        from pathlib import Path

        webbrowser.open(Path(args.html).resolve().as_uri())


def _serve(vm, geom, shown, scale, args, kw) -> int:
    from ..viewer import serve

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
