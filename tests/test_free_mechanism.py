"""``free=True`` on a model that is a mechanism with only the direction held (the paper's
Model C column pinned at its base, Model A/B chains with passive joints): ``trace_curve`` and
``critical_load`` refuse it before any tracing with :class:`FreeMechanism` (CLI: one line,
exit 2), instead of tracing rounding noise or calling the start "rigid".

Checked against:
- re-solved equilibria: the motions named in the message really carry (to first order) no
  force: the column moved across the push by the mechanism solver with every task component held
  needs a lateral force of second order only, ~1e-6 of the axial one;
- the same run without the check (monkeypatched to a no-op): a well-posed free case (the same
  column under a lateral dead load, which stiffens the swing) traces and searches exactly as
  before.
"""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.analysis import critical as critical_mod
from vjm_pin.analysis import curve as curve_mod
from vjm_pin.analysis.critical import critical_load
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.cli import main
from vjm_pin.exceptions import FreeMechanism, InputError, SingularStiffness, VjmError
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

# (model, direction, the task components the zero-stiffness motion moves the end in, along d?)
CASES = [
    ("paper-c-s", [-1, 0, 0], ("y", "z"), False),  # the bug report: the column swings across d
    ("paper-c-s", [0, 1, 0], ("z",), False),
    ("paper-b-s", [0, -1, 0], ("y",), True),  # the chain swings along d: zero force to rounding
]


def _run(fn, name, d):
    return (
        trace_curve(resolve_model(name), d, 0.002, 10, free=True)
        if fn == "curve"
        else critical_load(resolve_model(name), d, free=True)
    )


@pytest.mark.parametrize("fn", ["curve", "critical"])
@pytest.mark.parametrize("name,d,comps,along", CASES)
def test_free_mechanism_is_refused_naming_model_and_components(fn, name, d, comps, along):
    with pytest.raises(FreeMechanism) as info:
        _run(fn, name, d)
    e = info.value
    assert isinstance(e, InputError) and isinstance(e, VjmError) and not isinstance(e, SingularStiffness)
    assert e.model == name and e.components == comps
    assert len(e.eigenvalues) >= 1 and np.all(np.abs(e.eigenvalues) <= 1e-6)
    msg = str(e)
    assert "\n" not in msg and f"'{name}'" in msg and f"in {', '.join(comps)}" in msg
    assert ("(along the direction)" in msg) is along
    assert "rigid" not in msg


def test_named_motions_carry_no_force_in_re_solved_equilibria():
    """The column of Model C S held in every task component and moved across the push by
    1e-4 m needs only a second-order lateral force: the zero stiffness the error names in y, z."""
    vm = resolve_model("paper-c-s")
    ms = MechanismSolver(vm)
    axial = ms.solve(deflection=np.array([-1e-4, 0, 0, 0, 0, 0]))
    assert axial.converged
    f_axial = abs(axial.wrench[0])
    assert f_axial > 0
    for i in (1, 2):
        t = np.zeros(6)
        t[i] = 1e-4
        res = ms.solve(deflection=t)
        assert res.converged
        assert abs(res.wrench[i]) < 1e-6 * f_axial


@pytest.mark.parametrize("cmd", ["curve", "critical"])
def test_cli_free_mechanism_is_one_line_exit_2(cmd, capsys):
    argv = [cmd, "paper-c-s", "--direction", "-1", "0", "0", "--free"]
    if cmd == "curve":
        argv += ["--max-deflection", "0.002", "--steps", "10"]
    assert main(argv) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("vjm-pin: error:")
    assert "'paper-c-s'" in err and "y, z" in err and "Traceback" not in err
    assert cap.out == ""


# --------------------------------------------------------------------------- well-posed free case
LOAD = [Load("end", [0.0, -0.01, 0.0])]  # a lateral dead load stiffens the swing: well posed


def _no_check(monkeypatch):
    monkeypatch.setattr(curve_mod, "check_free_start", lambda vm, tr, p0: None)
    monkeypatch.setattr(critical_mod, "check_free_start", lambda vm, tr, p0: None)


def test_well_posed_free_curve_is_unchanged(monkeypatch):
    vm = resolve_model("paper-c-s")
    got = trace_curve(vm, [-1, 0, 0], 1e-4, 2, free=True, loads=LOAD)
    _no_check(monkeypatch)
    ref = trace_curve(vm, [-1, 0, 0], 1e-4, 2, free=True, loads=LOAD)
    assert got.free and len(got.points) == len(ref.points) == 3
    assert len(got.critical) == len(ref.critical)
    for p, q in zip(got.points, ref.points):
        np.testing.assert_allclose(p.wrench, q.wrench, rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(p.equilibrium.x, q.equilibrium.x, rtol=1e-12, atol=1e-300)
        assert p.stable == q.stable and p.stable  # stable with only x held: not a mechanism
    # the points are the mechanism solver's equilibria with only x held (truth, not just sameness)
    ms = MechanismSolver(vm, LOAD)
    for p in got.points:
        res = ms.solve(deflection=p.deflection * np.array([-1.0, 0, 0, 0, 0, 0]), held=("x",))
        np.testing.assert_allclose(p.wrench, res.wrench, rtol=1e-7, atol=1e-9)


def test_well_posed_free_critical_load_is_unchanged(monkeypatch):
    vm = resolve_model("paper-c-s")
    got = critical_load(vm, [-1, 0, 0], free=True, loads=LOAD)
    _no_check(monkeypatch)
    ref = critical_load(vm, [-1, 0, 0], free=True, loads=LOAD)
    assert got.converged and got.kind == ref.kind
    assert got.force == pytest.approx(ref.force, rel=1e-12)
    assert got.deflection == pytest.approx(ref.deflection, rel=1e-12, abs=1e-300)
    np.testing.assert_allclose(got.x, ref.x, rtol=1e-12, atol=1e-300)
