"""Critical forces of the nine paper models for several step counts (issue 12, acceptance).

    python scripts/critical_points_table.py [--steps 5,10,25,50,100,400,800]

Each model is traced along −x over the paper study's range (scripts/reproduce_paper.py:
1.0 L for Model A, 0.5 L for B and C); prints, per model and step count, the critical
forces (kind, F in Kθ/L), the number of critical points, the number of unstable points
on the followed branch and the time, then the largest relative spread of each critical
force over the step counts.
"""

from __future__ import annotations

import argparse
import time

from vjm_pin.model.registry import resolve_model
from vjm_pin.analysis.curve import trace_curve

RANGES = {"a": 1.0, "b": 0.5, "c": 0.5}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", default="5,10,25,50,100,400,800")
    ap.add_argument("--models", default="a-s,a-pi,a-z,b-s,b-pi,b-z,c-s,c-pi,c-z")
    args = ap.parse_args()
    steps = [int(s) for s in args.steps.split(",")]
    print(
        "| model | steps | critical points (kind: F [Kθ/L] at Δ [L]) | n | unstable pts | time [s] |"
    )
    print("|---|---|---|---|---|---|")
    summary = []
    for name in args.models.split(","):
        vm = resolve_model(f"paper-{name}")
        forces = {}
        for n in steps:
            t0 = time.perf_counter()
            c = trace_curve(vm, [-1, 0, 0], RANGES[name[0]], steps=n)
            dt = time.perf_counter() - t0
            forces[n] = [cp.force for cp in c.critical]
            crit = (
                "; ".join(f"{cp.kind}: {cp.force:.8f} at {cp.deflection:.6g}" for cp in c.critical)
                or "none"
            )
            unstable = sum(not p.stable for p in c.points)
            print(
                f"| paper-{name} | {n} | {crit} | {len(c.critical)} | {unstable} | {dt:.2f} |",
                flush=True,
            )
        counts = {len(v) for v in forces.values()}
        if len(counts) == 1 and counts != {0}:
            spread = max(
                (max(v[j] for v in forces.values()) - min(v[j] for v in forces.values()))
                / abs(forces[steps[0]][j])
                for j in range(len(forces[steps[0]]))
            )
        else:
            spread = float("nan") if len(counts) > 1 else 0.0
        summary.append((name, sorted(counts), spread))
    print()
    for name, counts, spread in summary:
        print(
            f"paper-{name}: critical point counts {counts}, largest relative spread of the forces {spread:.2e}"
        )


if __name__ == "__main__":
    main()
