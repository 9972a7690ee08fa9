"""``vjm-pin analyze``: loaded equilibrium, stability and stiffness at one load."""

from __future__ import annotations

import numpy as np


def add_parser(sub):
    p = sub.add_parser(
        "analyze",
        help="equilibrium, stability and loaded stiffness for a deflection or a wrench",
        description=(
            "Solve the loaded equilibrium of MODEL (eq. 5) for a prescribed end deflection, or for a "
            "wrench (eq. 11), check its stability (eq. 23) and compute the loaded Cartesian stiffness "
            "(eq. 30). Deflection: from the unloaded end location, world axes, m and rad (rotation "
            "vector). Wrench: force at the end frame origin and moment, world axes, N and N·m."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="VJM URDF path or bundled model name (see 'vjm-pin models')")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--deflection", nargs="+", type=float, metavar="D", help="DX DY DZ [RX RY RZ] (m, rad)")
    g.add_argument("--wrench", nargs="+", type=float, metavar="W", help="FX FY FZ [MX MY MZ] (N, N·m)")
    p.add_argument("--method", choices=("eq30", "eq32", "eq33"), default="eq30", help="stiffness formula (default eq30)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func=run)


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
    for key, fn in (("stiffness", lambda: loaded_stiffness(vm, res, method)), ("stiffness_unloaded", lambda: unloaded_stiffness(vm, method))):
        try:
            out[key] = fn().stiffness
        except SingularStiffness as e:
            out[key] = None
            out[key + "_note"] = str(e)
    return out


def run(args) -> int:
    from ..registry import resolve_model
    from ..solver import EquilibriumSolver
    from .common import dump_json, finite_vector, fmt_matrix

    vm = resolve_model(args.model)
    solver = EquilibriumSolver(vm)
    if args.deflection is not None:
        res = solver.solve(finite_vector(args.deflection, "--deflection"))
    else:
        res = solver.solve_wrench(finite_vector(args.wrench, "--wrench"))
    out = analysis_dict(vm, res, args.method)
    if args.json:
        print(dump_json(out))
        return 0
    w, d = res.wrench, res.deflection
    print(f"model {vm.name}: end frame '{vm.frame}', task {' '.join(vm.task_names)}")
    print(f"equilibrium: converged={res.converged} in {res.iterations} iterations ({res.path}); energy {res.energy:.6g} J")
    print(f"  deflection  [m, m, m, rad, rad, rad]: {np.array2string(d, precision=6)}")
    print(f"  wrench      [N, N, N, N·m, N·m, N·m]: {np.array2string(w, precision=6)}")
    if res.stability is not None:
        verdict = "stable" if res.stable else "UNSTABLE"
        print(f"  stability (eq. 23): {verdict}; eigenvalues of the reduced matrix {np.array2string(res.stability.eigenvalues, precision=4)}")
    for key, label in (("stiffness", "loaded stiffness K_C"), ("stiffness_unloaded", "unloaded stiffness")):
        if out[key] is None:
            print(f"{label}: {out[key + '_note']}")
        else:
            print(f"{label} (N/m, N/rad, N·m/rad; world axes at the end frame):")
            print(fmt_matrix(out[key]))
    return 0
