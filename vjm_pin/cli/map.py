"""``vjm-pin map``: deflection and stiffness indices over many poses of the workspace."""

from __future__ import annotations

import numpy as np

from vjm_pin.cli.analyze import add_robot_options
from vjm_pin.cli.common import add_load_option

EXAMPLES = (
    "vjm-pin map ur5 --samples 20 --wrench 0 0 -100 --out map.csv --plot map.png",
    "vjm-pin map four-bar --grid crank=-3:3:13 --wrench 0 0 -50 --backend dask --workers 2 --out map.npz",
    "vjm-pin map orthoglide-q0 --grid leg1_act=-0.36:-0.26:3 leg2_act=-0.36:-0.26:3 --load platform 0 0 -100",
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
            "wrench and dead loads: deflection (m, rad), the translational stiffness along the force "
            "1/(f̂ᵀC f̂) and the smallest eigenvalue of the translational block of the loaded K_C (N/m). "
            "A closed mechanism (loop closures, parallel robots) is mapped over its actuated joints and "
            "re-assembled at each pose from its reference; a pose it cannot reach is reported with "
            "status no-assembly. Runs on all local cores by default, or on Dask (--scheduler ADDRESS, "
            "or --backend dask for a local cluster); the results are the same bit for bit whatever "
            "the backend."
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
    add_load_option(p)
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
        help="plot of the map (PNG, PDF, SVG): a heat map of the weakest stiffness over a 1- or "
        "2-joint grid, top and side views of the end positions coloured by the deflection; checked "
        "before the work starts, written atomically; an existing file is replaced",
    )
    p.add_argument(
        "--floor",
        default="0",
        metavar="Z",
        help="poses whose unloaded end is below Z (m, world) are drawn as grey crosses in --plot "
        "(default 0; 'none': no floor)",
    )
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bar (shown only on a terminal)"
    )
    p.add_argument("--json", action="store_true", help="summary as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    """Parse → :func:`~vjm_pin.analysis.maps.run_map` → format (text or ``--json``)."""
    import sys

    from vjm_pin.analysis.maps import run_map, stream_map
    from vjm_pin.cli.common import dump_json, envelope, show_progress, summary
    from vjm_pin.exceptions import MapInterrupted
    from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY

    vm, names, poses, w, loads, backend = _problem(args)
    floor = _floor(args)
    bar = None
    if show_progress(args):  # on a terminal only: no bars in log files
        from tqdm import tqdm

        bar = tqdm(total=poses.shape[0], unit="pose", file=sys.stderr, desc=f"map {vm.name}")

    def progress(done):
        if bar is not None:
            bar.update(done - bar.n)

    import time

    t0 = time.perf_counter()
    # a CSV without a plot is streamed: rows written as chunks finish, the map never held
    stream = bool(args.out) and str(args.out).endswith(".csv") and not args.plot
    kwargs = dict(
        gravity=np.array([0.0, 0.0, -STANDARD_GRAVITY]) if args.gravity else None,
        loads=loads,
        backend=backend,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress,
    )
    try:
        if stream:
            res = _scheduler_option(stream_map, vm, names, poses, w, args.out, **kwargs)
        else:
            res = _scheduler_option(run_map, vm, names, poses, w, **kwargs)
    except MapInterrupted as e:
        if bar is not None:
            bar.close()
        return _interrupted(args, e, floor)
    finally:
        if bar is not None:
            bar.close()
    try:
        if args.out and not stream:
            res.save(args.out)
        if args.plot:
            from vjm_pin.viz.plots import save_map_plot

            save_map_plot(res, args.plot, floor=floor)
    except KeyboardInterrupt:
        print(
            "vjm-pin: interrupted while writing the output; no half file was left", file=sys.stderr
        )
        return 130
    out = _summary_dict(args, vm, names, res, backend)
    _done_line(args, out["poses"], time.perf_counter() - t0)
    summary(args, f"{vm.name}: {out['poses']} poses, {out['status'].get('ok', 0)} solved, {out['unstable']} unstable")
    if args.json:
        print(dump_json(envelope("map", out, UNITS)))
    else:
        _print_text(vm, out)
    return 0


def _problem(args):
    """(vm, joint names, poses, end wrench (6,), dead loads, backend) from the options, every
    check done before any work (output paths first)."""
    import os

    from vjm_pin.analysis.map_backends import check_scheduler
    from vjm_pin.analysis.maps import MAX_WORKERS_PER_CORE, grid_poses, parse_grid, sample_poses
    from vjm_pin.cli.analyze import load_from_args
    from vjm_pin.cli.common import check_output_option, finite_vector, loads_from_args
    from vjm_pin.exceptions import InputError, RoleError
    from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY, Load
    from vjm_pin.outputs import PLOT_EXTENSIONS

    check_output_option(args, "--out", (".csv", ".npz"))  # output paths before any work
    check_output_option(args, "--plot", PLOT_EXTENSIONS)
    vm, _ = load_from_args(args)
    loads = loads_from_args(args)
    w = finite_vector(args.wrench, "--wrench")
    if args.payload is not None:  # a dead load at the end frame, as analyze
        if not (np.isfinite(args.payload) and args.payload >= 0):
            raise InputError(f"--payload must be a finite non-negative number of kg, got {args.payload:g}")
        if not np.isfinite(float(args.payload) * STANDARD_GRAVITY):
            raise InputError(f"--payload {args.payload:g} kg: its weight is not a finite force")
        loads = (*loads, Load.weight(vm.frame, args.payload))
    try:
        if args.samples is not None:
            names, poses = sample_poses(vm, args.samples, args.seed)
        else:
            names, poses = grid_poses(vm, parse_grid(args.grid))
    except (InputError, RoleError) as e:
        if type(e) not in (InputError, RoleError):
            raise
        raise type(e)(_option_words(str(e))) from None
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be positive, got {args.workers}")
    cores = os.cpu_count() or 1
    if args.workers is not None and args.workers > MAX_WORKERS_PER_CORE * cores and not args.scheduler:
        raise InputError(
            f"--workers {args.workers}: more than {MAX_WORKERS_PER_CORE} processes per core "
            f"({cores} cores) would make the map slower, not faster"
        )
    backend = args.backend or ("dask" if args.scheduler is not None else "local")
    if args.scheduler is not None:
        if backend != "dask":
            raise InputError("--scheduler needs the dask backend")
        _scheduler_option(check_scheduler, args.scheduler)
    return vm, names, poses, w, loads, backend


def _option_words(message: str) -> str:
    """A message of :func:`~vjm_pin.analysis.maps.sample_poses` / ``parse_grid`` / ``grid_poses``,
    which name their parameters (``n``, ``seed``, ``grid``), in the words of this command's options."""
    import re

    for param, option in (("n", "--samples"), ("seed", "--seed"), ("grid", "--grid")):
        m = re.match(rf"{param}\b(?: item)?", message)
        if m:
            return option + message[m.end() :]
    if "give the joints to vary" in message:
        return message.split(";")[0] + "; give the joints to vary with --grid NAME=LO:HI:N"
    return message


def _done_line(args, n: int, seconds: float) -> None:
    """Without a terminal (no progress bar: a log file, a batch job) one line on stderr when
    the map is done: poses, time and rate; nothing with ``--quiet`` or ``--no-progress``."""
    import sys

    from vjm_pin.cli.common import quiet

    if quiet(args) or getattr(args, "no_progress", False):
        return
    try:
        if sys.stderr.isatty():
            return  # the bar said it
    except (AttributeError, ValueError):
        pass
    rate = n / seconds if seconds > 0 else float("inf")
    print(f"vjm-pin: map: {n} poses in {seconds:.1f} s ({rate:.0f} poses/s)", file=sys.stderr)


def _floor(args):
    """``--floor`` (m) or None for ``none``."""
    from vjm_pin.exceptions import InputError

    text = str(args.floor).strip()
    if text.lower() == "none":
        return None
    try:
        z = float(text)
    except ValueError:
        z = float("nan")
    if not np.isfinite(z):
        raise InputError(f"--floor must be a finite height in m or 'none', got '{args.floor}'")
    return z


def _summary_dict(args, vm, names, res, backend) -> dict:
    """The ``--json`` body (SI; see ``vjm-pin schema map``) of a MapResult or MapSummary."""
    from vjm_pin.analysis.maps import MapSummary

    ok = res.ok
    if isinstance(res, MapSummary):
        n, counts = res.n_poses, res.status_counts()
        dn, rn = res.deflection_norm[ok], res.rotation_norm[ok]
    else:
        n = int(res.poses.shape[0])
        counts = {str(s): int(np.sum(res.status == s)) for s in np.unique(res.status)}
        dn, rn = np.linalg.norm(res.deflection[ok, :3], axis=1), np.linalg.norm(res.deflection[ok, 3:], axis=1)
    return {
        "model": vm.name,
        "frame": vm.frame,
        "joints": list(names),
        "poses": int(n),
        "backend": backend,
        "status": counts,
        "unstable": int(np.sum(ok & ~res.stable)),
        "wrench": res.wrench,
        "gravity": bool(args.gravity),
        "loads": [{"frame": ld.frame, "wrench": ld.wrench} for ld in res.loads],
        "deflection": _stats(dn),
        "rotation": _stats(rn),
        "stiffness_along": _stats(res.k_along[ok]),
        "weakest_stiffness_along": _stats(res.k_min[ok]),
        "out": args.out,
        "plot": args.plot,
    }


def _print_text(vm, out: dict) -> None:
    """The summary for a terminal (mm, N/mm: said in each line)."""
    print(
        f"map of {vm.name} (end frame '{vm.frame}'): {out['poses']} poses over {', '.join(out['joints'])}; "
        f"backend {out['backend']}"
    )
    print(f"  status: {', '.join(f'{k} {v}' for k, v in out['status'].items())}; unstable {out['unstable']}")
    if out["status"].get("no-assembly"):
        print("  no-assembly: the mechanism does not close at those actuator positions (reached from its reference)")
        if out["status"]["no-assembly"] == out["poses"]:
            ref = ", ".join(f"{n} = {vm.reference[vm.joint_index(n)]:.6g}" for n in out["joints"])
            print(f"  none assembles: map closer to the reference ({ref}; rad, m) with --grid NAME=LO:HI:N")
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


def _interrupted(args, e, floor=0.0) -> int:
    """Ctrl-C during the map: write the finished poses to the requested files (atomically;
    a second Ctrl-C leaves no half file), say so in one line, exit status 130."""
    import sys

    from vjm_pin.analysis.maps import MapSummary

    res, total = e.result, e.requested
    targets = [t for t in (args.out, args.plot) if t]
    written = []
    if isinstance(res, MapSummary):  # streamed: the finished poses are already in the file
        n = res.n_poses
        if n:
            written.append(args.out)
    else:
        n = int(res.poses.shape[0])
    try:
        if n and args.out and not isinstance(res, MapSummary):
            res.save(args.out)
            written.append(args.out)
        if n and args.plot:
            from vjm_pin.viz.plots import save_map_plot

            save_map_plot(res, args.plot, floor=floor)
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
