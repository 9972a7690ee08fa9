"""The warm-start solve's lean path (``EquilibriumSolver._solve_lean``) and the escape's hand-off to
the local iteration (``EquilibriumSolver._relaxed_local``) change no result.

The lean path is a shortcut of :meth:`EquilibriumSolver.solve` for a warm start from the equilibrium
the solver found last: its results are compared, bit for bit, with the general path's (the lean path
switched off) along whole warm-started sequences, under the numpy twin and the compiled kernel, and
its input checks with the general path's errors. The escape's hand-off changes the iterates, not the
equilibrium: compared with the safeguarded escape alone to the solver's tolerance.
Timings live in scripts/benchmark.py, never here."""

from __future__ import annotations

import numpy as np
import pytest

from tests.columns import COMPRESSION, max_deflection
from vjm_pin.exceptions import InputError
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver

from .chains import ur5_link_springs, warm_sequence


def _general(monkeypatch):
    monkeypatch.setattr(EquilibriumSolver, "_solve_lean", lambda self, *a, **k: None)


def _assert_same(a, b):
    for name in ("x", "q", "theta", "wrench", "deflection", "position", "rotation"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.converged, a.iterations, a.path, a.held, a.warnings) == (b.converged, b.iterations, b.path, b.held,
                                                                       b.warnings)
    assert a.residuals == b.residuals and a.energy == b.energy
    assert a.stable == b.stable and a.stable_end_held == b.stable_end_held
    np.testing.assert_array_equal(a.stability.eigenvalues, b.stability.eigenvalues)


CASES = {
    # through the buckling of the straight column: a fallback to the safeguarded path and an escape
    "model-c": (lambda: resolve_model("paper-c-s"), COMPRESSION, max_deflection(), 30),
    "ur5": (ur5_link_springs, np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0]), 1e-3, 12),
}


@pytest.mark.parametrize("jit", ["0", "1"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_lean_path_gives_the_general_path_results_bit_for_bit(case, jit, monkeypatch):
    if jit == "1":
        pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", jit)
    make, direction, top, steps = CASES[case]
    vm = make()
    calls = []
    inner = EquilibriumSolver._solve_lean

    def spy(self, *a, **k):
        out = inner(self, *a, **k)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(EquilibriumSolver, "_solve_lean", spy)
    lean = warm_sequence(vm, direction, top, steps)
    assert sum(calls) >= steps // 2  # the lean path did run (and found the equilibria)
    _general(monkeypatch)
    general = warm_sequence(vm, direction, top, steps)
    assert len(lean) == len(general)
    for a, b in zip(lean, general):
        _assert_same(a, b)
    if case == "model-c":  # the sequence crossed the buckling: an escape ran, the stable branch kept
        assert any("escape" in r.path for r in lean) and all(r.stable for r in lean)


def test_lean_path_follows_the_unstable_branch_like_the_general_path(monkeypatch):
    """``follow_stable=False``: the straight column is followed past its buckling (unstable), by the
    lean path as by the general one, bit for bit."""
    vm = resolve_model("paper-c-s")
    lean = warm_sequence(vm, COMPRESSION, max_deflection(), 20, follow_stable=False)
    _general(monkeypatch)
    general = warm_sequence(vm, COMPRESSION, max_deflection(), 20, follow_stable=False)
    for a, b in zip(lean, general):
        _assert_same(a, b)
    assert not lean[-1].stable  # past buckling on the straight branch


def test_lean_path_runs_without_a_pinocchio_evaluation_or_the_general_set_up(monkeypatch):
    """A warm start from the last equilibrium: no kinematics evaluation, no general-path call."""
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    r = s.solve(1e-5 * COMPRESSION)
    ref = EquilibriumSolver(resolve_model("paper-c-s"))
    r_ref = ref.solve(1.1e-5 * COMPRESSION, x0=r.x.copy(), wrench0=r.wrench)  # not a warm start: general

    def refuse(*a, **k):
        raise AssertionError("the general path ran")

    monkeypatch.setattr(EquilibriumSolver, "_solve_limited", refuse)
    monkeypatch.setattr(s.kin, "evaluate", refuse)
    got = s.solve(1.1e-5 * COMPRESSION, x0=r.x, wrench0=r.wrench)
    assert got.converged and got.path == "newton"
    np.testing.assert_allclose(got.x, r_ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.wrench, r_ref.wrench, rtol=1e-9, atol=0)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"deflection": np.array([np.nan, 0, 0, 0, 0, 0])},
        {"deflection": np.array([np.inf, 0, 0, 0, 0, 0])},
        {"deflection": np.array([-1e-5, 0, 0, 0.1, 0, 0])},  # a rotation outside the task (x y z)
        {"wrench0": np.array([np.nan, 0, 0, 0, 0, 0])},
        {"wrench0": np.array([1.0, 2.0])},
    ],
)
def test_lean_path_refuses_what_the_general_path_refuses(kwargs, monkeypatch):
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    r = s.solve(1e-5 * COMPRESSION)
    call = {"deflection": 1.1e-5 * COMPRESSION, "x0": r.x, "wrench0": r.wrench, **kwargs}
    with pytest.raises(InputError) as lean_err:
        s.solve(call.pop("deflection"), **call)
    _general(monkeypatch)
    s2 = EquilibriumSolver(resolve_model("paper-c-s"))
    r2 = s2.solve(1e-5 * COMPRESSION)
    call = {"deflection": 1.1e-5 * COMPRESSION, "x0": r2.x, "wrench0": r2.wrench, **kwargs}
    with pytest.raises(InputError) as general_err:
        s2.solve(call.pop("deflection"), **call)
    assert str(lean_err.value) == str(general_err.value)


