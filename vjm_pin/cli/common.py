"""Helpers shared by the CLI commands: number parsing, JSON output, formatting."""

from __future__ import annotations

import json
import math

import numpy as np

from ..exceptions import InputError


def finite_vector(values, name: str, sizes=(3, 6)) -> np.ndarray:
    """Floats from the command line; :class:`InputError` on NaN/inf or a wrong count."""
    v = np.asarray([float(x) for x in values], dtype=float)
    if v.size not in sizes:
        raise InputError(f"{name} needs {' or '.join(map(str, sizes))} numbers, got {v.size}")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{name} contains NaN or infinite values: {v.tolist()}")
    if v.size == 3 and 6 in sizes:
        v = np.concatenate([v, np.zeros(3)])
    return v


def to_jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def dump_json(obj) -> str:
    return json.dumps(to_jsonable(obj), indent=2)


def fmt_matrix(m: np.ndarray, width: int = 11) -> str:
    return "\n".join("  " + " ".join(f"{v:{width}.4g}" for v in row) for row in np.asarray(m))
