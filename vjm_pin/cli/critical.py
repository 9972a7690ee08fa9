"""``vjm-pin critical``: the critical (buckling) load of a model along a direction, directly."""

from __future__ import annotations

from vjm_pin.cli.common import (
    add_dead_load_options,
    add_model_direction,
    add_subdivide_option,
    float_range,
    positive_float,
)

EXAMPLES = (
    "vjm-pin critical paper-c-s --direction -1 0 0",
    "vjm-pin critical paper-c-s --direction -1 0 0 --subdivide 4 --json",
    "vjm-pin critical four-bar --direction -1 0 0 --load coupler_link -163 0 -419.4",
)

#: Accepted ``--rtol`` (relative force tolerance of the location).
RTOL_RANGE = (1e-13, 0.1)

#: The unit of each key of ``critical --json`` (its ``units`` object).
UNITS = {
    "direction": "1 (unit vector, world axes)",
    "force": "N (N·m along a rotational direction)",
    "deflection": "m (rad along a rotational direction)",
    "wrench": "N (moment components: N·m), world axes",
    "x": "rad (prismatic joints: m), Pinocchio configuration order",
    "mode": "1 (unit eigenvector over the free coordinates; rad, m per unit)",
    "margin": "N·m/rad (largest eigenvalue of the force-control matrix; ~0 at the critical point)",
    "margin_rate": "margin per m (per rad along a rotational direction)",
    "stiffness": "N/m (N·m/rad along a rotational direction)",
    "estimate": "N (N·m along a rotational direction)",
    "residuals": (
        "location and margin: 1 (relative); position, closure_position: m; orientation, "
        "closure_orientation: rad; statics: N·m; statics_prismatic: N"
    ),
    "loads": "N (moment components: N·m), world axes, force at the frame origin",
}


def add_parser(sub):
    p = sub.add_parser(
        "critical",
        help="the critical (buckling) load along a direction, directly (no curve)",
        description=(
            "Answer 'at what load does it buckle?': the first critical point of the loading path of "
            "MODEL when its end is moved along DIRECTION (every other task component held), located "
            "directly: a linearised buckling estimate (eq. 23 as an eigenproblem), then Newton on the "
            "force-control stability margin with warm-started equilibria. It is the first critical "
            "point that 'vjm-pin curve' reports on the same path (same definition and kind: "
            "'bifurcation' where the straight branch loses eq. 23 with the force still rising, "
            "'limit' at a force maximum, 'imperfect' at a sharp near-loss). Every model the curve "
            "command takes: serial chains, closed loops and parallel robots; --load and --gravity add "
            "dead loads anywhere, kept constant along the path; --free holds only the component along "
            "DIRECTION. Units: the text prints the load in N (mN below 1 N) and the deflection in mm (or rad "
            "and N·m for a rotational direction); --json is SI (m, rad, N, N·m). Exit status 3 when "
            "there is no critical point up to --max-deflection or the search does not converge."
        ),
    )
    add_model_direction(p)
    p.add_argument(
        "--max-deflection",
        type=positive_float,
        default=None,
        metavar="D",
        help="search the path up to this deflection (m or rad; default 4x the linearised estimate)",
    )
    p.add_argument(
        "--rtol",
        type=float_range(*RTOL_RANGE),
        default=1e-7,
        help=f"relative force tolerance of the critical point (from {RTOL_RANGE[0]:g} to {RTOL_RANGE[1]:g}, default 1e-7)",
    )
    add_subdivide_option(p)
    p.add_argument(
        "--free",
        action="store_true",
        help="hold only the component along DIRECTION: the end (a parallel robot's platform) is free "
        "across it, with no load there (default: every task component held); a model that is then a mechanism (no stiffness across DIRECTION at the start) is refused, exit 2",
    )
    add_dead_load_options(p)
    p.add_argument(
        "--json",
        action="store_true",
        help="one JSON object on stdout, SI units (see 'vjm-pin schema critical')",
    )
    p.set_defaults(func=run)


