"""``vjm-pin analyze``: loaded equilibrium, stability and stiffness at one load."""

from __future__ import annotations

import numpy as np

from vjm_pin.cli.common import MAX_SUBDIVIDE, int_range

EXAMPLES = (
    "vjm-pin analyze paper-a-s --deflection -0.001 0 0",
    "vjm-pin analyze ur5 --q shoulder_lift_joint=-1 elbow_joint=1 --wrench 0 0 -100 --json",
    "vjm-pin analyze orthoglide-q0 --wrench -100 -100 -100 --json",
)

#: Keys of every ``analyze --json`` object, whatever the model kind and solver path (null
#: where a key does not apply): see ``vjm-pin schema analyze``.
KEYS = (
    "model", "parallel", "frame", "task", "control", "converged", "iterations", "path",
    "wrench", "deflection", "payload", "gravity", "stable", "stable_end_held",
    "stability_eigenvalues", "stability_end_held_eigenvalues", "warnings", "checks",
    "residual", "energy", "q", "theta", "stiffness", "stiffness_note", "stiffness_unloaded",
    "stiffness_unloaded_note", "weakest", "pose", "pose_name", "legs", "unstable_legs",
)

#: The quantities with units in ``analyze --json`` (:data:`vjm_pin.cli.common.UNITS`).
UNIT_KEYS = (
    "deflection", "wrench", "stiffness", "stiffness_along", "compliance_eigenvalues", "q",
    "theta", "energy", "payload", "direction", "stability_eigenvalues",
)


def analyze_json(body: dict) -> dict:
    """The ``analyze --json`` object: :func:`vjm_pin.cli.common.envelope` over ``body`` with
    every key of :data:`KEYS` (missing ones null), in that order."""
    from vjm_pin.cli.common import envelope

    extra = set(body) - set(KEYS)
    if extra:
        raise AssertionError(f"analyze: keys outside the vocabulary: {sorted(extra)}")
    return envelope("analyze", {k: body.get(k) for k in KEYS}, UNIT_KEYS)


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
            "Solve the loaded equilibrium of MODEL (eq. 5) for a prescribed end deflection (every task "
            "component held), or for a dead wrench (every task component loaded; Newton on the total "
            "potential), check it and report two stability verdicts: 'stable' for the control as run "
            "and 'stable_end_held' (eq. 23), and the loaded Cartesian stiffness (eq. 30). Deflection: from the unloaded end location, world axes, m and rad (rotation "
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
        type=int_range(1, MAX_SUBDIVIDE),
        default=1,
        metavar="K",
        help="split every beam link into K sub-links (models whose springs keep <vjm:beam>; "
        f"K from 1 to {MAX_SUBDIVIDE})",
    )
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=run)


def weakest_direction(k6: np.ndarray, task, lost=()) -> dict | None:
    """Weakest translational stiffness with the end free in all other task components (free to
    rotate): :func:`vjm_pin.analysis.indices.weakest_translation` on the task block of K_C, as a JSON
    mapping (stiffness N/m, unit direction in world axes, its definition, the free and lost
    directions). None without K_C or without a translational task component.

    Args:
        k6: (6, 6) K_C (zero rows outside the task) or None. task: task component indices.
        lost: Names of the directions a singular pose loses (:func:`vjm_pin.analysis.indices.lost_directions`).
    """
    from vjm_pin.analysis.indices import weakest_translation

    t = list(task)
    if k6 is None or not any(c < 3 for c in t):
        return None
    d = weakest_translation(np.asarray(k6, float)[np.ix_(t, t)], t, lost).to_dict()
    # the JSON vocabulary: a scalar stiffness along a direction is "stiffness_along"
    d["stiffness_along"] = d.pop("stiffness")
    d["stiffness_along_rotations_held"] = d.pop("stiffness_rotations_held")
    return d


def control_dict(vm, held) -> dict:
    """``{"held": [...], "loaded": [...]}``: task component names held (deflection prescribed)
    and loaded (dead wrench prescribed); ``held=None`` holds every task component."""
    names = ("x", "y", "z", "rx", "ry", "rz")
    held = list(vm.task) if held is None else list(held)
    return {
        "held": [names[c] for c in vm.task if c in held],
        "loaded": [names[c] for c in vm.task if c not in held],
    }


