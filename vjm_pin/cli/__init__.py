"""The ``vjm-pin`` command line: a thin layer that parses, calls the library, formats.

Each command lives in its own module of this package with ``add_parser(subparsers)``
and ``run(args) -> int``. The contract of :func:`main` with the shell:

- exit 0 on success; a bad input (a :class:`~vjm_pin.exceptions.VjmError` or a usage
  error of the command line) prints one line ``vjm-pin: error: ...`` on stderr and exits
  with status 2, never a traceback; an analysis that fails on a valid input (no
  equilibrium, a singular stiffness, an equilibrium that fails its check, a wrench beyond
  the buckling load: :data:`ANALYSIS_FAILURES`) prints one line the same way and exits
  with status 3;
- Ctrl-C at any point (imports, parsing, computation) prints ``vjm-pin: interrupted`` on
  stderr and exits with status 130 (128 + SIGINT), no traceback;
- a stdout closed by the reader (``vjm-pin models | head -1``) ends the run quietly with
  status 0: the reader asked for no more output, which is not an error of the command;
- numeric options take negative numbers in every float form (``-1e-3``, ``-.5``, ``-inf``).

Output files are checked before the work starts and written atomically
(:mod:`vjm_pin.outputs`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
import warnings

#: Command modules, in the order ``--help`` lists them.
COMMANDS = ("demo", "analyze", "curve", "critical", "view", "map", "models", "schema")

#: Exit statuses of ``vjm-pin`` (documented in ``vjm-pin --help`` and the README).
EXIT_OK, EXIT_USAGE, EXIT_ANALYSIS, EXIT_INTERRUPTED = 0, 2, 3, 130

EPILOG = """exit status:
  0    success (an unstable equilibrium that was found is a result, not a failure)
  2    usage error or bad input (unknown model, malformed file, out-of-range option)
  3    analysis failure: no equilibrium, singular stiffness, an equilibrium that fails
       its check, a wrench beyond the buckling load
  130  interrupted (Ctrl-C)

examples:
  vjm-pin demo --out vjm-demo
  vjm-pin analyze paper-a-s --deflection -0.001 0 0 --json
  vjm-pin schema curve"""

#: A negative number as ``float()`` reads it: ``-1``, ``-1.5``, ``-.5``, ``-1.``, ``-1e-3``,
#: ``-1_000``, ``-inf``, ``-nan``. argparse's own matcher knows only plain decimals and takes
#: ``-1e-3`` for an option.
NEGATIVE_NUMBER = re.compile(
    r"^-(?:(?:\d[\d_]*(?:\.[\d_]*)?|\.\d[\d_]*)(?:[eE][-+]?\d+)?|inf(?:inity)?|nan)$",
    re.IGNORECASE,
)


class Parser(argparse.ArgumentParser):
    """ArgumentParser with the contract of :func:`main`: negative numbers in exponent form
    are values, not options, and a usage error is one line on stderr (exit 2).

    Subparsers made by ``add_subparsers().add_parser`` are of this class too (argparse
    uses the parent's class), so every command gets both.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str):
        command = self.prog.split(" ", 1)[1] if " " in self.prog else ""
        where = f"{command}: " if command else ""
        sys.stderr.write(f"vjm-pin: error: {where}{message} (see '{self.prog} --help')\n")
        raise UsageError(2)


class UsageError(SystemExit):
    """A usage error of the command line, already reported; :func:`main` returns 2 for it
    (``--help`` and ``--version`` keep argparse's ``SystemExit(0)``)."""


def version() -> str:
    """The installed distribution's version, else the package's ``__version__``."""
    from importlib import metadata

    try:
        return metadata.version("vjm_pin")
    except metadata.PackageNotFoundError:
        from vjm_pin import __version__

        return __version__


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="vjm-pin",
        description=(
            "Loaded-mode stiffness analysis of manipulators with passive joints (Virtual Joint Method, "
            "Pashkevich-Klimchik-Chablat 2011) on Pinocchio. Units are SI (m, rad, N, N·m) unless a "
            "command says otherwise. Output files (--plot, --html, --out) are checked before the "
            "work starts, written atomically, never over an input file, and replace an existing "
            "file of the same name. Start with 'vjm-pin demo'. Every --json output has a "
            "'version' and a 'units' field and follows the JSON Schema that 'vjm-pin schema "
            "COMMAND' prints."
        ),
        epilog=EPILOG,
    )
    from vjm_pin.cli.common import HelpFormatter, add_verbosity_options, examples_epilog

    parser.formatter_class = HelpFormatter
    add_verbosity_options(parser)
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"{__name__}.{name}":
                continue  # command not built yet
            raise
        mod.add_parser(sub)
        p = sub.choices[name]
        p.formatter_class = HelpFormatter
        p.epilog = examples_epilog(mod.EXAMPLES)
        add_verbosity_options(p, suppress=True)
    return parser


