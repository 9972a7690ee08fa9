"""Issue 5 acceptance run: a 1,000-pose map of ur5 with 6-D link springs, local cores vs Dask.

Usage: python scripts/map_ur5_1000.py [N]   (prints the times and whether the backends agree)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from vjm_pin.analysis.maps import run_map, sample_poses
from vjm_pin.model.robots import build_robot

#: Aluminium tubes for the two long links of the UR5 (6-D beam springs, length from the URDF).
SPRINGS = {
    "links": {
        "upper_arm_link": {
            "beam": {
                "section": "tube",
                "outer_diameter": 0.09,
                "wall": 0.004,
                "E": 7.0e10,
                "nu": 0.33,
            }
        },
        "forearm_link": {
            "beam": {
                "section": "tube",
                "outer_diameter": 0.07,
                "wall": 0.0035,
                "E": 7.0e10,
                "nu": 0.33,
            }
        },
    }
}


def main(n: int = 1000) -> int:
    vm = build_robot("ur5", springs=SPRINGS).vm
    names, poses = sample_poses(vm, n, seed=0)
    wrench = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    times, maps = {}, {}
    for backend in ("local", "dask"):
        t = time.perf_counter()
        maps[backend] = run_map(vm, names, poses, wrench, backend=backend)
        times[backend] = time.perf_counter() - t
    a, b = maps["local"], maps["dask"]
    same = all(
        np.array_equal(getattr(a, f), getattr(b, f), equal_nan=(f != "status" and f != "stable"))
        for f in ("deflection", "k_along", "k_min", "p0", "stable", "status")
    )
    d = np.linalg.norm(a.deflection[a.ok, :3], axis=1) * 1e3
    print(
        f"ur5 with 6-D springs on upper_arm_link and forearm_link: n_theta = {vm.n_theta}, {n} poses"
    )
    print(f"status: { {str(k): int(v) for k, v in zip(*np.unique(a.status, return_counts=True))} }")
    print(f"deflection under 100 N down: median {np.median(d):.4g} mm, max {d.max():.4g} mm")
    for k, v in times.items():
        print(f"{k}: {v:.1f} s")
    print(f"local and dask agree bit for bit: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000))
