"""``vjm-pin analyze``: loaded equilibrium, stability and stiffness at one load."""

from __future__ import annotations

import numpy as np

from vjm_pin.cli.common import add_dead_load_options, add_subdivide_option

EXAMPLES = (
    "vjm-pin analyze paper-a-s --deflection -0.001 0 0",
    "vjm-pin analyze orthoglide-q0 --wrench -100 -100 -100 --json",
    "vjm-pin analyze portal-frame --wrench 100 0 0 --load top_left 0 0 -100 --load top_right 0 0 -100",
)

#: Keys of every ``analyze --json`` object, whatever the model kind and solver path (null
#: where a key does not apply): see ``vjm-pin schema analyze``.
KEYS = (
    "model", "parallel", "frame", "task", "control", "converged", "iterations", "path",
    "wrench", "deflection", "payload", "gravity", "stable", "stable_end_held",
    "stability_eigenvalues", "stability_end_held_eigenvalues", "warnings", "checks",
    "residual", "energy", "q", "theta", "stiffness", "stiffness_note", "stiffness_unloaded",
    "stiffness_unloaded_note", "weakest", "pose", "pose_name", "loads", "closures", "redundant",
    "multipliers_note",
)

#: The quantities with units in ``analyze --json`` (:data:`vjm_pin.cli.common.UNITS`).
UNIT_KEYS = (
    "deflection", "wrench", "stiffness", "stiffness_along", "compliance_eigenvalues", "q",
    "theta", "energy", "payload", "direction", "stability_eigenvalues",
)

#: Units of the keys of ``analyze --json`` that only this command has.
OWN_UNITS = {
    "loads": "N (moment components: N·m), world axes, force at the frame origin",
    "multipliers": "N on translation rows, N·m on rotation rows (closure components in frame_b's axes)",
    "wrench_a": "N (moment components: N·m), world axes, at frame_a's origin",
    "wrench_b": "N (moment components: N·m), world axes, at frame_b's origin",
}


def analyze_json(body: dict) -> dict:
    """The ``analyze --json`` object: :func:`vjm_pin.cli.common.envelope` over ``body`` with
    every key of :data:`KEYS` (missing ones null), in that order."""
    from vjm_pin.cli.common import envelope

    extra = set(body) - set(KEYS)
    if extra:
        raise AssertionError(f"analyze: keys outside the vocabulary: {sorted(extra)}")
    from vjm_pin.cli.common import UNITS

    units = {**{k: UNITS[k] for k in UNIT_KEYS}, **OWN_UNITS}
    return envelope("analyze", {k: body.get(k) for k in KEYS}, units)


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
            "potential), and report two stability verdicts: 'stable' for the control as run "
            "and 'stable_end_held' (eq. 23), and the loaded Cartesian stiffness (eq. 30). Every model "
            "kind: open chains, robots, mechanisms with loop closures (parallel robots, closed loops: "
            "one Newton over the whole mechanism, closure reactions in the output). Deflection: from "
            "the unloaded end location, world axes, m and rad (rotation vector). Wrench: force at the "
            "end frame origin and moment, world axes, N and N·m. --load, --payload and --gravity add "
            "dead loads anywhere; without --deflection/--wrench the end is then free (zero end wrench), "
            "else held at its unloaded location. Open chains loaded at the end only are solved by the "
            "serial solver and checked (residuals, verdicts, K_C against re-solved equilibria); models "
            "with closures or dead loads by the mechanism solver (K_C: eq. 28 bordered with the closure "
            "rows)."
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
    add_dead_load_options(p)
    p.add_argument(
        "--method",
        choices=("eq30", "eq32", "eq33"),
        default=None,
        help="stiffness formula (default: eq30 for an open chain loaded at its end only; models with "
        "closures or dead loads: eq. 28 bordered with the closure rows, and eq30/eq32/eq33 with the "
        "closure rows bordered like passive joints; all agree where defined)",
    )
    add_subdivide_option(p)
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=run)


