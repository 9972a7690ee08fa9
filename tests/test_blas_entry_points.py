"""Public entry points that do dense linear algebra before any solve run under one BLAS thread
too (vjm_pin/solver/threads.py): ``EquilibriumSolver`` (its inverses of K_θ and of the metric,
order 6n on a k-subdivided model, built when first read) and ``unloaded_stiffness``. Found by CPU time above wall time in a
single-process solve: the second OpenBLAS thread worked outside the limit."""

from __future__ import annotations

import numpy as np

from tests.blas_pools import blas_threads
from vjm_pin.model.registry import resolve_model


def test_solver_setup_runs_under_one_blas_thread(two_blas_threads, monkeypatch):
    from vjm_pin.solver import EquilibriumSolver

    seen = []
    inv = np.linalg.inv

    def recording_inv(a):
        seen.append(blas_threads())
        return inv(a)

    monkeypatch.setattr(np.linalg, "inv", recording_inv)
    s = EquilibriumSolver(resolve_model("paper-c-s"))
    assert all(n == 1 for s in seen for n in s), seen
    # K_θ⁻¹ and the metric's inverse are built when first read, also under one thread
    kinv, minv = s.Kinv, s.Minv
    assert len(seen) >= 2 and all(n == 1 for s in seen for n in s), seen
    assert all(n == 2 for n in blas_threads())  # restored
    np.testing.assert_allclose(kinv @ s.vm.K_theta, np.eye(s.nt), atol=1e-9)
    assert s.Kinv is kinv and s.Minv is minv  # built once


def test_unloaded_stiffness_runs_under_one_blas_thread(two_blas_threads, monkeypatch):
    from vjm_pin.solver import stiffness as smod
    from vjm_pin.solver import unloaded_stiffness

    seen = []
    real = smod.stiffness_from_blocks

    def recording(*args, **kwargs):
        seen.append(blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(smod, "stiffness_from_blocks", recording)
    vm = resolve_model("paper-c-s")
    k = unloaded_stiffness(vm).stiffness
    assert seen and all(n == 1 for s in seen for n in s), seen
    assert all(n == 2 for n in blas_threads())
    # the same numbers as without the limit (the limit changes threads, not arithmetic)
    np.testing.assert_allclose(k, real(_blocks(vm), vm.task, "eq30").stiffness, rtol=1e-12, atol=0)


def _blocks(vm):
    from vjm_pin.solver import blocks_at

    return blocks_at(vm, vm.reference, np.zeros(6))
