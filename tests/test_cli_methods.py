"""``analyze --method`` on closed mechanisms and the range of ``curve --refine-tol``.

The CLI passes ``--method eq30|eq32|eq33`` to :meth:`MechanismSolver.stiffness`; each K_C
is compared with the bordered eq. (28) value computed here from the library."""

import json

import numpy as np
import pytest

from vjm_pin.cli import main
from vjm_pin.exceptions import SingularStiffness
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import MechanismSolver

CASES = {
    # a horizontal force at the top, dead loads on both column tops (below the 2k/h buckling load)
    "portal-frame": (["--wrench", "60", "0", "0", "--load", "top_left", "0", "0", "-50",
                      "--load", "top_right", "0", "0", "-50"],
                     {"wrench": [60.0, 0, 0, 0, 0, 0]},
                     (Load("top_left", [0, 0, -50.0]), Load("top_right", [0, 0, -50.0]))),
    # a held deflection of the coupler point (task x z; no dead loads): the loaded K_C with H ≠ 0
    "four-bar": (["--deflection", "0.002", "0", "-0.001"],
                 {"deflection": [0.002, 0, -0.001, 0, 0, 0]},
                 ()),
}


def _cli(capsys, model, argv, method):
    extra = [] if method is None else ["--method", method]
    assert main(["analyze", model, *argv, *extra, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("model", sorted(CASES))
@pytest.mark.parametrize("method", [None, "eq30", "eq32", "eq33"])
def test_analyze_method_on_a_closed_mechanism_agrees_with_eq28(capsys, model, method):
    argv, solve_kw, loads = CASES[model]
    vm = resolve_model(model)
    assert vm.closures
    solver = MechanismSolver(vm, loads)
    res = solver.solve(**{k: np.array(v, float) for k, v in solve_kw.items()})
    k28 = solver.stiffness(res, method="eq28").stiffness
    scale = np.abs(k28).max()
    assert scale > 0
    out = _cli(capsys, model, argv, method)
    assert out["converged"] is True
    assert np.allclose(out["deflection"], res.deflection, rtol=1e-9, atol=1e-12)
    try:
        solver.stiffness(res, method=method or "eq28")
    except SingularStiffness:
        # eq. 33 needs the springs alone to move the task frame: refused with the reason
        assert method == "eq33"
        assert out["stiffness"] is None and "eq. 33" in out["stiffness_note"]
        return
    k = np.array(out["stiffness"])
    assert k.shape == (6, 6)
    assert np.allclose(k, k28, rtol=1e-9, atol=1e-9 * scale)


def test_analyze_method_eq33_on_the_four_bar_gives_the_reason(capsys):
    """The four-bar's springs alone cannot move the coupler point in every task direction:
    eq. (33) is refused with that reason, not a wrong number, and the command still succeeds."""
    vm = resolve_model("four-bar")
    solver = MechanismSolver(vm)
    res = solver.solve(deflection=np.zeros(6))
    with pytest.raises(SingularStiffness, match="springs alone"):
        solver.stiffness(res, method="eq33")
    out = _cli(capsys, "four-bar", [], "eq33")
    assert out["stiffness"] is None and "springs alone" in out["stiffness_note"]


@pytest.mark.parametrize("value,ok", [("1e300", False), ("0.5", False), ("1e-12", False), ("1e-3", True)])
def test_curve_refine_tol_has_a_sane_range(capsys, value, ok):
    argv = ["curve", "paper-a-s", "--direction", "-1", "0", "0", "--max-deflection", "0.01", "--steps", "2",
            "--refine-tol", value, "--json"]
    if ok:
        assert main(argv) == 0
        assert json.loads(capsys.readouterr().out)["points"]
        return
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--refine-tol" in err[0] and "1e-10 to 0.1" in err[0]