def _escape_results(monkeypatch, handoff: bool):
    """The solve across the column's buckling (an escape from the straight, unstable equilibrium)."""
    if not handoff:
        monkeypatch.setattr(EquilibriumSolver, "_relaxed_local", lambda self, *a: None)
    spent = []
    inner = EquilibriumSolver._relaxed_local

    def spy(self, *a):
        out = inner(self, *a)
        spent.append(out is not None)
        return out

    monkeypatch.setattr(EquilibriumSolver, "_relaxed_local", spy)
    out = warm_sequence(resolve_model("paper-c-s"), COMPRESSION, max_deflection(), 30)
    monkeypatch.undo()
    return out, spent


@pytest.mark.parametrize("jit", ["0", "1"])
def test_escape_hand_off_finds_the_safeguarded_escape_equilibrium(jit, monkeypatch):
    if jit == "1":
        pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", jit)
    fast, used = _escape_results(monkeypatch, True)
    monkeypatch.setenv("VJM_PIN_JIT", jit)
    slow, unused = _escape_results(monkeypatch, False)
    assert any(used) and not any(unused)  # the hand-off took over in the escape attempts
    k = next(i for i, r in enumerate(slow) if "escape" in r.path)
    assert "escape" in fast[k].path and fast[k].path == slow[k].path
    assert fast[k].iterations <= slow[k].iterations
    for a, b in zip(fast, slow):  # the same branch (the same buckling side) all along
        assert a.converged and b.converged and a.stable and b.stable
        scale = np.abs(b.wrench).max()
        assert np.abs(a.wrench - b.wrench).max() <= 1e-9 * scale
        assert np.abs(a.x - b.x).max() <= 1e-9
        assert a.energy == pytest.approx(b.energy, rel=1e-9)


def test_hand_off_refuses_an_equilibrium_above_the_iterate_energy(monkeypatch):
    """``_relaxed_local`` keeps a converged point only below the energy of the iterate it started
    from (the safeguarded path only descends): a start whose energy is lowered artificially gets
    None and leaves the solver's verdict to the safeguarded path."""
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    r = s.solve(1e-5 * COMPRESSION)
    p_t, r_t = s._target_pose(1e-5 * COMPRESSION)
    start = r.x.copy()
    got = s._relaxed_local(start, p_t, r_t)  # at an equilibrium on the target: converges there
    assert got is not None and np.abs(got[0] - start).max() <= 1e-12
    real = EquilibriumSolver.energy
    monkeypatch.setattr(EquilibriumSolver, "energy", lambda self, x: real(self, x) - (1.0 if x is start else 0.0))
    assert s._relaxed_local(start, p_t, r_t) is None


def test_lean_path_fallback_runs_under_one_blas_thread(two_blas_threads, monkeypatch):
    """The lean path of a small model runs without the BLAS limit (OpenBLAS uses one thread at these
    orders); when its local iteration gives way (here at the column's buckling) the rest of the solve
    (restorations, escape) runs under one BLAS thread, restored afterwards."""
    from tests.blas_pools import blas_threads

    # the numpy path, whose kinematics go through kin.evaluate (the compiled kernel's own compiled
    # kinematics do not call it: under VJM_PIN_JIT=1 nothing would be seen)
    monkeypatch.setenv("VJM_PIN_JIT", "0")
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    seen = []
    inner = s.kin.evaluate

    def evaluate(x, hessian=True):
        seen.append(blas_threads())
        return inner(x, hessian)

    steps = 30
    top = max_deflection()
    prev = s.solve(top / steps * COMPRESSION)
    monkeypatch.setattr(s.kin, "evaluate", evaluate)
    escaped = False
    for t in np.linspace(top / steps, top, steps)[1:]:
        seen.clear()
        prev = s.solve(t * COMPRESSION, x0=prev.x, wrench0=prev.wrench)
        if "escape" in prev.path:
            escaped = True
            assert seen and all(n == 1 for counts in seen for n in counts)
        assert all(n == 2 for n in blas_threads())
    assert escaped


