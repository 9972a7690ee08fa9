"""``vjm-pin analyze``: loaded equilibrium, stability and stiffness at one load."""

from __future__ import annotations

import numpy as np


def add_robot_options(p) -> None:
    """Options shared by the commands that accept a robot or a plain URDF (analyze, map)."""
    p.add_argument(
        "model",
        metavar="MODEL",
        help="VJM URDF, plain URDF, bundled model or example-robot-data robot name "
        "(see 'vjm-pin models' and 'vjm-pin models --robots')",
    )
    p.add_argument(
        "--q", nargs="+", default=None, metavar="NAME=VALUE", help="joint positions (rad, m)"
    )
    p.add_argument(
        "--pose-name",
        default=None,
        metavar="STATE",
        help="named pose from the robot's SRDF (e.g. ready, default)",
    )
    p.add_argument(
        "--frame", default=None, help="end frame (default: the last frame of the kinematic chain)"
    )
    p.add_argument(
        "--springs",
        default=None,
        metavar="SPEC.yaml",
        help="spring specification (actuators: ..., links: ...) over the defaults "
        "(actuators 1e5 N·m/rad, 1e7 N/m; rigid links)",
    )


def add_parser(sub):
    p = sub.add_parser(
        "analyze",
        help="equilibrium, stability and loaded stiffness for a deflection or a wrench",
        description=(
            "Solve the loaded equilibrium of MODEL (eq. 5) for a prescribed end deflection, or for a "
            "wrench (eq. 11), check its stability (eq. 23) and compute the loaded Cartesian stiffness "
            "(eq. 30). Deflection: from the unloaded end location, world axes, m and rad (rotation "
            "vector). Wrench: force at the end frame origin and moment, world axes, N and N·m. "
            "Without --deflection/--wrench the end wrench is zero. --payload and --gravity add dead "
            "loads (eq. 5' and 28' of vjm_pin.loads)."
        ),
    )
    add_robot_options(p)
    g = p.add_mutually_exclusive_group(required=False)
    g.add_argument(
        "--deflection", nargs="+", type=float, metavar="D", help="DX DY DZ [RX RY RZ] (m, rad)"
    )
    g.add_argument(
        "--wrench", nargs="+", type=float, metavar="W", help="FX FY FZ [MX MY MZ] (N, N·m)"
    )
    p.add_argument(
        "--payload",
        type=float,
        default=None,
        metavar="MASS",
        help="payload mass (kg) at the end frame origin",
    )
    p.add_argument(
        "--gravity",
        action="store_true",
        help="load every link with its weight at its centre of mass (URDF inertials)",
    )
    p.add_argument(
        "--method",
        choices=("eq30", "eq32", "eq33"),
        default="eq30",
        help="stiffness formula (default eq30)",
    )
    p.add_argument(
        "--subdivide",
        type=int,
        default=1,
        metavar="K",
        help="split every beam link into K sub-links (models whose springs keep <vjm:beam>)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=run)


def weakest_direction(k6: np.ndarray, task) -> dict | None:
    """Lowest translational stiffness: the smallest eigenvalue (N/m) of the symmetric part of
    the translational block of K_C (task rows x, y, z only) and its unit direction (world)."""
    t = [i for i in task if i < 3]
    if not t or k6 is None:
        return None
    blk = np.asarray(k6)[np.ix_(t, t)]
    ev, vec = np.linalg.eigh(0.5 * (blk + blk.T))
    d = np.zeros(3)
    d[t] = vec[:, 0]
    if d[np.argmax(np.abs(d))] < 0:
        d = -d
    return {"stiffness": float(ev[0]), "direction": d}


def analysis_dict(vm, res, method="eq30") -> dict:
    """The JSON object of ``analyze`` for an equilibrium ``res`` of model ``vm``."""
    from ..exceptions import SingularStiffness
    from ..solver import loaded_stiffness, unloaded_stiffness

    out = {
        "model": vm.name,
        "frame": vm.frame,
        "task": vm.task_names,
        "converged": res.converged,
        "iterations": res.iterations,
        "path": res.path,
        "wrench": res.wrench,
        "deflection": res.deflection,
        "stable": res.stable,
        "stability_eigenvalues": None if res.stability is None else res.stability.eigenvalues,
        "residual": res.residuals,
        "energy": res.energy,
        "q": dict(zip(vm.q_names, res.q)),
        "theta": dict(zip(vm.theta_names, res.theta)),
    }
    for key, fn in (
        ("stiffness", lambda: loaded_stiffness(vm, res, method)),
        ("stiffness_unloaded", lambda: unloaded_stiffness(vm, method)),
    ):
        try:
            out[key] = fn().stiffness
        except SingularStiffness as e:
            out[key] = None
            out[key + "_note"] = str(e)
    return out


def loaded_dict(vm, eq, method="eq30", gravity=False) -> dict:
    """The JSON object of ``analyze`` for a :class:`~vjm_pin.loads.LoadedEquilibrium`."""
    from ..exceptions import SingularStiffness
    from ..solver import unloaded_stiffness

    out = {
        "model": vm.name,
        "frame": vm.frame,
        "task": vm.task_names,
        "converged": True,
        "iterations": eq.iterations,
        "path": "newton(eq. 5')" + ("+gravity" if gravity else ""),
        "wrench": eq.wrench,
        "deflection": eq.deflection,
        "stable": eq.stable,
        "stability_eigenvalues": eq.stability.eigenvalues,
        "residual": {"statics": eq.residual},
        "theta": dict(zip(vm.theta_names, eq.theta)),
        "gravity": gravity,
    }
    if eq.stiffness is None:
        out["stiffness"] = None
        out["stiffness_note"] = "the loaded stiffness matrix of eq. (28') is singular"
    else:
        out["stiffness"] = eq.stiffness.stiffness
    try:
        out["stiffness_unloaded"] = unloaded_stiffness(vm, method).stiffness
    except SingularStiffness as e:
        out["stiffness_unloaded"] = None
        out["stiffness_unloaded_note"] = str(e)
    return out


def load_from_args(args):
    """(vm, robot) for the model options of ``args`` (see :func:`add_robot_options`)."""
    from ..registry import resolve
    from ..robots import parse_q

    return resolve(
        args.model,
        frame=args.frame,
        q=parse_q(args.q),
        pose_name=args.pose_name,
        springs=args.springs,
    )


def run(args) -> int:
    from ..exceptions import InputError
    from ..loads import LinkLoads, payload_wrench, solve_loaded
    from ..solver import EquilibriumSolver
    from .common import dump_json, finite_vector, fmt_matrix
    from .parallel_cmds import is_parallel_model, run_analyze

    if is_parallel_model(args.model):  # parallel robots (<vjm:leg> tags): vjm_pin/cli/parallel_cmds.py
        return run_analyze(args)
    vm, robot = load_from_args(args)
    if args.subdivide != 1:
        from ..subdivide import subdivide_model

        if args.subdivide < 1:
            raise InputError(f"--subdivide must be a positive integer, got {args.subdivide}")
        vm = subdivide_model(vm.urdf, args.subdivide)
    extra = args.payload is not None or args.gravity
    if extra and args.deflection is not None:
        raise InputError("--payload/--gravity take a --wrench (or none), not a --deflection")
    if args.deflection is not None:
        res = EquilibriumSolver(vm).solve(finite_vector(args.deflection, "--deflection"))
        out = analysis_dict(vm, res, args.method)
    else:
        w = np.zeros(6) if args.wrench is None else finite_vector(args.wrench, "--wrench")
        if args.payload is not None:
            w = w + payload_wrench(args.payload)
        if extra or vm.n_q == 0:  # springs and motors only: Newton on eq. (5') directly
            eq = solve_loaded(
                vm, w, LinkLoads.earth() if args.gravity else None, method=args.method
            )
            out = loaded_dict(vm, eq, args.method, args.gravity)
        else:
            res = EquilibriumSolver(vm).solve_wrench(w)
            out = analysis_dict(vm, res, args.method)
    out["weakest"] = weakest_direction(out["stiffness"], vm.task)
    out["payload_kg"] = args.payload
    if robot is not None:
        out["pose"] = robot.pose
        out["pose_name"] = robot.pose_name
    if args.json:
        print(dump_json(out))
        return 0
    print(_human(vm, robot, out, fmt_matrix))
    return 0


def _human(vm, robot, out, fmt_matrix) -> str:
    d = np.asarray(out["deflection"], float)
    w = np.asarray(out["wrench"], float)
    lines = [f"model {vm.name}: end frame '{vm.frame}', task {' '.join(vm.task_names)}"]
    if robot is not None:
        pose = ", ".join(f"{k}={v:.4g}" for k, v in robot.pose.items() if k in vm.joint_names)
        lines.append(f"pose {robot.pose_name or '(given/default)'}: {pose or 'all joints at 0'}")
    loads = []
    if out.get("payload_kg") is not None:
        loads.append(f"payload {out['payload_kg']:g} kg")
    if out.get("gravity"):
        loads.append("link weights (gravity)")
    lines.append(
        f"end wrench [N, N, N, N·m, N·m, N·m]: {np.array2string(w, precision=4)}"
        + (f"  (+ {', '.join(loads)})" if loads else "")
    )
    lines.append(f"equilibrium: {out['path']}, {out['iterations']} iterations")
    lines.append(
        f"deflection: translation {np.array2string(d[:3] * 1e3, precision=4)} mm (|d| = {np.linalg.norm(d[:3]) * 1e3:.4g} mm), "
        f"rotation {np.array2string(d[3:] * 1e3, precision=4)} mrad (|r| = {np.linalg.norm(d[3:]) * 1e3:.4g} mrad)"
    )
    if out.get("stable") is not None:
        verdict = "stable" if out["stable"] else "UNSTABLE"
        ev = out.get("stability_eigenvalues")
        extra = (
            f"; eigenvalues of the reduced matrix {np.array2string(np.asarray(ev), precision=4)}"
            if ev is not None and len(ev)
            else ""
        )
        lines.append(f"stability (eq. 23): {verdict}{extra}")
    for key, label in (
        ("stiffness", "loaded stiffness K_C"),
        ("stiffness_unloaded", "unloaded stiffness"),
    ):
        if out[key] is None:
            lines.append(f"{label}: {out.get(key + '_note', 'singular')}")
        else:
            lines.append(f"{label} (N/m, N/rad, N·m/m, N·m/rad; world axes at the end frame):")
            lines.append(fmt_matrix(out[key]))
    wk = out.get("weakest")
    if wk is not None:
        lines.append(
            f"lowest translational stiffness: {wk['stiffness'] / 1e3:.4g} N/mm along {np.array2string(wk['direction'], precision=3, suppress_small=True)} (world)"
        )
    return "\n".join(lines)
