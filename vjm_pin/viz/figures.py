"""Paper-style snapshot figures of an animation (matplotlib), like Fig. 6 of the paper
("Evolution of the Z-configuration under external loading").

The figure draws some frames of a :class:`vjm_pin.viz.viewer.Animation` side by side, from
the same geometry and configurations as the page (:meth:`~vjm_pin.viz.viewer.Animation.frame_bodies`):
link segments green where stable and red where unstable (the parts of the unstable mode, as
in the page), joint markers in their role colours, the unloaded robot in light grey, the
force at the end frame as an arrow (length ∝ |F| over the figure), and the critical frame
with a magenta ring around the end point and a magenta panel border. Each panel is the 2-D
projection onto the two world axes along which the drawn points spread most (the plane of a
planar chain), axes in mm, equal aspect, the same limits in every panel.

Only the link segments of :func:`vjm_pin.viz.viewer.chain_geometry` (cylinders or boxes) and
its joint spheres are drawn as such (plus a dotted cyan line where translational virtual springs
stacked at one point have moved apart, which the link geometry does not show); other geometry (meshes) is drawn as its origin point,
so build the animation on ``chain_geometry`` for a figure.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vjm_pin.exceptions import InputError

__all__ = ["SnapshotFigure", "pick_frames", "save_snapshots", "snapshot_figure"]

_AXES = "xyz"
_FORCE_COLOR = "#c89600"  # the page's yellow, darkened to show on white
_GHOST_COLOR = "#b8bcc8"
_CRITICAL_COLOR = "#e600e6"
_MAX_COLS = 4  # panels per row at most


@dataclass(frozen=True)
class SnapshotFigure:
    """A written snapshot figure (:func:`save_snapshots`).

    Attributes:
        path: The file written.
        frames: Animation frame index of each panel, in order.
        critical_frame: The critical frame (one of ``frames``), or None.
        plane: The two world axes of the projection, e.g. ``"xy"``.
    """

    path: str
    frames: tuple[int, ...]
    critical_frame: int | None
    plane: str


def pick_frames(n: int, count: int, critical: int | None = None) -> list[int]:
    """``count`` frame indices out of ``n``, evenly spread from the first to the last, with
    the ``critical`` frame among them (it replaces the nearest pick); fewer when ``n`` is
    smaller. Raises InputError for ``count < 1``."""
    if int(count) != count or count < 1:
        raise InputError(f"the number of snapshots must be a positive integer, got {count}")
    if n < 1:
        raise InputError("the animation has no frames")
    count = min(int(count), n)
    picks = [int(np.rint(v)) for v in np.linspace(0, n - 1, count)]
    if critical is not None and critical not in picks:
        inner = [t for t in range(len(picks)) if 0 < t < len(picks) - 1]
        if inner:  # the nearest pick that is neither the first nor the last frame
            picks[min(inner, key=lambda t: abs(picks[t] - critical))] = int(critical)
        elif count == 1:
            picks = [int(critical)]
        else:
            picks[-1] = int(critical)
    return sorted(set(picks))


def _segments(bodies):
    """(segments [(p, q, flag, rgba)], points [(p, rgba, size)]) of the drawn bodies."""
    import coal

    segs, pts = [], []
    for go, m, flag in bodies:
        g, rot, p = go.geometry, m[:3, :3], m[:3, 3]
        rgba = tuple(float(c) for c in go.meshColor)
        if isinstance(g, coal.Cylinder):
            h = float(g.halfLength) * rot[:, 2]
            segs.append((p - h, p + h, flag, rgba))
        elif isinstance(g, coal.Box):
            h = float(np.asarray(g.halfSide)[2]) * rot[:, 2]
            segs.append((p - h, p + h, flag, rgba))
        elif isinstance(g, coal.Sphere):
            pts.append((p, rgba, float(g.radius)))
        else:
            pts.append((p, rgba, 0.0))
    return segs, pts


def _spring_gaps(model, q) -> list[tuple[np.ndarray, np.ndarray]]:
    """Segments between joints that sit at one point in the model (a zero joint placement:
    the stacked virtual springs of a link) but apart in configuration ``q``: the deflection
    of translational springs, which the link geometry does not show."""
    import pinocchio as pin

    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(q, float))
    out = []
    for j in range(2, model.njoints):
        p = model.parents[j]
        if p == 0 or np.linalg.norm(model.jointPlacements[j].translation) > 1e-12:
            continue
        a, b = np.array(data.oMi[p].translation), np.array(data.oMi[j].translation)
        if np.linalg.norm(b - a) > 1e-9:
            out.append((a, b))
    return out


def _plane(points: np.ndarray) -> tuple[int, int]:
    """The two world axes along which ``points`` spread most (in x, y, z order)."""
    spread = points.max(axis=0) - points.min(axis=0)
    keep = sorted(np.argsort(-spread, kind="stable")[:2])
    return int(keep[0]), int(keep[1])


def _title(anim, k: int) -> str:
    parts = []
    if anim.slider is not None:
        sl = anim.slider
        parts.append(f"{sl['name']} = {sl['values'][k]:.4g} {sl['unit']}")
    if anim.forces is not None and not (anim.slider and anim.slider["name"] == "|F|"):
        parts.append(f"|F| = {float(np.linalg.norm(anim.forces[k])):.4g} N")
    if anim.stable is not None:
        parts.append("stable" if anim.stable[k] else "UNSTABLE")
    return "\n".join([", ".join(parts[:2])] + parts[2:]) if parts else f"frame {k}"


def snapshot_figure(anim, frames: Sequence[int], *, title: str = "", panel_size: float = 2.6):
    """A matplotlib Figure with one panel per frame index of ``anim`` (module docstring).

    Args:
        anim: A :class:`vjm_pin.viz.viewer.Animation` (best built on ``chain_geometry``).
        frames: Frame indices to draw, in panel order.
        title: Figure title (e.g. the model and the deformation scale).
        panel_size: Panel width and height, inches.

    Returns:
        (figure, plane) with ``plane`` the two world axes drawn, e.g. ``"xz"``. Panel ``i``
        is ``figure.axes[i]``; its title holds the frame's load and verdict.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    frames = [int(k) for k in frames]
    if not frames:
        raise InputError("no frames to draw")
    n = len(anim.frames)
    for k in frames:
        if not 0 <= k < n:
            raise InputError(f"frame {k} is outside 0..{n - 1}")
    lay = _layout(anim, frames)
    nrows = math.ceil(len(frames) / _MAX_COLS)
    ncols = math.ceil(len(frames) / nrows)
    height = panel_size * min(max(lay["hy"] / lay["hx"], 0.35), 1.4)
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(panel_size * ncols, (height + 0.55) * nrows + 0.7), squeeze=False
    )
    for a in axes.ravel()[len(frames):]:
        fig.delaxes(a)
    any_red = False
    for ax, k in zip(axes.ravel(), frames):
        any_red = _draw_panel(ax, anim, k, lay) or any_red
    handles = _legend_handles(anim, any_red, any(lay["gaps"].values()))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.5 / fig.get_figheight(), 1, 1))
    return fig, _AXES[lay["i"]] + _AXES[lay["j"]]


