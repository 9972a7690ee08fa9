"""A closed loop: the sway buckling of a portal frame under dead loads on its columns.

The bundled ``portal-frame`` is a planar frame: two rigid columns of height h, a rigid beam,
rotational springs k at the four corners. Its URDF is a tree cut open at the right foot and
closed again by ``<vjm:closure name="right_foot" frame_a="foot" frame_b="anchor"
components="x z ry"/>`` (docs/format.md); the task frame is the middle of the beam, held or
loaded along x. :class:`~vjm_pin.solver.mechanism.MechanismSolver` solves the whole loop in one
Newton iteration, with the closure reactions as multipliers.

Here: a vertical dead load P on each column top (``Load``, the ``--load`` of the CLI), then

1. horizontal push curves at several P (``trace_curve``): the sway force against the closed
   form of the total potential ``Π = 2kφ² − F h sin φ − 2Ph(1 − cos φ)``, sway ``s = h sin φ``;
2. the critical load per column, found as the P where the straight frame, loaded (not held)
   along x, stops being stable — compared with the closed form ``P_cr = 2k/h``.

Units: SI (m, rad, N, N·m).

    python examples/closed_loop_portal_frame.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from vjm_pin.analysis.curve import trace_curve
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

PUSH = (1.0, 0.0, 0.0)  # world x: the sway direction
MAX_SWAY = 0.2  # m
LOAD_FRACTIONS = (0.0, 0.5, 0.9)  # P / (2k/h) for the push curves


def column_loads(p: float) -> list[Load]:
    """A vertical dead force P (N, downwards) on top of each column."""
    return [Load("top_left", [0.0, 0.0, -p]), Load("top_right", [0.0, 0.0, -p])]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="output folder (default: a new temporary one)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)

    vm = resolve_model("portal-frame")
    (closure,) = vm.closures
    print(
        f"closure '{closure.name}': {closure.frame_a} on {closure.frame_b}, {' '.join(closure.components)}"
    )
    # The data of the closed forms, read from the model: k (all four springs equal) and h (the
    # height of the left column's top corner).
    k = float(vm.K_theta[0, 0])
    h = float(vm.model.jointPlacements[vm.model.getJointId("corner_tl")].translation[2])
    p_closed = 2.0 * k / h
    print(
        f"corner springs k = {k:g} N·m/rad, column height h = {h:g} m: closed form P_cr = 2k/h = {p_closed:g} N"
    )

    # 1. Push curves: every point is an equilibrium with the beam held along x at s.
    curves = []
    for frac in LOAD_FRACTIONS:
        p = frac * p_closed
        curve = trace_curve(vm, PUSH, MAX_SWAY, steps=10, loads=column_loads(p))
        s = np.array([pt.deflection for pt in curve.points])
        f = np.array([pt.force for pt in curve.points])
        phi = np.arcsin(s / h)
        f_closed = (4 * k * phi - 2 * p * h * np.sin(phi)) / (h * np.cos(phi))  # dΠ/dφ = 0
        err = np.max(np.abs(f - f_closed)) / np.max(np.abs(f_closed[1:]))
        print(
            f"P = {p:7.2f} N: sway stiffness at s = 0 {curve.points[0].stiffness:8.3f} N/m "
            f"(closed form (4k − 2Ph)/h² = {(4 * k - 2 * p * h) / h**2:8.3f}); "
            f"force at s = {s[-1]:.2f} m: {f[-1]:8.4f} N, largest relative error vs closed form {err:.1e}"
        )
        curves.append(
            {
                "P_N": p,
                "sway_m": s.tolist(),
                "force_N": f.tolist(),
                "stiffness_N_per_m": [pt.stiffness for pt in curve.points],
            }
        )

    # 2. Critical load: the straight frame with the beam loaded (zero force) along x. The
    #    largest eigenvalue of the reduced Hessian on the closure null space crosses zero there.
    def largest_eigenvalue(p: float) -> float:
        res = MechanismSolver(vm, loads=column_loads(p)).solve(wrench=[0.0])  # task x loaded
        return float(res.stability.eigenvalues.max())

    p_cr = brentq(largest_eigenvalue, 0.5 * p_closed, 1.5 * p_closed, xtol=1e-12 * p_closed)
    above = MechanismSolver(vm, loads=column_loads(1.1 * p_cr)).solve(wrench=[0.0])
    print(
        f"critical load per column: {p_cr:.9g} N (2k/h = {p_closed:g} N, relative difference "
        f"{abs(p_cr - p_closed) / p_closed:.1e})"
    )
    print(
        f"at 1.1 P_cr: stable (beam loaded along x) = {above.stable}, "
        f"stable_end_held (beam held) = {above.stable_end_held}"
    )

    result = {
        "k_N_m_per_rad": k,
        "h_m": h,
        "P_cr_closed_form_N": p_closed,
        "P_cr_N": p_cr,
        "above_critical": {
            "P_N": 1.1 * p_cr,
            "stable": bool(above.stable),
            "stable_end_held": bool(above.stable_end_held),
        },
        "curves": curves,
    }
    (out / "portal_frame.json").write_text(json.dumps(result, indent=1))
    print(f"written {out / 'portal_frame.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
