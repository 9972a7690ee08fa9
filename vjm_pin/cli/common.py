"""Helpers shared by the CLI commands: number parsing, output checks, JSON output, formatting."""

from __future__ import annotations

import json
import math

import numpy as np

from vjm_pin.exceptions import InputError


def finite_vector(values, name: str, sizes=(3, 6)) -> np.ndarray:
    """Floats from the command line; :class:`InputError` on NaN/inf or a count not in
    ``sizes``. 3 or 6 numbers (with 6 in ``sizes``) go through the library's one check,
    :func:`vjm_pin.model.task.task_vector` (3 numbers: the rotation part zero); other counts
    (one per task component) are returned as given."""
    from vjm_pin.model.task import task_vector

    v = np.asarray([float(x) for x in values], dtype=float)
    if v.size not in sizes:
        raise InputError(f"{name} needs {' or '.join(map(str, sizes))} numbers, got {v.size}")
    if v.size in (3, 6) and 6 in sizes:
        return task_vector(v, name=name, outside_task="keep")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{name} contains NaN or infinite values: {v.tolist()}")
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


def float_range(lo: float, hi: float):
    """An argparse ``type``: a finite number > 0 in ``[lo, hi]``; anything else is a usage
    error (one line, exit 2) before any work."""
    import argparse

    def number(text: str) -> float:
        v = positive_float(text)
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be from {lo:g} to {hi:g}, got {text}")
        return v

    return number


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
    from vjm_pin.model.registry import model_path

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
    from vjm_pin.outputs import check_output

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
    # (+ 0.0: a negative zero prints as 0, not -0)
    return "\n".join("  " + " ".join(f"{v + 0.0:{width}.4g}" for v in row) for row in np.asarray(m))


# ----------------------------------------------------------------------------- JSON vocabulary
#: Units of the quantities of every ``--json`` output (SI). The same key means the same quantity
#: in every command: ``stiffness`` is the 6×6 loaded Cartesian stiffness K_C, ``stiffness_along``
#: a scalar stiffness along a direction; ``wrench`` is a 6-vector (force, moment) and
#: ``deflection`` a 6-vector (translation, rotation vector) except where the object has a
#: ``direction`` (curves): there ``deflection`` and ``force`` are the scalars along it.
UNITS = {
    "deflection": "m (rotation components: rad)",
    "wrench": "N (moment components: N·m)",
    "force": "N (N·m along a rotational direction)",
    "stiffness": "N/m, N/rad, N·m/m, N·m/rad (6×6, rows and columns x y z rx ry rz, world axes)",
    "stiffness_along": "N/m (N·m/rad along a rotational direction)",
    "stiffness_before": "N/m (N·m/rad along a rotational direction)",
    "stiffness_after": "N/m (N·m/rad along a rotational direction)",
    "force_control_margin": "N/m (N·m/rad along a rotational direction)",
    "q": "rad (prismatic joints: m)",
    "theta": "rad (prismatic springs: m)",
    "energy": "J",
    "payload": "kg",
    "direction": "1 (unit vector, world axes)",
    "compliance_eigenvalues": "m/N",
    "stability_eigenvalues": "mixed (eigenvalues of an energy Hessian: only their sign matters)",
}


def envelope(command: str, body: dict, units=None) -> dict:
    """The JSON object of ``command``: ``version`` (package version), ``command``, ``units``
    (:data:`UNITS` restricted to the names ``units``, all of it for None, or ``units`` itself
    when it is a dict) first, then ``body``."""
    from vjm_pin.cli import version

    if isinstance(units, dict):
        names = units
    else:
        names = UNITS if units is None else {k: UNITS[k] for k in units}
    return {"version": version(), "command": command, "units": dict(names), **body}


# ----------------------------------------------------------------------------- help, verbosity
import argparse as _argparse


class HelpFormatter(_argparse.RawDescriptionHelpFormatter):
    """Wraps the description like argparse's default, keeps indented lines (the examples of
    the epilog) as written."""

    def _fill_text(self, text, width, indent):
        import textwrap

        out = []
        for para in text.split("\n\n"):
            lines = para.splitlines()
            if any(ln.startswith(" ") for ln in lines) or para.rstrip().endswith(":"):
                out.append("\n".join(indent + ln for ln in lines))
            else:
                out.append(
                    textwrap.fill(" ".join(para.split()), width, initial_indent=indent, subsequent_indent=indent)
                )
        return "\n\n".join(out)