def _layout(anim, frames) -> dict:
    """What every panel shares: the drawn bodies per frame, the plane ``(i, j)``, the limits
    (centre ``cx, cy``, half sizes ``hx, hy``; m), the arrow scale."""
    drawn = {k: _segments(anim.frame_bodies(k)) for k in frames}
    gaps = {k: _spring_gaps(anim.model, anim.frames[k]) for k in frames}
    ghost = anim.ghost_bodies()
    ghost_segs = _segments([(go, m, None) for go, m in ghost])[0] if ghost else []
    pts = [p for segs, _ in drawn.values() for s in segs for p in s[:2]]
    pts += [d[0] for _, dots in drawn.values() for d in dots]
    pts += [p for s in ghost_segs for p in s[:2]]
    allp = np.array(pts) if pts else np.zeros((1, 3))
    i, j = _plane(allp)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = max(float(hi[i] - lo[i]), float(hi[j] - lo[j]), 1e-6)
    forces = anim.forces if anim.forces is not None else [np.zeros(3)]
    fmax = max(float(np.linalg.norm(f)) for f in forces)
    arrow = 0.25 * span
    pad = 0.08 * span + (arrow if fmax > 0 else 0.0)
    hx = 0.5 * float(hi[i] - lo[i]) + pad
    hy = max(0.5 * float(hi[j] - lo[j]) + pad, 0.3 * hx)
    return {
        "drawn": drawn, "gaps": gaps, "ghost": ghost_segs, "i": i, "j": j,
        "cx": 0.5 * (lo[i] + hi[i]), "cy": 0.5 * (lo[j] + hi[j]), "hx": max(hx, 0.3 * hy),
        "hy": hy, "fmax": fmax, "arrow": arrow, "center": np.mean(allp, axis=0),
    }  # fmt: skip


