"""The command-line interfaces: one JSON vocabulary (SI, ``version`` and ``units`` in every
object, the same keys for the same quantity and whatever the solver path), the JSON Schemas
shipped in the package, the examples of every ``--help``, the exit statuses, ``--quiet`` /
``--verbose`` and the progress bars.

Every ``--json`` output of the suite is also validated against its schema by the autouse
fixture of ``tests/conftest.py``.
"""

from __future__ import annotations

import csv
import importlib
import io
import json
import shlex
import sys

import jsonschema
import numpy as np
import pytest

from vjm_pin.cli import COMMANDS, build_parser, main, version
from vjm_pin.cli.schema import SCHEMAS, load_schema

V = jsonschema.Draft202012Validator


def run_json(capsys, argv) -> dict:
    """``main(argv)`` (with ``--json``): exit 0, one JSON object that names its command and
    validates against that command's schema."""
    assert main(argv) == 0, capsys.readouterr().err
    out = json.loads(capsys.readouterr().out)
    assert out["command"] == argv[0] and out["version"] == version()
    V(load_schema(argv[0])).validate(out)
    return out


# --------------------------------------------------------------------------- schemas
@pytest.mark.parametrize("name", SCHEMAS)
def test_schema_is_valid_and_printed_by_the_schema_command(name, capsys):
    s = load_schema(name)
    V.check_schema(s)
    assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert main(["schema", name]) == 0
    assert json.loads(capsys.readouterr().out) == s


