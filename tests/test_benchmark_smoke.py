"""Smoke test of scripts/benchmark.py: its functions run on tiny sizes, the report has the
documented structure, and the finite-difference baseline (same algorithm, J and H by central
differences of Pinocchio placements) reproduces the Pinocchio path. Timings are never asserted."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from vjm_pin.kinematics.chain import Kinematics

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("vjm_benchmark", ROOT / "scripts" / "benchmark.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["vjm_benchmark"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def vm(bench):
    return bench.paper_model(1)


def test_fd_kinematics_matches_pinocchio(bench, vm):
    rng = np.random.default_rng(3)
    x = vm.reference + 1e-2 * rng.standard_normal(vm.model.nq)
    ref = Kinematics(vm.model, vm.frame_id).evaluate(x)
    fd = bench.FDKinematics(vm.model, vm.frame_id).evaluate(x)
    np.testing.assert_allclose(fd.position, ref.position, atol=1e-14, err_msg="end position (m)")
    np.testing.assert_allclose(fd.jacobian, ref.jacobian, atol=1e-8, err_msg="FD Jacobian vs Pinocchio (m/rad)")
    scale = np.abs(ref.hessian).max()
    np.testing.assert_allclose(fd.hessian, ref.hessian, atol=1e-6 * scale, err_msg="FD Hessian vs Pinocchio")


def test_fd_baseline_curve_equals_pinocchio_curve(bench, vm):
    md = bench.default_max_deflection(vm)
    # 6 points: the first ones on the straight (axially stiff) branch, the last ones buckled
    ref = bench.trace(vm, bench.EquilibriumSolver(vm), md, 6, use_library=False)
    fd = bench.trace(vm, bench.fd_solver(vm), md, 6, use_library=False)
    fmax = np.abs(ref.force).max()
    assert fmax > 0
    np.testing.assert_allclose(fd.force, ref.force, atol=1e-6 * fmax, err_msg="force along the curve (N)")
    np.testing.assert_allclose(fd.deflection, ref.deflection, atol=1e-12, err_msg="deflection (m)")
    np.testing.assert_array_equal(fd.stable, ref.stable)
    # the buckled column's tangent stiffness is ~1e-5 of the axial one and comes from H alone,
    # so the FD Hessian's error (~1e-7 abs) shows at the 1e-3 level there
    np.testing.assert_allclose(fd.stiffness, ref.stiffness, rtol=5e-3, err_msg="tangent stiffness (N/m)")
    # the curve crosses buckling: the stiffness collapses and the force stays below the axial line
    assert ref.stiffness[-1] < 1e-3 * ref.stiffness[0]
    assert ref.force[-1] < 0.5 * ref.stiffness[0] * ref.deflection[-1]


def test_report_structure_and_targets(bench, vm):
    md = bench.default_max_deflection(vm)
    report = {
        "machine": bench.machine_info(),
        "model": {"name": vm.name, "nv": vm.model.nv, "n_theta": vm.n_theta, "task": list(vm.task)},
        "floor": bench.bench_floor(vm, repeats=1, number=2),
        "newton": bench.bench_newton(vm, md, steps=3, repeats=1),
        "stiffness": bench.bench_stiffness(vm, 0.5 * md, repeats=1, number=1),
        "curve": bench.bench_curve(vm, md, steps=4, repeats=1, fd=False),
        "scaling": bench.bench_scaling((1, 2), steps=2, repeats=1),
        "ur5": {"skipped": "tested in test_ur5_benchmark_structure"},
        "map": bench.bench_map(n=4),
    }
    assert report["machine"]["cores"] >= 1
    for key in ("floor", "kinematics_evaluate"):
        t = report["floor"][key]
        assert 0 < t["min"] <= t["median"]
    assert report["newton"]["iterations"] >= 0 and report["newton"]["solves"] == 3
    for key in ("blocks", "eq30", "stability"):
        assert report["stiffness"][key]["min"] > 0
    assert report["curve"]["steps"] == 4
    rows = report["scaling"]["rows"]
    assert [r["k"] for r in rows] == [1, 2]
    assert rows[1]["n_theta"] == 2 * rows[0]["n_theta"]
    assert np.isfinite(report["scaling"]["exponent"])
    assert report["map"]["serial"]["ok"] == report["map"]["local"]["ok"] == 4, report["map"]
    report["targets"] = bench.targets(report)
    names = [t["target"] for t in report["targets"]]
    assert names[:2] == ["Newton iteration <= 3x floor", "200-point curve <= 0.2 s"]
    for t in report["targets"]:
        assert isinstance(t["met"], bool) and np.isfinite(t["measured"])
    text = bench.format_report(report)
    assert "targets:" in text and "floor" in text


def test_critical_from_curve_knee(bench):
    d = np.linspace(0.1, 1.0, 10)
    f = np.minimum(10.0 * d, 4.0)  # k0 = 10, plateau at 4 from d = 0.4
    run = bench.CurveRun(d, f, np.zeros(10, int), np.ones(10, bool), np.zeros(10), "test", np.zeros((10, 0)))
    assert bench.critical_from_curve(run) == pytest.approx(4.0)
    assert bench.curve_critical(run) == pytest.approx(4.0)


def test_eigen_critical_force_matches_curve_and_converges_to_euler(bench, vm):
    """The eq. (23) eigenproblem equals the critical force found by tracing the curve, and the
    subdivided model approaches Euler's load of the pinned-pinned column (closed form)."""
    md = bench.default_max_deflection(vm)
    run = bench.trace(vm, bench.EquilibriumSolver(vm), md, 12)
    f_eig = bench.vjm_eigen_critical_force(vm)
    assert f_eig == pytest.approx(bench.curve_critical(run), rel=1e-3), "critical force (N): eigenproblem vs curve"
    e = bench.euler_load_c()
    f2 = bench.vjm_eigen_critical_force(bench.paper_model(2))
    assert abs(f2 / e - 1) < abs(f_eig / e - 1), "subdivision must move F_cr towards Euler's load"
    assert f2 / e - 1 < 0.15


