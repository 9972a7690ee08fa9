"""A workspace map of the UR5 on Dask: deflection and stiffness under a tool load at many poses.

:func:`vjm_pin.analysis.maps.run_map` evaluates every pose with one pure function (loaded equilibrium
of eq. 5 under the wrench, loaded stiffness of eq. 30, stability of eq. 23), so the poses can
be spread over any ``dask.distributed`` cluster. Here a ``LocalCluster`` of two workers
stands in for a real cluster: to use yours, pass its address
(``scheduler="tcp://host:8786"``, or ``vjm-pin map ... --scheduler tcp://host:8786``).
The same poses are then evaluated serially in this process to show that the backend does
not change the numbers.

The UR5 comes from ``example-robot-data`` with vjm_pin's default springs (every actuator
1e5 N·m/rad, rigid links: an order of magnitude, not a measurement; see
docs/stiffness_values.md). Units: SI (m, N, N/m).

    python examples/workspace_map_dask.py [--out DIR] [--poses 16]

Writes DIR/map.csv and DIR/map.png (default DIR: a new temporary folder). Needs the
``dask`` extra: ``pip install "vjm_pin[dask]"``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from vjm_pin.analysis.maps import mapped_joints, run_map, sample_poses
from vjm_pin.model.registry import resolve_model

WRENCH = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])  # N, N·m: 100 N downwards on the tool


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: a new temp folder)"
    )
    parser.add_argument("--poses", type=int, default=16, help="number of random poses (default 16)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)

    try:
        from dask.distributed import LocalCluster
    except ImportError:
        raise SystemExit('this example needs Dask: pip install "vjm_pin[dask]"') from None

    vm = resolve_model("ur5")
    names = mapped_joints(vm)  # the actuated joints
    _, poses = sample_poses(vm, args.poses, seed=0, names=names)  # uniform within the joint limits

    # Two workers with one thread each, no dashboard (no port to open). processes=False keeps
    # them inside this process so that the example starts in a second; on a real cluster
    # every worker is a separate process (or machine) that imports vjm_pin itself.
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, protocol="tcp", dashboard_address=None
    ) as cluster:
        result = run_map(
            vm, names, poses, WRENCH, backend="dask", scheduler=cluster.scheduler_address
        )
    serial = run_map(vm, names, poses, WRENCH, backend="serial")

    ok = result.ok
    same = bool(
        np.array_equal(result.deflection[ok], serial.deflection[ok])
        and np.array_equal(result.k_along[ok], serial.k_along[ok])
    )
    print(
        f"{args.poses} poses of {vm.name}, {int(ok.sum())} ok; statuses: "
        f"{dict(zip(*np.unique(result.status, return_counts=True)))}"
    )
    print(
        f"tool deflection |d| under 100 N: {1e3 * np.nanmin(np.linalg.norm(result.deflection[ok, :3], axis=1)):.3f}"
        f" … {1e3 * np.nanmax(np.linalg.norm(result.deflection[ok, :3], axis=1)):.3f} mm"
    )
    print(
        f"stiffness along the load: {np.nanmin(result.k_along[ok]) / 1e3:.1f} … "
        f"{np.nanmax(result.k_along[ok]) / 1e3:.1f} N/mm; dask == serial: {same}"
    )

    result.save(out / "map.csv")
    from vjm_pin.viz.plots import save_map_plot

    save_map_plot(result, out / "map.png")
    summary = {
        "model": vm.name,
        "joints": list(names),
        "poses": args.poses,
        "ok": int(ok.sum()),
        "k_along_N_per_m": result.k_along.tolist(),
        "status": result.status.tolist(),
        "dask_equals_serial": same,
    }
    (out / "map.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {out / 'map.csv'}, {out / 'map.png'} and {out / 'map.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
