"""Matplotlib figures of force–deflection curves (paper Fig. 4–5).

Viewer layer: imports matplotlib lazily; the solver never imports this module.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def _units(direction: np.ndarray) -> tuple[str, str]:
    rot = np.any(direction[3:] != 0)
    return ("rad", "N·m") if rot else ("m", "N")


def plot_curve(
    curve,
    ax=None,
    *,
    label: str | None = None,
    color: str | None = None,
    force_unit: float = 1.0,
    force_label: str | None = None,
    deflection_unit: float = 1.0,
    deflection_label: str | None = None,
    mark_critical: bool = True,
    legend: bool = True,
    analytic: Sequence[tuple[str, np.ndarray, np.ndarray]] = (),
):
    """Draw a :class:`~vjm_pin.analysis.curve.Curve` on ``ax`` (a new figure if None); returns ``ax``.

    Stable points are drawn solid, unstable ones (and the ``branches``) dashed; critical
    points are marked with a star and annotated with their force. Forces are divided by
    ``force_unit`` (e.g. Kθ/L) and labelled ``force_label``; deflections likewise.
    ``analytic`` adds reference curves ``(label, deflection, force)`` (SI) as thin lines.
    """
    import matplotlib

    if ax is None:
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 4.4))
    dunit, funit = _units(curve.direction)
    # the followed branch, with each critical point inserted where it was located (the
    # step grid alone would draw a chord across the transition)
    s_l, f_l, st_l = [], [], []
    crit = sorted(curve.critical, key=lambda c: c.index)
    for i, p in enumerate(curve.points):
        for c in crit:
            if c.index == i:
                s_l += [c.deflection, np.nan, c.deflection]
                f_l += [c.force, np.nan, c.force]
                st_l += [True, True, True]
        s_l.append(p.deflection)
        f_l.append(p.force)
        st_l.append(p.stable)
    s = np.array(s_l) / deflection_unit
    f = np.array(f_l) / force_unit
    stable = np.array(st_l)
    line = ax.plot(
        np.where(stable, s, np.nan),
        np.where(stable, f, np.nan),
        "-",
        color=color,
        lw=1.8,
        label=(label or "followed branch") + " (stable)",
    )[0]
    color = line.get_color()
    if not stable.all():
        ax.plot(
            np.where(~stable, s, np.nan),
            np.where(~stable, f, np.nan),
            ":",
            color=color,
            lw=1.5,
            label=(label or "followed branch") + " (unstable)",
        )
    for i, br in enumerate(curve.branches):
        bs = np.array([p.deflection for p in br]) / deflection_unit
        bf = np.array([p.force for p in br]) / force_unit
        ax.plot(
            bs,
            bf,
            "--",
            color=color,
            lw=1.2,
            alpha=0.8,
            label=f"{label or ''} unstable branch".strip() if i == 0 else None,
        )
    for name, x, y in analytic:
        ax.plot(
            np.asarray(x) / deflection_unit,
            np.asarray(y) / force_unit,
            "-",
            color="k",
            lw=0.7,
            alpha=0.6,
            label=name,
        )
    if mark_critical:
        for c in curve.critical:
            ax.plot(
                [c.deflection / deflection_unit],
                [c.force / force_unit],
                "*",
                color=color,
                ms=13,
                mec="k",
                mew=0.6,
            )
            ax.annotate(
                f"{c.force / force_unit:.4g}",
                (c.deflection / deflection_unit, c.force / force_unit),
                textcoords="offset points",
                xytext=(6, -12),
                fontsize=8,
                color=color,
            )
    ax.set_xlabel(
        deflection_label
        if deflection_label is not None
        else f"deflection along the direction [{dunit}]"
    )
    ax.set_ylabel(
        force_label if force_label is not None else f"force along the direction [{funit}]"
    )
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(fontsize=8, loc="best")
    return ax


def save_curve_plot(curve, path, *, title: str | None = None, **kwargs) -> None:
    """Plot ``curve`` (see :func:`plot_curve`) and write it to ``path``.

    The format follows the extension (:data:`vjm_pin.outputs.PLOT_EXTENSIONS`: PNG, PDF,
    SVG, ...). The path is checked first (:func:`vjm_pin.outputs.check_output`) and the file
    written atomically: an existing file is replaced only by a complete plot.

    Raises:
        OutputError: the path cannot be written (unknown extension, missing or read-only
            folder).
    """
    from vjm_pin.outputs import PLOT_EXTENSIONS, atomic_output, check_output

    path = check_output(path, PLOT_EXTENSIONS, what="plot")
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    try:
        plot_curve(curve, ax, **kwargs)
        if title:
            ax.set_title(title, fontsize=10)
        fig.tight_layout()
        with atomic_output(path) as tmp:
            fig.savefig(tmp, dpi=120, format=path.suffix[1:].lower())
    finally:
        plt.close(fig)