def analysis_failures() -> tuple:
    """The errors of an analysis that fails on a valid input (exit status 3)."""
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness

    return (NoEquilibrium, SingularStiffness)  # EquilibriumCheckError is a NoEquilibrium


def _run(argv) -> int:
    from vjm_pin.exceptions import VjmError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        print("\nTry 'vjm-pin demo' for the bundled example (Model C chain buckling).")
        return 0
    import time

    args._t0 = time.perf_counter()
    if getattr(args, "quiet", False):
        warnings.simplefilter("ignore")
    try:
        return int(args.func(args) or 0)
    except VjmError as e:
        msg = "; ".join(ln.strip() for ln in str(e).splitlines() if ln.strip())  # one line
        hint = _hint(e)
        if hint:
            msg += (" " if msg.endswith("?") else "; ") + hint
        print(f"vjm-pin: error: {msg}", file=sys.stderr)
        return EXIT_ANALYSIS if isinstance(e, analysis_failures()) else EXIT_USAGE


def _hint(e) -> str:
    """Where the command line lists the names an error did not find."""
    from vjm_pin.exceptions import AmbiguousFrame, UnknownRobot

    if isinstance(e, UnknownRobot):
        return "see 'vjm-pin models' and 'vjm-pin models --robots'"
    if isinstance(e, AmbiguousFrame):
        return "give it with --frame"
    return ""


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's final flush of a closed pipe is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # stdout is not a real file (captured)
        pass


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings as one line each on stderr (not the default two with source code)."""
    text = " ".join(str(message).split())
    where = f"{os.path.basename(str(filename))}:{lineno}"
    print(f"vjm-pin: warning: {text} ({category.__name__} at {where})", file=sys.stderr)


class _SigintWatch:
    """Record that SIGINT arrived while :func:`main` runs (then raise KeyboardInterrupt as
    Python's own handler does).

    Some libraries catch the KeyboardInterrupt raised inside them and raise another error
    (pydantic-core turns it into a ``SchemaError`` during an import): with the record, such
    an error is still reported as an interruption. Installed only in the main thread and
    only over Python's default handler; the previous handler is restored on exit.
    """

    def __init__(self):
        self.fired = False
        self._previous = None

    def _handler(self, signum, frame):
        self.fired = True
        raise KeyboardInterrupt

    def __enter__(self):
        import signal
        import threading

        main_thread = threading.current_thread() is threading.main_thread()
        if main_thread and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc):
        if self._previous is not None:
            import signal

            signal.signal(signal.SIGINT, self._previous)
        return False


def main(argv=None) -> int:
    """Entry point of the ``vjm-pin`` console script; returns the exit status (see the
    module docstring for the contract: 0, 2 on bad input, 3 on an analysis failure, 130 on
    Ctrl-C)."""
    watch = _SigintWatch()
    try:
        with watch:
            try:
                with warnings.catch_warnings():
                    warnings.showwarning = _show_warning
                    return _run(argv)
            except UsageError as e:
                return int(e.code)
            finally:
                if sys.stdout is not None:
                    sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:
        _silence_stdout()
        return 0
    except Exception:
        if watch.fired:  # a library turned the KeyboardInterrupt into another error
            return _interrupted()
        raise


def _interrupted() -> int:
    try:
        sys.stderr.write("vjm-pin: interrupted\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    return 130


if __name__ == "__main__":
    raise SystemExit(main())