def critical_dict(vm, r, *, free=False, gravity=None, load_list=None) -> dict:
    """The ``critical --json`` body of the :class:`~vjm_pin.analysis.critical.CriticalLoad` ``r``
    (``load_list``: the dead loads as JSON, :func:`~vjm_pin.cli.analyze.loads_list`)."""
    return {
        "model": vm.name,
        "direction": r.direction,
        "free": bool(free),
        "loads": load_list if load_list is not None else [],
        "gravity": gravity is not None,
        "force": r.force,
        "deflection": r.deflection,
        "kind": r.kind,
        "wrench": r.wrench,
        "x": r.x,
        "mode": r.mode,
        "margin": r.margin,
        "margin_rate": r.margin_rate,
        "stiffness": r.stiffness,
        "estimate": r.estimate,
        "converged": r.converged,
        "iterations": r.iterations,
        "residuals": dict(r.residuals),
        "message": r.message or None,
    }


def _text(vm, r, loads=(), gravity=None, free=False) -> str:
    import numpy as np

    rot = bool(np.any(r.direction[3:]))
    if rot:
        load, du, dv = f"{r.force:.8g} N·m", "rad", r.deflection
    elif abs(r.force) < 1.0:
        load, du, dv = f"{r.force * 1e3:.8g} mN", "mm", r.deflection * 1e3
    else:
        load, du, dv = f"{r.force:.8g} N", "mm", r.deflection * 1e3
    d = np.round(r.direction, 6).tolist()
    est = (
        f"linearised estimate {r.estimate:.8g} {'N·m' if rot else 'N'}"
        if np.isfinite(r.estimate)
        else "no linearised estimate"
    )
    if not r.converged:  # no headline number: the point reached is not a located critical point
        lines = [
            f"{vm.name}: NOT CONVERGED along {d}: {r.message}",
            (
                f"  the search's last point (not a located critical point): load {load} at "
                f"deflection {dv:.8g} {du} ({r.kind} by the rule there), {est}, "
                f"{r.iterations} equilibrium "
                f"evaluation{'' if r.iterations == 1 else 's'}"
            ),
        ]
    else:
        lines = [
            f"{vm.name}: critical load {load} along {d} ({r.kind}) at deflection {dv:.8g} {du}",
            (
                f"  {est}; located to "
                f"{r.residuals['location']:.1e} (relative) in {r.iterations} equilibrium "
                f"evaluation{'' if r.iterations == 1 else 's'}"
            ),
        ]
    if free:
        lines.append("  end free across the direction (only the component along it held)")
    for ld in loads:
        lines.append(
            f"  dead load at '{ld.frame}' [N, N·m, world axes]: {np.array2string(ld.wrench, precision=4)}"
        )
    if gravity is not None:
        lines.append("  dead loads: link weights (gravity)")
    return "\n".join(lines)


def run(args) -> int:
    import numpy as np

    from vjm_pin.analysis.critical import critical_load
    from vjm_pin.cli.analyze import dead_loads_from_args, loads_list
    from vjm_pin.cli.common import direction_vector, dump_json, envelope, summary
    from vjm_pin.cli.curve import load_model
    from vjm_pin.exceptions import InputError, NoCriticalPoint

    vm = load_model(args.model, args.subdivide)
    d = direction_vector(args.direction, "--direction")
    if args.max_deflection is not None and not np.isfinite(args.max_deflection):
        raise InputError(f"--max-deflection must be finite, got {args.max_deflection}")
    loads, gravity = dead_loads_from_args(args, vm)
    # the mechanism options only when asked (as 'curve': open chains keep the serial path)
    extra = {k: v for k, v in (("loads", loads), ("gravity", gravity), ("free", args.free)) if v}
    try:
        r = critical_load(vm, d, max_deflection=args.max_deflection, rtol=args.rtol, **extra)
    except NoCriticalPoint as e:
        import sys

        print(f"vjm-pin: error: {e}", file=sys.stderr)
        return 3
    unit = "N·m" if np.any(r.direction[3:]) else "N"
    summary(
        args,
        f"{vm.name}: {r.kind} at {r.force:.6g} {unit}, {r.iterations} equilibrium "
        f"evaluation{'' if r.iterations == 1 else 's'}",
    )
    if args.json:
        body = critical_dict(
            vm, r, free=args.free, gravity=gravity, load_list=loads_list(args, loads)
        )
        print(dump_json(envelope("critical", body, UNITS)))
    else:
        print(_text(vm, r, loads, gravity, args.free))
    return 0 if r.converged else 3
