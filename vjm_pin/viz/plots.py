"""Matplotlib figures: force–deflection curves (paper Fig. 4–5) with a pre-buckling inset,
stiffness against load, and workspace maps as heat maps.

Viewer layer: imports matplotlib lazily; the solver never imports this module. Every axis
label carries its unit; the critical-point labels too.
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
    inset: bool = True,
):
    """Draw a :class:`~vjm_pin.analysis.curve.Curve` on ``ax`` (a new figure if None); returns ``ax``.

    Stable points are drawn solid, unstable ones (and the ``branches``) dashed; critical
    points are marked with a star and annotated with their force. Forces are divided by
    ``force_unit`` (e.g. Kθ/L) and labelled ``force_label``; deflections likewise.
    ``analytic`` adds reference curves ``(label, deflection, force)`` (SI) as thin lines.
    ``inset`` adds a zoom on the pre-buckling branch when the first critical point is within
    :data:`INSET_FRACTION` of the deflection range.
    """
    import matplotlib

    if ax is None:
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 4.4))
    dunit, funit = _units(curve.direction)
    color = _draw_followed(ax, curve, deflection_unit, force_unit, color, label)
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
        _mark_critical(
            ax,
            curve,
            deflection_unit,
            force_unit,
            color,
            "" if force_label is not None else f" {funit}",
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
    if inset:
        _pre_buckling_inset(ax, curve, deflection_unit, force_unit, color)
    return ax


def _draw_followed(ax, curve, deflection_unit: float, force_unit: float, color, label):
    """The followed branch (stable solid, unstable dotted) with each critical point inserted
    where it was located (the step grid alone would draw a chord across the transition), and
    the other branches dashed. Returns the colour used."""
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
    name = label or "followed branch"
    line = ax.plot(
        np.where(stable, s, np.nan),
        np.where(stable, f, np.nan),
        "-",
        color=color,
        lw=1.8,
        label=name + " (stable)",
    )[0]
    color = line.get_color()
    if not stable.all():
        ax.plot(
            np.where(~stable, s, np.nan),
            np.where(~stable, f, np.nan),
            ":",
            color=color,
            lw=1.5,
            label=name + " (unstable)",
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
    return color


def _mark_critical(ax, curve, deflection_unit: float, force_unit: float, color, unit: str) -> None:
    """A star at each critical point, annotated with its force (and ``unit``)."""
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
            f"{c.force / force_unit:.4g}{unit}",
            (c.deflection / deflection_unit, c.force / force_unit),
            textcoords="offset points",
            xytext=(6, -12),
            fontsize=8,
            color=color,
        )


#: The pre-buckling inset is drawn when the first critical point lies within this fraction
#: of the traced deflection range (the branch before it would be squashed against the axis).
INSET_FRACTION = 0.15


def _pre_buckling_inset(ax, curve, deflection_unit: float, force_unit: float, color) -> None:
    """Zoom on the branch before the first critical point (``[0, 3 s_c]``) when that branch
    is a small part of the plot."""
    if not curve.critical or not curve.points:
        return
    s = np.array([p.deflection for p in curve.points])
    span = float(np.nanmax(np.abs(s))) if s.size else 0.0
    c = min(curve.critical, key=lambda c: abs(c.deflection))
    if span == 0.0 or abs(c.deflection) > INSET_FRACTION * span:
        return
    lim = max(3.0 * abs(c.deflection), 0.02 * span)
    order = sorted(curve.points, key=lambda p: abs(p.deflection))
    pts = [p for p in order if abs(p.deflection) <= lim]
    pts += order[len(pts) : len(pts) + 1]  # and the first point past the zoom, for the shape
    if len(pts) < 2:
        return
    ins = ax.inset_axes([0.56, 0.12, 0.4, 0.36])
    line = sorted(
        [(p.deflection, p.force) for p in pts]
        + [
            (k.deflection, k.force)
            for k in curve.critical
            if abs(k.deflection) <= abs(pts[-1].deflection)
        ],
        key=lambda sf: abs(sf[0]),
    )
    xs = np.array([s for s, _ in line]) / deflection_unit
    fs = np.array([f for _, f in line]) / force_unit
    ins.plot(xs, fs, "-", color=color, lw=1.4)
    ins.plot(
        [c.deflection / deflection_unit],
        [c.force / force_unit],
        "*",
        color=color,
        ms=10,
        mec="k",
        mew=0.5,
    )
    ins.set_title("before the critical point", fontsize=7)
    ins.tick_params(labelsize=6)
    ins.grid(True, alpha=0.3)


def plot_stiffness(
    curve,
    ax=None,
    *,
    force_unit: float = 1.0,
    force_label: str | None = None,
    color: str | None = None,
):
    """Tangent stiffness ``dᵀK_C d`` (eq. 30) against the force along the direction, for the
    points of the followed branch; critical points marked where the stiffness changes sign or
    dips (their ``stiffness_before``/``_after``). Returns ``ax``."""
    import matplotlib

    if ax is None:
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6.4, 4.4))
    dunit, funit = _units(curve.direction)
    kunit = f"{funit}/{dunit}"
    f = np.array([p.force for p in curve.points]) / force_unit
    k = np.array([p.stiffness for p in curve.points], dtype=float)
    k = np.where(np.isfinite(k), k, np.nan)
    stable = np.array([p.stable for p in curve.points], dtype=bool)
    line = ax.plot(
        np.where(stable, f, np.nan),
        np.where(stable, k, np.nan),
        "-",
        color=color,
        lw=1.6,
        label="stable",
    )[0]
    if not stable.all():
        ax.plot(
            np.where(~stable, f, np.nan),
            np.where(~stable, k, np.nan),
            ":",
            color=line.get_color(),
            lw=1.4,
            label="unstable",
        )
    for c in curve.critical:
        ax.plot([c.force / force_unit], [0.0], "*", color=line.get_color(), ms=12, mec="k", mew=0.6)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel(
        force_label if force_label is not None else f"force along the direction [{funit}]"
    )
    ax.set_ylabel(f"stiffness along the direction [{kunit}]")
    ax.set_title("stiffness against load (eq. 30)", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return ax


def save_curve_plot(
    curve, path, *, title: str | None = None, stiffness: bool = True, **kwargs
) -> None:
    """Plot ``curve`` (see :func:`plot_curve`; with ``stiffness`` a second panel of
    :func:`plot_stiffness`) and write it to ``path``.

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

    ncols = 2 if stiffness and curve.points else 1
    fig, axes = plt.subplots(1, ncols, figsize=(6.4 * ncols, 4.4), squeeze=False)
    try:
        plot_curve(curve, axes[0, 0], **kwargs)
        if ncols == 2:
            plot_stiffness(
                curve,
                axes[0, 1],
                force_unit=kwargs.get("force_unit", 1.0),
                force_label=kwargs.get("force_label"),
            )
        if title:
            fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        with atomic_output(path) as tmp:
            fig.savefig(tmp, dpi=120, format=path.suffix[1:].lower())
    finally:
        plt.close(fig)


