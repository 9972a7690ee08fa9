"""The ``vjm-pin`` command line: a thin layer that parses, calls the library, formats.

Each command lives in its own module of this package with ``add_parser(subparsers)``
and ``run(args) -> int``. Errors of vjm_pin (:class:`~vjm_pin.exceptions.VjmError`)
print one line ``vjm-pin: error: ...`` on stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Command modules, in the order ``--help`` lists them.
COMMANDS = ("demo", "analyze", "curve", "view", "map", "models")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vjm-pin",
        description=(
            "Loaded-mode stiffness analysis of manipulators with passive joints (Virtual Joint Method, "
            "Pashkevich-Klimchik-Chablat 2011) on Pinocchio. Units are SI (m, rad, N, N·m) unless a "
            "command says otherwise. Start with 'vjm-pin demo'."
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"{__name__}.{name}":
                continue  # command not built yet
            raise
        mod.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``vjm-pin`` console script; returns the exit status."""
    from ..exceptions import VjmError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        print("\nTry 'vjm-pin demo' for the bundled example (Model C chain buckling).")
        return 0
    try:
        return int(args.func(args) or 0)
    except VjmError as e:
        print(f"vjm-pin: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
