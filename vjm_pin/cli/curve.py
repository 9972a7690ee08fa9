"""``vjm-pin curve``: force–deflection curve and buckling (critical points) of a model."""

from __future__ import annotations

from pathlib import Path

from vjm_pin.cli.common import (
    OUTPUT_NOTE,
    add_dead_load_options,
    add_model_direction,
    add_subdivide_option,
    float_range,
    int_range,
    positive_float,
)

EXAMPLES = (
    "vjm-pin curve paper-c-s --direction -1 0 0 --max-deflection 0.05 --steps 40 --plot curve.png",
    "vjm-pin curve paper-a-s --direction -1 0 0 --max-deflection 0.01 --steps 20 --json",
    "vjm-pin curve portal-frame --direction 1 0 0 --max-deflection 0.2 --steps 20 --load top_left 0 0 -50 "
    "--load top_right 0 0 -50",
)

#: Accepted ``--refine-tol``: the critical forces are located to ``1e-3·refine_tol``
#: relative, so below 1e-10 rounding alone exceeds that; above 0.1 (10 %) it is no
#: tolerance.
REFINE_TOL_RANGE = (1e-10, 0.1)

#: Keys of ``curve --json`` (every model kind alike; null where a key does not apply): the
#: object, each point (of ``points`` and of each of ``branches``), each critical point.
#: ``stiffness`` (the 6×6 K_C) is in the points with ``--matrices`` only.
CURVE_KEYS = (
    "model", "parallel", "direction", "free", "loads", "gravity", "points", "critical", "branches", "stopped",
)
POINT_KEYS = (
    "deflection", "force", "wrench", "stable", "stable_end_held", "force_control_margin",
    "stiffness_along",
)
CRITICAL_KEYS = (
    "force", "deflection", "stiffness_before", "stiffness_after", "index", "force_after", "kind",
)
UNIT_KEYS = (
    "deflection", "force", "wrench", "stiffness", "stiffness_along", "stiffness_before",
    "stiffness_after", "force_control_margin", "direction",
)


def curve_json(body: dict) -> dict:
    """The ``curve --json`` object: :func:`vjm_pin.cli.common.envelope` over ``body``, every
    key of :data:`CURVE_KEYS`, :data:`POINT_KEYS` and :data:`CRITICAL_KEYS` present (null
    where it does not apply)."""
    from vjm_pin.cli.common import envelope

    def point(d):
        return {**{k: d.get(k) for k in POINT_KEYS}, **({"stiffness": d["stiffness"]} if "stiffness" in d else {})}

    body = {k: body.get(k) for k in CURVE_KEYS}
    body["points"] = [point(d) for d in body["points"]]
    body["branches"] = [[point(d) for d in br] for br in body["branches"] or []]
    body["critical"] = [{k: c.get(k) for k in CRITICAL_KEYS} for c in body["critical"]]
    from vjm_pin.cli.common import UNITS

    units = {**{k: UNITS[k] for k in UNIT_KEYS}, "loads": "N (moment components: N·m), world axes, force at the frame origin"}
    return envelope("curve", body, units)


def add_parser(sub):
    p = sub.add_parser(
        "curve",
        help="force–deflection curve along a direction, with buckling detection",
        description=(
            "Trace the loaded equilibrium of MODEL (eq. 5) while its end moves along DIRECTION up "
            "to --max-deflection (predictor-corrector continuation in adaptive sub-steps; the stable "
            "branch is followed, switching to the stable buckled branch at a bifurcation), and locate "
            "the critical points: where the followed equilibrium stops being stable under a dead force "
            "along DIRECTION (bifurcation or force maximum; or a sharp near-loss, 'imperfect'), found "
            "by root finding on that stability margin, independently of --steps. Every point reports "
            "'stable' (the end held, eq. 23) and the force-control margin. Units: m and N (rad and "
            "N·m for a rotation). The force is the external force along the direction that holds "
            "the end there. Every model kind: open chains and mechanisms with loop closures "
            "(parallel robots: the platform is the end). --load and --gravity add dead loads "
            "anywhere, kept constant along the curve; --free holds only the component along "
            "DIRECTION (the end free across it, no load there) instead of every task component."
        ),
    )
    _add_options(p)
    p.set_defaults(func=run)


