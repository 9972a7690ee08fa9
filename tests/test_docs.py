"""The documentation: the site builds with warnings as errors, the generated CLI reference
covers the whole parser, and the paths the README links to exist."""

from __future__ import annotations

import argparse
import html
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
HOOK = ROOT / "docs" / "_hooks" / "cli_reference.py"


def _hook():
    spec = importlib.util.spec_from_file_location("cli_reference", HOOK)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return dict(a.choices)
    return {}


def test_cli_reference_covers_every_command_and_option():
    from vjm_pin.cli import build_parser

    md = _hook().cli_markdown()
    commands = _subparsers(build_parser())
    assert commands, "the parser has no sub-commands"
    for name, sub in commands.items():
        section = re.search(
            rf"^## `vjm-pin {re.escape(name)}`$(.*?)(?=^## |\Z)", md, re.DOTALL | re.MULTILINE
        )
        assert section, f"no section for 'vjm-pin {name}'"
        body = section.group(1)
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            for opt in action.option_strings or [action.metavar or action.dest]:
                assert f"`{opt}" in body, (
                    f"'vjm-pin {name}': {opt} missing from the generated reference"
                )


def test_readme_links_into_docs_exist():
    readme = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\(((?:docs|examples)/[^)#\s]+)", readme)
    assert links, "the README links to no documentation page"
    missing = [p for p in links if not (ROOT / p).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_site_builds_strict(tmp_path):
    pytest.importorskip(
        "mkdocs", reason="the docs packages are not installed (pip install -e '.[docs]')"
    )
    pytest.importorskip("mkdocstrings")
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--site-dir",
            str(site),
            "--config-file",
            str(ROOT / "mkdocs.yml"),
        ],
        check=False,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode == 0, (
        f"mkdocs build --strict failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    )
    # The generated pages are there and hold what they are generated from.
    cli = (site / "cli" / "index.html").read_text()
    from vjm_pin.cli import build_parser

    for name in _subparsers(build_parser()):
        assert f"vjm-pin {name}" in cli, f"CLI page lacks 'vjm-pin {name}'"
    solver = (site / "api" / "solver" / "index.html").read_text()
    assert 'id="vjm_pin.solver.EquilibriumSolver"' in solver
    analysis = (site / "api" / "analysis" / "index.html").read_text()
    assert 'id="vjm_pin.analysis.curve.trace_curve"' in analysis
    examples = (site / "examples" / "index.html").read_text()
    for script in sorted((ROOT / "examples").glob("*.py")):
        first = script.read_text().splitlines()[0].strip('"')  # the docstring's first line
        assert html.escape(first, quote=False) in examples, (
            f"examples page does not include {script.name}"
        )
    for page in (
        "stiffness_values",
        "concepts",
        "getting_started",
        "performance",
        "paper_reproduction",
        "orthoglide",
        "format",
    ):
        assert (site / page / "index.html").is_file(), f"page {page} not built"


def test_getting_started_python_block_runs(capsys):
    """The Python block of the getting-started page runs as written and shows what it says:
    Model A buckles at Kθ/L = 1 N, and the end held 0.2 m in is stable."""
    text = (ROOT / "docs" / "getting_started.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.DOTALL)
    assert len(blocks) == 1, "expected one Python block on the getting-started page"
    ns: dict = {}
    exec(compile(blocks[0], "getting_started.md", "exec"), ns)  # noqa: S102 (our own page)
    assert ns["eq"].stable and ns["eq"].stable_end_held
    assert ns["eq"].wrench[0] < 0  # pushing the end towards the base needs a force along −x
    assert ns["curve"].critical[0].force == pytest.approx(1.0, rel=1e-4)


def test_cli_reference_shows_exit_statuses():
    """The generated page carries the top-level epilog of ``vjm-pin --help``: each exit status
    (0 ok, 2 usage/input, 3 analysis failure, 130 interrupted) on a line of its own."""
    from vjm_pin import cli

    md = _hook().cli_markdown()
    section = re.search(r"^## Exit status and examples$(.*?)(?=^## )", md, re.DOTALL | re.MULTILINE)
    assert section, "no exit-status section on the CLI page"
    body = section.group(1)
    assert cli.EPILOG.strip() in body
    for code in (cli.EXIT_OK, cli.EXIT_USAGE, cli.EXIT_ANALYSIS, cli.EXIT_INTERRUPTED):
        assert re.search(rf"^  {code}\s+\S", body, re.MULTILINE), f"exit status {code} missing"
