"""``vjm-pin map``: deflection and stiffness indices over many poses of the workspace."""

from __future__ import annotations

import numpy as np

from .analyze import add_robot_options


def add_parser(sub):
    p = sub.add_parser(
        "map",
        help="workspace map: deflection and stiffness indices over many poses (local cores or Dask)",
        description=(
            "Evaluate MODEL over many poses (random within the joint limits, or a grid) under an end "
            "wrench: deflection (mm, mrad), the translational stiffness along the force 1/(f̂ᵀC f̂) "
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
        help="grid over joints (rad, m); others at the pose",
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
        help="Dask scheduler address (tcp://host:8786)",
    )
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.add_argument(
        "--out", default=None, metavar="FILE", help="write the map to FILE.csv or FILE.npz"
    )
    p.add_argument(
        "--plot",
        default=None,
        metavar="FILE",
        help="scatter plot of the deflection (PNG, PDF, SVG)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="summary as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from ..exceptions import InputError
    from ..loads import STANDARD_GRAVITY, payload_wrench
    from ..maps import grid_poses, parse_grid, run_map, sample_poses
    from .analyze import load_from_args
    from .common import dump_json, finite_vector

    vm, _ = load_from_args(args)
    w = finite_vector(args.wrench, "--wrench")
    if args.payload is not None:
        w = w + payload_wrench(args.payload)
    if args.samples is not None:
        names, poses = sample_poses(vm, args.samples, args.seed)
    else:
        names, poses = grid_poses(vm, parse_grid(args.grid))
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be positive, got {args.workers}")
    backend = args.backend or ("dask" if args.scheduler else "local")
    if args.scheduler and backend != "dask":
        raise InputError("--scheduler needs the dask backend")
    bar = None
    if not args.no_progress and not args.json:
        from tqdm import tqdm

        bar = tqdm(total=poses.shape[0], unit="pose", file=sys.stderr, desc=f"map {vm.name}")

    def progress(done):
        if bar is not None:
            bar.update(done - bar.n)

    try:
        res = run_map(
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
    finally:
        if bar is not None:
            bar.close()
    if args.out:
        res.save(args.out)
    if args.plot:
        res.plot(args.plot)
    ok = res.ok
    d_mm = np.linalg.norm(res.deflection[ok, :3], axis=1) * 1e3
    summary = {
        "model": vm.name,
        "frame": vm.frame,
        "joints": list(names),
        "poses": int(poses.shape[0]),
        "backend": backend,
        "status": {s: int(np.sum(res.status == s)) for s in np.unique(res.status)},
        "unstable": int(np.sum(ok & ~res.stable)),
        "wrench": w,
        "gravity": bool(args.gravity),
        "deflection_mm": _stats(d_mm),
        "k_along_N_per_m": _stats(res.k_along[ok]),
        "k_min_N_per_m": _stats(res.k_min[ok]),
        "out": args.out,
        "plot": args.plot,
    }
    if args.json:
        print(dump_json(summary))
        return 0
    print(
        f"map of {vm.name} (end frame '{vm.frame}'): {poses.shape[0]} poses over {', '.join(names)}; backend {backend}"
    )
    print(
        f"  status: {', '.join(f'{k} {v}' for k, v in summary['status'].items())}; unstable {summary['unstable']}"
    )
    for key, label, scale, unit in (
        ("deflection_mm", "deflection", 1.0, "mm"),
        ("k_along_N_per_m", "stiffness along the force", 1e-3, "N/mm"),
        ("k_min_N_per_m", "lowest translational stiffness", 1e-3, "N/mm"),
    ):
        s = summary[key]
        if s is not None:
            print(
                f"  {label}: min {s['min'] * scale:.4g}, median {s['median'] * scale:.4g}, max {s['max'] * scale:.4g} {unit}"
            )
    for what in ("out", "plot"):
        if summary[what]:
            print(f"  wrote {summary[what]}")
    return 0


def _stats(a):
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return None
    return {"min": float(a.min()), "median": float(np.median(a)), "max": float(a.max())}