def _add_options(p) -> None:
    """The arguments and options of ``vjm-pin curve``."""
    add_model_direction(p)
    p.add_argument(
        "--max-deflection",
        type=positive_float,
        required=True,
        metavar="D",
        help="final deflection (m or rad)",
    )
    p.add_argument(
        "--steps", type=int_range(1), default=100, help="number of steps (default 100)"
    )
    p.add_argument(
        "--all-branches", action="store_true", help="also trace the unstable branches (Fig. 4)"
    )
    add_subdivide_option(p)
    p.add_argument(
        "--free",
        action="store_true",
        help="hold only the component along DIRECTION: the end (a parallel robot's platform) is free "
        "across it, with no load there (default: every task component held, nothing moves across it); a model that is then a mechanism (no stiffness across DIRECTION at the start) is refused, exit 2",
    )
    add_dead_load_options(p)
    p.add_argument(
        "--refine-tol",
        type=float_range(*REFINE_TOL_RANGE),
        default=1e-4,
        help="relative force tolerance of critical points (located to 1e-3 of it; from "
        f"{REFINE_TOL_RANGE[0]:g} to {REFINE_TOL_RANGE[1]:g}, default 1e-4)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="one JSON object {points, critical, branches, ...} on stdout (see 'vjm-pin schema curve')",
    )
    p.add_argument(
        "--plot",
        metavar="OUT.png",
        help="write a force–deflection plot; format from the extension (.png, .pdf, .svg, ...); "
        f"{OUTPUT_NOTE}",
    )
    p.add_argument(
        "--matrices",
        action="store_true",
        help="also give the loaded 6x6 stiffness K_C (eq. 30) at every point (JSON: 'stiffness'); "
        "in text, at the points just before and after each critical point",
    )


def load_model(name: str, subdivide: int = 1):
    """Resolve ``name`` (path or bundled model; every model kind) and subdivide its beam links if
    asked (open chains only)."""
    from vjm_pin.exceptions import InputError
    from vjm_pin.model.registry import bundled_models, resolve_model

    if subdivide < 1:
        raise InputError(f"--subdivide must be a positive integer, got {subdivide}")
    if subdivide == 1:
        return resolve_model(name)
    from vjm_pin.model.subdivide import subdivide_model

    if resolve_model(name).closures:  # also the error of an unknown name
        raise InputError("--subdivide is not available for models with loop closures")

    src = bundled_models().get(name, name)
    if not Path(src).is_file():
        resolve_model(name)  # the error of an unknown name, else:
        raise InputError(
            f"--subdivide applies to VJM models with beam springs (a URDF file or a bundled "
            f"model), not to the robot '{name}'"
        )
    return subdivide_model(src, subdivide)


def point_dict(p) -> dict:
    return {
        "deflection": p.deflection,
        "force": p.force,
        "wrench": p.wrench,
        "stable": p.stable,
        "stable_end_held": p.stable_end_held,
        "force_control_margin": p.force_control_margin,
        "stiffness_along": p.stiffness,
    }


def critical_dict(c) -> dict:
    return {
        "force": c.force,
        "deflection": c.deflection,
        "stiffness_before": c.stiffness_before,
        "stiffness_after": c.stiffness_after,
        "index": c.index,
        "force_after": c.force_after,
        "kind": c.kind,
    }


