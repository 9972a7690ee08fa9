"""A parallel robot: the bundled Orthoglide (paper §6.2) at its isotropic point Q0.

The Orthoglide is three identical legs (linear actuator, parallelogram folded into an
equivalent spring, bar) meeting at one platform. Its URDF is one tree with ``<vjm:leg>`` tags
(docs/parallel.md): ``load_vjm`` puts the platform on the first leg and holds the other two on
it with loop closures, and :class:`~vjm_pin.solver.mechanism.MechanismSolver` solves the whole
mechanism in one Newton iteration. This is what ``vjm-pin analyze orthoglide-q0 --wrench ...``
does, through the Python API.

Here: the unloaded stiffness at the platform, then the platform pushed along the workspace
bisector (−1, −1, −1)/√3 by dead forces of growing size: the deflection, the loaded stiffness
along the load, the stability (eq. 23 with the closures), and the legs split off as serial
chains (``split_legs``), each solved at the platform location: their wrenches sum to the load
and their stiffnesses to the mechanism's (K_C = Σ K_C⁽ⁱ⁾, paper §5).
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

from vjm_pin.model.format import load_vjm
from vjm_pin.model.legs import split_legs
from vjm_pin.model.registry import bundled_models
from vjm_pin.solver import EquilibriumSolver, loaded_stiffness
from vjm_pin.solver.mechanism import MechanismSolver

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

    vm = load_vjm(bundled_models()["orthoglide-q0"])  # one URDF, three <vjm:leg> tags
    ms = MechanismSolver(vm)
    legs = split_legs(vm)  # leg name -> the leg alone, a serial model ending at the platform
    k0 = ms.stiffness(ms.solve()).stiffness  # (6, 6) unloaded K_C at the platform point, world axes
    k0_along = float(DIRECTION @ k0[:3, :3] @ DIRECTION)
    print(f"Orthoglide Q0, legs {[lg.name for lg in vm.legs]}, closures {[c.name for c in vm.closures]}")
    print(
        f"unloaded: translational stiffness {np.diag(k0)[:3] / 1e3} N/mm, "
        f"rotational {np.diag(k0)[3:]} N·m/rad"
    )

    rows = []
    for f in FORCES:
        wrench = np.concatenate([f * DIRECTION, np.zeros(3)])  # N, N·m on the platform
        eq = ms.solve(wrench=wrench)  # one Newton iteration over the whole mechanism
        k = ms.stiffness(eq).stiffness
        k_along = float(DIRECTION @ k[:3, :3] @ DIRECTION)
        leg_rows, leg_k = [], np.zeros((6, 6))
        for name, lv in legs.items():  # each leg alone at the platform location
            le = EquilibriumSolver(lv).solve(target=(eq.position, eq.rotation))
            leg_k += loaded_stiffness(lv, le).stiffness
            leg_rows.append({"name": name, "wrench_N": le.wrench.tolist(), "stable": bool(le.stable)})
        leg_sum = np.sum([r["wrench_N"] for r in leg_rows], axis=0)
        print(
            f"F = {f:6.0f} N: platform moves {1e3 * DIRECTION @ eq.deflection[:3]:.4f} mm along the load, "
            f"stiffness along it {k_along / 1e3:.1f} N/mm (unloaded {k0_along / 1e3:.1f}), "
            f"stable: {eq.stable}; Σ legs' K_C − K_C: {np.abs(leg_k - k).max() / np.abs(k).max():.1e} (relative)"
        )
        rows.append(
            {
                "force_N": f,
                "wrench_N": wrench.tolist(),
                "deflection_m": eq.deflection.tolist(),
                "leg_wrench_sum_N": leg_sum.tolist(),
                "legs": leg_rows,
                "stable": bool(eq.stable),
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
