"""``vjm-pin analyze`` and ``vjm-pin curve`` on parallel models (``<vjm:leg>`` tags).

The two commands call :func:`is_parallel_model` first and hand parallel models to
:func:`run_analyze` / :func:`run_curve` here, so their own code paths stay unchanged. The
output has the same keys as for a serial chain where they apply, plus ``legs`` (name,
wrench, stable) and ``unstable_legs``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def model_path(name: str) -> Path | None:
    """The URDF path of ``name`` (a file or a bundled model), or None."""
    from vjm_pin.model.registry import bundled_models

    p = Path(name)
    if p.is_file():
        return p
    return bundled_models().get(name)


def is_parallel_model(name: str) -> bool:
    """True when ``name`` is a VJM URDF (file or bundled) with ``<vjm:leg>`` tags."""
    from vjm_pin.exceptions import VjmError
    from vjm_pin.parallel import is_parallel
    from vjm_pin.model.registry import is_vjm_urdf

    p = model_path(name)
    if p is None or p.suffix != ".urdf" or not is_vjm_urdf(p):
        return False
    try:
        return is_parallel(p)
    except VjmError:
        return False


def _reject(args, names: dict) -> None:
    from vjm_pin.exceptions import InputError

    given = [
        flag for attr, (flag, default) in names.items() if getattr(args, attr, default) != default
    ]
    if given:
        raise InputError(
            f"{', '.join(given)} do not apply to a parallel model ('{args.model}'): "
            "its legs, springs and platform are in its tags"
        )


def legs_list(eq) -> list[dict]:
    return [{"name": lg.name, "wrench": lg.wrench, "stable": lg.stable} for lg in eq.legs]


def run_analyze(args) -> int:
    """``vjm-pin analyze`` on a parallel model: robot equilibrium for a platform deflection
    (each leg solved at the same platform pose, wrenches summed) or a wrench (eq. 11 on the
    aggregated stiffness), stability per leg, ``K_C = Σ K_C⁽ⁱ⁾`` (eq. 30/32/33 per leg)."""
    from vjm_pin.model.format import COMPONENTS
    from vjm_pin.parallel import RobotSolver, load_parallel
    from vjm_pin.cli.analyze import _summary, analyze_json, weakest_direction
    from vjm_pin.cli.common import dump_json, finite_vector, fmt_matrix

    _reject(
        args,
        {
            "q": ("--q", None),
            "pose_name": ("--pose-name", None),
            "frame": ("--frame", None),
            "springs": ("--springs", None),
            "payload": ("--payload", None),
            "gravity": ("--gravity", False),
        },
    )
    pm = load_parallel(model_path(args.model))
    rs = RobotSolver(pm)
    if args.deflection is not None:
        eq = rs.solve(finite_vector(args.deflection, "--deflection"))
    else:
        w = np.zeros(6) if args.wrench is None else finite_vector(args.wrench, "--wrench")
        eq = _solve_wrench_or_buckling(rs, w) if np.any(w) else rs.solve(np.zeros(6))
    k = rs.stiffness(eq, args.method)
    k0 = rs.stiffness(None, args.method)
    out = {
        "model": pm.name,
        "parallel": True,
        "frame": pm.platform,
        "task": [COMPONENTS[c] for c in pm.task],
        "converged": eq.converged,
        "path": "parallel(deflection)" if args.deflection is not None else "parallel(wrench, eq. 11)",
        "wrench": eq.wrench,
        "deflection": eq.deflection,
        "gravity": False,
        "stable": eq.stable,
        "unstable_legs": list(eq.unstable_legs),
        "warnings": [],
        "stiffness": k,
        "stiffness_unloaded": k0,
        "legs": legs_list(eq),
    }
    out["weakest"] = weakest_direction(k, list(pm.task))
    _summary(args, out)
    if args.json:
        print(dump_json(analyze_json(out)))
        return 0
    lines = [
        f"parallel model {pm.name}: {len(pm.legs)} legs ({', '.join(lg.name for lg in pm.legs)})",
        f"platform deflection [m, rad]: {np.round(eq.deflection, 9).tolist()}",
        f"platform wrench [N, N·m]:     {np.round(eq.wrench, 6).tolist()}",
        f"equilibrium {'converged' if eq.converged else 'NOT converged'}, "
        + ("stable" if eq.stable else f"UNSTABLE (legs: {', '.join(eq.unstable_legs)})"),
        "legs:",
    ]
    for lg in eq.legs:
        lines.append(
            f"  {lg.name:12s} {'stable' if lg.stable else 'UNSTABLE':9s} wrench {np.round(lg.wrench, 6).tolist()}"
        )
    lines += ["loaded stiffness K_C = Σ legs [N/m, N/rad, N·m/rad]:", fmt_matrix(k)]
    print("\n".join(lines))
    return 0


def curve_dict(pm, curve, solver=None) -> dict:
    """The ``curve --json`` body of a parallel curve (keys of :data:`vjm_pin.cli.curve.POINT_KEYS`;
    with ``solver`` (a :class:`~vjm_pin.parallel.RobotSolver`) each point also has its 6×6
    ``stiffness``)."""

    def point(p):
        d = {
            "deflection": p.s,
            "force": p.force,
            "wrench": p.wrench,
            "stable": p.stable,
            "stiffness_along": p.stiffness,
            "unstable_legs": list(p.unstable_legs),
            "legs": legs_list(p.equilibrium),
        }
        if solver is not None:
            d["stiffness"] = solver.stiffness(p.equilibrium)
        return d

    return {
        "model": pm.name,
        "parallel": True,
        "direction": curve.direction,
        "free": curve.free,
        "points": [point(p) for p in curve.points],
        "critical": [
            {
                "force": c.force,
                "deflection": c.deflection,
                "stiffness_before": c.stiffness_before,
                "stiffness_after": c.stiffness_after,
                "index": c.index,
                "kind": c.kind,
            }
            for c in curve.critical
        ],
        "branches": [],
        "stopped": curve.stopped or None,  # null: traced to --max-deflection
    }


def run_curve(args) -> int:
    """``vjm-pin curve`` on a parallel model: the platform moves along DIRECTION (a
    translation) and is free across it (no load there), or held there with ``--held``, with
    critical-point detection (:func:`vjm_pin.parallel.trace_robot_force_curve`). A curve that
    stops early (no equilibrium found) says so, with the reason (``stopped`` in --json)."""
    from vjm_pin.exceptions import InputError
    from vjm_pin.parallel import RobotSolver, load_parallel, trace_robot_force_curve
    from vjm_pin.cli.common import direction_vector, dump_json
    from vjm_pin.cli.curve import curve_json, trace_and_plot

    _reject(args, {"all_branches": ("--all-branches", False), "subdivide": ("--subdivide", 1)})
    pm = load_parallel(model_path(args.model))
    d = direction_vector(args.direction, "--direction")
    if not np.isfinite(args.max_deflection):
        raise InputError(f"--max-deflection must be finite, got {args.max_deflection}")
    rs = RobotSolver(pm)
    curve = trace_and_plot(
        lambda cb: trace_robot_force_curve(
            rs,
            d,
            args.max_deflection,
            args.steps,
            free=not getattr(args, "held", False),
            refine_tol=args.refine_tol,
            progress=cb,
        ),
        args,
        pm.name,
    )
    if args.json:
        print(dump_json(curve_json(curve_dict(pm, curve, rs if args.matrices else None))))
        return 0
    print(
        f"parallel model {pm.name}: direction {np.round(curve.direction, 4).tolist()} "
        f"(platform {'free' if curve.free else 'held'} across it), {len(curve.points)} points"
    )
    print(f"{'deflection [m]':>18} {'force [N]':>16} {'stiffness [N/m]':>20}  stable")
    for p in curve.points:
        note = "yes" if p.stable else "NO (" + ", ".join(p.unstable_legs) + ")"
        print(f"{p.s:18.8g} {p.force:16.8g} {p.stiffness:20.8g}  {note}")
    if curve.stopped:
        print(f"WARNING: the curve stopped before --max-deflection: {curve.stopped}")
    if not curve.critical:
        print("no critical point (no loss of stability, no sharp stiffness drop) in this range")
    for c in curve.critical:
        print(
            f"critical point ({c.kind}): force {c.force:.8g} N at deflection {c.deflection:.8g} m; "
            f"stiffness {c.stiffness_before:.6g} -> {c.stiffness_after:.6g} N/m"
        )
    if args.plot:
        print(f"plot written to {args.plot}")
    return 0


def _solve_wrench_or_buckling(rs, w, max_outer: int = 30, tol: float = 1e-9):
    """Platform wrench ``w`` (6,): the outer iteration of eq. (11) with one Newton attempt per
    leg at each trial pose (no restarts: a leg past its critical load fails fast or comes back
    unstable instead of searching for minutes). An unstable leg (eq. 23) or a loaded stiffness
    that is not positive definite means the wrench exceeds the critical force: raised as
    :class:`~vjm_pin.exceptions.NoEquilibrium` whose message starts with "buckling"."""
    from vjm_pin.exceptions import NoEquilibrium
    from vjm_pin.kinematics.chain import displace

    task = list(rs.task)
    res = rs.solve(np.zeros(6))
    scale = max(float(np.abs(w).max()), 1e-300)
    err = (w - res.wrench)[task]
    for _ in range(max_outer):
        if np.abs(err).max() <= tol * scale:
            break
        k = rs.stiffness(res)[np.ix_(task, task)]
        ev = np.linalg.eigvalsh(0.5 * (k + k.T))
        if ev.min() <= 1e-9 * np.abs(ev).max():
            break
        dt_task = np.linalg.solve(k, err)
        new = None
        for step in 0.5 ** np.arange(6):
            dt = np.zeros(6)
            dt[task] = step * dt_task
            try:
                cand = rs.solve(target=displace(res.position, res.rotation, dt), x0=res, fast_fail=True)
            except NoEquilibrium:
                continue
            if np.abs((w - cand.wrench)[task]).max() < np.abs(err).max():
                new = cand
                break
        if new is None:
            break
        res = new
        err = (w - res.wrench)[task]
        if not res.stable:
            break
    done = np.abs(err).max() <= tol * scale
    k = rs.stiffness(res)[np.ix_(task, task)] if res.converged else None
    k_ok = k is not None and np.linalg.eigvalsh(0.5 * (k + k.T)).min() > 0
    if done and res.stable and k_ok:
        return res
    f = np.linalg.norm(w[:3])
    if not res.stable:
        why = f"legs {', '.join(res.unstable_legs)} lose stability (eq. 23)"
    elif not k_ok and k is not None:
        why = "the loaded platform stiffness is not positive definite"
    else:
        why = f"no stable equilibrium reached (wrench error {np.abs(err).max():.3g} N)"
    raise NoEquilibrium(
        f"buckling: under the wrench {np.round(w, 3).tolist()} (|F| = {f / 1e3:.4g} kN) {why}: the load "
        "exceeds the critical force of the platform along this direction (see 'vjm-pin curve' for the "
        "critical point)",
        None,
        float(np.abs(err).max()),
    )