def stiffness_matrix(vm, p, mechanism=None):
    """Loaded K_C (6, 6) at a traced point, or None where it is singular/infinite: eq. (30) for an
    :class:`~vjm_pin.solver.EquilibriumResult`, eq. (28) bordered with the closure rows for a
    :class:`~vjm_pin.solver.MechanismResult` (``mechanism``: the
    :class:`~vjm_pin.solver.MechanismSolver` with the curve's dead loads)."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import MechanismResult, loaded_stiffness

    try:
        if isinstance(p.equilibrium, MechanismResult):
            return mechanism.stiffness(p.equilibrium).stiffness
        return loaded_stiffness(vm, p.equilibrium).stiffness
    except SingularStiffness:
        return None


def curve_dict(vm, curve, matrices: bool = False, *, free=False, loads=(), gravity=None, load_list=None) -> dict:
    """The ``curve --json`` body (:func:`curve_json` completes it): ``loads`` the dead loads
    (:class:`~vjm_pin.kinematics.dead_loads.Load`) the curve was traced under, ``gravity`` (3,) or
    None, ``load_list`` their JSON form."""
    mech = None
    if matrices and any(_is_mechanism_point(p) for p in curve.points):
        from vjm_pin.solver import MechanismSolver

        mech = MechanismSolver(vm, loads, gravity)

    def pd(p):
        d = point_dict(p)
        if matrices:
            d["stiffness"] = stiffness_matrix(vm, p, mech)
        return d

    return {
        "model": vm.name,
        "parallel": bool(vm.closures),
        "direction": curve.direction,
        "free": bool(free),
        "loads": load_list if load_list is not None else [],
        "gravity": gravity is not None,
        "points": [pd(p) for p in curve.points],
        "critical": [critical_dict(c) for c in curve.critical],
        "branches": [[pd(p) for p in br] for br in curve.branches],
        "stopped": getattr(curve, "stopped", None) or None,  # null: traced to --max-deflection
    }


def _is_mechanism_point(p) -> bool:
    from vjm_pin.solver import MechanismResult

    return isinstance(p.equilibrium, MechanismResult)


def trace_and_plot(trace, args, name: str):
    """Run ``trace(progress)`` with a progress bar on a terminal (:class:`~vjm_pin.cli.common.Progress`)
    and write ``--plot``; shared by single-chain and parallel curves. Returns the curve."""
    import numpy as np

    from vjm_pin.cli.common import Progress, summary

    with Progress(args, args.steps + 1, f"curve {name}") as bar:
        curve = trace(bar.update)
    fu = "N·m" if np.any(np.asarray(curve.direction, float)[3:]) else "N"
    crit = ", ".join(f"{c.kind} at {c.force:.6g} {fu}" for c in curve.critical) or "none"
    summary(args, f"{name}: {len(curve.points)} points, critical points: {crit}")
    if args.plot is not None:
        from vjm_pin.viz.plots import save_curve_plot

        save_curve_plot(
            curve,
            args.plot,
            title=f"{name}: force–deflection along {np.round(curve.direction, 3).tolist()}",
        )
    return curve


def run(args) -> int:
    import numpy as np

    from vjm_pin.analysis.curve import trace_curve
    from vjm_pin.cli.analyze import dead_loads_from_args, loads_list
    from vjm_pin.cli.common import check_output_option, direction_vector, dump_json
    from vjm_pin.exceptions import InputError
    from vjm_pin.outputs import PLOT_EXTENSIONS

    check_output_option(args, "--plot", PLOT_EXTENSIONS)  # before any work
    vm = load_model(args.model, args.subdivide)
    d = direction_vector(args.direction, "--direction")
    if not np.isfinite(args.max_deflection):
        raise InputError(f"--max-deflection must be finite, got {args.max_deflection}")
    loads, gravity = dead_loads_from_args(args, vm)
    # the one tracer for every model kind; the mechanism options only when asked (open chains
    # without them keep the serial tracer's defaults)
    extra = {k: v for k, v in (("loads", loads), ("gravity", gravity), ("free", args.free)) if v}
    curve = trace_and_plot(
        lambda cb: trace_curve(
            vm,
            d,
            args.max_deflection,
            args.steps,
            refine_tol=args.refine_tol,
            all_branches=args.all_branches,
            progress=cb,
            **extra,
        ),
        args,
        vm.name,
    )
    body = curve_dict(
        vm, curve, args.matrices, free=args.free, loads=loads, gravity=gravity, load_list=loads_list(args, loads)
    )
    if args.json:
        print(dump_json(curve_json(body)))
        return 0
    _print_curve(args, vm, curve, loads, gravity)
    return 0


def _print_curve(args, vm, curve, loads, gravity) -> None:
    """The text output of ``curve``."""
    import numpy as np

    rot = bool(np.any(curve.direction[3:]))
    du, fu = ("rad", "N·m") if rot else ("m", "N")
    print(
        f"model {vm.name}: direction {np.round(curve.direction, 4).tolist()}, {len(curve.points)} points"
        + (" (end free across the direction)" if args.free else "")
    )
    for ld in loads:
        print(f"dead load at '{ld.frame}' [N, N·m, world axes]: {np.array2string(ld.wrench, precision=4)}")
    if gravity is not None:
        print("dead loads: link weights (gravity)")
    print(
        f"{'deflection [' + du + ']':>18} {'force [' + fu + ']':>16} {'stiffness [' + fu + '/' + du + ']':>20}"
        f"  stable  {'force-control margin':>20}"
    )
    for p in curve.points:
        print(
            f"{p.deflection:18.8g} {p.force:16.8g} {p.stiffness:20.8g}  {'yes' if p.stable else 'NO':>6}"
            f"  {p.force_control_margin:20.6g}"
        )
    print(
        "stable: the end held (eq. 23), the control as run; force-control margin > 0: also stable under "
        "a dead force along the direction"
    )
    if not curve.critical:
        print("no critical point (the followed branch stays stable under a force along the direction) in this range")
    for c in curve.critical:
        print(
            f"critical point: force {c.force:.8g} {fu} at deflection {c.deflection:.8g} {du} ({c.kind}); "
            f"tangent stiffness {c.stiffness_before:.6g} -> {c.stiffness_after:.6g} {fu}/{du}"
        )
    if args.matrices:
        from vjm_pin.cli.common import fmt_matrix

        mech = None
        if any(_is_mechanism_point(p) for p in curve.points):
            from vjm_pin.solver import MechanismSolver

            mech = MechanismSolver(vm, loads, gravity)

        for c in curve.critical:
            for label, idx in (("before", c.index - 1), ("after", c.index)):
                if 0 <= idx < len(curve.points):
                    p = curve.points[idx]
                    k = stiffness_matrix(vm, p, mech)
                    print(
                        f"loaded stiffness K_C {label} the critical point (deflection {p.deflection:.6g} {du}):"
                    )
                    print(
                        fmt_matrix(k)
                        if k is not None
                        else "  singular (infinite in some direction)"
                    )
    for i, br in enumerate(curve.branches):
        print(
            f"branch {i + 1}: {len(br)} points, {'unstable' if not any(p.stable for p in br) else 'mixed'}, "
            f"force {br[0].force:.6g} .. {br[-1].force:.6g} {fu}"
        )
    if getattr(curve, "stopped", None):
        print(f"WARNING: the curve stopped before --max-deflection: {curve.stopped}")
    if args.plot:
        print(f"plot written to {args.plot}")
