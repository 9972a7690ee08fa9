"""Force–deflection curve and buckling of a paper model, plotted with matplotlib.

The bundled ``paper-a-s`` is Model A of the paper (§6.1): three rigid links of L = 1 m, two
actuator springs Kθ = 1 N·m/rad, a passive joint at the base and a passive spherical joint at
the end, straight (S posture). Its end is pushed towards the base (direction −x): the chain
stays straight up to the critical force Kθ/L = 1 N, then buckles into a trapezoid whose
stable branch is eq. (35): F_s(Δ) = Kθ/L · φ / sin φ with φ = arccos(1 − Δ/(2L)).

The curve is traced by :func:`vjm_pin.analysis.curve.trace_curve` (deflection-driven equilibria of
eq. 5, stability of eq. 23 at every point, critical points located by root finding).

    python examples/buckling_curve.py [--out DIR] [--model paper-a-s] [--steps 40]

Writes DIR/curve.png and DIR/curve.json (default DIR: a new temporary folder).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt
import numpy as np

from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.registry import resolve_model

K_THETA = 1.0  # N·m/rad, actuator stiffness of the paper models
L = 1.0  # m, link length


def eq35_stable(delta: np.ndarray) -> np.ndarray:
    """Stable branch of Model A, S posture (eq. 35): force (N) for end shortening Δ (m)."""
    phi = np.arccos(1.0 - delta / (2.0 * L))
    return K_THETA / L * phi / np.sin(phi)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: a new temp folder)"
    )
    parser.add_argument("--model", default="paper-a-s", help="bundled model (default paper-a-s)")
    parser.add_argument(
        "--max-deflection", type=float, default=1.0, help="end shortening (m), default 1"
    )
    parser.add_argument("--steps", type=int, default=40, help="curve steps (default 40)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)

    vm = resolve_model(args.model)
    curve = trace_curve(vm, [-1.0, 0.0, 0.0], args.max_deflection, steps=args.steps)
    s, f = curve.deflections, curve.forces  # m, N (force along the direction, compressive > 0)
    stable = np.array([p.stable for p in curve.points])

    fig, ax = plt.subplots(figsize=(6, 4))
    # The critical points lie on the followed branch: insert them so that the line passes
    # through them (Model A stays straight, Δ = 0, until the force reaches Kθ/L).
    pts = sorted([*zip(s, f), *((c.deflection, c.force) for c in curve.critical)])
    ax.plot(*zip(*pts), "-", lw=1.5, label=f"{args.model}: followed branch (vjm_pin)")
    ax.plot(s, f, "o", ms=3, color="C0")
    if not stable.all():
        ax.plot(s[~stable], f[~stable], "rx", label="unstable points")
    if args.model == "paper-a-s":
        grid = np.linspace(1e-6, args.max_deflection, 200)
        ax.plot(grid, eq35_stable(grid), "k--", lw=1, label="eq. (35), stable branch")
    for c in curve.critical:
        ax.plot(c.deflection, c.force, "r*", ms=14, label=f"critical ({c.kind}): {c.force:.4g} N")
        print(
            f"critical point ({c.kind}): force {c.force:.6g} N at deflection {c.deflection:.4g} m; "
            f"stiffness {c.stiffness_before:.4g} -> {c.stiffness_after:.4g} N/m"
        )
    ax.set_xlabel("end shortening Δ (m)")
    ax.set_ylabel("compressive force F (N)")
    ax.set_title(f"{args.model}: force–deflection curve (Kθ = 1 N·m/rad, L = 1 m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    png = out / "curve.png"
    fig.savefig(png, dpi=120)
    plt.close(fig)

    summary = {
        "model": args.model,
        "deflection_m": s.tolist(),
        "force_N": f.tolist(),
        "stable": stable.tolist(),
        "critical": [
            {
                "kind": c.kind,
                "force_N": c.force,
                "deflection_m": c.deflection,
                "stiffness_before_N_per_m": c.stiffness_before,
                "stiffness_after_N_per_m": c.stiffness_after,
            }
            for c in curve.critical
        ],
    }
    (out / "curve.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {png} and {out / 'curve.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