def test_ur5_benchmark_structure(bench):
    out = bench.bench_ur5(repeats=1, steps=2)
    assert "skipped" not in out, out.get("skipped")
    assert out["nv"] == out["n_theta"] == 6 + 6 * len(bench.UR5_LINKS)
    assert out["curve"]["iterations"] >= 0 and out["curve"]["time"]["min"] > 0
    assert out["floor"]["min"] > 0 and out["eq30"]["min"] > 0


_NO_OPENSEES = importlib.util.find_spec("openseespy") is None


@pytest.mark.skipif(_NO_OPENSEES, reason="OpenSeesPy (the 'bench' extra) is not installed")
def test_opensees_peer_converges_to_euler(bench):
    """The OpenSees peer's column buckles at Euler's closed form as the mesh is refined: the
    linearised load falls towards it as 1/n² (corotational elastic beams), any element count
    is allowed (n_elements) and agrees with the per-link count, and the nonlinear trace's knee
    agrees with the linearised load of the same mesh."""
    peer = bench.load_peer()
    b = bench.PAPER_BEAM
    kw = {"E": b["E"], "nu": b["nu"], "L": 1.0, "a": b["a"], "b": b["b"]}
    euler = np.pi**2 * b["E"] * (b["b"] * b["a"] ** 3 / 12.0) / 3.0**2
    assert peer.euler_load(**{k: kw[k] for k in ("E", "L", "a", "b")}) == pytest.approx(euler, rel=1e-14)
    err = {n: peer.linear_buckling_force(n_elements=n, **kw)["linear_buckling_force"] / euler - 1.0 for n in (5, 10, 20)}
    assert 0 < err[20] < err[10] < err[5]
    assert 0.2 < err[10] / err[5] < 0.3 and 0.2 < err[20] / err[10] < 0.3, err
    per_link = peer.linear_buckling_force(elements_per_link=2, **kw)
    assert per_link["n_elements"] == 6
    assert per_link["linear_buckling_force"] == pytest.approx(
        peer.linear_buckling_force(n_elements=6, **kw)["linear_buckling_force"], rel=1e-12)
    nl = peer.critical_force(n_elements=10, max_deflection=2 * 3 * euler / (b["E"] * b["a"] * b["b"]), steps=10, **kw)
    assert nl["buckled"] and nl["n_elements"] == 10
    assert nl["critical_force"] == pytest.approx((1 + err[10]) * euler, rel=2e-3)


@pytest.mark.skipif(_NO_OPENSEES, reason="OpenSeesPy (the 'bench' extra) is not installed")
def test_opensees_same_accuracy_comparison(bench):
    """Issue 14's comparison picks the coarsest OpenSees mesh within the tolerance of Euler's
    load, and both codes' critical forces are the ones their own methods give."""
    tol = 0.1
    o = bench.bench_opensees_same_accuracy(2, repeats=1, tol=tol)
    assert "skipped" not in o, o.get("skipped")
    b = bench.PAPER_BEAM
    euler = np.pi**2 * b["E"] * (b["b"] * b["a"] ** 3 / 12.0) / 3.0**2
    assert o["euler_load"] == pytest.approx(euler, rel=1e-14)
    n = o["opensees_elements"]
    errs = o["opensees_mesh_errors"]
    assert abs(errs[n]) <= tol and not abs(errs[n - 1]) <= tol, errs  # the coarsest within tol
    r = o["results"]
    assert r["opensees"]["rel_err"] == pytest.approx(errs[n], abs=1e-12)
    vm2 = bench.paper_model(2)
    assert r["vjm_curve"]["critical_force"] == pytest.approx(bench.vjm_eigen_critical_force(vm2), rel=2e-3)
    assert r["vjm_eig"]["critical_force"] == pytest.approx(bench.vjm_eigen_critical_force(vm2), rel=1e-10)
    for v in r.values():
        assert v["rel_err"] == pytest.approx(v["critical_force"] / euler - 1.0, rel=1e-12)
    assert o["vjm_within_tol"] == (abs(r["vjm_curve"]["rel_err"]) <= tol)
    text = "\n".join(bench.format_opensees_same_accuracy(o))
    assert f"OpenSees {n} corotational elements" in text


def test_release_package_traces_the_same_curve(bench):
    """The benchmark's release side (the package of ``RELEASE_COMMIT`` imported as ``vjm_pin_release``)
    traces the same Model C curve as today's code: forces to 1e-9, the same critical point to its
    location tolerance; its model is loaded from the same URDF."""
    rel = bench.release_package()
    if rel is None:
        pytest.skip("git or the release commit is unavailable (a source archive without history)")
    from vjm_pin.analysis.curve import trace_curve

    vm = bench.paper_model(1)
    md = bench.default_max_deflection(vm)
    old = rel.solver.curve.trace_curve(rel.model.load_vjm(vm.urdf), bench.DIRECTION, md, steps=8)
    new = trace_curve(vm, bench.DIRECTION, md, steps=8)
    assert rel.__name__ == "vjm_pin_release" and not rel.__file__.startswith(str(ROOT))
    scale = np.abs(new.forces).max()
    assert np.abs(np.asarray(old.forces) - new.forces).max() <= 1e-9 * scale
    assert len(old.critical) == len(new.critical) == 1
    assert old.critical[0].force == pytest.approx(new.critical[0].force, rel=1e-7)
