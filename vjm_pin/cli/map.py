"""``vjm-pin map``: deflection and stiffness indices over many poses of the workspace."""

from __future__ import annotations

import numpy as np

from vjm_pin.cli.analyze import add_robot_options

EXAMPLES = (
    "vjm-pin map ur5 --samples 20 --wrench 0 0 -100 --out map.csv --plot map.png",
    "vjm-pin map ur5 --grid shoulder_lift_joint=-1:0:3 elbow_joint=0:1.5:3 --backend serial --json",
    "vjm-pin map ur5 --samples 40 --backend dask --workers 2 --out map.npz",
)

#: Keys of ``map --json``: see ``vjm-pin schema map``. ``deflection`` and ``rotation`` are the
#: statistics (min, median, max over the poses solved) of the end translation (m) and rotation
#: (rad) magnitudes; ``stiffness_along`` those of the translational stiffness along the force
#: 1/(f̂ᵀC f̂), ``weakest_stiffness_along`` those of the weakest translational stiffness (end
#: free to rotate, ``weakest.stiffness_along`` of ``analyze``), N/m.
UNITS = {
    "wrench": "N (moment components: N·m)",
    "deflection": "m",
    "rotation": "rad",
    "stiffness_along": "N/m",
    "weakest_stiffness_along": "N/m",
}