def weakest_direction(k6: np.ndarray, task, lost=(), rigid=None) -> dict | None:
    """Weakest translational stiffness with the end free in all other task components (free to
    rotate): :func:`vjm_pin.analysis.indices.weakest_translation` on the task block of K_C, as a JSON
    mapping (stiffness N/m, unit direction in world axes, its definition, the free and lost
    directions). None without K_C or without a translational task component.

    Args:
        k6: (6, 6) K_C (zero rows outside the task) or None. task: task component indices.
        lost: Names of the directions a singular pose loses (:func:`vjm_pin.analysis.indices.lost_directions`).
        rigid: (r, 6) rigid task directions of a K_C infinite along them (:func:`rigid_stiffness`);
            ``k6`` is then its finite part (``finite_part``: the other directions alone) and the
            weakest direction is sought among those (:func:`_stiff_along_rigid`); None when
            every translation is rigid.
    """
    from vjm_pin.analysis.indices import weakest_translation

    t = list(task)
    if k6 is None or not any(c < 3 for c in t):
        return None
    k = np.asarray(k6, float)[np.ix_(t, t)]
    if rigid is not None and np.size(rigid):
        k = _stiff_along_rigid(k, t, rigid)
        if k is None:
            return None
    elif not np.isfinite(k).all():
        return None
    d = weakest_translation(k, t, lost).to_dict()
    # the JSON vocabulary: a scalar stiffness along a direction is "stiffness_along"
    d["stiffness_along"] = d.pop("stiffness")
    d["stiffness_along_rotations_held"] = d.pop("stiffness_rotations_held")
    return d


#: :func:`_stiff_along_rigid`: the stiffness standing in for an infinite one, × the largest finite
#: one (its compliance, 1e-6 of the rest, moves the weakest stiffness by at most that fraction;
#: a larger one would drown the finite part in the rank test of the weakest-direction search).
RIGID_STAND_IN = 1e6


def _stiff_along_rigid(k: np.ndarray, task, rigid) -> np.ndarray | None:
    """A finite stand-in for a task K_C infinite along the rigid task directions ``rigid`` (r, 6)
    (:func:`vjm_pin.solver.stiffness.stiffness_rigid`) for the weakest-direction search: its
    finite part ``k`` (the other directions alone, zero along ``rigid``) plus
    :data:`RIGID_STAND_IN` × its size along them, so that they never come out weakest. None when
    every translational task direction is rigid (no weakest translation)."""
    t = list(task)
    r = np.asarray(rigid, float).reshape(-1, 6)[:, t]
    proj = r.T @ r
    tt = [i for i, c in enumerate(t) if c < 3]
    if np.abs((np.eye(len(t)) - proj)[tt]).max() <= 1e-9:
        return None
    fin = np.where(np.isfinite(k), k, 0.0)
    big = RIGID_STAND_IN * max(float(np.abs(fin).max()), 1.0)
    return fin + big * proj


def control_dict(vm, held) -> dict:
    """``{"held": [...], "loaded": [...]}``: task component names held (deflection prescribed)
    and loaded (dead wrench prescribed); ``held=None`` holds every task component."""
    names = ("x", "y", "z", "rx", "ry", "rz")
    held = list(vm.task) if held is None else list(held)
    return {
        "held": [names[c] for c in vm.task if c in held],
        "loaded": [names[c] for c in vm.task if c not in held],
    }


