"""A stiffness map (``vjm-pin map --out MAP.npz|csv``) as a coloured point cloud over the robot.

:func:`read_map` reads the files :class:`vjm_pin.analysis.maps.MapResult` writes (``to_npz``,
``to_csv``, or the streamed CSV: the same columns); :func:`map_points` turns one quantity of
it into the ``points`` option of :class:`vjm_pin.viz.viewer.Animation`: each pose's unloaded
end position ``p0`` (m, world) coloured by

- ``k_min``: the weakest translational stiffness (N/m), on a log scale, or
- ``deflection``: the end deflection |δ| under the map's load (m, shown in mm), linear,

with the viridis colour map (dark: low), poses that were not solved (status other than
``ok``, or a non-finite value) grey, and legend rows giving the colour of five values.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import InputError

__all__ = ["COLOR_BY", "MapCloud", "map_points", "read_map"]

#: The quantities a map can be coloured by: key → (label, unit shown, factor from SI, log scale).
COLOR_BY = {
    "k_min": ("k_min", "N/m", 1.0, True),
    "deflection": ("|δ|", "mm", 1e3, False),
}
NOT_SOLVED_COLOR = (0.55, 0.55, 0.55, 1.0)
LEGEND_STEPS = 5


@dataclass(frozen=True)
class MapCloud:
    """The columns of a map file needed to draw it.

    Attributes:
        path: The file read.
        frame: The mapped end frame (None when the file does not say: CSV).
        p0: (N, 3) unloaded end positions (m, world).
        k_min: (N,) weakest translational stiffness (N/m; NaN where not solved).
        deflection: (N,) end deflection |δ| (m; NaN where not solved).
        ok: (N,) the pose was solved (status ``ok``).
        model: The model name stored in the file, or None (CSV).
    """

    path: str
    frame: str | None
    p0: np.ndarray
    k_min: np.ndarray
    deflection: np.ndarray
    ok: np.ndarray
    model: str | None = None


def read_map(path) -> MapCloud:
    """Read a map file (``.npz`` or ``.csv``) written by ``vjm-pin map --out``.

    Raises:
        InputError: a missing or unreadable file, another extension, missing columns.
    """
    p = Path(path)
    if p.suffix not in (".npz", ".csv"):
        raise InputError(f"a map file ends in .npz or .csv, got '{p.name}'")
    if not p.is_file():
        raise InputError(f"no such map file '{p}'")
    try:
        if p.suffix == ".npz":
            return _read_npz(p)
        return _read_csv(p)
    except (OSError, ValueError, KeyError, csv.Error) as e:
        msg = " ".join(str(e).split())
        raise InputError(f"'{p}' is not a map written by 'vjm-pin map --out' or run_map ({msg})") from None


def _read_npz(p: Path) -> MapCloud:
    with np.load(p, allow_pickle=False) as z:
        p0 = np.asarray(z["p0"], float).reshape(-1, 3)
        d = np.asarray(z["deflection"], float).reshape(len(p0), -1)
        status = np.asarray(z["status"]).astype(str)
        return MapCloud(
            str(p),
            str(z["frame"]),
            p0,
            np.asarray(z["k_min"], float).ravel(),
            np.linalg.norm(d[:, :3], axis=1),
            status == "ok",
            str(z["model"]),
        )


def _read_csv(p: Path) -> MapCloud:
    with p.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ValueError("no rows")

    def col(name):
        if name not in rows[0]:
            raise KeyError(f"column '{name}' missing")
        return np.array([float(r[name]) if r[name] not in ("", None) else math.nan for r in rows])

    p0 = np.column_stack([col(f"p0_{a}_m") for a in "xyz"])
    if "status" not in rows[0]:
        raise KeyError("column 'status' missing")
    ok = np.array([r["status"] == "ok" for r in rows])
    return MapCloud(str(p), None, p0, col("k_min_N_per_m"), col("deflection_m"), ok)


def map_points(cloud: MapCloud, color_by: str = "k_min", size: float | None = None) -> dict:
    """The ``points`` option of :class:`vjm_pin.viz.viewer.Animation` for ``cloud`` coloured by
    ``color_by`` (:data:`COLOR_BY`), and its numbers: ``{"positions", "colors", "size",
    "legend", "range": (lo, hi) in SI or None, "not_solved": count}``. ``size`` (m) defaults
    to 1/40 of the cloud's extent (at least 2 mm)."""
    import matplotlib

    if color_by not in COLOR_BY:
        raise InputError(f"color_by must be one of {', '.join(COLOR_BY)}, got '{color_by}'")
    label, unit, factor, log = COLOR_BY[color_by]
    vals = np.asarray(getattr(cloud, color_by), float)
    good = cloud.ok & np.isfinite(vals) & ((vals > 0) if log else True)
    if not np.all(np.isfinite(cloud.p0)):
        raise InputError(f"map file '{cloud.path}' has non-finite end positions p0")
    cmap = matplotlib.colormaps["viridis"]
    colors = np.tile(np.array(NOT_SOLVED_COLOR[:3]), (len(vals), 1))
    legend = []
    rng = None
    if good.any():
        lo, hi = float(vals[good].min()), float(vals[good].max())
        rng = (lo, hi)

        def unit_pos(v):
            if hi <= lo:
                return np.full(np.shape(v), 0.5)
            if log:
                return (np.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo))
            return (np.asarray(v) - lo) / (hi - lo)

        colors[good] = cmap(unit_pos(vals[good]))[:, :3]
        steps = [lo] if hi <= lo else (
            np.geomspace(lo, hi, LEGEND_STEPS) if log else np.linspace(lo, hi, LEGEND_STEPS)
        )
        for v in steps[::-1]:
            rgba = tuple(float(c) for c in cmap(float(unit_pos(v)))[:3]) + (1.0,)
            legend.append((rgba, f"{label} = {v * factor:.3g} {unit}"))
    bad = int((~good).sum())
    if bad:
        legend.append((NOT_SOLVED_COLOR, f"not solved ({bad} of {len(vals)} poses)"))
    if size is None:
        ext = float(np.linalg.norm(cloud.p0.max(axis=0) - cloud.p0.min(axis=0)))
        size = max(ext / 40.0, 0.002)
    return {
        "positions": cloud.p0,
        "colors": np.clip(colors, 0.0, 1.0),
        "size": float(size),
        "legend": legend,
        "range": rng,
        "not_solved": bad,
    }