def _draw_panel(ax, anim, k: int, lay: dict) -> bool:
    """Draw frame ``k`` on ``ax`` (:func:`snapshot_figure`); True when something is red."""
    from vjm_pin.viz.viewer import STABLE_COLOR, STYLE_COLORS, UNSTABLE_COLOR

    i, j, mm = lay["i"], lay["j"], 1e3

    def line(p, q, **kw):
        ax.plot([p[i] * mm, q[i] * mm], [p[j] * mm, q[j] * mm], **kw)

    for p, q, _, _ in lay["ghost"]:
        line(p, q, color=_GHOST_COLOR, lw=1.2, ls="--", zorder=1)
    segs, dots = lay["drawn"][k]
    red = False
    for p, q, flag, rgba in segs:
        col = rgba if flag is None else (STABLE_COLOR if flag else UNSTABLE_COLOR)
        red = red or flag is False
        line(p, q, color=col[:3], lw=2.4, solid_capstyle="round", zorder=2, gid="link")
    for p, q in lay["gaps"][k]:
        line(p, q, color=STYLE_COLORS["spring"][:3], lw=1.0, ls=":", zorder=2)
    for p, rgba, r in dots:
        ax.plot([p[i] * mm], [p[j] * mm], "o", color=rgba[:3], alpha=max(rgba[3], 0.3),
                ms=5 if r > 0 else 3, zorder=3)
    end = anim.end_position(k)
    if end is not None and anim.forces is not None and lay["fmax"] > 0:
        f = np.asarray(anim.forces[k], float)
        fp = np.array([f[i], f[j]])
        if np.linalg.norm(fp) > 1e-12 * lay["fmax"]:
            d = fp / np.linalg.norm(fp) * lay["arrow"] * float(np.linalg.norm(f)) / lay["fmax"]
            e2, c2 = np.array([end[i], end[j]]), lay["center"][[i, j]]
            # a pull starts at the end point; a push towards the robot ends there
            tail = e2 - d if np.linalg.norm(e2 + d - c2) < np.linalg.norm(e2 - c2) else e2
            ax.annotate("", xy=((tail + d) * mm), xytext=(tail * mm), zorder=4,
                        arrowprops={"arrowstyle": "-|>", "color": _FORCE_COLOR, "lw": 1.6})
    crit = k == anim.critical_index
    if crit and end is not None:
        ax.plot([end[i] * mm], [end[j] * mm], "o", mfc="none", mec=_CRITICAL_COLOR, ms=13,
                mew=2, zorder=5)
    ax.set_title(("CRITICAL — " if crit else "") + _title(anim, k), fontsize=7.5,
                 color=_CRITICAL_COLOR if crit else "black")
    if crit:
        for sp in ax.spines.values():
            sp.set_edgecolor(_CRITICAL_COLOR)
            sp.set_linewidth(2.0)
    ax.set_xlim((lay["cx"] - lay["hx"]) * mm, (lay["cx"] + lay["hx"]) * mm)
    ax.set_ylim((lay["cy"] - lay["hy"]) * mm, (lay["cy"] + lay["hy"]) * mm)
    ax.set_aspect("equal")
    ax.set_xlabel(f"{_AXES[i]} (mm)", fontsize=7)
    ax.set_ylabel(f"{_AXES[j]} (mm)", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.grid(True, lw=0.3, alpha=0.5)
    return red


def _legend_handles(anim, any_red: bool, any_gap: bool) -> list:
    """The figure legend's entries (only what is drawn)."""
    from matplotlib.lines import Line2D

    from vjm_pin.viz.viewer import STABLE_COLOR, STYLE_COLORS, UNSTABLE_COLOR

    handles = [Line2D([], [], color=STABLE_COLOR[:3], lw=2.4, label="stable")]
    if any_red:
        handles.append(Line2D([], [], color=UNSTABLE_COLOR[:3], lw=2.4,
                              label="unstable (parts of the mode)"))
    handles.append(Line2D([], [], color=_GHOST_COLOR, lw=1.2, ls="--", label="unloaded"))
    if any_gap:
        handles.append(Line2D([], [], color=STYLE_COLORS["spring"][:3], lw=1.0, ls=":",
                              label="spring translation (link deflection)"))
    if anim.forces is not None:
        handles.append(Line2D([], [], color=_FORCE_COLOR, lw=1.6, label="force (length ∝ |F|)"))
    if anim.critical_index is not None:
        handles.append(Line2D([], [], color=_CRITICAL_COLOR, marker="o", mfc="none", ls="",
                              label="critical point"))
    return handles


def save_snapshots(
    anim, path: str | os.PathLike, *, count: int = 6, frames: Sequence[int] | None = None,
    title: str = "",
) -> SnapshotFigure:
    """Write the snapshot figure of ``anim`` to ``path`` (format from the extension:
    :data:`vjm_pin.outputs.PLOT_EXTENSIONS`), checked first and written atomically.

    ``frames`` are the frame indices drawn; default :func:`pick_frames` (``count`` of them,
    the critical frame among them).

    Raises:
        OutputError: the path cannot be written (extension, folder).
        InputError: ``count`` < 1 or a frame index out of range.
    """
    from vjm_pin.outputs import PLOT_EXTENSIONS, atomic_output, check_output

    out = check_output(path, PLOT_EXTENSIONS, what="figure")
    if frames is None:
        frames = pick_frames(len(anim.frames), count, anim.critical_index)
    import matplotlib.pyplot as plt

    fig, plane = snapshot_figure(anim, frames, title=title)
    try:
        with atomic_output(out) as tmp:
            fig.savefig(tmp, dpi=150, format=out.suffix[1:].lower())
    finally:
        plt.close(fig)
    crit = anim.critical_index if anim.critical_index in frames else None
    return SnapshotFigure(str(out), tuple(int(k) for k in frames), crit, plane)
