"""What the mechanism core reuses instead of recomputing (issue 14, the Orthoglide table): the
Newton states kept per solver (``MechanismSolver._state``), the joints that support each closure
and the task frame (known from the joint tree, not from the Jacobians' nonzero columns), and the
full-row-rank test without an SVD next to a matrix already tested (Weyl's bound). Each must give
the same numbers, bit for bit, as the computation it replaces."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import vjm_pin.solver.mechanism as mechanism_mod
from tests.mechanisms import spatial_rssr
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.kinematics.closures import ClosureSet
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

U = np.ones(3) / np.sqrt(3)


def _same(a, b, where="result") -> None:
    """Recursive bit-for-bit equality (arrays, dataclasses, dicts, sequences, scalars)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"{where} differs"
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (u, v) in enumerate(zip(a, b)):
            _same(u, v, f"{where}[{i}]")
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert a == b, where


def _curve(monkeypatch, cache_size: int, counter: list):
    monkeypatch.setattr(mechanism_mod, "STATE_CACHE_SIZE", cache_size)
    orig = MechanismSolver._evaluate_state

    def counted(self, *args):
        counter.append(1)
        return orig(self, *args)

    monkeypatch.setattr(MechanismSolver, "_evaluate_state", counted)
    vm = resolve_model("orthoglide-q2")
    return trace_curve(vm, -U, 2e-3, 8, solver=MechanismSolver(vm), free=True)


def test_state_cache_gives_the_curve_of_fresh_evaluations(monkeypatch):
    fresh, cached = [], []
    a = _curve(monkeypatch, 0, fresh)  # size 0: every state evaluated anew
    b = _curve(monkeypatch, mechanism_mod.STATE_CACHE_SIZE, cached)
    assert len(cached) < len(fresh)  # states were reused
    _same(a.points, b.points, "points")
    _same(a.critical, b.critical, "critical")


def test_state_cache_tells_inputs_and_solvers_apart():
    vm = resolve_model("orthoglide-q0")
    ms = MechanismSolver(vm)
    hr = list(range(len(ms.task)))
    x = vm.reference.copy()
    x[ms.free] += 1e-3 * np.random.default_rng(3).standard_normal(len(ms.free))
    s1 = ms._state(x, hr, np.zeros(6), ms.p0, ms.r0, 1.0, True)
    assert ms._state(x.copy(), hr, np.zeros(6), ms.p0, ms.r0, 1.0, True) is s1  # same bytes
    p_t = ms.p0 + np.array([1e-4, 0.0, 0.0])
    s2 = ms._state(x, hr, np.zeros(6), p_t, ms.r0, 1.0, True)
    assert s2 is not s1 and not np.array_equal(s2.b, s1.b)
    x2 = x.copy()
    x2[ms.free[0]] += 1e-12
    assert ms._state(x2, hr, np.zeros(6), ms.p0, ms.r0, 1.0, True) is not s1
    assert ms._state(x, hr[:1], np.zeros(6), ms.p0, ms.r0, 1.0, True) is not s1
    # siblings share the states (their options do not enter them); other task axes do not
    assert ms.sibling(follow_stable=False)._state(x, hr, np.zeros(6), ms.p0, ms.r0, 1.0, True) is s1
    axes = ms.with_task_axes(np.eye(6)[list(ms.task)][::-1])
    s3 = axes._state(x, hr, np.zeros(6), ms.p0, ms.r0, 1.0, True)
    assert s3 is not s1
    # the kept Hessian cannot be changed through a Linearization that shares it
    lin = ms.linearize(x, hr, state=s1)
    with pytest.raises(ValueError):
        lin.hessian[0, 0] = 1.0


@pytest.mark.parametrize("name", ["orthoglide-2bar-q1", "orthoglide-loop-q3", "rssr"])
def test_structural_supports_are_the_nonzero_jacobian_columns(name):
    vm = spatial_rssr(3, weld=True, task=("x", "y", "z"))[1] if name == "rssr" else resolve_model(name)
    cs = ClosureSet(vm, screw=True)
    assert cs.screw
    ms = MechanismSolver(vm)
    rng = np.random.default_rng(11)
    for _ in range(3):
        x = vm.reference + 0.3 * rng.standard_normal(vm.model.nq)  # far from the reference too
        st = cs.evaluate(x)
        lam = rng.standard_normal(cs.n_rows) * 1e3
        lams = st._split(lam)
        for i, cf in enumerate(st.frames):
            cols = np.flatnonzero(np.any(cf.a.jacobian != 0, axis=0) | np.any(cf.b.jacobian != 0, axis=0))
            assert np.array_equal(cs.support(i)[0], cols)
            bare = dataclasses.replace(cf, support=None)  # columns found from the Jacobians
            _same(cf.hessian_block(lams[i]), bare.hessian_block(lams[i]), f"closure {i}")
        end = ms.frames.evaluate(x, hessian=False)[vm.frame_id]
        nz = np.flatnonzero(np.any(end.jacobian[:, ms.free] != 0, axis=0))
        assert np.array_equal(ms._end_support[0], nz)


def test_full_row_rank_without_svd_agrees_with_row_rank(monkeypatch):
    vm = resolve_model("orthoglide-q0")
    ms = MechanismSolver(vm)
    rng = np.random.default_rng(5)
    n = 40
    # a 6 × n matrix with a smallest singular value of ~1e-6 (row-normalised)
    q1, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    q2, _ = np.linalg.qr(rng.standard_normal((n, 6)))
    a0 = q1 @ np.diag([1.0, 0.9, 0.5, 0.2, 0.1, 1e-6]) @ q2.T
    calls = []
    orig = mechanism_mod.row_rank

    def counted(a, rtol):
        calls.append(1)
        return orig(a, rtol)

    monkeypatch.setattr(mechanism_mod, "row_rank", counted)
    assert ms._full_row_rank(a0) and len(calls) == 1  # remembered
    near = a0 + 1e-13 * rng.standard_normal(a0.shape)
    assert ms._full_row_rank(near) and len(calls) == 1  # decided by the bound
    assert orig(near, ms.rank_rtol)[4] == 6
    # a rank-deficient matrix next to it (the 1e-6 direction removed): the bound cannot decide,
    # the SVD says "not full"
    u, s, vt = np.linalg.svd(a0, full_matrices=False)
    s[-1] = 0.0
    deficient = (u * s) @ vt
    assert orig(deficient, ms.rank_rtol)[4] == 5
    assert not ms._full_row_rank(deficient) and len(calls) == 2
    # random nearby matrices: always the SVD's answer
    for scale in (1e-12, 1e-8, 1e-6, 1e-4):
        for _ in range(5):
            a = a0 + scale * rng.standard_normal(a0.shape)
            assert ms._full_row_rank(a) == (orig(a, ms.rank_rtol)[4] == 6)