def analysis_dict(vm, res, method="eq30", keep: dict | None = None) -> dict:
    """The JSON object of ``analyze`` for an equilibrium ``res`` of model ``vm``."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import loaded_stiffness, unloaded_stiffness

    out = {
        "model": vm.name,
        "parallel": bool(vm.closures),
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
    if out["stiffness"] is None:
        rigid = rigid_stiffness(vm, res, method)
        if rigid is not None:
            out["stiffness"] = rigid.stiffness
            out["stiffness_note"] = rigid_note(vm, rigid)
            if keep is not None:  # (the caller's weakest-direction search reads its finite part)
                keep["rigid"] = rigid
    return out


def rigid_stiffness(vm, res, method="eq30"):
    """K_C of the equilibrium ``res`` where the end frame cannot move along some task directions
    (:func:`vjm_pin.solver.stiffness.stiffness_rigid`: finite on the other task directions,
    ``±inf`` along them), or None: no such direction, or the rest is singular too."""
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import blocks_at
    from vjm_pin.solver.stiffness import stiffness_rigid

    try:
        return stiffness_rigid(blocks_at(vm, res.x, res.wrench), vm.task, method)
    except SingularStiffness:
        return None


def _task_direction_text(vm, rigid) -> str:
    """The rigid directions (r, 6) as task-row vectors, as the stiffness diagnosis names them."""
    t = list(vm.task)
    return "; ".join(str(np.round(np.asarray(r, float)[t], 3).tolist()) for r in rigid)


def rigid_note(vm, kres) -> str:
    """The one-line note of a K_C infinite along rigid task directions (``kres``: the result of
    :func:`rigid_stiffness`). Where a rigid direction is not along a task axis, its infinite
    entries hide the finite stiffness of the other directions: the note then gives it
    (``finite_part`` on the task rows)."""
    rigid = kres.rigid
    t = list(vm.task)
    many = len(rigid) > 1
    note = (
        f"the end frame cannot move along task direction{'s' if many else ''} {_task_direction_text(vm, rigid)} "
        "to first order (a rigid direction, e.g. a straight chain of rigid links): the stiffness there is "
        "infinite (inf entries, null in --json)"
    )
    axis = all(np.count_nonzero(np.abs(np.asarray(r, float)[t]) > 1e-12) == 1 for r in rigid)
    if axis:
        return note + "; the finite entries are K_C along the other task directions"
    fin = np.asarray(kres.finite_part, float)[np.ix_(t, t)]
    text = np.array2string(fin, precision=4, separator=", ", max_line_width=10**6).replace("\n", "")
    rows = " ".join(vm.task_names)
    return note + f"; on the other task directions alone K_C is {text} (task rows {rows}, zero along the rigid ones)"


def load_from_args(args):
    """(vm, robot) for the model options of ``args`` (see :func:`add_robot_options`): every model
    kind (open chains, robots, mechanisms with loop closures; :func:`vjm_pin.model.registry.resolve`)."""
    from vjm_pin.model.registry import resolve
    from vjm_pin.model.robots import parse_q

    return resolve(
        args.model,
        frame=args.frame,
        q=parse_q(args.q),
        pose_name=args.pose_name,
        springs=args.springs,
    )


#: Frame names shown in an unknown-frame message (the rest are counted).
SHOWN_FRAMES = 12


def check_load_frames(vm, loads, option: str = "--load") -> None:
    """Every load frame exists in ``vm``; else an :class:`~vjm_pin.exceptions.InputError` naming
    the frame, the closest names (did you mean) and some frames of the model (one line)."""
    import difflib

    from vjm_pin.exceptions import InputError

    names = list(dict.fromkeys(f.name for f in vm.model.frames if f.name != "universe"))
    for ld in loads:
        if vm.model.existFrame(ld.frame):
            continue
        close = difflib.get_close_matches(ld.frame, names, n=3, cutoff=0.6)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        more = f" (+{len(names) - SHOWN_FRAMES} more)" if len(names) > SHOWN_FRAMES else ""
        raise InputError(
            f"{option}: unknown frame '{ld.frame}' in model '{vm.name}'{hint} "
            f"(frames: {', '.join(names[:SHOWN_FRAMES])}{more})"
        )


def dead_loads_from_args(args, vm) -> tuple[tuple, object]:
    """``(loads, gravity)`` of ``--load``, ``--payload`` (the weight of a point mass at the end frame
    origin, kg) and ``--gravity`` (link weights, standard gravity along −z): the dead loads of
    :class:`~vjm_pin.solver.MechanismSolver`. Frames are checked (:func:`check_load_frames`).

    Raises:
        InputError: a malformed ``--load``, an unknown frame, a negative or non-finite payload.
    """
    import math

    from vjm_pin.cli.common import loads_from_args
    from vjm_pin.exceptions import InputError
    from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY, Load

    loads = list(loads_from_args(args))
    check_load_frames(vm, loads)
    payload = getattr(args, "payload", None)
    if payload is not None:
        if not (math.isfinite(payload) and payload >= 0):
            raise InputError(f"--payload must be a finite non-negative mass in kg, got {payload}")
        loads.append(Load.weight(vm.frame, payload))
    gravity = (0.0, 0.0, -STANDARD_GRAVITY) if getattr(args, "gravity", False) else None
    return tuple(loads), gravity


def loads_list(args, loads) -> list[dict]:
    """The dead loads as JSON: ``{"frame", "wrench" (6, N and N·m, world axes), "source"}`` with
    source ``"load"`` (``--load``) or ``"payload"`` (``--payload``, the last one)."""
    n_payload = 1 if getattr(args, "payload", None) is not None else 0
    return [
        {"frame": ld.frame, "wrench": ld.wrench, "source": "payload" if i >= len(loads) - n_payload else "load"}
        for i, ld in enumerate(loads)
    ]


def closures_list(vm, res) -> list[dict] | None:
    """The closures of ``vm`` at the equilibrium ``res`` (a
    :class:`~vjm_pin.solver.MechanismResult`) as JSON: name, frames, held components, the
    multiplier of each component (N on translation rows, N·m on rotation rows; minimum-norm when
    the rows are redundant) and the reaction wrenches on ``frame_a`` and ``frame_b`` (6, N and
    N·m, world axes, at the frame origins). None for a model without closures."""
    if not vm.closures:
        return None
    mu = dict(zip(res.closure_labels, np.asarray(res.closure_multipliers, float)))
    out = []
    for c in vm.closures:
        wa, wb = res.reaction_wrenches[c.name]
        out.append(
            {
                "name": c.name,
                "frame_a": c.frame_a,
                "frame_b": c.frame_b,
                "components": list(c.components),
                "multipliers": {comp: mu[f"{c.name}.{comp}"] for comp in c.components},
                "wrench_a": wa,
                "wrench_b": wb,
            }
        )
    return out


def run(args) -> int:
    """``vjm-pin analyze`` (one path): :class:`~vjm_pin.solver.MechanismSolver` for a model with
    loop closures or under dead loads (``--load``, ``--payload``, ``--gravity``),
    :class:`~vjm_pin.solver.EquilibriumSolver` (with its checks and eq. 30/32/33) for an open chain
    loaded at its end only."""
    from vjm_pin.analysis.indices import lost_directions, name_direction
    from vjm_pin.cli.common import finite_vector
    from vjm_pin.exceptions import InputError, NoEquilibrium
    from vjm_pin.model.format import COMPONENTS
    from vjm_pin.solver import EquilibriumSolver

    vm, robot = load_from_args(args)
    if args.subdivide != 1:
        if vm.closures:
            raise InputError("--subdivide is not available for models with loop closures")
        from vjm_pin.model.subdivide import subdivide_model

        vm = subdivide_model(vm.urdf, args.subdivide)
    loads, gravity = dead_loads_from_args(args, vm)
    method = args.method or "eq30"
    kept: dict = {}  # (analysis_dict's rigid K_C, when there is one)
    if vm.closures or loads or gravity is not None:
        out = _run_mechanism(args, vm, loads, gravity)
    elif args.deflection is not None or args.wrench is None:
        # every task component held (no load at all: the end held at its unloaded location; where
        # the end cannot move along some task direction the solver returns the unloaded reference
        # with zero wrench: EquilibriumSolver._unloaded_reference)
        solver = EquilibriumSolver(vm)
        d = np.zeros(6) if args.deflection is None else finite_vector(args.deflection, "--deflection")
        try:
            eq = solver.solve(d)
        except NoEquilibrium as e:
            _raise_if_out_of_reach(vm, solver, d, e)
            raise
        res = solver.verify(eq, method=method)
        out = analysis_dict(vm, res, method, kept)
    else:  # every task component loaded: Newton on the total potential
        solver = EquilibriumSolver(vm)
        res = solver.verify(solver.solve_wrench(finite_vector(args.wrench, "--wrench")), method=method)
        out = analysis_dict(vm, res, method, kept)
    k6, rigid = out["stiffness"], None
    if "rigid" in kept:  # K_C infinite along a rigid direction (serial paths): its finite part
        k6, rigid = kept["rigid"].finite_part, kept["rigid"].rigid
    # a robot's default task drops the directions its pose cannot move (robots.default_task)
    lost = [name_direction(v, COMPONENTS) for v in lost_directions(vm)] if robot is not None else []
    out["weakest"] = weakest_direction(k6, vm.task, lost, rigid)
    if robot is not None:
        out["pose"] = robot.pose
        out["pose_name"] = robot.pose_name
    out["loads"] = loads_list(args, loads)
    return _emit(args, vm, robot, out)


def _raise_if_out_of_reach(vm, solver, d, err) -> None:
    """After ``solver.solve(d)`` found no equilibrium (``err``): the same failure (a
    :class:`NoEquilibrium`: exit status 3, the contract for "no equilibrium: a deflection the
    chain cannot reach") with a message that says why, when ``d`` lies beyond the second-order
    reach of the end frame along a task direction it cannot move along to first order at the
    unloaded configuration (:func:`vjm_pin.solver.checks.rigid_reach`: a straight chain of rigid
    links cannot be stretched, nor moved sideways with its length held); else nothing (the
    caller re-raises ``err``)."""
    from vjm_pin.exceptions import NoEquilibrium
    from vjm_pin.solver import blocks_at
    from vjm_pin.solver.checks import rigid_reach
    from vjm_pin.solver.stiffness import rigid_directions

    from vjm_pin.exceptions import InputError
    from vjm_pin.model.task import task_vector

    t = list(vm.task)
    try:  # (as the solver reads a deflection)
        d6 = task_vector(d, vm.task, "deflection", "m, rad", task_sized=True, outside_task="keep")
    except InputError:
        return
    x = np.asarray(vm.reference, float)
    b = blocks_at(vm, x, np.zeros(6), solver.kin)
    rig = rigid_directions(b)
    if not rig.size:
        return

    def hessian(rho):  # the Hessian of ρᵀt over (θ, q): eq. (16) contracted with the task wrench ρ
        w = np.zeros(6)
        w[t] = rho
        h = blocks_at(vm, x, w, solver.kin)
        return np.block([[h.H_tt, h.H_tq], [h.H_qt, h.H_qq]])

    found = rigid_reach(np.hstack([b.J_theta, b.J_q]), rig, hessian, d6[t])
    if found is None:
        return
    rho, asked, reach = found
    if abs(reach) <= 1e-12 * max(float(np.abs(d6).max()), 1e-300):
        reach = 0.0  # (rounding of a zero reach)
    unit = "m" if all(c < 3 for c, v in zip(t, rho) if abs(v) > 1e-12) else "m or rad"
    raise NoEquilibrium(
        f"no equilibrium for --deflection {(np.round(d6, 9) + 0.0).tolist()}: it is out of reach. At the "
        f"unloaded configuration the end frame cannot move along task direction {(np.round(rho, 3) + 0.0).tolist()} "
        "to first order (a rigid direction, e.g. a straight chain of rigid links, which cannot be stretched), and "
        f"to second order it reaches at most {reach + 0.0:.3g} {unit} along it with the other components as "
        f"asked, not {asked:.3g}",
        err.result,
        err.residual,
    ) from None


def _run_mechanism(args, vm, loads, gravity) -> dict:
    """``analyze`` through :class:`~vjm_pin.solver.MechanismSolver` (closures, dead loads): every
    task component held for ``--deflection``, loaded for ``--wrench``; without either, loaded (zero
    task wrench: the task frame carries the dead loads) when there are dead loads, else held at
    its reference. K_C: eq. (28) bordered with the closure rows, or ``--method`` eq. (30), (32),
    (33) with the closure rows bordered like passive joints (:meth:`MechanismSolver.stiffness`)."""
    from vjm_pin.cli.common import finite_vector
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import MechanismSolver, unloaded_stiffness

    method = args.method or "eq28"
    solver = MechanismSolver(vm, loads, gravity)
    if args.deflection is not None:
        res = solver.solve(deflection=finite_vector(args.deflection, "--deflection"))
    elif args.wrench is not None or loads or gravity is not None:
        w = np.zeros(6) if args.wrench is None else finite_vector(args.wrench, "--wrench")
        res = solver.solve(wrench=w)
    else:
        res = solver.solve(deflection=np.zeros(6))
    out = analysis_dict_mechanism(vm, res)

    def unloaded():
        if not vm.closures:  # the open chain at its reference: eq. (30) with H = 0
            return unloaded_stiffness(vm, args.method or "eq30")
        bare = MechanismSolver(vm)
        return bare.stiffness(bare.solve(deflection=np.zeros(6)), method=method)

    for key, fn in (("stiffness", lambda: solver.stiffness(res, method=method)), ("stiffness_unloaded", unloaded)):
        try:
            out[key] = fn().stiffness
        except SingularStiffness as e:
            out[key] = None
            out[key + "_note"] = str(e)
    return out


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
    keys filled by the caller): closure multipliers and reactions, the redundant constraint rows
    and, with redundant rows, the note that the multipliers are the minimum-norm set."""
    return {
        "model": vm.name,
        "parallel": bool(vm.closures),
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
        "warnings": list(res.warnings),
        "checks": {},
        "residual": res.residuals,
        "energy": res.energy,
        "q": dict(zip(vm.q_names, res.q)),
        "theta": dict(zip(vm.theta_names, res.theta)),
        "closures": closures_list(vm, res),
        "redundant": list(res.redundant),
        "multipliers_note": res.multipliers_note,
    }


def _summary(args, out) -> None:
    """The ``--verbose`` line of ``analyze``."""
    from vjm_pin.cli.common import summary

    verdict = "stable" if out.get("stable") is not False else "UNSTABLE"
    summary(args, f"{out['model']}: {'converged' if out.get('converged') else 'NOT converged'}, {verdict}")


#: Stability eigenvalues shown in the text output (the largest: the ones that decide; all in --json).
SHOWN_EIGENVALUES = 6


def _eigenvalues_text(ev) -> str:
    """``"; eigenvalues [...]"`` for the text output: all of them, or the largest
    :data:`SHOWN_EIGENVALUES` of a large mechanism (the verdict's margin) and their count."""
    if ev is None or not len(ev):
        return ""
    ev = np.sort(np.asarray(ev, float))
    if ev.size <= SHOWN_EIGENVALUES:
        return f"; eigenvalues {np.array2string(ev, precision=4)}"
    top = np.array2string(ev[-SHOWN_EIGENVALUES:], precision=4)
    return f"; largest {SHOWN_EIGENVALUES} of {ev.size} eigenvalues {top} (all in --json)"


def _human(vm, robot, out, fmt_matrix) -> str:
    # (+ 0.0 throughout: a negative zero prints as 0, not -0)
    d = np.asarray(out["deflection"], float) + 0.0
    w = np.asarray(out["wrench"], float) + 0.0
    lines = [f"model {vm.name}: end frame '{vm.frame}', task {' '.join(vm.task_names)}"]
    if robot is not None:
        pose = ", ".join(f"{k}={v:.4g}" for k, v in robot.pose.items() if k in vm.joint_names)
        lines.append(f"pose {robot.pose_name or '(given/default)'}: {pose or 'all joints at 0'}")
    extra = []
    if out.get("payload") is not None:
        extra.append(f"payload {out['payload']:g} kg")
    if out.get("gravity"):
        extra.append("link weights (gravity)")
    lines.append(
        f"end wrench [N, N, N, N·m, N·m, N·m]: {np.array2string(w, precision=4)}"
        + (f"  (+ {', '.join(extra)})" if extra else "")
    )
    for ld in out.get("loads") or ():
        if ld["source"] == "load":
            lines.append(
                f"dead load at '{ld['frame']}' [N, N·m, world axes]: {np.array2string(np.asarray(ld['wrench']), precision=4)}"
            )
    for c in out.get("closures") or ():
        mu = ", ".join(f"{k} {v:.6g}" for k, v in c["multipliers"].items())
        lines.append(
            f"closure {c['name']} ({c['frame_a']} on {c['frame_b']}): multipliers [N, N·m] {mu}; reaction on "
            f"{c['frame_a']} [N, N·m, world] {np.array2string(np.asarray(c['wrench_a']), precision=4)}"
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
        extra = _eigenvalues_text(out.get("stability_eigenvalues"))
        what = "stable (as controlled)" if ctl is not None and ctl["loaded"] else "stable (eq. 23, end held)"
        lines.append(f"{what}: {verdict}{extra}")
    if out.get("stable_end_held") is not None and ctl is not None and ctl["loaded"]:
        extra = _eigenvalues_text(out.get("stability_end_held_eigenvalues"))
        lines.append(
            f"stable_end_held (eq. 23): {'stable' if out['stable_end_held'] else 'UNSTABLE'}{extra}"
        )
    if out.get("multipliers_note"):
        lines.append(f"note: {out['multipliers_note']}")
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
            if out.get(key + "_note"):  # a K_C infinite along a rigid direction (rigid_note)
                lines.append(f"{label}: {out[key + '_note']}")
    wk = out.get("weakest")
    if wk is not None:
        lines.append(
            f"weakest translational stiffness (end free to rotate): {wk['stiffness_along'] / 1e3 + 0.0:.4g} N/mm along "
            f"{np.array2string(np.asarray(wk['direction'], float) + 0.0, precision=3, suppress_small=True)} (world); "
            f"with the rotations held: {wk['stiffness_along_rotations_held'] / 1e3 + 0.0:.4g} N/mm"
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
