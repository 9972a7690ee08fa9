"""A curve's common sub-step in one compiled call (``vjm_pin.analysis.curve._Tracer._merged_step``:
the prediction, the corrector's one-call loop and the point on its QR, ``point_kernel._step_loops``)
against the same three compiled calls with Python between them (private switch ``curve._merged``):
every point, verdict and critical point bit for bit, through each of the merged call's exits (the
prediction's move rejected, the corrector giving way, converged, a point kernel that raises)."""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.analysis import curve as curve_mod
from vjm_pin.analysis import point_kernel as pk
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.equilibrium import EquilibriumSolver

#: Model C buckling (bifurcation, branch switch), the imperfect column of Model B, the knee of Model C Z.
CASES = [("paper-c-s", [-1, 0, 0], 0.004, 40), ("paper-b-z", [-1, 0, 0], 0.1, 20),
         ("paper-c-z", [-1, 0, 0], 0.012, 20)]


@pytest.fixture
def compiled(monkeypatch):
    if not pk.compiled() or pk.step() is None:
        pytest.skip("numba or the compiled kinematics are not available here")
    monkeypatch.setenv("VJM_PIN_JIT", "1")


def _phases(monkeypatch):
    """Count the merged call's exits (phase 0 rejected, 1 gave way, 2 converged) while tracing."""
    seen = {0: 0, 1: 0, 2: 0}
    original = pk.step()

    def counted(*args):
        out = original(*args)
        seen[out[0]] += 1
        return out

    monkeypatch.setattr(pk, "_step", counted)
    return seen


def _curves(vm, direction, md, steps, monkeypatch):
    """The curve merged (with its phase counts) and unmerged."""
    seen = _phases(monkeypatch)
    on = trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    counts = dict(seen)
    monkeypatch.setattr(curve_mod, "_merged", False)
    for k in seen:
        seen[k] = 0
    off = trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    assert not any(seen.values())  # the switch: no merged call
    monkeypatch.setattr(curve_mod, "_merged", True)
    return on, off, counts


def _assert_bitwise(on, off):
    assert len(on.points) == len(off.points)
    for p, q in zip(on.points, off.points):
        assert np.array_equal(p.equilibrium.x, q.equilibrium.x) and np.array_equal(p.wrench, q.wrench)
        assert p.deflection == q.deflection and p.force == q.force
        assert (p.stiffness, p.force_control_margin) == (q.stiffness, q.force_control_margin) or (
            np.isnan(p.stiffness) and np.isnan(q.stiffness))
        assert (p.stable, p.stable_end_held) == (q.stable, q.stable_end_held)
        assert p.equilibrium.iterations == q.equilibrium.iterations
        assert p.equilibrium.path == q.equilibrium.path
    assert [(c.kind, c.index, c.force, c.deflection, c.stiffness_before, c.force_after) for c in on.critical] == [
        (c.kind, c.index, c.force, c.deflection, c.stiffness_before, c.force_after) for c in off.critical]


@pytest.mark.parametrize("name,direction,md,steps", CASES, ids=[c[0] for c in CASES])
def test_merged_step_is_the_three_calls_bit_for_bit(name, direction, md, steps, compiled, monkeypatch):
    vm = resolve_model(name)
    on, off, seen = _curves(vm, direction, md, steps, monkeypatch)
    assert seen[2] >= steps  # the merged call took the common steps
    _assert_bitwise(on, off)
    assert on.critical or name != "paper-c-s"


def test_merged_step_where_the_corrector_gives_way(compiled, monkeypatch):
    """A corrector allowed one Newton iteration gives way on the steps that need more: the merged call
    hands its prediction to the general path, which then finds the same points as unmerged."""
    init = curve_mod._Tracer.__init__

    def short(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.cont._fast_max_iter = 1

    monkeypatch.setattr(curve_mod._Tracer, "__init__", short)
    vm = resolve_model("paper-c-s")
    on, off, seen = _curves(vm, [-1, 0, 0], 0.004, 40, monkeypatch)
    assert seen[1] > 0 and seen[2] > 0
    _assert_bitwise(on, off)


def test_merged_step_where_the_predicted_move_is_too_large(compiled, monkeypatch):
    """With a small move limit the merged call rejects predictions before its corrector (phase 0): the
    tracer halves those steps as unmerged."""
    monkeypatch.setattr(curve_mod, "MAX_MOVE", 2e-3)
    vm = resolve_model("paper-c-s")
    on, off, seen = _curves(vm, [-1, 0, 0], 0.004, 20, monkeypatch)
    assert seen[0] > 0 and seen[2] > 0
    _assert_bitwise(on, off)


def test_merged_step_falls_back_when_the_point_kernel_raises(compiled, monkeypatch):
    """numba's ``np.linalg`` raises on an exactly singular matrix: the merged call's step is run again
    unmerged (which declines that point), so a raising merged call changes nothing."""
    vm = resolve_model("paper-c-z")
    ref = trace_curve(vm, [-1, 0, 0], 0.012, steps=20, solver=EquilibriumSolver(vm))
    calls = {"n": 0}

    def raising(*args):
        calls["n"] += 1
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setattr(pk, "_step", raising)
    got = trace_curve(vm, [-1, 0, 0], 0.012, steps=20, solver=EquilibriumSolver(vm))
    assert calls["n"] >= 20
    _assert_bitwise(got, ref)


def test_merged_step_is_not_taken_in_numpy_or_for_a_rotating_target(monkeypatch):
    """The numpy kernels (``VJM_PIN_JIT=0``) keep the unmerged step (no compiled prediction: the merged
    step is never asked), and so does a direction with a rotation (its target rotation moves with the
    deflection: the merged call keeps the rotation fixed). No bundled serial model has a rotation in a
    task narrower than its chain, so the tracer's flag is cleared here: no merged call, the same curve."""
    asked = {"n": 0}
    original = curve_mod._Tracer._merged_step

    def counted(self, *args):
        asked["n"] += 1
        return original(self, *args)

    monkeypatch.setattr(curve_mod._Tracer, "_merged_step", counted)
    monkeypatch.setenv("VJM_PIN_JIT", "0")
    vm = resolve_model("paper-c-s")
    trace_curve(vm, [-1, 0, 0], 0.004, steps=10, solver=EquilibriumSolver(vm))
    assert asked["n"] == 0
    if not pk.compiled() or pk.step() is None:
        return
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    init = curve_mod._Tracer.__init__

    def rotating(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self._d_translation = False

    ref = trace_curve(vm, [-1, 0, 0], 0.004, steps=20, solver=EquilibriumSolver(vm))
    monkeypatch.setattr(curve_mod._Tracer, "__init__", rotating)
    seen = _phases(monkeypatch)
    got = trace_curve(vm, [-1, 0, 0], 0.004, steps=20, solver=EquilibriumSolver(vm))
    assert not any(seen.values()) and asked["n"] > 0
    _assert_bitwise(got, ref)
