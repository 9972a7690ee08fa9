"""A parallel robot: the bundled Orthoglide (paper §6.2) at its isotropic point Q0.

The Orthoglide is three identical legs (linear actuator, parallelogram folded into an
equivalent spring, bar) meeting at one platform. vjm_pin loads the one URDF tree with its
``<vjm:leg>`` tags (docs/parallel.md), solves every leg at the same platform location and sums
the leg forces and stiffnesses (K_C = Σ K_C⁽ⁱ⁾, paper §5). This is what
``vjm-pin analyze orthoglide-q0 --wrench ...`` does, through the Python API.

Here: the unloaded stiffness at the platform, then the platform pushed along the workspace
bisector (−1, −1, −1)/√3 by dead forces of growing size (eq. 11 outer loop): the deflection,
the loaded stiffness along the load, and the per-leg forces and stability (eq. 23).
Units: SI (m, rad, N, N·m).

    python examples/parallel_orthoglide.py [--out DIR]

Writes DIR/orthoglide.json (default DIR: a new temporary folder).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from vjm_pin.parallel import RobotSolver, load_parallel
from vjm_pin.model.registry import bundled_models

FORCES = (200.0, 500.0, 1000.0)  # N, magnitude of the push along the bisector
DIRECTION = -np.ones(3) / np.sqrt(3.0)  # world axes, towards the actuators


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: a new temp folder)"
    )
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)

    pm = load_parallel(bundled_models()["orthoglide-q0"])  # one URDF, three <vjm:leg> tags
    rs = RobotSolver(pm)
    k0 = rs.stiffness()  # (6, 6) unloaded K_C at the platform point, world axes
    k0_along = float(DIRECTION @ k0[:3, :3] @ DIRECTION)
    print(f"Orthoglide Q0, legs {[lg.name for lg in pm.legs]}")
    print(
        f"unloaded: translational stiffness {np.diag(k0)[:3] / 1e3} N/mm, "
        f"rotational {np.diag(k0)[3:]} N·m/rad"
    )

    rows = []
    for f in FORCES:
        wrench = np.concatenate([f * DIRECTION, np.zeros(3)])  # N, N·m on the platform
        eq = rs.solve_wrench(wrench)  # eq. (11) on the aggregated stiffness
        k = rs.stiffness(eq)
        k_along = float(DIRECTION @ k[:3, :3] @ DIRECTION)
        leg_sum = np.sum([lg.wrench for lg in eq.legs], axis=0)
        print(
            f"F = {f:6.0f} N: platform moves {1e3 * DIRECTION @ eq.deflection[:3]:.4f} mm along the load, "
            f"stiffness along it {k_along / 1e3:.1f} N/mm (unloaded {k0_along / 1e3:.1f}), "
            f"stable legs: {[lg.name for lg in eq.legs if lg.stable]}"
        )
        rows.append(
            {
                "force_N": f,
                "wrench_N": wrench.tolist(),
                "deflection_m": eq.deflection.tolist(),
                "leg_wrench_sum_N": leg_sum.tolist(),
                "legs": [
                    {"name": lg.name, "wrench_N": lg.wrench.tolist(), "stable": lg.stable}
                    for lg in eq.legs
                ],
                "stable": eq.stable,
                "stiffness_along_N_per_m": k_along,
            }
        )
    result = {
        "model": "orthoglide-q0",
        "direction": DIRECTION.tolist(),
        "unloaded_stiffness_along_N_per_m": k0_along,
        "loads": rows,
    }
    (out / "orthoglide.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'orthoglide.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
