"""The CLI in process: analyze --json has the documented keys and agrees with the library."""

import json

import numpy as np
import pytest

from vjm_pin import EquilibriumSolver, loaded_stiffness
from vjm_pin.cli import main
from vjm_pin.model.registry import resolve_model

KEYS = {"converged", "iterations", "wrench", "deflection", "stable", "stability_eigenvalues", "stiffness",
        "stiffness_unloaded", "q", "theta", "residual"}


def test_analyze_json_model_a(capsys):
    assert main(["analyze", "paper-a-s", "--deflection", "-0.2", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    phi = np.arccos(1 - 0.2 / 2)
    assert -out["wrench"][0] == pytest.approx(phi / np.sin(phi), rel=1e-6)
    assert out["converged"] and out["stable"]
    assert set(out["q"]) == {"base_z"} and set(out["theta"]) == {"qa1", "qa2"}
    k = np.array(out["stiffness"])
    assert k.shape == (6, 6) and np.all(k[2:] == 0) and np.all(k[:, 2:] == 0)
    vm = resolve_model("paper-a-s")
    res = EquilibriumSolver(vm).solve([-0.2, 0, 0])
    assert np.allclose(k, loaded_stiffness(vm, res).stiffness, rtol=1e-8, atol=1e-12)
    # rigid straight chain: unloaded stiffness is infinite along x, and the output says so
    assert out["stiffness_unloaded"] is None and "infinite" in out["stiffness_unloaded_note"]


def test_analyze_human_output(capsys):
    assert main(["analyze", "paper-c-s", "--deflection", "-0.001", "0", "0"]) == 0
    out = capsys.readouterr().out
    assert "stable" in out and "loaded stiffness" in out and "N/m" in out


def test_models_lists_bundled(capsys):
    assert main(["models", "--json"]) == 0
    names = json.loads(capsys.readouterr().out)["models"]
    assert "paper-a-s" in names and "paper-c-s" in names


def test_help_on_every_command(capsys):
    from vjm_pin.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in sub.choices:
        with pytest.raises(SystemExit) as e:
            main([name, "--help"])
        assert e.value.code == 0
        assert "usage" in capsys.readouterr().out


def test_curve_matrices_match_analyze_on_the_traced_state(capsys):
    """The loaded K_C at a curve point (curve --matrices) is the one of the traced equilibrium."""
    from vjm_pin.analysis.curve import trace_curve

    assert main(["curve", "paper-c-s", "--direction", "-1", "0", "0", "--max-deflection", "0.002", "--steps", "4",
                 "--matrices", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    vm = resolve_model("paper-c-s")
    curve = trace_curve(vm, [-1, 0, 0], 0.002, 4)
    last = curve.points[-1]
    k_cli = np.array(out["points"][-1]["stiffness"])
    assert np.allclose(k_cli, loaded_stiffness(vm, last.equilibrium).stiffness, rtol=1e-8, atol=1e-12)
    # the directional stiffness reported for the point is dᵀ K_C d
    assert out["points"][-1]["stiffness_along"] == pytest.approx(k_cli[0, 0], rel=1e-8)


def test_analyze_subdivide_refines_the_model(capsys):
    assert main(["analyze", "paper-c-s", "--deflection", "-0.0001", "0", "0", "--subdivide", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["theta"]) == 36  # 3 links × 2 sub-links × 6 springs
    assert main(["analyze", "paper-c-s", "--deflection", "0", "0", "0", "--subdivide", "0"]) == 2
