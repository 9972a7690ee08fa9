"""Helpers shared by the CLI commands: number parsing, output checks, JSON output, formatting."""

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


#: Largest ``--subdivide K``: every sub-link adds 6 spring joints and Pinocchio's data grow
#: with the square of the joint count (Model C, 3 links: K=10 runs in about a minute, K=30
#: needs ~15 GB, K=100 fails to allocate).
MAX_SUBDIVIDE = 10


def int_range(lo: int, hi: int | None = None):
    """An argparse ``type``: an integer in ``[lo, hi]``; out of range is a usage error
    (one line, exit 2) before any work."""
    import argparse

    def integer(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from None
        if v < lo or (hi is not None and v > hi):
            bounds = f"from {lo} to {hi}" if hi is not None else f"at least {lo}"
            raise argparse.ArgumentTypeError(f"must be an integer {bounds}, got {v}")
        return v

    return integer


def positive_float(text: str) -> float:
    """An argparse ``type``: a finite number > 0 (a usage error otherwise, before any work)."""
    import argparse

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def direction_vector(values, name: str) -> np.ndarray:
    """A direction (3 or 6 finite numbers, see :func:`finite_vector`) scaled so that its
    largest component is ±1: only its direction matters, and the scaling keeps the later
    normalisation free of overflow (``1e308 1e308 0``) and underflow (``1e-320 0 0``)."""
    v = finite_vector(values, name)
    m = float(np.max(np.abs(v)))
    return v / m if m > 0 else v


#: The sentence every output option's --help ends with.
OUTPUT_NOTE = "checked before the work starts, written atomically; an existing file is replaced"


def input_files(args) -> list:
    """The input files a command reads, from its ``args``: the model (a URDF path, or the file
    of a bundled model) and ``--springs``. Outputs must never be one of them."""
    from .parallel_cmds import model_path

    files = []
    model = getattr(args, "model", None)
    if model:
        files.append(model_path(model))
    springs = getattr(args, "springs", None)
    if springs:
        files.append(springs)
    return [f for f in files if f is not None]


def check_output_option(args, option: str, extensions):
    """Check the file of the output option ``option`` (``"--plot"``) before the work starts
    (:func:`vjm_pin.outputs.check_output`, the inputs being :func:`input_files`); returns its
    Path, or None when the option is not given. Raises :class:`~vjm_pin.exceptions.OutputError`."""
    from ..outputs import check_output

    value = getattr(args, option.lstrip("-").replace("-", "_"), None)
    if value is None:
        return None
    return check_output(value, extensions, what=option, inputs=input_files(args))


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
