"""Edge cases found by a sweep of the CLI over the bundled models (``vjm-pin critical`` first).

- A force-control margin within rounding of zero at the start (a zero-stiffness direction that
  stiffens with the deflection: Model B Π, B Z, C S, A Z along y) is a neutral start, not "already
  unstable": the search steps along the path from it, finds the critical point ``vjm-pin curve``
  finds (Model C S along y), or says that there is none (exit 3, one line).
- No headline "critical load" unless a critical point was located: a path that ends (Model A Z
  along y runs into the end of its reach, √3 − 1 m) or a branch that stays stable is one line
  "no critical point ...", exit 3, whatever ended the search; a search stopped by its budget
  prints NOT CONVERGED first, without a number that looks like a result.
- A linearised estimate that is rounding (a portal frame pushed sideways: nothing compresses)
  does not send the search to 10¹⁴ m.
"""

from __future__ import annotations

import functools
import json
import math
import re
import shlex
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from vjm_pin.cli import main
from vjm_pin.model.registry import bundled_models


def run(capsys, line: str):
    code = main(shlex.split(line))
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_error(err: str) -> str:
    lines = err.splitlines()
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert lines[0].startswith("vjm-pin: error: "), err
    return lines[0]


def numbers_after(text: str, word: str) -> float:
    m = re.search(re.escape(word) + r"\s*(-?[0-9.]+(?:e[-+]?[0-9]+)?)", text)
    assert m, (word, text)
    return float(m.group(1))


def k_theta_norm(name: str) -> float:
    from vjm_pin.cli.curve import load_model
    from vjm_pin.solver.stability import spectral_norm

    vm = load_model(name, 1)
    return spectral_norm(vm.K_theta)


# --------------------------------------------------------------------------- neutral start
@pytest.mark.parametrize("model", ["paper-b-pi", "paper-b-z"])
def test_neutral_start_is_not_called_unstable(capsys, model):
    code, out, err = run(capsys, f"critical {model} --direction 0 -1 0")
    line = one_line_error(err)
    assert code == 3 and out == ""
    assert "already unstable" not in line and "no critical point" in line
    # independently: the curve's margin at the start is zero to rounding (|μ| ≤ 1e-10·‖K_θ‖)
    # and stable (margin > 0) just after it, as the message's "stays stable" says
    code, out, _ = run(
        capsys, f"curve {model} --direction 0 -1 0 --max-deflection 0.01 --steps 4 --json"
    )
    assert code == 0
    pts = json.loads(out)["points"]
    assert abs(pts[0]["force_control_margin"]) <= 1e-10 * k_theta_norm(model)
    assert all(p["force_control_margin"] > 0 for p in pts[1:])
    assert "stays stable" in line


def test_neutral_start_finds_the_curves_critical_point(capsys):
    """Model C S pushed sideways: zero stiffness at the start, a bifurcation at ~42 mm that the
    curve finds on its own grid (its refinement: an independent location)."""
    code, out, err = run(capsys, "critical paper-c-s --direction 0 -1 0 --json")
    assert code == 0, err
    crit = json.loads(out)
    assert crit["converged"] and crit["kind"] == "bifurcation"
    code, out, _ = run(
        capsys, "curve paper-c-s --direction 0 -1 0 --max-deflection 0.05 --json"
    )
    assert code == 0
    ref = json.loads(out)["critical"]
    assert ref, "the curve finds a critical point in this range"
    assert crit["force"] == pytest.approx(ref[0]["force"], rel=1e-5)
    assert crit["deflection"] == pytest.approx(ref[0]["deflection"], rel=1e-5)
    assert crit["kind"] == ref[0]["kind"]
    # the text headline carries the same number (mN below 1 N)
    code, out, _ = run(capsys, "critical paper-c-s --direction 0 -1 0")
    assert code == 0
    assert numbers_after(out, "critical load") == pytest.approx(1e3 * crit["force"], rel=1e-7)