def _grid_shape(poses: np.ndarray):
    """``(values per joint)`` when ``poses`` is a full 1- or 2-joint grid (row-major), else None."""
    if poses.ndim != 2 or poses.shape[1] not in (1, 2) or len(poses) < 2:
        return None
    vals = [np.unique(poses[:, j]) for j in range(poses.shape[1])]
    if int(np.prod([len(v) for v in vals])) != len(poses):
        return None
    return vals


def save_map_plot(result, path, *, floor: float | None = 0.0) -> None:
    """Workspace map of a :class:`~vjm_pin.analysis.maps.MapResult`, written to ``path``.

    Panels: a heat map of the weakest translational stiffness ``k_min`` (N/m, log colour
    scale) over the sampled joints when they form a 1- or 2-joint grid; the unloaded end
    positions seen from the top and the side, coloured by the deflection (mm). Poses whose
    end is below ``floor`` (m, world z; None: no floor) and poses without a result are drawn
    as grey crosses, never coloured. PNG/PDF/SVG by extension; checked first, written
    atomically.
    """
    from vjm_pin.outputs import PLOT_EXTENSIONS, atomic_output, check_output

    path = check_output(path, PLOT_EXTENSIONS, what="plot")
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    ok = np.asarray(result.status) == "ok"
    if floor is not None:
        ok &= ~(result.p0[:, 2] < floor)
    grid = _grid_shape(np.asarray(result.poses, float))
    ncols = 3 if grid is not None else 2
    fig, axes = plt.subplots(1, ncols, figsize=(5.2 * ncols, 4.6), constrained_layout=True)
    try:
        if grid is not None:
            _joint_heat_map(fig, axes[0], result, grid, ok)
        _workspace_views(fig, axes[-2:], result, ok, floor)
        w = np.round(np.asarray(result.wrench, float), 3).tolist()
        fig.suptitle(f"{result.model}: end '{result.frame}', wrench {w} (N, N·m)", fontsize=10)
        with atomic_output(path) as tmp:
            fig.savefig(tmp, dpi=110, format=path.suffix[1:].lower())
    finally:
        plt.close(fig)