def add_parser(sub):
    p = sub.add_parser(
        "map",
        help="workspace map: deflection and stiffness indices over many poses (local cores or Dask)",
        description=(
            "Evaluate MODEL over many poses (random within the joint limits, or a grid) under an end "
            "wrench: deflection (m, rad), the translational stiffness along the force 1/(f̂ᵀC f̂) "
            "and the smallest eigenvalue of the translational block of the loaded K_C (N/m). Runs on "
            "all local cores by default, or on Dask (--scheduler ADDRESS, or --backend dask for a "
            "local cluster); the results are the same bit for bit whatever the backend."
        ),
    )
    add_robot_options(p)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument(
        "--samples", type=int, metavar="N", help="N random poses within the joint limits"
    )
    g.add_argument(
        "--grid",
        nargs="+",
        metavar="NAME=LO:HI:N",
        help="grid over joints (rad, m; LO ≤ HI, within the URDF limits); others at the pose",
    )
    p.add_argument(
        "--wrench",
        nargs="+",
        type=float,
        default=[0.0, 0.0, -100.0],
        metavar="W",
        help="FX FY FZ [MX MY MZ] (N, N·m; default 0 0 -100)",
    )
    p.add_argument(
        "--payload", type=float, default=None, metavar="MASS", help="payload (kg) at the end frame"
    )
    p.add_argument("--gravity", action="store_true", help="link weights at their centres of mass")
    p.add_argument("--seed", type=int, default=0, help="seed of the random poses (default 0)")
    p.add_argument(
        "--backend",
        choices=("local", "dask", "serial"),
        default=None,
        help="default local (dask if --scheduler)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler address tcp://HOST:PORT (checked before the work, 3 s to answer)",
    )
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.add_argument(
        "--out",
        default=None,
        metavar="FILE",
        help="write the map to FILE.csv or FILE.npz; on Ctrl-C (exit status 130) the poses "
        "finished so far are written to it and to --plot; checked before the work starts, "
        "written atomically; an existing file is replaced",
    )
    p.add_argument(
        "--plot",
        default=None,
        metavar="FILE",
        help="scatter plot of the deflection (PNG, PDF, SVG); checked before the work starts, "
        "written atomically; an existing file is replaced",
    )
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bar (shown only on a terminal)"
    )
    p.add_argument("--json", action="store_true", help="summary as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    import os
    import sys

    from vjm_pin.exceptions import InputError, MapInterrupted
    from vjm_pin.loads import STANDARD_GRAVITY, payload_wrench
    from vjm_pin.analysis.map_backends import check_scheduler
    from vjm_pin.analysis.maps import MAX_WORKERS_PER_CORE, grid_poses, parse_grid, run_map, sample_poses
    from vjm_pin.outputs import PLOT_EXTENSIONS
    from vjm_pin.cli.analyze import load_from_args
    from vjm_pin.cli.common import check_output_option, dump_json, finite_vector

    check_output_option(args, "--out", (".csv", ".npz"))  # output paths before any work
    check_output_option(args, "--plot", PLOT_EXTENSIONS)
    vm, _ = load_from_args(args)
    w = finite_vector(args.wrench, "--wrench")
    if args.payload is not None:
        w = w + payload_wrench(args.payload)
        if not np.all(np.isfinite(w)):
            raise InputError(f"--payload {args.payload:g} kg: its weight is not a finite force")
    if args.samples is not None:
        names, poses = sample_poses(vm, args.samples, args.seed)
    else:
        names, poses = grid_poses(vm, parse_grid(args.grid))
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be positive, got {args.workers}")
    cores = os.cpu_count() or 1
    if (
        args.workers is not None
        and args.workers > MAX_WORKERS_PER_CORE * cores
        and not args.scheduler
    ):
        raise InputError(
            f"--workers {args.workers}: more than {MAX_WORKERS_PER_CORE} processes per core "
            f"({cores} cores) would make the map slower, not faster"
        )
    backend = args.backend or ("dask" if args.scheduler is not None else "local")
    if args.scheduler is not None:
        if backend != "dask":
            raise InputError("--scheduler needs the dask backend")
        _scheduler_option(check_scheduler, args.scheduler)
    from vjm_pin.cli.common import envelope, show_progress, summary

    bar = None
    if show_progress(args):  # on a terminal only: no bars in log files
        from tqdm import tqdm

        bar = tqdm(total=poses.shape[0], unit="pose", file=sys.stderr, desc=f"map {vm.name}")

    def progress(done):
        if bar is not None:
            bar.update(done - bar.n)

    try:
        res = _scheduler_option(
            run_map,
            vm,
            names,
            poses,
            w,
            gravity=np.array([0.0, 0.0, -STANDARD_GRAVITY]) if args.gravity else None,
            backend=backend,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=progress,
        )
    except MapInterrupted as e:
        if bar is not None:
            bar.close()
        return _interrupted(args, e)
    finally:
        if bar is not None:
            bar.close()
    try:
        if args.out:
            res.save(args.out)
        if args.plot:
            res.plot(args.plot)
    except KeyboardInterrupt:
        print(
            "vjm-pin: interrupted while writing the output; no half file was left", file=sys.stderr
        )
        return 130
    ok = res.ok
    out = {
        "model": vm.name,
        "frame": vm.frame,
        "joints": list(names),
        "poses": int(poses.shape[0]),
        "backend": backend,
        "status": {s: int(np.sum(res.status == s)) for s in np.unique(res.status)},
        "unstable": int(np.sum(ok & ~res.stable)),
        "wrench": w,
        "gravity": bool(args.gravity),
        "deflection": _stats(np.linalg.norm(res.deflection[ok, :3], axis=1)),
        "rotation": _stats(np.linalg.norm(res.deflection[ok, 3:], axis=1)),
        "stiffness_along": _stats(res.k_along[ok]),
        "weakest_stiffness_along": _stats(res.k_min[ok]),
        "out": args.out,
        "plot": args.plot,
    }
    summary(args, f"{vm.name}: {out['poses']} poses, {out['status'].get('ok', 0)} solved, {out['unstable']} unstable")
    if args.json:
        print(dump_json(envelope("map", out, UNITS)))
        return 0
    print(
        f"map of {vm.name} (end frame '{vm.frame}'): {poses.shape[0]} poses over {', '.join(names)}; backend {backend}"
    )
    print(
        f"  status: {', '.join(f'{k} {v}' for k, v in out['status'].items())}; unstable {out['unstable']}"
    )
    for key, label, scale, unit in (
        ("deflection", "deflection", 1e3, "mm"),
        ("stiffness_along", "stiffness along the force", 1e-3, "N/mm"),
        ("weakest_stiffness_along", "weakest translational stiffness (end free to rotate)", 1e-3, "N/mm"),
    ):
        s = out[key]
        if s is not None:
            print(
                f"  {label}: min {s['min'] * scale:.4g}, median {s['median'] * scale:.4g}, max {s['max'] * scale:.4g} {unit}"
            )
    for what in ("out", "plot"):
        if out[what]:
            print(f"  wrote {out[what]}")
    return 0


def _stats(a):
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return None
    return {"min": float(a.min()), "median": float(np.median(a)), "max": float(a.max())}


def _scheduler_option(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` with a :class:`SchedulerError` worded for ``--scheduler``."""
    from vjm_pin.exceptions import SchedulerError

    try:
        return fn(*args, **kwargs)
    except SchedulerError as e:
        raise SchedulerError(e.address, e.reason, name="--scheduler") from None


def _interrupted(args, e) -> int:
    """Ctrl-C during the map: write the finished poses to the requested files (atomically;
    a second Ctrl-C leaves no half file), say so in one line, exit status 130."""
    import sys

    res, n, total = e.result, int(e.result.poses.shape[0]), e.requested
    targets = [t for t in (args.out, args.plot) if t]
    written = []
    try:
        if n and args.out:
            res.save(args.out)
            written.append(args.out)
        if n and args.plot:
            res.plot(args.plot)
            written.append(args.plot)
    except KeyboardInterrupt:
        pass
    if written:
        msg = f"interrupted: wrote {n} of {total} poses to {' and '.join(written)}"
        missed = [t for t in targets if t not in written]
        if missed:
            msg += f"; {' and '.join(missed)} not written (interrupted again)"
    elif targets:
        msg = f"interrupted after {n} of {total} poses; nothing written"
    else:
        msg = f"interrupted after {n} of {total} poses"
    print(f"vjm-pin: {msg}", file=sys.stderr)
    return 130