# --------------------------------------------------------------------------- no critical point
def _reach_along_minus_y(name: str) -> float:
    """The largest deflection along −y of the end of a planar chain of rigid links (joint
    origins along x, revolute about z) from its VJM positions: |p − s·e_y| = total length."""
    root = ET.parse(bundled_models()[name]).getroot()
    ns = {"vjm": "urn:vjm-pin:1"}
    pos = {j.get("name"): float(j.get("position")) for j in root.findall("vjm:joint", ns)}
    joints = root.findall("joint")
    angle, p, total = 0.0, np.zeros(2), 0.0
    for j in joints:
        o = j.find("origin")
        dx = float(o.get("xyz").split()[0]) if o is not None else 0.0
        p = p + dx * np.array([math.cos(angle), math.sin(angle)])
        total += dx
        angle += pos.get(j.get("name"), 0.0) if j.get("type") == "revolute" else 0.0
    return p[1] + math.sqrt(total**2 - p[0] ** 2)


def test_path_that_ends_at_the_reach_is_no_critical_point(capsys):
    """Model A Z along −y: zero stiffness at the start, then stiffening without a limit point up
    to the end of the reach (the chain straight); before: 'critical load 51.4 N' headline from
    the last point of a search that bracketed nothing."""
    code, out, err = run(capsys, "critical paper-a-z --direction 0 -1 0")
    line = one_line_error(err)
    assert code == 3 and out == ""
    assert "no critical point" in line and "critical load" not in line
    assert "could not be continued" in line
    reach = _reach_along_minus_y("paper-a-z")
    assert reach == pytest.approx(math.sqrt(3) - 1, rel=1e-6)  # the geometry, by hand
    s_end = numbers_after(line, "up to deflection")
    assert s_end <= reach * (1 + 1e-6) and s_end == pytest.approx(reach, rel=1e-3)


@pytest.mark.parametrize("model", ["portal-frame", "portal-frame-6", "paper-a-pi"])
def test_stable_branch_one_wording(capsys, model):
    """A branch that stays stable: the same one line whichever model, naming the range."""
    code, out, err = run(capsys, f"critical {model} --direction -1 0 0")
    line = one_line_error(err)
    assert code == 3 and out == ""
    assert line.startswith(
        "vjm-pin: error: no critical point: the followed branch stays stable under a force "
        "along the direction up to deflection"
    ), line
    assert "evaluations" not in line  # not a search that ran out of budget


def test_stable_branch_names_the_given_range(capsys):
    code, _, err = run(capsys, "critical portal-frame --direction -1 0 0 --max-deflection 0.3")
    line = one_line_error(err)
    assert code == 3
    assert numbers_after(line, "up to deflection") == pytest.approx(0.3, rel=1e-6)
    # independently: the curve over that range is stable under force control throughout
    code, out, _ = run(
        capsys, "curve portal-frame --direction -1 0 0 --max-deflection 0.3 --steps 6 --json"
    )
    data = json.loads(out)
    assert code == 0 and data["critical"] == []
    assert all(p["force_control_margin"] > 0 for p in data["points"])


def test_budget_stop_has_no_headline_number(capsys, monkeypatch):
    """A search stopped by its evaluation budget before any bracket: NOT CONVERGED first, the
    point reached described as such, exit 3; --json says converged false (schema-valid)."""
    from vjm_pin.analysis import critical as mod

    full = mod.critical_load(bundled_models_vm("paper-a-z"), [-1, 0, 0])
    monkeypatch.setattr(mod, "critical_load", functools.partial(mod.critical_load, max_iter=2))
    code, out, err = run(capsys, "critical paper-a-z --direction -1 0 0")
    assert code == 3 and "Traceback" not in err
    first = out.splitlines()[0]
    assert "NOT CONVERGED" in first and "critical load" not in out
    assert "not a located critical point" in out
    code, out, _ = run(capsys, "critical paper-a-z --direction -1 0 0 --json")
    data = json.loads(out)
    assert code == 3 and data["converged"] is False and data["message"]
    assert abs(data["force"] / full.force - 1) > 1e-6  # the point reached, not the answer


