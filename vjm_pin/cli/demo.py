"""``vjm-pin demo``: the main job on the bundled example (paper's Model C chain, S posture)."""

from __future__ import annotations

import numpy as np

MODEL = "paper-c-s"
DIRECTION = (-1.0, 0.0, 0.0)
MAX_DEFLECTION = 0.05  # m
STEPS = 60

EXAMPLES = (
    "vjm-pin demo",
    "vjm-pin demo --out results/demo",
    "vjm-pin demo --quiet --out results/demo",
)


def add_parser(sub):
    p = sub.add_parser(
        "demo",
        help="trace the buckling of the paper's Model C chain (S posture); write a plot and an animated page",
        description=(
            f"Run the main job on the bundled model '{MODEL}' (paper's Model C: three flexible links with "
            f"passive joints, S posture): trace its force-deflection curve for an end deflection along "
            f"{list(DIRECTION)} up to {MAX_DEFLECTION * 1e3:g} mm, print the critical (buckling) force and "
            f"the stiffness before and after it, write the plot (curve.png) and the animated meshcat page "
            f"(curve.html, plays offline in any browser) to --out."
        ),
    )
    p.add_argument(
        "--out",
        default="vjm-demo",
        metavar="DIR",
        help="output folder, created if missing (default ./vjm-demo); its curve.png and curve.html "
        "are checked before the work starts, written atomically, and replaced if they exist",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from vjm_pin.cli.common import Progress, summary
    from vjm_pin.cli.view import curve_page, trace
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.outputs import HTML_EXTENSIONS, PLOT_EXTENSIONS, check_output, check_output_dir

    out = check_output_dir(args.out, what="--out")  # before any work
    png, html = out / "curve.png", out / "curve.html"
    if out.is_dir():
        check_output(png, PLOT_EXTENSIONS, what="--out")
        check_output(html, HTML_EXTENSIONS, what="--out")
    vm = resolve_model(MODEL)
    direction = np.array([*DIRECTION, 0.0, 0.0, 0.0])
    print(
        f"model {vm.name}: end frame '{vm.frame}', deflection along {list(DIRECTION)} up to {MAX_DEFLECTION * 1e3:g} mm"
    )
    with Progress(args, STEPS + 1, f"curve {vm.name}") as bar:
        curve = trace(vm, direction, MAX_DEFLECTION, STEPS, progress=bar.update)
    n_unstable = sum(1 for p in curve.points if p.stable is False)
    print(f"traced {len(curve.points)} equilibria ({n_unstable} unstable)")
    if curve.critical:
        for c in curve.critical:
            print(
                f"critical point: force {abs(c.force):.6g} N at deflection {c.deflection * 1e3:.6g} mm; "
                f"stiffness before {c.stiffness_before:.6g} N/m, after {c.stiffness_after:.6g} N/m"
            )
    else:
        print("no critical point on this path")
    out.mkdir(parents=True, exist_ok=True)
    try:
        from vjm_pin.viz.plots import save_curve_plot
    except ModuleNotFoundError as e:
        if e.name != "vjm_pin.viz.plots":
            raise
        print("plot: skipped (vjm_pin.viz.plots is not available)")
    else:
        save_curve_plot(
            curve,
            png,
            title=f"Model C ({vm.name}), S posture: force-deflection under end compression",
            deflection_unit=1e-3,
            deflection_label="end deflection along -x [mm]",
            force_label="compressive force [N]",
        )
        print(f"plot:      {png.resolve()}")
    page = curve_page(
        vm,
        curve,
        path=html,
        title=f"Model C ({vm.name}), S posture: buckling",
    )
    print(
        f"animation: {html.resolve()} ({page.frames} frames, deformation ×{page.scale:g}; open it in a browser)"
    )
    summary(args, f"{vm.name}: {len(curve.points)} points, {len(curve.critical)} critical, wrote {out}")
    return 0
