"""Issue 14 quick wins change no result: the subnormal flush (curves with and without it agree),
one BLAS thread inside the solver's public calls (active inside, restored after), one
Kinematics per map worker and no link-load terms without gravity (same numbers bit for bit).
Timings live in scripts/benchmark.py, never here."""

from __future__ import annotations

import os

import numpy as np
import pytest

import vjm_pin.kinematics.chain as kmod
from tests.blas_pools import blas_threads
from tests.columns import COMPRESSION, max_deflection
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.exceptions import InputError
from vjm_pin.kinematics.chain import FLUSH_BELOW, flush_tiny
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver, loaded_stiffness
from vjm_pin.solver import threads as tmod


def _tiny(x):
    return int(np.sum((np.abs(x) < FLUSH_BELOW) & (x != 0)))


def test_flush_tiny_zeroes_only_tiny_entries():
    x = np.array([1e-320, -1e-200, 1e-149, -2e-150, 0.0, np.nan, np.inf, 0.5, 9e-151])
    out = flush_tiny(x)
    assert out is x  # in place
    np.testing.assert_array_equal(x[[0, 1, 4, 8]], 0.0)
    assert x[2] == 1e-149 and x[3] == -2e-150 and x[7] == 0.5
    assert np.isnan(x[5]) and x[6] == np.inf


@pytest.mark.parametrize("k", [1, 2])
def test_curve_with_and_without_flush_agree(k, monkeypatch):
    vm = resolve_model("paper-c-s") if k == 1 else load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=k))
    md = max_deflection()
    monkeypatch.setattr(kmod, "_flush_enabled", False)
    raw = trace_curve(vm, COMPRESSION, md, steps=30)
    monkeypatch.setattr(kmod, "_flush_enabled", True)
    flushed = trace_curve(vm, COMPRESSION, md, steps=30)
    # the unflushed straight column does converge to tiny coordinates: the flush has work to do
    assert max(_tiny(p.equilibrium.x) for p in raw.points) > 0
    assert max(_tiny(p.equilibrium.x) for p in flushed.points) == 0
    fr = np.array([p.force for p in raw.points])
    ff = np.array([p.force for p in flushed.points])
    np.testing.assert_allclose(ff, fr, rtol=1e-12, atol=1e-12 * np.abs(fr).max())
    np.testing.assert_array_equal([p.stable for p in flushed.points], [p.stable for p in raw.points])
    assert len(raw.critical) == len(flushed.critical) >= 1
    for a, b in zip(raw.critical, flushed.critical):
        assert b.kind == a.kind
        assert b.force == pytest.approx(a.force, rel=1e-12)
        assert b.deflection == pytest.approx(a.deflection, rel=1e-12, abs=1e-15)
    sr = np.array([p.stiffness for p in raw.points])
    sf = np.array([p.stiffness for p in flushed.points])
    np.testing.assert_allclose(sf, sr, rtol=1e-9, atol=1e-12 * np.nanmax(np.abs(sr)))


def _spy_kinematics(solver, seen):
    """Record the BLAS thread counts every time the solver evaluates its kinematics."""
    inner = solver.kin.evaluate

    def evaluate(x, hessian=True):
        seen.append(blas_threads())
        return inner(x, hessian)

    solver.kin.evaluate = evaluate


def test_one_blas_thread_inside_solve_and_restored_after(two_blas_threads):
    vm = resolve_model("paper-c-s")
    solver = EquilibriumSolver(vm)
    seen = []
    _spy_kinematics(solver, seen)
    res = solver.solve(1e-5 * COMPRESSION)
    assert res.converged and seen
    assert all(n == 1 for counts in seen for n in counts)
    assert all(n == 2 for n in blas_threads())
    # nested public calls (solve_wrench -> solve_mixed): still one thread, restored at the end
    seen.clear()
    solver.solve_wrench(0.5 * res.wrench)
    assert seen and all(n == 1 for counts in seen for n in counts)
    assert all(n == 2 for n in blas_threads())
    loaded_stiffness(vm, res, kin=solver.kin)
    assert all(n == 2 for n in blas_threads())
    # restored after an error too
    with pytest.raises(InputError):
        solver.solve([1.0, 2.0])
    assert all(n == 2 for n in blas_threads())