def test_schema_of_an_unknown_command_is_a_usage_error(capsys):
    assert main(["schema", "demo"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "invalid choice" in err


def test_schemas_reject_a_drifted_vocabulary(capsys):
    """The schemas are strict: a renamed key or a missing unit field fails validation."""
    out = run_json(capsys, ["analyze", "paper-a-s", "--deflection", "-0.001", "0", "0", "--json"])
    s = load_schema("analyze")
    for drift in (
        lambda o: o.update(stiffness_matrix=o.pop("stiffness")),
        lambda o: o.pop("units"),
        lambda o: o.update(stiffness=3.0),  # a scalar where the 6×6 K_C belongs
        lambda o: o["weakest"].update(stiffness=o["weakest"].pop("stiffness_along")),
    ):
        bad = json.loads(json.dumps(out))
        drift(bad)
        assert not V(s).is_valid(bad)


# --------------------------------------------------------------------------- one vocabulary
def test_analyze_has_the_same_keys_on_every_solver_path_and_model_kind(capsys):
    runs = {
        "deflection": ["analyze", "paper-a-s", "--deflection", "-0.001", "0", "0"],
        "wrench": ["analyze", "ur5", "--wrench", "0", "0", "-100"],
        "link loads": ["analyze", "ur5", "--payload", "2", "--gravity"],
        "parallel": ["analyze", "orthoglide-q0", "--wrench", "-100", "-100", "-100"],
    }
    outs = {k: run_json(capsys, argv + ["--json"]) for k, argv in runs.items()}
    keys = {k: list(o) for k, o in outs.items()}
    assert all(v == keys["deflection"] for v in keys.values()), keys
    assert [o["parallel"] for o in outs.values()] == [False, False, False, True]
    for name, o in outs.items():
        k = np.asarray(o["stiffness"], float)
        assert k.shape == (6, 6), name  # "stiffness" is always the 6×6 K_C
        assert np.all(np.isfinite(k))
        assert {"deflection", "wrench", "stiffness", "stiffness_along"} <= set(o["units"])
        w = o["weakest"]
        # stiffness_along is the scalar 1/(dᵀ C d) of the 6×6 stiffness along the direction
        d = np.asarray(w["direction"], float)
        t = [i for i, c in enumerate(["x", "y", "z", "rx", "ry", "rz"]) if c in o["task"]]
        c = np.linalg.inv(k[np.ix_(t, t)])
        tr = [j for j, i in enumerate(t) if i < 3]
        assert 1.0 / (d[[t[j] for j in tr]] @ c[np.ix_(tr, tr)] @ d[[t[j] for j in tr]]) == pytest.approx(
            w["stiffness_along"], rel=1e-7
        ), name
    # SI: the wrench is the one asked for, in N
    assert np.allclose(outs["parallel"]["wrench"][:3], [-100, -100, -100], rtol=1e-6)
    assert outs["link loads"]["payload"] == 2.0


def test_curve_serial_and_parallel_points_and_critical_points_share_keys(capsys):
    serial = run_json(
        capsys,
        ["curve", "paper-a-s", "--direction", "-1", "0", "0", "--max-deflection", "0.01", "--steps", "6",
         "--all-branches", "--matrices", "--json"],
    )
    par = run_json(
        capsys,
        ["curve", "orthoglide-q1", "--direction", "-1", "-1", "-1", "--max-deflection", "0.001", "--steps", "2",
         "--free", "--matrices", "--json"],
    )
    assert list(serial) == list(par)
    assert serial["critical"] and par["critical"]
    assert list(serial["critical"][0]) == list(par["critical"][0])
    assert list(serial["points"][-1]) == list(par["points"][-1])
    assert serial["branches"] and list(serial["branches"][0][0]) == list(serial["points"][0])
    for out in (serial, par):
        d = np.asarray(out["direction"], float)
        for p in out["points"]:
            w = np.asarray(p["wrench"], float)
            assert p["force"] == pytest.approx(d @ w, rel=1e-9, abs=1e-9)  # force: the scalar dᵀF
            if p["stiffness"] is not None and p["stiffness_along"] is not None:
                k = np.asarray(p["stiffness"], float)
                if not out["parallel"]:  # serial: dᵀ K_C d (eq. 30) at the traced state
                    assert p["stiffness_along"] == pytest.approx(d @ k @ d, rel=1e-6)
                assert k.shape == (6, 6)


def test_map_json_and_csv_are_si(tmp_path, capsys):
    out = tmp_path / "m.csv"
    s = run_json(capsys, ["map", "ur5", "--samples", "5", "--backend", "serial", "--out", str(out), "--json"])
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    d = [np.linalg.norm([float(r["dx_m"]), float(r["dy_m"]), float(r["dz_m"])]) for r in rows]
    assert [float(r["deflection_m"]) for r in rows] == pytest.approx(d, rel=1e-12)
    rot = [np.linalg.norm([float(r[f"{a}_rad"]) for a in ("rx", "ry", "rz")]) for r in rows]
    assert [float(r["rotation_rad"]) for r in rows] == pytest.approx(rot, rel=1e-12)
    assert s["deflection"]["max"] == pytest.approx(max(d), rel=1e-12)  # m, as the CSV
    assert s["deflection"]["max"] < 0.01  # metres: a 100 N load bends a UR5 by < 1 cm
    k = [float(r["k_min_N_per_m"]) for r in rows]
    assert s["weakest_stiffness_along"]["min"] == pytest.approx(min(k), rel=1e-12)
    assert s["units"]["deflection"] == "m" and s["units"]["weakest_stiffness_along"] == "N/m"


def test_view_json_describes_the_true_equilibria_of_the_page(tmp_path, capsys):
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver

    html = tmp_path / "p.html"
    out = run_json(capsys, ["view", "paper-a-s", "--wrench", "2", "0.1", "0", "--html", str(html), "--json"])
    assert html.is_file() and out["mode"] == "wrench" and out["direction"] is None
    last = out["frames"][-1]
    assert last["load_factor"] == 1.0 and np.allclose(last["wrench"], [2, 0.1, 0, 0, 0, 0])
    ref = EquilibriumSolver(resolve_model("paper-a-s")).solve_wrench([2, 0.1, 0, 0, 0, 0])
    assert np.allclose(last["deflection"], ref.deflection, atol=1e-9)

    out = run_json(
        capsys,
        ["view", "paper-c-s", "--curve", "--direction", "-1", "0", "0", "--max-deflection", "0.05", "--steps", "20",
         "--html", str(html), "--json"],
    )
    k = out["critical_frame"]
    assert out["mode"] == "curve" and out["critical"] and out["frames"][k]["kind"] == "critical"
    assert out["frames"][k]["deflection"] == pytest.approx(out["critical"][0]["deflection"], rel=1e-3)
    d = np.asarray(out["direction"], float)
    assert all(f["force"] == pytest.approx(d @ np.asarray(f["wrench"]), abs=1e-9) for f in out["frames"])
    assert main(["view", "paper-a-s", "--wrench", "1", "0", "0", "--json"]) == 2  # --json needs --html
    assert "--html" in capsys.readouterr().err


def test_models_json_has_version_and_units(capsys):
    out = run_json(capsys, ["models", "--json"])
    assert "paper-c-s" in out["models"] and out["units"] == {}


# --------------------------------------------------------------------------- examples
def _examples():
    for name in COMMANDS:
        mod = importlib.import_module(f"vjm_pin.cli.{name}")
        for ex in mod.EXAMPLES:
            yield name, ex


EXAMPLES = list(_examples())


def _served(argv) -> bool:
    """``view`` without ``--html`` serves until Ctrl-C: parsed, not run."""
    return argv[0] == "view" and "--html" not in argv


@pytest.mark.parametrize("command", COMMANDS)
def test_every_help_ends_with_two_or_three_examples(command, capsys):
    mod = importlib.import_module(f"vjm_pin.cli.{command}")
    assert 2 <= len(mod.EXAMPLES) <= 3
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text
    tail = text[text.index("examples:"):]
    for ex in mod.EXAMPLES:
        assert f"  {ex}\n" in tail + "\n"


def test_top_help_documents_the_exit_statuses(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for code in ("0 ", "2 ", "3 ", "130 "):
        assert f"\n  {code}" in text
    assert "examples:" in text and "--quiet" in text and "--verbose" in text


@pytest.mark.parametrize("command,example", EXAMPLES, ids=[e for _, e in EXAMPLES])
def test_help_example_runs(command, example, tmp_path, monkeypatch, capsys):
    """Each example of each ``--help`` parses, and runs (exit 0) in a scratch folder; its
    ``--json`` output, if any, validates."""
    argv = shlex.split(example)
    assert argv[0] == "vjm-pin" and argv[1] == command
    args = build_parser().parse_args(argv[1:])
    assert args.command == command
    if _served(argv[1:]):
        return
    monkeypatch.chdir(tmp_path)
    assert main(argv[1:]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    if "--json" in argv or command == "schema":
        obj = json.loads(out)
        if command != "schema":
            V(load_schema(command)).validate(obj)


# --------------------------------------------------------------------------- exit statuses
def test_analysis_failures_exit_3_bad_input_exits_2(capsys):
    # no equilibrium: a deflection the chain cannot reach
    assert main(["analyze", "paper-a-s", "--deflection", "5", "0", "0"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.startswith("vjm-pin: error:") and "no equilibrium" in err and len(err.splitlines()) == 1
    # no equilibrium under a dead force far beyond the buckling load
    assert main(["analyze", "paper-c-s", "--wrench", "-1e9", "0", "0"]) == 3
    assert "no equilibrium" in capsys.readouterr().err
    # bad input stays 2
    assert main(["analyze", "paper-a-s", "--deflection", "1", "2"]) == 2
    assert main(["analyze", "no-such-model"]) == 2
    assert main(["curve", "paper-a-s", "--direction", "1", "0", "0"]) == 2  # usage
    capsys.readouterr()


def test_singular_stiffness_is_an_analysis_failure(monkeypatch, capsys):
    from vjm_pin.cli import curve as curve_cmd
    from vjm_pin.exceptions import SingularStiffness

    def boom(*a, **k):
        raise SingularStiffness("the matrix of eq. (28) is singular")

    monkeypatch.setattr(curve_cmd, "load_model", boom)
    assert main(["curve", "paper-a-s", "--direction", "-1", "0", "0", "--max-deflection", "0.01"]) == 3
    assert "singular" in capsys.readouterr().err


# --------------------------------------------------------------------------- quiet, verbose, progress
class _Tty(io.StringIO):
    def isatty(self):
        return True


CURVE = ["curve", "paper-a-s", "--direction", "-1", "0", "0", "--max-deflection", "0.01", "--steps", "8"]


def test_progress_bar_only_on_a_terminal_and_never_with_quiet(monkeypatch, capsys):
    assert main(CURVE) == 0
    assert capsys.readouterr().err == ""  # stderr is not a terminal: no bar, no summary
    for argv, bar in ((CURVE, True), (["--quiet"] + CURVE, False), (CURVE + ["--quiet"], False)):
        tty = _Tty()
        monkeypatch.setattr(sys, "stderr", tty)
        assert main(argv) == 0
        monkeypatch.undo()
        assert ("curve paper-a-s" in tty.getvalue()) is bar, (argv, tty.getvalue())
        capsys.readouterr()


def test_verbose_prints_one_summary_line(capsys):
    for argv in (["--verbose"] + CURVE, CURVE + ["--verbose"]):
        assert main(argv) == 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("vjm-pin: curve: paper-a-s:") and "critical" in err[0]
    assert main(["analyze", "paper-a-s", "--deflection", "-0.001", "0", "0", "--verbose", "--json"]) == 0
    cap = capsys.readouterr()
    json.loads(cap.out)  # stdout stays one JSON object
    assert cap.err.startswith("vjm-pin: analyze: paper-a-s: converged")
    assert main(["--quiet", "--verbose", "models"]) == 2  # one or the other
    capsys.readouterr()


def test_quiet_silences_warnings(capsys):
    import warnings

    from vjm_pin.cli import analyze as analyze_cmd

    real = analyze_cmd._summary

    def warn(args, out):
        warnings.warn("a library warning")
        real(args, out)

    argv = ["analyze", "paper-a-s", "--deflection", "-0.001", "0", "0"]
    try:
        analyze_cmd._summary = warn
        assert main(argv) == 0
        assert "vjm-pin: warning: a library warning" in capsys.readouterr().err
        assert main(["--quiet"] + argv) == 0
        assert capsys.readouterr().err == ""
    finally:
        analyze_cmd._summary = real


def test_the_suite_fixture_validates_every_json_output(capsys):
    """tests/conftest.py validates what ``--json`` prints (here: counted, and a drift fails)."""
    from tests.conftest import JSON_VALIDATED
    from vjm_pin.cli import common

    before = JSON_VALIDATED["models"]
    assert main(["models", "--json"]) == 0
    assert JSON_VALIDATED["models"] == before + 1
    with pytest.raises(jsonschema.ValidationError):
        common.dump_json({"version": "0", "command": "models", "units": {}, "modelz": {}})
    capsys.readouterr()
