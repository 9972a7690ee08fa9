"""A cross-linked linkage: the bundled four-bar with a dead load at its coupler point.

``four-bar`` is a crank (actuator spring about y at the base pin), a coupler and a rocker
with planar link springs, closed by a pin at the rocker pivot (``<vjm:closure
name="rocker_pivot" ... components="x z"/>``). A dead force at the coupler point is given
as a ``Load`` (anywhere on the mechanism) with the task free, and again as the task wrench:
both are the same equilibrium. Checks printed: the deflection against the unloaded
stiffness ``K_C⁻¹ F`` (small load), and the moment balance about the base pin of the load,
the closure reaction at the rocker pivot and the crank spring torque.
Units: SI (m, rad, N, N·m).

    python examples/four_bar_coupler_load.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin

from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

FORCE = np.array([0.0, 0.0, -5.0])  # N at the coupler point, world axes


def moment_y(p: np.ndarray, f: np.ndarray) -> float:
    """y component of p × f (N·m): the planar moment about the origin (the base pin)."""
    return float(p[2] * f[0] - p[0] * f[2])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="output folder (default: a new temporary one)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)

    vm = resolve_model("four-bar")  # task: coupler_point, components x z
    # 1. The load anywhere: a Load at the coupler point, the task frame free (zero wrench).
    loaded = MechanismSolver(vm, loads=[Load("coupler_point", FORCE)]).solve(wrench=[0.0, 0.0])
    # 2. The same force as the task wrench (x and z components).
    ms = MechanismSolver(vm)
    as_task = ms.solve(wrench=FORCE[[0, 2]])
    k0 = ms.stiffness(ms.solve()).stiffness[np.ix_([0, 2], [0, 2])]  # unloaded K_C, x z block
    linear = np.linalg.solve(k0, FORCE[[0, 2]])
    print(
        f"coupler point deflection (x, z): {loaded.deflection[[0, 2]] * 1e3} mm (Load), "
        f"{as_task.deflection[[0, 2]] * 1e3} mm (task wrench), {linear * 1e3} mm (K_C⁻¹F, linear)"
    )
    print(f"stable: {loaded.stable}, stable_end_held: {loaded.stable_end_held}, path {loaded.path}")

    # Statics of the whole linkage about the base pin (it carries no moment): the load, the
    # reaction of the ground on the rocker pivot (closure multipliers) and the crank spring.
    data = vm.model.createData()
    pin.framesForwardKinematics(vm.model, data, loaded.x)
    p_load = data.oMf[vm.model.getFrameId("coupler_point")].translation
    p_foot = data.oMf[vm.model.getFrameId("foot")].translation
    w_foot = loaded.reaction_wrenches["rocker_pivot"][0]  # on frame_a (the rocker), world axes
    i = vm.theta_names.index("crank")
    crank_torque = -float(vm.K_theta[i, i] * (loaded.theta[i] - vm.theta0[i]))  # on the crank
    m_load, m_pivot = moment_y(p_load, FORCE), moment_y(p_foot, w_foot[:3]) + float(w_foot[4])
    print(
        f"moments about the base pin (N·m): load {m_load:.6f}, pivot reaction {m_pivot:.6f}, "
        f"crank spring {crank_torque:.6f}; sum {m_load + m_pivot + crank_torque:.2e}"
    )

    result = {
        "force_N": FORCE.tolist(),
        "deflection_load_m": loaded.deflection.tolist(),
        "deflection_task_wrench_m": as_task.deflection.tolist(),
        "deflection_linear_m": linear.tolist(),
        "moments_about_base_N_m": {"load": m_load, "pivot": m_pivot, "crank": crank_torque},
        "stable": bool(loaded.stable),
    }
    (out / "four_bar.json").write_text(json.dumps(result, indent=1))
    print(f"written {out / 'four_bar.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