def analysis_dict(vm, res, method="eq30") -> dict:
    """The JSON object of ``analyze`` for an equilibrium ``res`` of model ``vm``."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import loaded_stiffness, unloaded_stiffness

    out = {
        "model": vm.name,
        "parallel": False,
        "frame": vm.frame,
        "task": vm.task_names,
        "converged": res.converged,
        "iterations": res.iterations,
        "path": res.path,
        "wrench": res.wrench,
        "deflection": res.deflection,
        "control": control_dict(vm, res.held),
        "stable": res.stable,
        "stable_end_held": res.stable_end_held,
        "stability_eigenvalues": None if res.stability is None else res.stability.eigenvalues,
        "stability_end_held_eigenvalues": None
        if res.stability_end_held is None
        else res.stability_end_held.eigenvalues,
        "warnings": list(res.warnings),
        "checks": dict(res.checks),
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


def loaded_dict(vm, eq, method="eq30", gravity=False, loads=None) -> dict:
    """The JSON object of ``analyze`` for a :class:`~vjm_pin.loads.LoadedEquilibrium`
    (every task component loaded: ``stable`` is ``K − H − H^G`` positive definite,
    ``stable_end_held`` eq. 23)."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.loads import LinkLoads, loaded_blocks
    from vjm_pin.solver import unloaded_stiffness
    from vjm_pin.solver.stability import check_stability_held

    b = loaded_blocks(vm, eq.x, eq.wrench, loads if loads is not None else LinkLoads(np.zeros(3)))
    free = check_stability_held(b, np.zeros((0, len(vm.task))))

    out = {
        "model": vm.name,
        "parallel": False,
        "frame": vm.frame,
        "task": vm.task_names,
        "converged": True,
        "iterations": eq.iterations,
        "path": "newton(eq. 5')" + ("+gravity" if gravity else ""),
        "wrench": eq.wrench,
        "deflection": eq.deflection,
        "control": control_dict(vm, ()),
        "stable": free.stable,
        "stable_end_held": eq.stable,
        "stability_eigenvalues": free.eigenvalues,
        "stability_end_held_eigenvalues": eq.stability.eigenvalues,
        "warnings": [] if free.stable else ["unstable under the prescribed loads (the end is free under them)"],
        "residual": {"statics": eq.residual},
        "q": dict(zip(vm.q_names, np.asarray(eq.x, float)[vm.q_idx])),
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


def load_from_args(args, allow_closures=False):
    """(vm, robot) for the model options of ``args`` (see :func:`add_robot_options`); models
    with loop closures only with ``allow_closures`` (:func:`vjm_pin.model.registry.resolve`)."""
    from vjm_pin.model.registry import resolve
    from vjm_pin.model.robots import parse_q

    return resolve(
        args.model,
        frame=args.frame,
        q=parse_q(args.q),
        pose_name=args.pose_name,
        springs=args.springs,
        allow_closures=allow_closures,
    )


def run(args) -> int:
    from vjm_pin.exceptions import InputError
    from vjm_pin.loads import LinkLoads, payload_wrench, solve_loaded
    from vjm_pin.solver import EquilibriumSolver
    from vjm_pin.cli.common import finite_vector
    from vjm_pin.cli.parallel_cmds import is_parallel_model, run_analyze

    if is_parallel_model(args.model):  # parallel robots (<vjm:leg> tags): vjm_pin/cli/parallel_cmds.py
        return run_analyze(args)
    vm, robot = load_from_args(args, allow_closures=True)
    if vm.closures:  # a closed mechanism: vjm_pin.solver.MechanismSolver
        return _run_mechanism(args, vm)
    if args.subdivide != 1:
        from vjm_pin.model.subdivide import subdivide_model

        if args.subdivide < 1:
            raise InputError(f"--subdivide must be a positive integer, got {args.subdivide}")
        vm = subdivide_model(vm.urdf, args.subdivide)
    extra = args.payload is not None or args.gravity
    if extra and args.deflection is not None:
        raise InputError("--payload/--gravity take a --wrench (or none), not a --deflection")
    if args.deflection is not None or (args.wrench is None and not extra):
        # every task component held (no load at all: the end held at its unloaded location)
        solver = EquilibriumSolver(vm)
        d = np.zeros(6) if args.deflection is None else finite_vector(args.deflection, "--deflection")
        res = solver.verify(solver.solve(d), method=args.method)
        out = analysis_dict(vm, res, args.method)
    else:
        w = np.zeros(6) if args.wrench is None else finite_vector(args.wrench, "--wrench")
        if args.payload is not None:
            w = w + payload_wrench(args.payload)
        if extra:  # link loads: Newton on eq. (5') (springs and motors only, vjm_pin.loads)
            loads = LinkLoads.earth() if args.gravity else None
            eq = solve_loaded(vm, w, loads, method=args.method)
            out = loaded_dict(vm, eq, args.method, args.gravity, loads)
        else:  # every task component loaded: Newton on the total potential
            solver = EquilibriumSolver(vm)
            res = solver.verify(solver.solve_wrench(w), method=args.method)
            out = analysis_dict(vm, res, args.method)
    from vjm_pin.analysis.indices import lost_directions, name_direction
    from vjm_pin.model.format import COMPONENTS

    # a robot's default task drops the directions its pose cannot move (robots.default_task)
    lost = [name_direction(v, COMPONENTS) for v in lost_directions(vm)] if robot is not None else []
    out["weakest"] = weakest_direction(out["stiffness"], vm.task, lost)
    if robot is not None:
        out["pose"] = robot.pose
        out["pose_name"] = robot.pose_name
    return _emit(args, vm, robot, out)


def _run_mechanism(args, vm) -> int:
    """``analyze`` of a model with loop closures (:class:`~vjm_pin.solver.MechanismSolver`): every
    task component held for ``--deflection`` (or no load), loaded for ``--wrench``; ``--payload``
    and ``--gravity`` are dead loads (a weight at the end frame, the link weights)."""
    from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY, Load
    from vjm_pin.exceptions import InputError, SingularStiffness
    from vjm_pin.solver import MechanismSolver
    from vjm_pin.cli.common import finite_vector

    if args.subdivide != 1:
        raise InputError("--subdivide is not available for models with loop closures")
    extra = args.payload is not None or args.gravity
    if extra and args.deflection is not None:
        raise InputError("--payload/--gravity take a --wrench (or none), not a --deflection")
    loads = [Load.weight(vm.frame, args.payload)] if args.payload is not None else []
    solver = MechanismSolver(vm, loads, (0.0, 0.0, -STANDARD_GRAVITY) if args.gravity else None)
    if args.deflection is not None or (args.wrench is None and not extra):
        d = np.zeros(6) if args.deflection is None else finite_vector(args.deflection, "--deflection")
        res = solver.solve(deflection=d)
    else:
        w = np.zeros(len(vm.task)) if args.wrench is None else finite_vector(args.wrench, "--wrench")
        res = solver.solve(wrench=w)
    out = analysis_dict_mechanism(vm, res)

    def unloaded():
        bare = MechanismSolver(vm)
        return bare.stiffness(bare.solve(deflection=np.zeros(6)))

    for key, fn in (("stiffness", lambda: solver.stiffness(res)), ("stiffness_unloaded", unloaded)):
        try:
            out[key] = fn().stiffness
        except SingularStiffness as e:
            out[key] = None
            out[key + "_note"] = str(e)
    out["weakest"] = weakest_direction(out["stiffness"], vm.task, [])
    return _emit(args, vm, None, out)


def _emit(args, vm, robot, out) -> int:
    """Finish the ``analyze`` object (load options) and print it: ``--json`` or text."""
    from vjm_pin.cli.common import dump_json, fmt_matrix

    out["payload"] = args.payload
    out["gravity"] = bool(args.gravity)
    _summary(args, out)
    if args.json:
        print(dump_json(analyze_json(out)))
        return 0
    print(_human(vm, robot, out, fmt_matrix))
    return 0


def analysis_dict_mechanism(vm, res) -> dict:
    """The JSON object of ``analyze`` for a :class:`~vjm_pin.solver.MechanismResult` (stiffness
    keys filled by the caller); redundant closure rows and the multiplier choice as warnings."""
    notes = [res.multipliers_note] if res.multipliers_note else []
    return {
        "model": vm.name,
        "parallel": False,
        "frame": vm.frame,
        "task": vm.task_names,
        "converged": res.converged,
        "iterations": res.iterations,
        "path": "mechanism:" + res.path,
        "wrench": res.wrench,
        "deflection": res.deflection,
        "control": control_dict(vm, res.held),
        "stable": res.stable,
        "stable_end_held": res.stable_end_held,
        "stability_eigenvalues": None if res.stability is None else res.stability.eigenvalues,
        "stability_end_held_eigenvalues": None
        if res.stability_end_held is None
        else res.stability_end_held.eigenvalues,
        "warnings": list(res.warnings) + notes,
        "checks": {},
        "residual": res.residuals,
        "energy": res.energy,
        "q": dict(zip(vm.q_names, res.q)),
        "theta": dict(zip(vm.theta_names, res.theta)),
    }


def _summary(args, out) -> None:
    """The ``--verbose`` line of ``analyze``."""
    from vjm_pin.cli.common import summary

    verdict = "stable" if out.get("stable") is not False else "UNSTABLE"
    summary(args, f"{out['model']}: {'converged' if out.get('converged') else 'NOT converged'}, {verdict}")


def _human(vm, robot, out, fmt_matrix) -> str:
    d = np.asarray(out["deflection"], float)
    w = np.asarray(out["wrench"], float)
    lines = [f"model {vm.name}: end frame '{vm.frame}', task {' '.join(vm.task_names)}"]
    if robot is not None:
        pose = ", ".join(f"{k}={v:.4g}" for k, v in robot.pose.items() if k in vm.joint_names)
        lines.append(f"pose {robot.pose_name or '(given/default)'}: {pose or 'all joints at 0'}")
    loads = []
    if out.get("payload") is not None:
        loads.append(f"payload {out['payload']:g} kg")
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
    ctl = out.get("control")
    if ctl is not None:
        lines.append(
            f"control: held {' '.join(ctl['held']) or '(none)'}; loaded {' '.join(ctl['loaded']) or '(none)'}"
        )
    if out.get("stable") is not None:
        verdict = "stable" if out["stable"] else "UNSTABLE"
        ev = out.get("stability_eigenvalues")
        extra = (
            f"; eigenvalues {np.array2string(np.asarray(ev), precision=4)}"
            if ev is not None and len(ev)
            else ""
        )
        what = "stable (as controlled)" if ctl is not None and ctl["loaded"] else "stable (eq. 23, end held)"
        lines.append(f"{what}: {verdict}{extra}")
    if out.get("stable_end_held") is not None and ctl is not None and ctl["loaded"]:
        ev = out.get("stability_end_held_eigenvalues")
        extra = f"; eigenvalues {np.array2string(np.asarray(ev), precision=4)}" if ev is not None and len(ev) else ""
        lines.append(
            f"stable_end_held (eq. 23): {'stable' if out['stable_end_held'] else 'UNSTABLE'}{extra}"
        )
    for note in out.get("warnings") or ():
        lines.append(f"warning: {note}")
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
            f"weakest translational stiffness (end free to rotate): {wk['stiffness_along'] / 1e3:.4g} N/mm along "
            f"{np.array2string(np.asarray(wk['direction']), precision=3, suppress_small=True)} (world); "
            f"with the rotations held: {wk['stiffness_along_rotations_held'] / 1e3:.4g} N/mm"
        )
        if wk["free_directions"]:
            lines.append(
                f"warning: K_C is singular: the end moves without a force change along {'; '.join(wk['free_directions'])}"
            )
        if wk["lost_directions"]:
            lines.append(
                f"warning: singular pose: the joints cannot move the end along {'; '.join(wk['lost_directions'])} "
                "(to first order); K_C carries no stiffness for it (a zero row there is not a zero stiffness)"
            )
    return "\n".join(lines)