def examples_epilog(examples) -> str:
    """The ``examples:`` epilog of a command: one command line per entry."""
    return "examples:\n" + "\n".join(f"  {ex}" for ex in examples)


def add_verbosity_options(parser, suppress: bool = False) -> None:
    """``--quiet`` and ``--verbose`` (global: before or after the command name).
    On the subcommands the defaults are suppressed so they do not undo the global value."""
    default = _argparse.SUPPRESS if suppress else False
    g = parser.add_mutually_exclusive_group()
    g.add_argument(
        "--quiet", action="store_true", default=default,
        help="nothing on stderr but errors: no progress bar, no warning, no summary",
    )
    g.add_argument(
        "--verbose", action="store_true", default=default,
        help="a one-line summary on stderr at the end (what ran, how long)",
    )


def quiet(args) -> bool:
    return bool(getattr(args, "quiet", False))


def verbose(args) -> bool:
    return bool(getattr(args, "verbose", False)) and not quiet(args)


def show_progress(args) -> bool:
    """Progress bars: on a terminal only, never with ``--quiet`` (or ``--no-progress``)."""
    import sys

    if quiet(args) or getattr(args, "no_progress", False):
        return False
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


class Progress:
    """A tqdm bar on stderr when :func:`show_progress`, else nothing. ``update(done, total)``
    is the callback of the curve tracers; ``close()`` ends the bar."""

    def __init__(self, args, total: int | None, desc: str, unit: str = "pt"):
        self.bar = None
        if show_progress(args):
            import sys

            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False)

    def update(self, done, total=None) -> None:
        if self.bar is not None:
            if total is not None:
                self.bar.total = total
            self.bar.n = done
            self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def summary(args, text: str) -> None:
    """With ``--verbose``: one line ``vjm-pin: COMMAND: TEXT (N.N s)`` on stderr."""
    import sys
    import time

    if verbose(args):
        t0 = getattr(args, "_t0", None)
        took = f" ({time.perf_counter() - t0:.1f} s)" if t0 is not None else ""
        print(f"vjm-pin: {args.command}: {text}{took}", file=sys.stderr)


LOAD_HELP = (
    "dead load at a frame of the model: FRAME FX FY FZ [MX MY MZ] (N, N·m, world axes; force at the "
    "frame's origin); repeat for several loads"
)


def add_load_option(parser) -> None:
    """``--load FRAME FX FY FZ [MX MY MZ]`` (repeatable), one spelling for every command."""
    parser.add_argument(
        "--load",
        nargs="+",
        action="append",
        metavar="FRAME_FX_FY_FZ",
        default=None,
        help=LOAD_HELP,
    )


def add_dead_load_options(parser) -> None:
    """``--gravity`` (every link's weight) and ``--load`` (:func:`add_load_option`), in that order,
    as ``analyze``, ``curve`` and ``critical`` take them."""
    parser.add_argument(
        "--gravity",
        action="store_true",
        help="load every link with its weight at its centre of mass (URDF inertials; 9.80665 m/s² along −z)",
    )
    add_load_option(parser)


def add_subdivide_option(parser) -> None:
    """``--subdivide K`` (1 to :data:`MAX_SUBDIVIDE`, default 1): the model's beam links split into
    ``K`` sub-links when it is loaded."""
    parser.add_argument(
        "--subdivide",
        type=int_range(1, MAX_SUBDIVIDE),
        default=1,
        metavar="K",
        help="split every beam link into K sub-links (models whose springs keep <vjm:beam>; "
        f"K from 1 to {MAX_SUBDIVIDE})",
    )


def add_model_direction(parser) -> None:
    """``MODEL`` (a VJM URDF path or a bundled name) and the required ``--direction`` of the end
    deflection, as ``curve`` and ``critical`` take them (checked by :func:`direction_vector`)."""
    parser.add_argument(
        "model", metavar="MODEL", help="VJM URDF path or bundled model name (see 'vjm-pin models')"
    )
    parser.add_argument(
        "--direction",
        nargs="+",
        type=float,
        required=True,
        metavar="D",
        help="DX DY DZ [RX RY RZ]: direction of the end deflection, world axes (normalised)",
    )


def loads_from_args(args) -> tuple:
    """The :class:`~vjm_pin.kinematics.dead_loads.Load` tuple of ``--load`` (empty when absent).

    Raises:
        InputError: a wrong count or a word that is not a finite number (one line).
    """
    from vjm_pin.kinematics.dead_loads import parse_load_args

    return parse_load_args(getattr(args, "load", None))
