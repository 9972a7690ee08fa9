"""MkDocs hook: the CLI reference page, generated from ``vjm_pin.cli.build_parser()``.

Nothing is copied by hand: at every build the argparse parser is walked and ``cli.md`` is
written from it (usage, description, the top-level options and epilog — exit status,
examples —, one table of arguments per command, its epilog).
``cli_markdown()`` is importable so that the tests can check the page against the parser.
"""

from __future__ import annotations

import argparse
import html

PAGE = "cli.md"


def _cell(text: str) -> str:
    """``text`` made safe for one cell of a Markdown table (one line, no bars, no tags)."""
    return html.escape(" ".join(str(text).split()), quote=False).replace("|", "\\|")


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Name → parser of every sub-command, in the order ``--help`` lists them."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _signature(action: argparse.Action) -> str:
    """How the argument is written on the command line (``--steps STEPS``, ``MODEL``)."""
    fmt = argparse.HelpFormatter("vjm-pin")
    if not action.option_strings:
        return fmt._metavar_formatter(action, action.dest)(1)[0]
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    args = fmt._format_args(action, action.dest.upper())
    return ", ".join(f"{o} {args}" for o in action.option_strings)


def _help(action: argparse.Action) -> str:
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return argparse.HelpFormatter("vjm-pin")._expand_help(action)


def _command_section(name: str, parser: argparse.ArgumentParser, level: int) -> list[str]:
    out = [f"{'#' * level} `{parser.prog}`", ""]
    out += ["```text", parser.format_usage().strip(), "```", ""]
    if parser.description:
        out += [html.escape(" ".join(parser.description.split()), quote=False), ""]
    rows = [
        a
        for a in parser._actions
        if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
    ]
    if rows:
        out += ["| argument | required | default | description |", "|---|---|---|---|"]
        for a in rows:
            required = "yes" if (a.required or not a.option_strings) else ""
            default = (
                ""
                if a.default in (None, False, argparse.SUPPRESS) or a.nargs == 0
                else f"`{a.default}`"
            )
            if a.choices and not isinstance(a.choices, dict):
                choices = ", ".join(f"`{c}`" for c in a.choices)
                default = f"{default} (one of {choices})".strip()
            out.append(
                f"| `{_cell(_signature(a))}` | {required} | {_cell(default)} | {_cell(_help(a))} |"
            )
        out.append("")
    if parser.epilog:
        out += ["```text", parser.epilog.strip("\n"), "```", ""]
    return out


def cli_markdown() -> str:
    """The whole CLI reference page (Markdown)."""
    from vjm_pin.cli import build_parser

    parser = build_parser()
    lines = [
        "# Command-line reference",
        "",
        (
            "<!-- generated at build time by docs/_hooks/cli_reference.py from "
            "vjm_pin.cli.build_parser(); do not edit -->"
        ),
        "",
        (
            "Generated from the argparse parser of `vjm-pin` at every build of this site, so it "
            "always matches `vjm-pin COMMAND --help`. Units are SI (m, rad, N, N·m) unless an "
            "option says otherwise."
        ),
        "",
        "```text",
        parser.format_usage().strip(),
        "```",
        "",
    ]
    if parser.description:
        lines += [html.escape(" ".join(parser.description.split()), quote=False), ""]
    top = [
        a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)
    ]
    if top:
        lines += ["| option | description |", "|---|---|"]
        lines += [f"| `{_cell(_signature(a))}` | {_cell(_help(a))} |" for a in top]
        lines.append("")
    if parser.epilog:  # exit status and examples, as `vjm-pin --help` shows them
        lines += [
            "## Exit status and examples",
            "",
            "```text",
            parser.epilog.strip("\n"),
            "```",
            "",
        ]
    for name, sub in _subcommands(parser).items():
        lines += _command_section(name, sub, 2)
        for subname, subsub in _subcommands(sub).items():
            lines += _command_section(subname, subsub, 3)
    return "\n".join(lines) + "\n"


def _nav_paths(nav) -> set[str]:
    """Every page path named in a MkDocs ``nav`` (nested lists of dicts and strings)."""
    if isinstance(nav, str):
        return {nav}
    if isinstance(nav, dict):
        return set().union(*(_nav_paths(v) for v in nav.values())) if nav else set()
    if isinstance(nav, list):
        return set().union(*(_nav_paths(v) for v in nav)) if nav else set()
    return set()


def on_files(files, config):
    """Add the generated ``cli.md`` to the site (MkDocs ≥ 1.6 ``File.generated``), and list
    under "More" any page of docs/ that the ``nav`` of mkdocs.yml does not name yet (a page
    added by another change is then in the site rather than an omitted-file error)."""
    from mkdocs.structure.files import File

    files.append(File.generated(config, PAGE, content=cli_markdown()))
    nav = config.get("nav")
    if nav:
        named = _nav_paths(nav)
        extra = sorted(f.src_uri for f in files.documentation_pages() if f.src_uri not in named)
        if extra:
            nav.append({"More": extra})
    return files