def test_one_blas_thread_inside_trace_curve(two_blas_threads):
    vm = resolve_model("paper-c-s")
    seen = []
    trace_curve(vm, COMPRESSION, max_deflection(), steps=4, progress=lambda i, n: seen.append(blas_threads()))
    assert len(seen) == 5 and all(n == 1 for counts in seen for n in counts)
    assert all(n == 2 for n in blas_threads())


def test_blas_policy_switch_off_leaves_pools_alone(two_blas_threads, monkeypatch):
    monkeypatch.setattr(tmod, "_enabled", False)
    vm = resolve_model("paper-c-s")
    seen = []
    trace_curve(vm, COMPRESSION, max_deflection(), steps=2, progress=lambda i, n: seen.append(blas_threads()))
    assert seen and all(n == 2 for counts in seen for n in counts)


def test_map_pose_one_blas_thread_and_shared_kinematics(two_blas_threads, monkeypatch):
    from vjm_pin.analysis import maps
    from vjm_pin.model.robots import build_robot

    vm = build_robot("ur5").vm
    names, poses = maps.sample_poses(vm, 3, seed=1)
    w = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    seen = []
    inner = maps._evaluate_pose

    def spy(*a):
        seen.append(blas_threads())
        return inner(*a)

    monkeypatch.setattr(maps, "_evaluate_pose", spy)
    maps._KIN_CACHE.clear()
    shared = [maps.evaluate_pose(vm, names, p, w) for p in poses]
    assert len(seen) == 3 and all(n == 1 for counts in seen for n in counts)
    assert all(n == 2 for n in blas_threads())
    assert len({id(k) for k in maps._KIN_CACHE.values()}) == 1  # one pin.Data for all poses
    # a fresh Kinematics per pose (the old way) gives the same numbers bit for bit
    for p, row in zip(poses, shared):
        maps._KIN_CACHE.clear()
        fresh = maps.evaluate_pose(vm, names, p, w)
        assert fresh["status"] == row["status"] == "ok"
        np.testing.assert_array_equal(fresh["deflection"], row["deflection"])
        assert fresh["k_along"] == row["k_along"] and fresh["k_min"] == row["k_min"]


