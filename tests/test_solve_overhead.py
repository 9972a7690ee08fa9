"""The per-solve shortcuts of EquilibriumSolver (issue 14) give what the general code gives.

Each shortcut of the hot path (input checks, target pose, result construction, BLAS thread
accessors) is compared with the general code it replaces, and every bad input it could let
through is still refused.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from vjm_pin.exceptions import InputError
from vjm_pin.kinematics.chain import displace
from vjm_pin.model.registry import resolve_model
from vjm_pin.model.task import task_vector
from vjm_pin.solver import equilibrium as eq
from vjm_pin.solver import threads


@pytest.fixture(scope="module")
def solver():
    return eq.EquilibriumSolver(resolve_model("paper-c-s"))


def test_unrotated_target_is_displace_bit_for_bit(solver):
    d = np.array([-2e-4, 1e-5, 3e-6, 0.0, 0.0, 0.0])
    p, r = displace(solver.p0, solver.r0, d)
    assert solver._r_unrotated.tobytes() == r.tobytes()
    assert (solver.p0 + d[:3]).tobytes() == p.tobytes()


def test_fast_result_construction_equals_the_dataclass(solver):
    r = solver.solve(np.array([-1e-4, 0, 0]))
    fields = {f.name: getattr(r, f.name) for f in dataclasses.fields(r)}
    plain = eq.EquilibriumResult(**fields)
    fast = eq._new_result(**fields)
    assert type(fast) is eq.EquilibriumResult
    assert all(getattr(fast, k) is getattr(plain, k) for k in fields)
    assert dataclasses.replace(fast, path="x").path == "x" and fast.path == r.path
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.path = "y"
    # the result's arrays are its own: q and theta are copies, not views of x
    assert not np.shares_memory(r.q, r.x) and not np.shares_memory(r.theta, r.x)


def test_vector6_shortcut_reads_as_task_vector(solver):
    v = np.array([-1e-4, 2e-5, 0.0, 0.0, 0.0, 0.0])
    got = solver._vector6(v, "deflection", "m, rad")
    ref = task_vector(v, solver.task, "deflection", "m, rad", task_sized=True, outside_task="keep")
    assert got.tobytes() == ref.tobytes() and not np.shares_memory(got, v)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_inputs_still_refused(solver, bad):
    x0 = solver.vm.reference.copy()
    x0[3] = bad
    with pytest.raises(InputError, match="x0 must be a finite"):
        solver.solve(np.array([-1e-4, 0, 0]), x0=x0)
    with pytest.raises(InputError, match="wrench0 contains NaN"):
        solver.solve(np.array([-1e-4, 0, 0]), wrench0=np.array([bad, 0.0, 0.0]))
    with pytest.raises(InputError, match="deflection contains NaN"):
        solver.solve(np.array([-1e-4, 0, 0, 0, bad, 0]))


def test_huge_finite_start_is_accepted(solver):
    x0 = np.full(solver.vm.model.nq, 1e308)  # finite (its sum is not)
    assert solver._start(x0).tobytes() == x0.tobytes()
    assert solver._task_wrench(np.full(6, 1e308)).tobytes() == np.full(3, 1e308).tobytes()


def test_deflection_outside_the_task_still_refused(solver):
    with pytest.raises(InputError, match="outside the task"):
        solver.solve(np.array([-1e-4, 0, 0, 0, 1e-3, 0]))


def test_blas_accessors_read_what_threadpoolctl_reads():
    ctl = threads._blas_controller()
    if ctl is None:
        pytest.skip("threadpoolctl cannot inspect the BLAS libraries here")
    got = [get() for get, _ in threads._accessors(ctl)]
    assert got == [lib.get_num_threads() for lib in ctl.lib_controllers]
    with threads.single_blas_thread():
        inside = [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]
    assert inside and all(n == 1 for n in inside)
    after = sorted(d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas")
    assert after == sorted(got)  # restored


def test_frozen_shortcut_equals_the_constructor_and_keeps_its_errors():
    from vjm_pin.solver.blocks import Blocks
    from vjm_pin.solver.stability import StabilityResult

    ev = np.array([-3.0, -1.0])
    a = eq._frozen(StabilityResult, stable=True, eigenvalues=ev, null_dim=2, tolerance=1e-9)
    b = StabilityResult(True, ev, 2, 1e-9)
    assert type(a) is StabilityResult and vars(a) == vars(b)
    z = np.zeros((1, 1))
    blk = eq._frozen(Blocks, J_theta=z, J_q=z, H_tt=z, H_tq=z, H_qt=z, H_qq=z, K_theta=z, state=None)
    assert blk.chain is None  # the default of the field not given
    with pytest.raises(TypeError):
        eq._frozen(StabilityResult, stable=True, eigenvalues=ev, null_dim=2, tolerance=1e-9, extra=1)
    with pytest.raises(TypeError):
        eq._frozen(StabilityResult, stable=True, eigenvalues=ev, null_dim=2, bogus=1)
    with pytest.raises(TypeError):
        eq._frozen(StabilityResult, stable=True)


def test_solver_objects_built_without_init_equal_the_constructors(solver):
    """The result, its verdict and the kept kinematic state of a warm solve (built by ``_built``,
    without ``__init__``) hold exactly the constructors' fields, in order, and stay frozen."""
    from vjm_pin.kinematics.chain import KinematicState
    from vjm_pin.solver.stability import StabilityResult

    first = solver.solve(np.array([-1e-4, 0, 0]))
    r = solver.solve(np.array([-1.1e-4, 0, 0]), x0=first.x, wrench0=first.wrench)
    assert r.path == "newton"  # the fast lane
    st = solver.kin._last[1]
    for obj, cls in ((r, eq.EquilibriumResult), (r.stability, StabilityResult), (st, KinematicState)):
        names = [f.name for f in dataclasses.fields(cls)]
        assert type(obj) is cls and list(vars(obj)) == names
        plain = cls(**vars(obj))
        assert all(getattr(plain, k) is getattr(obj, k) for k in names)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, names[0], None)
    assert r.checks == {} and r.checks is not first.checks