def _joint_heat_map(fig, ax, result, grid, ok) -> None:
    import matplotlib.colors as mcolors

    k = np.where(ok & np.isfinite(result.k_min) & (result.k_min > 0), result.k_min, np.nan)
    names = list(result.joints)
    if len(grid) == 1:
        order = np.argsort(result.poses[:, 0])
        ax.semilogy(result.poses[order, 0], k[order], "-o", ms=3)
        ax.set_xlabel(f"{names[0]} (rad or m)")
        ax.set_ylabel("k_min (N/m)")
        return
    a, b = grid
    img = np.full((len(b), len(a)), np.nan)
    ia = np.searchsorted(a, result.poses[:, 0])
    ib = np.searchsorted(b, result.poses[:, 1])
    img[ib, ia] = k
    finite = img[np.isfinite(img)]
    norm = mcolors.LogNorm(finite.min(), finite.max()) if finite.size and finite.min() > 0 else None
    mesh = ax.pcolormesh(
        a, b, np.ma.masked_invalid(img), shading="nearest", cmap="viridis", norm=norm
    )
    fig.colorbar(mesh, ax=ax, label="weakest translational stiffness k_min (N/m)")
    ax.set_xlabel(f"{names[0]} (rad or m)")
    ax.set_ylabel(f"{names[1]} (rad or m)")
    ax.set_title("over the sampled joints (blank: no result / below the floor)", fontsize=8)


def _workspace_views(fig, axes, result, ok, floor) -> None:
    d = np.linalg.norm(np.asarray(result.deflection)[:, :3], axis=1) * 1e3
    sc = None
    for ax, (i, j, lab) in zip(axes, ((0, 1, ("x (m)", "y (m)")), (0, 2, ("x (m)", "z (m)")))):
        if ok.any():
            sc = ax.scatter(result.p0[ok, i], result.p0[ok, j], c=d[ok], s=12, cmap="viridis")
        bad = ~ok & np.all(np.isfinite(result.p0), axis=1)
        if bad.any():
            what = "no result" + ("" if floor is None else " / below the floor")
            ax.scatter(result.p0[bad, i], result.p0[bad, j], marker="x", c="0.6", s=12, label=what)
            ax.legend(loc="best", fontsize=8)
        if floor is not None and j == 2:
            ax.axhline(floor, color="0.4", lw=0.8, ls="--")
        ax.set_xlabel(lab[0])
        ax.set_ylabel(lab[1])
        ax.set_aspect("equal", adjustable="datalim")
    if sc is not None:
        fig.colorbar(sc, ax=list(axes), label="end deflection (mm)")