def bundled_models_vm(name):
    from vjm_pin.cli.curve import load_model

    return load_model(name, 1)


# --------------------------------------------------------------------------- other branches
def test_bracket_end_on_another_branch_is_not_a_critical_point(capsys):
    """The Orthoglide with coupled legs pushed down: the estimate's long first step lands on the
    straight (unstable) branch past a knee, while the followed branch bends away stably; before,
    the search narrowed that 'bracket' to nothing (NOT CONVERGED, location error 1.9). The
    curve (an independent tracer) finds no critical point in the default range and an imperfect
    one at ~46 mm, which critical finds when the range covers it."""
    code, _, err = run(capsys, "critical orthoglide-coupled-q3 --direction 0 0 -1")
    line = one_line_error(err)
    assert code == 3 and "stays stable" in line
    s_end = numbers_after(line, "up to deflection")
    code, out, _ = run(
        capsys,
        "curve orthoglide-coupled-q3 --direction 0 0 -1 --max-deflection 0.05 --steps 50 --json",
    )
    assert code == 0
    ref = json.loads(out)["critical"]
    assert len(ref) == 1 and ref[0]["deflection"] > s_end  # none inside critical's range
    code, out, err = run(
        capsys, "critical orthoglide-coupled-q3 --direction 0 0 -1 --max-deflection 0.05 --json"
    )
    assert code == 0, err
    crit = json.loads(out)
    assert crit["converged"] and crit["kind"] == ref[0]["kind"]
    assert crit["force"] == pytest.approx(ref[0]["force"], rel=1e-5)
    assert crit["deflection"] == pytest.approx(ref[0]["deflection"], rel=1e-5)


def test_end_of_reach_with_dead_loads_is_not_a_critical_point(capsys):
    """UR5 pushed down with gravity (the mechanism tracer): the path ends where the arm is
    stretched (~20.8 mm); before, tangent predictions chained past that end made a phantom
    'limit' of 3.5e9 N at 20.9 mm (NOT CONVERGED)."""
    code, out, err = run(capsys, "critical ur5 --direction 0 0 -1 --gravity")
    line = one_line_error(err)
    assert code == 3 and out == ""
    assert "could not be continued" in line and "critical load" not in line
    s_grav = numbers_after(line, "up to deflection")
    # independently: the curve with gravity reaches just short of it and no further
    code, _, _ = run(
        capsys, f"curve ur5 --direction 0 0 -1 --gravity --max-deflection {0.999 * s_grav} --steps 4"
    )
    assert code == 0
    code, _, err = run(
        capsys, f"curve ur5 --direction 0 0 -1 --gravity --max-deflection {1.01 * s_grav} --steps 4"
    )
    assert code == 3 and "no equilibrium" in one_line_error(err)


def test_sideways_path_out_of_reach_says_so(capsys):
    """Model A S (a straight chain of rigid links along x) moved along y with x held: no
    equilibrium at any deflection; 'analyze' says out of reach, and critical names the same."""
    code, _, err = run(capsys, "critical paper-a-s --direction 0 -1 0")
    line = one_line_error(err)
    assert code == 3 and line.startswith("vjm-pin: error: no critical point: ")
    assert "cannot be moved along the direction" in line
    code, _, err = run(capsys, "analyze paper-a-s --deflection 0 -0.003 0")
    assert code == 3 and "out of reach" in one_line_error(err)


def test_no_estimate_is_not_printed_as_nan(capsys):
    """A start of zero stiffness has no linearised estimate: the text says so, --json has null
    (not NaN), and the critical point is the curve's."""
    code, out, err = run(capsys, "critical paper-c-s --direction 0 -1 0")
    assert code == 0, err
    assert "nan" not in out.lower()
    code, out, _ = run(capsys, "critical paper-a-z --direction 0 -1 0 --max-deflection 0.5")
    assert "nan" not in (out + capsys.readouterr().err).lower()