def test_kept_blocks_are_built_when_asked_and_equal_fresh_ones(solver):
    """A fast-path equilibrium keeps its Blocks lazily: built by the first evaluate_blocks at that
    point, then the same object, equal to an evaluation from scratch."""
    from vjm_pin.kinematics.chain import Kinematics
    from vjm_pin.solver.blocks import Blocks, evaluate_blocks

    r = solver.solve(np.array([-1.2e-4, 0, 0]))
    kept = solver.kin._blocks_last
    assert not isinstance(kept[2], Blocks) and callable(kept[2].build)
    b = evaluate_blocks(solver.vm, solver.kin, r.x, r.wrench)
    assert isinstance(b, Blocks) and evaluate_blocks(solver.vm, solver.kin, r.x, r.wrench) is b
    fresh = evaluate_blocks(solver.vm, Kinematics(solver.vm.model, solver.vm.frame_id), r.x, r.wrench)
    for attr in ("J_theta", "J_q", "H_tt", "H_tq", "H_qt", "H_qq", "K_theta"):
        a, c = getattr(b, attr), getattr(fresh, attr)
        assert a.shape == c.shape
        if c.size:
            assert np.abs(a - c).max() <= 1e-12 * np.abs(c).max()


def test_warm_start_rank_check_reads_the_jacobian_at_the_start(solver):
    """The perturbed-start test of a warm start reads the kept J of the last equilibrium: it is J at
    that configuration (task rows, free columns), as a fresh evaluation gives it."""
    from vjm_pin.kinematics.chain import Kinematics

    r = solver.solve(np.array([-1.3e-4, 0, 0]))
    fact = solver._fast_fact
    assert fact[0] == r.x.tobytes()
    fresh = Kinematics(solver.vm.model, solver.vm.frame_id).evaluate(r.x, hessian=False)
    ref = fresh.jacobian[solver.task][:, solver.free]
    assert fact[3].shape == ref.shape and np.abs(fact[3] - ref).max() <= 1e-14 * np.abs(ref).max()


@pytest.mark.filterwarnings("error")  # huge finite entries: no overflow warning for the user
@pytest.mark.parametrize("values", [[1.0, 2.0], [np.nan, 1.0], [np.inf, 1.0], [-np.inf, np.inf], [1e308, 1e308],
                                    [1e308, np.nan], [-1e308, 1e308], [np.nan, np.inf], [], [0.0]])
def test_all_finite_is_isfinite_all(values):
    a = np.array(values, float)
    assert eq._all_finite(a) == bool(np.isfinite(a).all())


def test_task_wrench_shortcut_reads_as_the_general_path(solver):
    w = np.array([3.0, -2.0, 1.0, 0.0, 0.0, 0.0])
    got = solver._task_wrench(w)
    ref = solver._task_wrench(list(w))  # (a list: the general path)
    assert got.tobytes() == ref.tobytes() and not np.shares_memory(got, w)
