"""Speed paths of the mechanism core (issue 14): the eq. (16) contractions in screw form from the
Jacobians (closures, task frame, dead loads) against Pinocchio's kinematic Hessians, and the stall
cut that makes an unreachable held deflection fail sooner."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from tests.mechanisms import spatial_rssr
from vjm_pin.exceptions import NoEquilibrium
from vjm_pin.kinematics.closures import ClosureSet
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import DESCENT_ITER_FACTOR, MechanismSolver


def _orthoglide_loop():
    return resolve_model("orthoglide-loop-q3")


def _random_x(vm, rng, size=2e-2):
    x = vm.reference.copy()
    x += size * rng.standard_normal(x.size)
    return x


@pytest.mark.parametrize("which", ["orthoglide-loop", "rssr-weld"])
def test_closure_hessian_in_screw_form_equals_the_kinematic_hessian_contraction(which):
    vm = _orthoglide_loop() if which == "orthoglide-loop" else spatial_rssr(3, weld=True, task=("x", "y", "z"))[1]
    rng = np.random.default_rng(7)
    screw, tensor = ClosureSet(vm, screw=True), ClosureSet(vm)
    assert screw.screw and not tensor.screw
    for _ in range(3):
        x = _random_x(vm, rng)
        lam = rng.standard_normal(screw.n_rows) * 1e3
        a, b = screw.evaluate(x).hessian(lam), tensor.evaluate(x).hessian(lam)
        assert np.abs(a - b).max() <= 1e-11 * np.abs(b).max()
        # the block form: zero outside the joints that move the closure's frames
        st = screw.evaluate(x)
        lam6 = np.zeros(6)
        lam6[list(st.frames[0].closure.indices)] = lam[: len(st.frames[0].closure.indices)]
        cols, block = st.frames[0].hessian_block(lam6)
        full = tensor.evaluate(x).frames[0].hessian(lam6)
        assert np.abs(full[np.ix_(cols, cols)] - block).max() <= 1e-11 * np.abs(full).max()
        rest = np.ones(full.shape, bool)
        rest[np.ix_(cols, cols)] = False
        assert not np.any(full[rest])


def test_mechanism_linearization_in_screw_form_with_a_dead_load_equals_the_tensor_form():
    _, vm = spatial_rssr(5, weld=True, task=("x", "y", "z"))
    loads = (Load("link2", np.array([3.0, -2.0, 5.0, 0.4, -0.1, 0.2])),)
    ms = MechanismSolver(vm, loads)
    assert ms._screw
    ref = copy.copy(ms)
    ref._screw = False
    ref.closures = ClosureSet(vm, frames=ms.frames)
    rng = np.random.default_rng(11)
    for hrows in ([0, 1], []):
        x = _random_x(vm, rng)
        w = np.array([4.0, -1.0, 2.0, 0.0, 0.0, 0.0])
        a = ms.linearize(x, hrows, w)
        ms.frames._last = None
        b = ref.linearize(x, hrows, w)
        assert np.abs(a.hessian - b.hessian).max() <= 1e-11 * np.abs(b.hessian).max()
    assert not MechanismSolver(vm, gravity=(0.0, 0.0, -9.81))._screw  # link weights: Pinocchio's tensors


def test_an_unreachable_held_deflection_fails_with_the_same_error_after_fewer_iterations():
    """The four-bar cannot move its coupler point 5 m: the descents stall (no merit decrease, the
    held row's residual stays ~5 m) and give up instead of spending their whole budgets."""
    vm = resolve_model("four-bar")
    ms = MechanismSolver(vm)
    with pytest.raises(NoEquilibrium, match="no equilibrium of the mechanism found") as err:
        ms.solve(deflection=[5.0, 0.0, 0.0])
    res = err.value.result
    assert not res.converged and res.residuals["position"] > 4.0
    # without the stall cut: 480 descent + 8 × 60 continuation iterations
    budget = DESCENT_ITER_FACTOR * ms.max_iter + 8 * ms.max_iter
    assert res.iterations < 0.6 * budget
    # a reachable held deflection is still found, and is an equilibrium
    ok = ms.solve(deflection=[0.01, 0.0, 0.0])
    assert ok.converged and ok.deflection[0] == pytest.approx(0.01, abs=1e-9)