def test_benchmark_quick_wins_section_runs_and_before_after_agree():
    """scripts/benchmark.py's before/after section on tiny sizes: structure, and the old path
    (switches off, the copy of the old map pose evaluation) gives the same numbers."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "benchmark.py"
    spec = importlib.util.spec_from_file_location("vjm_benchmark_qw", path)
    bench = importlib.util.module_from_spec(spec)
    sys.modules["vjm_benchmark_qw"] = bench
    spec.loader.exec_module(bench)
    c = bench.bench_curve_quick_wins(1, 4, 1, ablation=False)
    assert c["agreement"] <= 1e-12 and c["before"]["min"] > 0 and c["after"]["min"] > 0
    m = bench.bench_map_quick_wins(2, 1)
    for row in m.values():
        assert row["k_along_max_rel_diff"] <= 1e-12
    text = bench.format_quick_wins(
        {"subnormal_eval": bench.bench_subnormal_eval(1, repeats=1, number=2), "newton_k1": bench.bench_newton_quick_wins(2, 1),
         "curve_k1": c, "curve_k8": c, "map": m},
        bench.machine_info(),
    )
    assert "trace_curve k=1" in text and "poses/s" in text
    # the switches are restored after the section
    assert kmod._flush_enabled and tmod._enabled


def test_solver_lapack_is_scipys_lapack_without_importing_scipy_linalg():
    """vjm_pin.solver.lapack loads scipy's compiled LAPACK module alone: importing the solver
    and solving does not import scipy.linalg, and a later ``import scipy.linalg`` reuses the
    very same routines (so results are those of scipy.linalg.lapack bit for bit)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from vjm_pin.model.registry import resolve_model\n"
        "from vjm_pin.solver import EquilibriumSolver\n"
        "r = EquilibriumSolver(resolve_model('paper-c-s')).solve([-1e-5, 0, 0])\n"
        "assert r.converged and r.stable\n"
        "assert 'scipy.linalg' not in sys.modules, 'scipy.linalg imported'\n"
        "from vjm_pin.solver.lapack import lapack\n"
        "import scipy.linalg\n"
        "names = ['dgeqrf', 'dorgqr', 'dtrtrs', 'dgesdd', 'dsyevd', 'dpotrf', 'dgesv', 'dgetrf', 'dgetri']\n"
        "assert all(getattr(lapack, n) is getattr(scipy.linalg.lapack, n) for n in names)\n"
        "print('ok')\n"
    )
    # the numpy path (numba's own np.linalg support imports scipy.linalg for its LAPACK bindings, so
    # under VJM_PIN_JIT=1 the import is numba's, not the solver's)
    env = {**os.environ, "VJM_PIN_JIT": "0"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False,
                         env=env)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_solve_triangular_matches_scipy():
    import scipy.linalg

    from vjm_pin.solver.lapack import solve_triangular

    rng = np.random.default_rng(4)
    a = np.triu(rng.standard_normal((7, 7))) + 3 * np.eye(7)
    for mat in (a, np.asfortranarray(a), a[:5, :5]):
        n = mat.shape[0]
        for b in (rng.standard_normal(n), rng.standard_normal((n, 2))):
            for trans in (0, "T", 1):
                np.testing.assert_array_equal(solve_triangular(mat, b, trans=trans), scipy.linalg.solve_triangular(mat, b, trans=trans))
    sing = a.copy()
    sing[3, 3] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        solve_triangular(sing, np.ones(7))
    with pytest.raises(ValueError):
        solve_triangular(a, np.full(7, np.nan))


def test_benchmark_issue14_section_runs_and_release_solver_agrees():
    """scripts/benchmark.py's issue 14 section on tiny sizes: the frozen release solver
    (scripts/release_solver/) and the current one give the same forces and critical points."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "benchmark.py"
    spec = importlib.util.spec_from_file_location("vjm_benchmark_i14", path)
    bench = importlib.util.module_from_spec(spec)
    sys.modules["vjm_benchmark_i14"] = bench
    spec.loader.exec_module(bench)
    vm = resolve_model("paper-c-s")
    n = bench.bench_newton_vs_floor("C", vm, COMPRESSION, max_deflection(), 4, 1, 2)
    assert n["force_agreement"] <= 1e-12
    # the same iterations as released when the safeguarded line search halves as it did then (the
    # quadratic backtrack, equilibrium._backtrack, may take other steps through the buckling crossing)
    from vjm_pin.solver import equilibrium

    monkey = equilibrium._safeguard_shortcuts
    equilibrium._safeguard_shortcuts = False
    try:
        h = bench.bench_newton_vs_floor("C", vm, COMPRESSION, max_deflection(), 4, 1, 2)
    finally:
        equilibrium._safeguard_shortcuts = monkey
    assert h["force_agreement"] <= 1e-12 and h["iterations"]["release"] == h["iterations"]["now"] == h["iterations"]["numpy"]
    assert n["floor_s"] > 0 and n["per_iteration_s"]["now"] > 0
    c = bench.bench_curve_point_vs_release(1, 8, 1)
    # the release side also runs the generic per-point algebra (eq. 30 inverse, SVD null space),
    # the current side analysis.point_kernel: μ differs by rounding, which moves the located
    # critical force by ~1e-11 relative
    assert c["agreement"] <= 1e-9 and len(c["critical"]) == 1
    q = {"newton_model_c": n, "newton_ur5": {"skipped": "not run here"}, "curve_k1": c, "curve_k8": c,
         "k8_over_k1": {"release": 1.0, "now": 1.0, "k": 1}, "import": {"skipped": "not run here"}, "map": {}}
    text = bench.format_issue14(q, bench.machine_info())
    assert "Newton iteration, C" in text and "curve point, Model C k=1" in text