def test_compiled_lean_verdict_defers_the_eigenvalues_and_gives_the_eager_ones(monkeypatch):
    """The compiled lean path certifies "stable" without the eigenvalues (a Cholesky factorisation past
    the threshold) and computes them when first read: bit for bit those of the compiled kernel's eager
    verdict (the general path), and the same verdicts along a sequence through the buckling."""
    pytest.importorskip("numba")
    from vjm_pin.solver.stability import SpectrumLater, StabilityResult

    monkeypatch.setenv("VJM_PIN_JIT", "1")
    make, direction, top, steps = CASES["model-c"]
    vm = make()
    lean = warm_sequence(vm, direction, top, steps)
    deferred = [r for r in lean if type(r.stability) is SpectrumLater]
    assert len(deferred) >= steps // 2  # the deferral did run
    assert all(r.stability._spectrum is None for r in deferred)  # nothing read yet
    _general(monkeypatch)
    general = warm_sequence(vm, direction, top, steps)
    for a, b in zip(lean, general):
        assert a.stable == b.stable and a.stability.null_dim == b.stability.null_dim
        assert a.stability.tolerance == b.stability.tolerance
        np.testing.assert_array_equal(a.stability.eigenvalues, b.stability.eigenvalues)
        assert a.stability.margin == b.stability.margin
    # pickled (a map's worker) as a plain verdict, spectrum included
    import pickle

    back = pickle.loads(pickle.dumps(deferred[0].stability))
    got = deferred[0].stability
    assert type(back) is StabilityResult and back.stable and (back.null_dim, back.tolerance) == (got.null_dim,
                                                                                              got.tolerance)
    np.testing.assert_array_equal(back.eigenvalues, got.eigenvalues)


def test_compiled_lean_start_test_reads_the_condition_bound(monkeypatch):
    """The perturbed-start test of a warm start reads the kernel's bound ‖R‖_F‖R⁻¹‖_F of cond(J) when it
    is conclusive (no SVD), and runs the SVD test otherwise."""
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    r = s.solve(1e-5 * COMPRESSION)
    r = s.solve(1.1e-5 * COMPRESSION, x0=r.x, wrench0=r.wrench)  # a lean solve: the bound kept
    key, cond = s._fast_cond
    assert key is s._fast_fact[0]
    sv = np.linalg.svd(s._fast_fact[3], compute_uv=False)
    assert sv[0] / sv[-1] <= cond * (1 + 1e-12) and 1e-9 * cond < 0.5
    calls = []
    inner = EquilibriumSolver._start_regular

    def spy(self, *a, **k):
        calls.append(1)
        return inner(self, *a, **k)

    monkeypatch.setattr(EquilibriumSolver, "_start_regular", spy)
    r = s.solve(1.2e-5 * COMPRESSION, x0=r.x, wrench0=r.wrench)
    assert r.path == "newton" and not calls
    s._fast_cond = (s._fast_fact[0], 1e12)  # an inconclusive bound: the SVD test decides
    r = s.solve(1.3e-5 * COMPRESSION, x0=r.x, wrench0=r.wrench)
    assert r.path == "newton" and calls == [1]


@pytest.mark.parametrize("jit", ["0", "1"])
def test_lean_results_keep_their_numbers_after_later_solves_and_writes(jit, monkeypatch):
    """A lean result's arrays are its own: after the whole sequence (later solves reuse the kernel's
    buffers) and after its ``x`` is overwritten, its deferred fields (computed from the iteration's own
    configuration) and its deferred eigenvalues are still the general path's, bit for bit."""
    if jit == "1":
        pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", jit)
    make, direction, top, steps = CASES["model-c"]
    vm = make()
    lean = warm_sequence(vm, direction, top, steps)
    for r in lean:
        r.x[:] = np.nan  # (a caller writing into a result's array)
    _general(monkeypatch)
    general = warm_sequence(vm, direction, top, steps)
    for a, b in zip(lean, general):
        for name in ("q", "theta", "wrench", "deflection", "position", "rotation"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        assert a.energy == b.energy and a.stable == b.stable and a.residuals == b.residuals
        np.testing.assert_array_equal(a.stability.eigenvalues, b.stability.eigenvalues)
