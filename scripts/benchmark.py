#!/usr/bin/env python
"""Speed benchmark of ``vjm_pin`` (issue 7): one command, a table and a JSON file.

Measured for the bundled ``paper-c-s`` model (Model C, S posture: a straight column of three
6-D beam springs with a passive universal joint at the base and a spherical joint at the end):

- the floor: one Pinocchio evaluation of the joint Jacobians, the kinematic Hessians and the
  frame Jacobian / Hessian at the end frame (what the method cannot avoid);
- the time per Newton iteration of :class:`~vjm_pin.solver.EquilibriumSolver` (warm-started
  curve solves divided by their iterations) and its ratio to the floor;
- loaded stiffness by eq. (30), (32), (33) and the stability check of eq. (23);
- a 200-point force–deflection curve in compression with stiffness and stability at each point;
- the same curve with ``J`` and ``H`` by central differences of Pinocchio placements (the
  baseline: :class:`FDKinematics`, a drop-in :class:`~vjm_pin.kinematics.chain.Kinematics`);
- scaling with link subdivision k = 1, 2, 4, 8, 16 (time per curve point versus nθ, fitted
  exponent);
- the OpenSeesPy peer (``scripts/opensees_peer.py``): critical force and wall time of the same
  column with corotational beams, next to vjm_pin's critical force on the subdivided model;
- ``ur5`` with 6-D link springs and map throughput, when those modules exist (else a note).
- the quick wins of issue 14 as before/after ratios measured side by side in the same run
  (interleaved repeats; "before" = the library's private switches off, plus a copy of the old
  map pose evaluation): the subnormal flush (one Pinocchio J + Hessian, warm-started solves, the
  k = 1 and k = 8 column curves), one BLAS thread inside the solver (k = 8 curve, with the two
  ablations), and the map pose evaluation (ur5 with actuator springs / 6-D link springs).
  ``--quick-wins-only`` runs this section alone.

Minimum and median over repeats are reported (other processes share the machine). Timings
are never asserted by tests; ``tests/test_benchmark_smoke.py`` runs these functions on tiny
sizes and checks structure and that the baseline reproduces the Pinocchio results.

- the targets of issue 14 (``run_issue14``, ``--issue14-only``): the Newton iteration against the
  Pinocchio floor on Model C and ur5 with 6-D link springs, and the marginal cost of a Model C
  curve point, each for the release solver (the frozen copy in ``scripts/release_solver/``)
  and the current one interleaved; the k = 8 / k = 1 per-point ratio; ``vjm-pin analyze ur5``
  against ``import pinocchio`` (fresh interpreters); serial map poses/s.

Usage: ``python scripts/benchmark.py [--quick] [--json bench.json] [--repeats N] [--quick-wins-only] [--issue14-only]``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import itertools
import json
import math
import os
import platform
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from vjm_pin.kinematics.chain import Kinematics, KinematicState
from vjm_pin.model.format import VjmModel, load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import (
    EquilibriumSolver,
    blocks_at,
    check_stability,
    loaded_stiffness,
    stiffness_eq30,
    stiffness_eq32,
    stiffness_eq33,
)

HERE = Path(__file__).resolve().parent
#: Compression of the column: the end moves towards the base (world −x).
DIRECTION = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])

TARGETS = {
    "newton_over_floor": 3.0,  # Newton iteration ≤ 3 × floor
    "curve_200_s": 0.2,  # 200-point curve ≤ 0.2 s
    "speedup_over_fd": 20.0,  # ≥ 20 × the finite-difference baseline
    "opensees_rel_err": 0.02,  # critical force within 2 %
    "opensees_slowdown": 100.0,  # OpenSees ≥ 100 × slower
}


# --------------------------------------------------------------------------- machine
def machine_info() -> dict:
    """Cores, CPU, Python/numpy/Pinocchio versions and numpy's BLAS."""
    info = {
        "cores": os.cpu_count(),
        "affinity_cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "cpu": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pinocchio": pin.__version__,
        "blas": "unknown",
    }
    try:
        from threadpoolctl import threadpool_info  # optional

        info["blas"] = "; ".join(f"{d.get('internal_api')} {d.get('version')} ({d.get('num_threads')} threads)" for d in threadpool_info())
    except ImportError:
        try:
            cfg = np.show_config(mode="dicts")
            blas = cfg["Build Dependencies"]["blas"]
            info["blas"] = f"{blas.get('name')} {blas.get('version')}"
        except Exception:  # noqa: BLE001 - old numpy without mode="dicts"
            pass
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    info["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return info


# --------------------------------------------------------------------------- timing
def timeit(fn, repeats: int = 5, number: int = 1) -> dict:
    """Run ``fn`` ``number`` times per repeat; min and median seconds per call."""
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        ts.append((time.perf_counter() - t) / number)
    return {"min": min(ts), "median": statistics.median(ts), "repeats": repeats, "number": number}


def _keep(box: list, value) -> None:
    """Keep only the latest result (curves of subdivided models hold large Hessians)."""
    box[:] = [value]


def paper_model(k: int = 1) -> VjmModel:
    """Model C, S posture, with the bundled beam (``PAPER_BEAM``), links subdivided ``k`` times."""
    if k == 1:
        from vjm_pin.model.registry import resolve_model

        return resolve_model("paper-c-s")
    return load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=k))


# --------------------------------------------------------------------------- FD baseline
class FDKinematics(Kinematics):
    """The baseline: the frame Jacobian and kinematic Hessian by central differences of
    Pinocchio placements only (no Pinocchio derivatives).

    ``J[:3, i] = (p(x + h eᵢ) − p(x − h eᵢ)) / 2h``, ``J[3:, i] = log3(R(x + h eᵢ) R(x − h eᵢ)ᵀ) / 2h``
    (world-aligned, as :class:`~vjm_pin.kinematics.chain.Kinematics`), and
    ``H[:, :, j] = (J(x + h_H eⱼ) − J(x − h_H eⱼ)) / 2h_H`` (inner step ``h_inner``; the steps
    minimise the error against Pinocchio's analytic derivatives on ``paper-c-s``, ~1e-7 abs.) — 2n + 4n² placements per
    evaluation with a Hessian. Every joint of a VJM model is 1-DOF (nq = nv), so ``x ± h eᵢ``
    is a valid configuration step.
    """

    def __init__(self, model: pin.Model, frame_id: int, h: float = 1e-5, h_hessian: float = 3e-4, h_inner: float = 3e-5):
        super().__init__(model, frame_id)
        self.screw = False  # H by differences of J, not in screw form from the FD Jacobian
        self.h = h
        self.h_hessian = h_hessian
        self.h_inner = h_inner

    def _jacobian(self, x: np.ndarray, h: float) -> np.ndarray:
        n = self.model.nv
        jac = np.empty((6, n))
        for i in range(n):
            xp = x.copy()
            xp[i] += h
            xm = x.copy()
            xm[i] -= h
            pp, rp = self.placement(xp)
            pm, rm = self.placement(xm)
            jac[:3, i] = (pp - pm) / (2 * h)
            jac[3:, i] = pin.log3(rp @ rm.T) / (2 * h)
        return jac

    def evaluate(self, x: np.ndarray, hessian: bool = True) -> KinematicState:
        x = np.asarray(x, float)
        # the same reuse of the last evaluation as Kinematics.evaluate (same algorithm)
        key = x.tobytes()
        last = self._last
        if last is not None and last[0] == key and (last[1].hessian is not None or not hessian):
            return last[1]
        jac = self._jacobian(x, self.h)
        hes = None
        if hessian:
            n = self.model.nv
            hh = self.h_hessian
            hes = np.empty((6, n, n))
            for j in range(n):
                xp = x.copy()
                xp[j] += hh
                xm = x.copy()
                xm[j] -= hh
                hes[:, :, j] = (self._jacobian(xp, self.h_inner) - self._jacobian(xm, self.h_inner)) / (2 * hh)
        p, r = self.placement(x)
        state = KinematicState(p, r, jac, hes)
        self._last = (key, state)
        return state


def fd_solver(vm: VjmModel, **kwargs) -> EquilibriumSolver:
    """An :class:`EquilibriumSolver` whose kinematics is :class:`FDKinematics` (same algorithm)."""
    s = EquilibriumSolver(vm, **kwargs)
    s.kin = FDKinematics(vm.model, vm.frame_id)
    return s


# --------------------------------------------------------------------------- curve
@dataclass
class CurveRun:
    """One traced curve: per point deflection (m), force along the direction (N), iterations,
    stability and the loaded stiffness along the direction (N/m)."""

    deflection: np.ndarray
    force: np.ndarray
    iterations: np.ndarray
    stable: np.ndarray
    stiffness: np.ndarray
    engine: str
    x: np.ndarray  # (steps, nq) configurations
    critical: float = float("nan")  # first critical force found by trace_curve (N)


def _trace_curve_fn():
    if importlib.util.find_spec("vjm_pin.analysis.curve") is None:
        return None
    try:
        from vjm_pin.analysis.curve import trace_curve
    except ImportError:
        return None
    return trace_curve


def trace(vm: VjmModel, solver: EquilibriumSolver, max_deflection: float, steps: int, use_library: bool = True) -> CurveRun:
    """A force–deflection curve in compression with stiffness (eq. 30) and stability at every
    point. Uses ``vjm_pin.analysis.curve.trace_curve`` when it exists (``use_library``), else a
    warm-started loop of ``solve`` + ``loaded_stiffness``."""
    fn = _trace_curve_fn() if use_library else None
    if fn is not None:
        c = fn(vm, DIRECTION, max_deflection, steps=steps, solver=solver)
        pts = [p for p in c.points if p.deflection > 0]
        return CurveRun(
            deflection=np.array([p.deflection for p in pts]),
            force=np.array([p.force for p in pts]),
            iterations=np.array([p.equilibrium.iterations for p in pts]),
            stable=np.array([bool(p.stable) for p in pts]),
            stiffness=np.array([p.stiffness for p in pts]),
            engine="vjm_pin.analysis.curve.trace_curve",
            x=np.array([p.equilibrium.x for p in pts]),
            critical=float(c.critical[0].force) if c.critical else float("nan"),
        )
    results = []
    prev = None
    for s in np.linspace(max_deflection / steps, max_deflection, steps):
        r = solver.solve(s * DIRECTION, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
        results.append(r)
        prev = r
    return _from_results(vm, solver, results, "benchmark loop (solve + loaded_stiffness + stability)")


def _from_results(vm, solver, results, engine) -> CurveRun:
    u = DIRECTION[:3]
    kc = []
    for r in results:
        k = loaded_stiffness(vm, r, "eq30", kin=solver.kin).stiffness
        kc.append(float(u @ k[:3, :3] @ u))
    return CurveRun(
        deflection=np.array([float(r.deflection[:3] @ u) for r in results]),
        force=np.array([float(r.wrench[:3] @ u) for r in results]),  # compression positive
        iterations=np.array([r.iterations for r in results]),
        stable=np.array([bool(r.stable) for r in results]),
        stiffness=np.array(kc),
        engine=engine,
        x=np.array([r.x for r in results]),
        critical=float("nan"),
    )


def critical_from_curve(run: CurveRun, knee_fraction: float = 0.01) -> float:
    """Force at the first point after which the secant stiffness falls below
    ``knee_fraction`` × the initial one (the definition of ``opensees_peer.critical_force``)."""
    d = np.concatenate([[0.0], run.deflection])
    f = np.concatenate([[0.0], run.force])
    sec = np.diff(f) / np.diff(d)
    k0 = sec[0]
    idx = np.nonzero(sec < knee_fraction * k0)[0]
    return float(f[idx[0] + 1]) if idx.size else float("nan")


def curve_critical(run: CurveRun) -> float:
    """The critical force located by ``trace_curve`` (bisection, eq. 23) when available, else the
    knee of :func:`critical_from_curve`."""
    return run.critical if np.isfinite(run.critical) else critical_from_curve(run)


def euler_load_c(beam=PAPER_BEAM, L: float = 1.0) -> float:
    """Euler load of the pinned-pinned column of length 3L about its weak axis (N)."""
    i_weak = beam["b"] * beam["a"] ** 3 / 12.0
    return math.pi**2 * beam["E"] * i_weak / (3 * L) ** 2


def default_max_deflection(vm: VjmModel, factor: float = 6.0) -> float:
    """``factor`` × the axial shortening at the Euler load (m): well past buckling."""
    a = PAPER_BEAM["a"] * PAPER_BEAM["b"]
    return factor * euler_load_c() * 3.0 / (PAPER_BEAM["E"] * a)


# --------------------------------------------------------------------------- benchmarks
def bench_floor(vm: VjmModel, repeats: int = 7, number: int = 200) -> dict:
    """One Pinocchio evaluation of J and the kinematic Hessian at the end frame (s)."""
    model, data, fid = vm.model, vm.model.createData(), vm.frame_id
    x = vm.reference.copy()

    def floor():
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacement(model, data, fid)
        pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        pin.computeJointKinematicHessians(model, data)
        pin.getFrameKinematicHessian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)

    kin = Kinematics(model, fid)
    # Kinematics keeps its last evaluation: alternate two configurations so that every call
    # runs Pinocchio
    xs = itertools.cycle((x, x + 1e-9))
    return {
        "floor": timeit(floor, repeats, number),
        "kinematics_evaluate": timeit(lambda: kin.evaluate(next(xs)), repeats, number),
    }


def bench_newton(vm: VjmModel, max_deflection: float, steps: int = 50, repeats: int = 5) -> dict:
    """Time per Newton iteration: warm-started curve solves (no stiffness) / total iterations."""
    pts = np.linspace(max_deflection / steps, max_deflection, steps)
    iters = []

    def run():
        s = EquilibriumSolver(vm)
        prev, total = None, 0
        for d in pts:
            r = s.solve(d * DIRECTION, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
            total += r.iterations
            prev = r
        iters.append(total)

    t = timeit(run, repeats)
    it = iters[0]
    return {
        "solves": steps,
        "iterations": int(it),
        "per_iteration": {"min": t["min"] / it, "median": t["median"] / it},
        "per_solve": {"min": t["min"] / steps, "median": t["median"] / steps},
    }


def bench_stiffness(vm: VjmModel, deflection: float, repeats: int = 7, number: int = 100) -> dict:
    """Per-evaluation cost of the blocks, eq. (30), (32), (33) and the stability check."""
    s = EquilibriumSolver(vm)
    r = s.solve(deflection * DIRECTION)
    b = blocks_at(vm, r.x, r.wrench, s.kin)
    # evaluate_blocks keeps its last result: alternate two wrenches so that every call evaluates
    ws = itertools.cycle((r.wrench, r.wrench * (1 + 1e-12)))
    out = {
        "blocks": timeit(lambda: blocks_at(vm, r.x, next(ws), s.kin), repeats, number),
        "stability": timeit(lambda: check_stability(b), repeats, number),
    }
    for name, fn in (("eq30", stiffness_eq30), ("eq32", stiffness_eq32), ("eq33", stiffness_eq33)):
        try:
            fn(b, vm.task)
            out[name] = timeit(lambda fn=fn: fn(b, vm.task), repeats, number)
        except Exception as e:  # noqa: BLE001 - e.g. eq33 needs J_θ k J_θᵀ invertible
            out[name] = {"error": f"{type(e).__name__}: {str(e)[:120]}"}
    return out


def bench_curve(vm: VjmModel, max_deflection: float, steps: int = 200, repeats: int = 3, fd: bool = True, fd_steps: int | None = None) -> dict:
    """The full curve (solve + stiffness + stability per point), and the FD baseline on the same
    curve (``fd_steps`` points over the same range when given, compared per point)."""
    runs = []

    def run():
        _keep(runs, trace(vm, EquilibriumSolver(vm), max_deflection, steps))

    t = timeit(run, repeats)
    c = runs[-1]
    out = {
        "engine": c.engine,
        "steps": steps,
        "max_deflection": max_deflection,
        "time": t,
        "per_point": {"min": t["min"] / steps, "median": t["median"] / steps},
        "iterations_per_point": {"mean": float(c.iterations.mean()), "max": int(c.iterations.max())},
        "all_stable": bool(c.stable.all()),
        "critical_force": curve_critical(c),
        "max_force": float(c.force.max()),
    }
    if fd:
        # the same algorithm on the same range, both through the benchmark's own loop
        n = fd_steps or steps
        t0 = time.perf_counter()
        cf = trace(vm, fd_solver(vm), max_deflection, n, use_library=False)
        tf = time.perf_counter() - t0
        refs = []
        tp = timeit(lambda: _keep(refs, trace(vm, EquilibriumSolver(vm), max_deflection, n, use_library=False)), repeats)
        ref = refs[-1]
        out["fd"] = {
            "steps": n,
            "time": tf,
            "pinocchio_time": tp,
            "per_point": tf / n,
            "iterations": int(cf.iterations.sum()),
            "pinocchio_iterations": int(ref.iterations.sum()),
            "max_force_diff_rel": float(np.abs(cf.force - ref.force).max() / max(np.abs(ref.force).max(), 1e-300)),
            "speedup": tf / tp["median"],
        }
    return out


def bench_scaling(ks=(1, 2, 4, 8, 16), steps: int = 20, repeats: int = 3) -> dict:
    """Time per curve point versus nθ over link subdivision k; fitted exponent of t ∝ nθ^p."""
    rows = []
    for k in ks:
        vm = paper_model(k)
        md = default_max_deflection(vm)
        runs = []
        solver = EquilibriumSolver(vm)  # built once: pin.Data creation is costly for large models
        t = timeit(lambda runs=runs, vm=vm, solver=solver, md=md: _keep(runs, trace(vm, solver, md, steps)), repeats)
        c = runs[-1]
        rows.append(
            {
                "k": k,
                "n_theta": int(vm.n_theta),
                "nv": int(vm.model.nv),
                "per_point": {"min": t["min"] / steps, "median": t["median"] / steps},
                "iterations_per_point": float(c.iterations.mean()),
                "critical_force": curve_critical(c),
            }
        )
    n = np.log([r["n_theta"] for r in rows])
    y = np.log([r["per_point"]["min"] for r in rows])
    p = float(np.polyfit(n, y, 1)[0]) if len(rows) > 1 else float("nan")
    return {"rows": rows, "exponent": p, "euler_load": euler_load_c()}


def vjm_critical_force(k: int, steps: int = 60, repeats: int = 3) -> dict:
    """Critical force of the subdivided Model C column by vjm_pin: a compression curve to 2×
    the Euler shortening, force at the knee (same definition as the OpenSees peer)."""
    vm = paper_model(k)
    md = default_max_deflection(vm, factor=2.0)
    runs = []
    solver = EquilibriumSolver(vm)
    t = timeit(lambda: _keep(runs, trace(vm, solver, md, steps)), repeats)
    return {"k": k, "n_theta": int(vm.n_theta), "critical_force": curve_critical(runs[-1]), "time": t, "steps": steps}


def vjm_eigen_critical_force(vm: VjmModel, kin: Kinematics | None = None) -> float:
    """Critical force of the straight column by the stability condition of eq. (23) as a
    linear eigenproblem (linearised buckling, the counterpart of the peer's
    ``linear_buckling_force``).

    At the unloaded configuration the Hessian of ``Ψ`` is linear in the wrench, ``H = P·H₁``
    for the unit compressive wrench; with ``V`` the null space of ``[J_θ J_q]`` (eq. 20–21)
    the reduced matrix of eq. (23), ``Vᵀ(P·H₁ − diag(K_θ, 0))V``, first becomes singular at
    ``P = 1/μ_max`` where ``μ`` are the eigenvalues of ``Vᵀ H₁ V y = μ Vᵀ diag(K_θ, 0) V y``.
    The pre-buckling axial shortening (``P/EA`` ~ 1e-4) is neglected.
    """
    from vjm_pin.solver.stability import null_space

    b = blocks_at(vm, vm.reference, DIRECTION.copy(), kin)
    v = null_space(b.J_theta, b.J_q)
    nt = b.K_theta.shape[0]
    h1 = np.block([[b.H_tt, b.H_tq], [b.H_qt, b.H_qq]])
    k = np.zeros_like(h1)
    k[:nt, :nt] = b.K_theta
    a = v.T @ k @ v
    bm = v.T @ h1 @ v
    lo = np.linalg.cholesky(0.5 * (a + a.T))
    li = np.linalg.inv(lo)
    mu = np.linalg.eigvalsh(li @ (0.5 * (bm + bm.T)) @ li.T)
    return float(1.0 / mu.max()) if mu.max() > 0 else float("inf")


def vjm_eigen_critical(k: int, repeats: int = 5) -> dict:
    """:func:`vjm_eigen_critical_force` on the ``k``-subdivided model, timed (model load excluded)."""
    vm = paper_model(k)
    kin = Kinematics(vm.model, vm.frame_id)  # pin.Data is reused (createData is costly for large models)
    t = timeit(lambda: vjm_eigen_critical_force(vm, kin), repeats)
    return {"k": k, "n_theta": int(vm.n_theta), "critical_force": vjm_eigen_critical_force(vm, kin), "time": t, "method": "eq. (23) eigenproblem"}


def load_peer():
    spec = importlib.util.spec_from_file_location("opensees_peer", HERE / "opensees_peer.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["opensees_peer"] = mod
    spec.loader.exec_module(mod)
    return mod


def _opensees_peer():
    """``scripts/opensees_peer.py`` with OpenSeesPy loaded, or ``{"skipped": why}`` when it is unavailable."""
    try:
        peer = load_peer()
        peer.load_opensees()
    except Exception as e:  # noqa: BLE001 - optional dependency
        return {"skipped": f"OpenSeesPy unavailable: {e}"}
    return peer


def bench_opensees(k: int = 16, vjm: dict | None = None, repeats: int = 1, vjm_curve: dict | None = None) -> dict:
    """OpenSees critical force and wall time with ``k`` elements per link, same beam (issue 7's
    comparison: the same element count as vjm_pin's sub-links, 200 displacement steps). Issue
    14's like-for-like comparison, each code on its coarsest mesh within 1 % of Euler's load
    and CPU times interleaved, is :func:`bench_opensees_same_accuracy`."""
    peer = _opensees_peer()
    if isinstance(peer, dict):
        return peer
    b = PAPER_BEAM
    walls, cpus, res = [], [], None
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        res = peer.critical_force(E=b["E"], nu=b["nu"], L=1.0, a=b["a"], b=b["b"], elements_per_link=k)
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    out = {
        "elements_per_link": k,
        "critical_force": float(res["critical_force"]),
        "euler_load": float(res["euler_load"]),
        "wall_time": {"min": min(walls), "median": statistics.median(walls), "internal": float(res["wall_time"])},
        "cpu_time": {"min": min(cpus), "median": statistics.median(cpus)},
        "n_steps": int(res["n_steps"]),
    }
    if vjm_curve is not None:
        out["vjm_curve"] = vjm_curve
        out["curve_rel_err"] = abs(vjm_curve["critical_force"] / out["critical_force"] - 1.0)
        out["curve_slowdown"] = out["wall_time"]["min"] / vjm_curve["time"]["min"]
    if vjm is not None:
        out["vjm"] = vjm
        out["rel_err"] = abs(vjm["critical_force"] / out["critical_force"] - 1.0)
        out["slowdown"] = out["wall_time"]["min"] / vjm["time"]["min"]
    return out


def _cpu_min(fns: dict, repeats: int) -> dict:
    """Run the callables of ``fns`` interleaved ``repeats`` times; per name the minimum CPU
    time (``time.process_time``: this process, all its threads; robust to other processes
    sharing the cores, unlike wall time), the minimum wall time and the last return value."""
    best = {k: {"cpu": float("inf"), "wall": float("inf"), "value": None} for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            c, w = time.process_time(), time.perf_counter()
            v = fn()
            c, w = time.process_time() - c, time.perf_counter() - w
            b = best[k]
            b["cpu"], b["wall"], b["value"] = min(b["cpu"], c), min(b["wall"], w), v
    return best


def bench_opensees_same_accuracy(k: int = 8, repeats: int = 3, tol: float = 0.01, range_factor: float = 2.0,
                                 opensees_steps: int = 10, vjm_steps: int = 1, max_elements: int = 60) -> dict:
    """Issue 14: the critical force of the Model C column with ``k`` VJM sub-links per link
    against OpenSees at the same accuracy, both within ``tol`` of the continuum value.

    The continuum value is Euler's load of the column as modelled: the three links are one
    straight beam of length 3L (the actuated joints are rigid), pinned at both ends for
    bending about y and z (universal joint at the base, spherical joint on a held point at
    the end), rectangle ``a`` (z) × ``b`` (y), so it buckles about the weak axis at
    ``P_E = π² E I_y / (3L)²``, ``I_y = b a³/12`` (pre-buckling shortening, ~1e-4, neglected).

    Each code computes the critical force as a user would, from the model in memory:

    - vjm_pin, directly: ``vjm_pin.analysis.critical.critical_load`` along −x (the first
      critical point of the same path: linearised estimate, then Newton on the force-control
      margin with warm-started equilibria; default tolerance 1e-7; the solver construction is
      timed, the URDF load is reported apart).
    - vjm_pin, the curve: ``trace_curve`` along −x to ``range_factor`` × the Euler shortening with
      ``vjm_steps`` steps, ``curve.critical[0].force`` (the bifurcation located by root
      finding on the stability margin, independent of the steps).
    - OpenSees: the standard nonlinear practice, ``opensees_peer.critical_force``: corotational
      elastic beams, initial bow 1e-7·3L, displacement control of the end over the same range
      in ``opensees_steps`` steps (failed steps cut), force at the knee of the curve; on the
      coarsest mesh (any element count along the column) within ``tol``.

    Also, for reference, the linearised buckling eigenproblems: vjm_pin's eq. (23) at the
    straight configuration (:func:`vjm_eigen_critical_force`) and OpenSees' tangent matrices
    at zero and reference load (``opensees_peer.linear_buckling_force``, ``printA`` + numpy).
    Both run under one BLAS thread (OpenSees' bundled BLAS is single-threaded; vjm_pin's
    ``trace_curve`` limits itself). Times are CPU seconds (``time.process_time``), min over
    ``repeats`` interleaved runs; wall times are kept too.
    """
    peer = _opensees_peer()
    if isinstance(peer, dict):
        return peer
    from vjm_pin.analysis.curve import trace_curve
    from vjm_pin.solver.threads import single_blas_thread

    b = PAPER_BEAM
    kw = {"E": b["E"], "nu": b["nu"], "L": 1.0, "a": b["a"], "b": b["b"]}
    p_e = euler_load_c()
    t = time.process_time()
    vm = paper_model(k)
    load_cpu = time.process_time() - t
    md = default_max_deflection(vm, factor=range_factor)

    def os_nonlinear(n):
        return lambda: peer.critical_force(n_elements=n, max_deflection=md, steps=opensees_steps, **kw)["critical_force"]

    def os_linear(n):
        def f():
            with single_blas_thread():
                return peer.linear_buckling_force(n_elements=n, **kw)["linear_buckling_force"]
        return f

    def vjm_curve():
        c = trace_curve(vm, DIRECTION, md, steps=vjm_steps, solver=EquilibriumSolver(vm))
        return float(c.critical[0].force) if c.critical else float("nan")

    def vjm_critical():
        from vjm_pin.analysis.critical import critical_load

        return critical_load(vm, DIRECTION, solver=EquilibriumSolver(vm)).force

    def vjm_eig():
        with single_blas_thread():
            return vjm_eigen_critical_force(vm, Kinematics(vm.model, vm.frame_id))

    # the coarsest OpenSees mesh within tol of P_E, by the timed method itself (the error
    # falls as 1/n² from above); and the coarsest at vjm_pin's own accuracy
    f_vjm = vjm_curve()
    err_vjm = f_vjm / p_e - 1.0
    meshes, n_tol, n_match = {}, None, None
    for n in range(1, max_elements + 1):
        meshes[n] = os_nonlinear(n)() / p_e - 1.0
        if n_tol is None and abs(meshes[n]) <= tol:
            n_tol = n
        if abs(meshes[n]) <= abs(err_vjm):
            n_match = n
            break
    if n_tol is None:
        return {"skipped": f"OpenSees not within {tol:.0%} of Euler's load with up to {max_elements} elements"}
    fns = {"vjm_critical": vjm_critical, "vjm_curve": vjm_curve, "opensees": os_nonlinear(n_tol), "vjm_eig": vjm_eig,
           "opensees_linear": os_linear(n_tol)}
    if n_match is not None and n_match != n_tol:
        fns["opensees_matched"] = os_nonlinear(n_match)
    r = _cpu_min(fns, repeats)
    res = {name: {"cpu_s": v["cpu"], "wall_s": v["wall"], "critical_force": float(v["value"]),
                  "rel_err": float(v["value"]) / p_e - 1.0} for name, v in r.items()}
    out = {
        "k": k,
        "n_theta": int(vm.n_theta),
        "euler_load": p_e,
        "tol": tol,
        "max_deflection": md,
        "range_factor": range_factor,
        "vjm_steps": vjm_steps,
        "opensees_steps": opensees_steps,
        "opensees_elements": n_tol,
        "opensees_matched_elements": n_match,
        "opensees_mesh_errors": meshes,
        "vjm_model_load_cpu_s": load_cpu,
        "results": res,
        "speedup": res["opensees"]["cpu_s"] / res["vjm_curve"]["cpu_s"],
        "speedup_critical": res["opensees"]["cpu_s"] / res["vjm_critical"]["cpu_s"],
        "vjm_critical_within_tol": abs(res["vjm_critical"]["rel_err"]) <= tol,
        # the direct solve and the curve locate the same critical point (relative difference)
        "critical_vs_curve": res["vjm_critical"]["critical_force"] / res["vjm_curve"]["critical_force"] - 1.0,
        "jit": os.environ.get("VJM_PIN_JIT", "auto"),
        "speedup_linear": res["opensees_linear"]["cpu_s"] / res["vjm_eig"]["cpu_s"],
        # vjm_pin's linearised solve (not in the library) against OpenSees' standard practice
        "speedup_eig_vs_nonlinear": res["opensees"]["cpu_s"] / res["vjm_eig"]["cpu_s"],
        "vjm_within_tol": abs(res["vjm_curve"]["rel_err"]) <= tol,
        "repeats": repeats,
        "loadavg": os.getloadavg(),
    }
    if "opensees_matched" in res:
        out["speedup_matched"] = res["opensees_matched"]["cpu_s"] / res["vjm_curve"]["cpu_s"]
    return out


#: 6-D link springs of the ur5 benchmark: aluminium tubes (illustrative, not UR data).
UR5_BEAM = {"section": "tube", "outer_diameter": 0.09, "wall": 0.005, "E": 7.0e10, "nu": 0.33}
UR5_LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link")


def ur5_model() -> VjmModel:
    """``ur5`` (example-robot-data) with default actuator springs and 6-D tube link springs."""
    from vjm_pin.model.robots import build_robot

    return build_robot("ur5", springs={"links": {ln: {"beam": dict(UR5_BEAM)} for ln in UR5_LINKS}}).vm


def bench_ur5(repeats: int = 3, steps: int = 200, max_deflection: float = 1e-3) -> dict:
    """Floor, Newton iteration, stiffness, stability and a curve (end pushed along −z) for ``ur5``."""
    if importlib.util.find_spec("vjm_pin.model.robots") is None:
        return {"skipped": "vjm_pin.model.robots does not exist yet (ur5 with 6-D link springs)"}
    try:
        vm = ur5_model()
    except Exception as e:  # noqa: BLE001 - example-robot-data missing, etc.
        return {"skipped": f"ur5 unavailable: {type(e).__name__}: {e}"}
    d = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
    out = {"nv": int(vm.model.nv), "n_theta": int(vm.n_theta), "direction": d.tolist(), "max_deflection": max_deflection}
    out.update(bench_floor(vm, repeats=repeats, number=100))
    solver = EquilibriumSolver(vm)
    pts = np.linspace(max_deflection / steps, max_deflection, steps)
    its = []

    def curve():
        prev, total = None, 0
        for s in pts:
            r = solver.solve(s * d, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
            loaded_stiffness(vm, r, "eq30", kin=solver.kin)
            total += r.iterations
            prev = r
        its[:] = [total]

    t = timeit(curve, repeats)
    out["curve"] = {"steps": steps, "time": t, "iterations": int(its[0])}
    r = solver.solve(0.5 * max_deflection * d)
    b = blocks_at(vm, r.x, r.wrench, solver.kin)
    out["eq30"] = timeit(lambda: stiffness_eq30(b, vm.task), repeats, 100)
    out["stability"] = timeit(lambda: check_stability(b), repeats, 100)
    return out


def bench_map(n: int = 200, wrench=(0.0, 0.0, -100.0, 0.0, 0.0, 0.0)) -> dict:
    """Map throughput (poses per second) of ``vjm_pin.analysis.maps.run_map`` on ``ur5`` with link
    springs: ``n`` sampled poses under an end force, serial and on all local cores."""
    if importlib.util.find_spec("vjm_pin.analysis.maps") is None or importlib.util.find_spec("vjm_pin.model.robots") is None:
        return {"skipped": "vjm_pin.analysis.maps or vjm_pin.model.robots missing (map throughput not measured)"}
    from vjm_pin.analysis.maps import run_map, sample_poses

    try:
        vm = ur5_model()
    except Exception as e:  # noqa: BLE001
        return {"skipped": f"ur5 unavailable: {type(e).__name__}: {e}"}
    names, poses = sample_poses(vm, n, seed=0)
    out = {"model": "ur5 + link springs", "poses": n, "wrench": list(wrench)}
    for backend in ("serial", "local"):
        t = time.perf_counter()
        res = run_map(vm, names, poses, np.array(wrench), backend=backend)
        dt = time.perf_counter() - t
        status = getattr(res, "status", None)
        out[backend] = {"time": dt, "poses_per_s": n / dt, "workers": 1 if backend == "serial" else os.cpu_count()}
        if status is not None:
            out[backend]["ok"] = int(np.sum(np.asarray(status) == "ok"))
    return out


# --------------------------------------------------------------------------- quick wins (issue 14)
@contextlib.contextmanager
def old_behaviour(flush: bool = False, one_thread: bool = False):
    """The behaviour before the quick wins of issue 14, through the library's private switches:
    no subnormal flush (``vjm_pin.kinematics.chain._flush_enabled``) and BLAS pools as the
    environment sets them (``vjm_pin.solver.threads._enabled``). ``flush`` / ``one_thread``
    keep one of the two on (ablation)."""
    import vjm_pin.kinematics.chain as kmod
    from vjm_pin.solver import threads

    old = (kmod._flush_enabled, threads._enabled)
    kmod._flush_enabled, threads._enabled = flush, one_thread
    try:
        yield
    finally:
        kmod._flush_enabled, threads._enabled = old


def side_by_side(variants: dict, repeats: int) -> dict:
    """Run every variant ``name -> (context factory, fn)`` ``repeats`` times, interleaved
    (before, after, before, after, …: the same machine load for both); min and median (s) and
    the last return value of each."""
    times = {k: [] for k in variants}
    last = {}
    for _ in range(repeats):
        for name, (ctx, fn) in variants.items():
            with ctx():
                t = time.perf_counter()
                last[name] = fn()
                times[name].append(time.perf_counter() - t)
    return {k: {"min": min(v), "median": statistics.median(v), "repeats": repeats, "value": last[k]} for k, v in times.items()}


def _curve_summary(c) -> dict:
    return {"force": np.array([p.force for p in c.points]), "critical": [float(cp.force) for cp in c.critical]}


def _agreement(a: dict, b: dict) -> float:
    """Largest relative difference of the curve forces and critical forces of two runs."""
    fa, fb = a["force"], b["force"]
    scale = max(np.abs(fa).max(), 1e-300)
    err = float(np.abs(fa - fb).max() / scale) if fa.shape == fb.shape else float("inf")
    if len(a["critical"]) != len(b["critical"]):
        return float("inf")
    for x, y in zip(a["critical"], b["critical"]):
        err = max(err, abs(x - y) / max(abs(x), 1e-300))
    return err


def bench_subnormal_eval(k: int = 1, repeats: int = 7, number: int = 50) -> dict:
    """Pinocchio J + kinematic Hessian (``Kinematics.evaluate``) at a converged straight-column
    configuration of an unflushed curve (coordinates down to subnormal floats) and at the same
    configuration flushed (|x| < 1e-150 → 0)."""
    from vjm_pin.kinematics.chain import FLUSH_BELOW
    from vjm_pin.analysis.curve import trace_curve

    vm = paper_model(k)
    with old_behaviour():
        c = trace_curve(vm, DIRECTION, default_max_deflection(vm), steps=20)
    tiny = [int(np.sum((np.abs(p.equilibrium.x) < FLUSH_BELOW) & (p.equilibrium.x != 0))) for p in c.points]
    x = c.points[int(np.argmax(tiny))].equilibrium.x.copy()
    xf = np.where(np.abs(x) < FLUSH_BELOW, 0.0, x)
    kin = Kinematics(vm.model, vm.frame_id)

    def ev(y):
        def f():
            kin._last = None  # force a Pinocchio call
            kin.evaluate(y)
        return f

    per_call = {"raw": [], "flushed": []}
    for _ in range(repeats):  # interleaved
        per_call["raw"].append(timeit(ev(x), 1, number)["min"])
        per_call["flushed"].append(timeit(ev(xf), 1, number)["min"])
    out = {"k": k, "nv": int(vm.model.nv), "tiny_coordinates": int(max(tiny)), "smallest_nonzero": float(np.abs(x[x != 0]).min())}
    for name, ts in per_call.items():
        out[name] = {"min": min(ts), "median": statistics.median(ts)}
    out["ratio"] = out["raw"]["min"] / out["flushed"]["min"]
    return out


def bench_curve_quick_wins(k: int, steps: int, repeats: int, ablation: bool = True) -> dict:
    """The ``k``-subdivided column's compression curve (``trace_curve``, ``steps`` points,
    stiffness, stability and critical points), before / after the quick wins side by side."""
    from vjm_pin.analysis.curve import trace_curve

    vm = paper_model(k)
    md = default_max_deflection(vm)

    def run():
        return _curve_summary(trace_curve(vm, DIRECTION, md, steps=steps))

    variants = {"before": (old_behaviour, run)}
    if ablation:
        variants["flush_only"] = (lambda: old_behaviour(flush=True), run)
        variants["one_thread_only"] = (lambda: old_behaviour(one_thread=True), run)
    variants["after"] = (contextlib.nullcontext, run)
    r = side_by_side(variants, repeats)
    out = {"k": k, "nv": int(vm.model.nv), "n_theta": int(vm.n_theta), "steps": steps}
    for name, v in r.items():
        out[name] = {"min": v["min"], "median": v["median"], "repeats": v["repeats"]}
    out["speedup"] = r["before"]["min"] / r["after"]["min"]
    out["agreement"] = max(_agreement(r["before"]["value"], v["value"]) for v in r.values())
    out["critical_force"] = r["after"]["value"]["critical"]
    return out


def bench_newton_quick_wins(steps: int, repeats: int) -> dict:
    """Warm-started solves along the k = 1 column's compression (no stiffness): per solve."""
    vm = paper_model(1)
    pts = np.linspace(default_max_deflection(vm) / steps, default_max_deflection(vm), steps)

    def run():
        s = EquilibriumSolver(vm)
        prev, total = None, 0
        for d in pts:
            r = s.solve(d * DIRECTION, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
            total += r.iterations
            prev = r
        return total

    r = side_by_side({"before": (old_behaviour, run), "after": (contextlib.nullcontext, run)}, repeats)
    return {
        "steps": steps,
        "iterations": {k: int(v["value"]) for k, v in r.items()},
        "per_solve": {k: {"min": v["min"] / steps, "median": v["median"] / steps} for k, v in r.items()},
        "speedup": r["before"]["min"] / r["after"]["min"],
    }


def _evaluate_pose_before(vm, names, values, wrench, method="eq30"):
    """A copy of ``vjm_pin.analysis.maps.evaluate_pose`` before issue 14 (no gravity requested): a fresh
    ``Kinematics`` (``pin.Data``) for the reference placement, the solver's own and the
    stiffness's, and, for models without passive joints, ``solve_loaded`` evaluating the link-load
    terms every Newton iteration (a model copy + ``createData`` + RNEA each; reproduced here by a
    gravity of 1e-300 m/s², whose terms are numerically nothing but cost the same)."""
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
    release_solver_class()  # scripts/ on sys.path
    from release_solver.loads import LinkLoads, solve_loaded  # frozen copy: vjm_pin.loads is deleted
    from vjm_pin.analysis.maps import stiffness_indices

    v = vm.with_positions(dict(zip(names, (float(x) for x in values))))
    Kinematics(v.model, v.frame_id).placement(v.reference)
    w = np.asarray(wrench, float)
    try:
        if v.n_q == 0:
            eq = solve_loaded(v, w, LinkLoads(np.array([0.0, 0.0, 1e-300])), method=method)
            if eq.stiffness is None:
                return None
            k = eq.stiffness.stiffness
        else:
            res = EquilibriumSolver(v).solve_wrench(w)
            k = loaded_stiffness(v, res, method).stiffness
    except (SingularStiffness, NoEquilibrium):
        return None
    return stiffness_indices(k, w, v.task)


def bench_map_quick_wins(n: int, repeats: int, wrench=(0.0, 0.0, -100.0, 0.0, 0.0, 0.0)) -> dict:
    """Serial map throughput (poses/s) of ``ur5`` with actuator springs only and with 6-D link
    springs: the pose evaluation before issue 14 (:func:`_evaluate_pose_before`, old switches)
    and ``vjm_pin.analysis.maps.evaluate_pose`` now, side by side, one process."""
    if importlib.util.find_spec("vjm_pin.model.robots") is None:
        return {"skipped": "vjm_pin.model.robots missing"}
    from vjm_pin.analysis.maps import evaluate_pose, sample_poses
    from vjm_pin.model.robots import build_robot

    out = {}
    for label, make in (("ur5 actuator springs", lambda: build_robot("ur5").vm), ("ur5 + 6-D link springs", ur5_model)):
        try:
            vm = make()
        except Exception as e:  # noqa: BLE001 - example-robot-data missing, etc.
            out[label] = {"skipped": f"{type(e).__name__}: {e}"}
            continue
        names, poses = sample_poses(vm, n, seed=0)
        w = np.array(wrench)

        def before():
            return [_evaluate_pose_before(vm, names, row, w) for row in poses]

        def after():
            return [evaluate_pose(vm, names, row, w) for row in poses]

        r = side_by_side({"before": (old_behaviour, before), "after": (contextlib.nullcontext, after)}, repeats)
        kb = np.array([np.nan if x is None else x[0] for x in r["before"]["value"]])
        ka = np.array([row["k_along"] for row in r["after"]["value"]])
        ok = np.isfinite(kb) & np.isfinite(ka)
        out[label] = {
            "poses": n,
            "before_poses_per_s": n / r["before"]["min"],
            "after_poses_per_s": n / r["after"]["min"],
            "speedup": r["before"]["min"] / r["after"]["min"],
            "k_along_max_rel_diff": float(np.max(np.abs(kb[ok] - ka[ok]) / np.abs(ka[ok]))) if ok.any() else float("nan"),
        }
    return out


def run_quick_wins(quick: bool = False, repeats: int = 3) -> dict:
    """Every quick win of issue 14 as a before/after ratio, measured side by side in one run."""
    reps = 1 if quick else repeats
    return {
        "subnormal_eval": bench_subnormal_eval(1, repeats=3 if quick else 7, number=20 if quick else 100),
        "newton_k1": bench_newton_quick_wins(20 if quick else 200, reps),
        "curve_k1": bench_curve_quick_wins(1, 20 if quick else 200, 1 if quick else 5),
        "curve_k8": bench_curve_quick_wins(2 if quick else 8, 10 if quick else 200, reps, ablation=True),
        "map": bench_map_quick_wins(10 if quick else 100, reps),
    }


def format_quick_wins(q: dict, machine: dict) -> str:
    lines = [
        "quick wins of issue 14, before / after side by side (min of interleaved repeats, same process)",
        f"machine: {machine['cores']} cores, {machine['cpu']}; BLAS {machine['blas']}",
    ]
    se = q["subnormal_eval"]
    lines.append(
        f"  J + kinematic Hessian at a converged straight-column configuration (k={se['k']}, {se['tiny_coordinates']} coordinates "
        f"< 1e-150, smallest {se['smallest_nonzero']:.1e}): raw {se['raw']['min'] * 1e6:.1f} µs, flushed "
        f"{se['flushed']['min'] * 1e6:.1f} µs: {se['ratio']:.2f}x"
    )
    nk = q["newton_k1"]
    lines.append(
        f"  warm-started solves, k=1, {nk['steps']} points: {nk['per_solve']['before']['min'] * 1e3:.3f} -> "
        f"{nk['per_solve']['after']['min'] * 1e3:.3f} ms/solve: {nk['speedup']:.2f}x (iterations {nk['iterations']['before']} -> {nk['iterations']['after']})"
    )
    for key in ("curve_k1", "curve_k8"):
        c = q[key]
        extra = ""
        if "flush_only" in c:
            extra = f" (flush only {c['flush_only']['min']:.3f} s, one BLAS thread only {c['one_thread_only']['min']:.3f} s)"
        lines.append(
            f"  trace_curve k={c['k']} (nθ={c['n_theta']}), {c['steps']} points: {c['before']['min']:.3f} -> {c['after']['min']:.3f} s: "
            f"{c['speedup']:.2f}x{extra}; forces and critical points agree to {c['agreement']:.1e} (rel); "
            f"min of {c['before']['repeats']}"
        )
    for label, m in q["map"].items():
        if "skipped" in m:
            lines.append(f"  map {label}: skipped ({m['skipped']})")
            continue
        lines.append(
            f"  map {label}, {m['poses']} poses serial: {m['before_poses_per_s']:.0f} -> {m['after_poses_per_s']:.0f} poses/s: "
            f"{m['speedup']:.2f}x; k_along agrees to {m['k_along_max_rel_diff']:.1e} (rel)"
        )
    return "\n".join(lines)


# --------------------------------------------------------------------------- issue 14 targets
def release_solver_class():
    """``EquilibriumSolver`` as released before issue 14's kernel work: the frozen copy in
    ``scripts/release_solver/`` (its own Kinematics, blocks and stability; Pinocchio's
    kinematic Hessian tensor; scipy.linalg imported at module level)."""
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))
    from release_solver import EquilibriumSolver as Release

    return Release


def _pin_floor_fn(vm: VjmModel):
    """One Pinocchio J + kinematic Hessian evaluation at the end frame (the floor of issue 14)."""
    model, data, fid = vm.model, vm.model.createData(), vm.frame_id
    x = vm.reference.copy()

    def floor():
        pin.computeJointJacobians(model, data, x)
        pin.updateFramePlacement(model, data, fid)
        pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
        pin.computeJointKinematicHessians(model, data)
        pin.getFrameKinematicHessian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)

    return floor


def _warm_solves(vm: VjmModel, cls, direction: np.ndarray, max_deflection: float, steps: int):
    """A function that builds a ``cls`` solver and solves the first point (untimed), then times
    ``steps`` further warm-started deflection-driven solves along ``direction`` (each from the
    previous equilibrium); returns (seconds, iterations, forces along the direction)."""
    pts = np.linspace(max_deflection / (steps + 1), max_deflection, steps + 1)

    def run():
        s = cls(vm)
        prev = s.solve(pts[0] * direction)
        total, forces = 0, []
        t = time.perf_counter()
        for d in pts[1:]:
            r = s.solve(d * direction, x0=prev.x, wrench0=prev.wrench)
            total += r.iterations
            forces.append(float(r.wrench @ direction))
            prev = r
        return time.perf_counter() - t, total, np.array(forces)

    return run


UR5_DIRECTION = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])


def _jit_env(value: str):
    """A context setting ``VJM_PIN_JIT`` (the fused kernel's implementation) for one run."""

    @contextlib.contextmanager
    def ctx():
        old = os.environ.get("VJM_PIN_JIT")
        os.environ["VJM_PIN_JIT"] = value
        try:
            yield
        finally:
            if old is None:
                os.environ.pop("VJM_PIN_JIT", None)
            else:
                os.environ["VJM_PIN_JIT"] = old

    return ctx


def bench_newton_vs_floor(label: str, vm: VjmModel, direction, max_deflection: float, steps: int, repeats: int, number: int) -> dict:
    """Newton iteration (warm-started solves / their iterations, solver construction and the
    first solve excluded) of the release solver and of the current one against the Pinocchio
    floor, interleaved in one process (min over repeats). The current solver twice: "now" with
    the compiled fused kernel (``VJM_PIN_JIT=1``; loaded, from numba's cache, before timing) and
    "numpy" with its numpy twin (``VJM_PIN_JIT=0``, the fallback and a one-shot run's path)."""
    from vjm_pin.solver import kernel

    state = (kernel._compiled, kernel._numpy_iterations)  # restored: later benchmarks' choice unchanged
    try:
        return _newton_vs_floor(label, vm, direction, max_deflection, steps, repeats, number, kernel)
    finally:
        kernel._compiled, kernel._numpy_iterations = state


def _newton_vs_floor(label, vm, direction, max_deflection, steps, repeats, number, kernel) -> dict:
    jit = kernel.load()  # numba's import, cache load (or first compile) outside the timings
    floor = _pin_floor_fn(vm)
    runs = {"release": (contextlib.nullcontext, _warm_solves(vm, release_solver_class(), direction, max_deflection, steps)),
            "now": (_jit_env("1"), _warm_solves(vm, EquilibriumSolver, direction, max_deflection, steps)),
            "numpy": (_jit_env("0"), _warm_solves(vm, EquilibriumSolver, direction, max_deflection, steps))}
    best = {"floor": float("inf"), **{k: float("inf") for k in runs}}
    bare = _bare_iteration_fns(vm, direction, max_deflection, kernel) if jit else {}
    best.update({k: float("inf") for k in bare})
    last = {}
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(number):
            floor()
        best["floor"] = min(best["floor"], (time.perf_counter() - t) / number)
        for k, fn in bare.items():
            t = time.perf_counter()
            for _ in range(number):
                fn()
            best[k] = min(best[k], (time.perf_counter() - t) / number)
        for k, (ctx, fn) in runs.items():
            with ctx():
                secs, its, forces = fn()
            last[k] = (its, forces)
            best[k] = min(best[k], secs / max(its, 1))
    fl = best["floor"]
    ref = last["release"][1]

    def agree(k):
        return float(np.abs(ref - last[k][1]).max() / max(np.abs(ref).max(), 1e-300))

    return {
        "label": label,
        "nv": int(vm.model.nv),
        "solves": steps,
        "floor_s": fl,
        "compiled": bool(jit),
        "iterations": {k: int(v[0]) for k, v in last.items()},
        "per_iteration_s": {k: best[k] for k in runs},
        "over_floor": {k: best[k] / fl for k in runs},
        "speedup": best["release"] / best["now"],
        "force_agreement": max(agree("now"), agree("numpy")),
        # one bare iteration (Pinocchio frame Jacobian + placement, one fused-kernel call), no solve
        # around it: what the kernel itself costs against the floor
        "bare_iteration_s": {k: best[k] for k in bare},
        "bare_over_floor": {k: best[k] / fl for k in bare},
    }


def _bare_iteration_fns(vm: VjmModel, direction, max_deflection: float, kernel) -> dict:
    """One iteration of the fused local Newton loop at a point near an equilibrium (half the
    deflection range, perturbed target), as the solver runs it: ``pin.computeFrameJacobian``, the
    end placement, ``log3`` when rotations are held, and one kernel call (compiled / numpy twin)."""
    s = EquilibriumSolver(vm)
    r = s.solve(0.5 * max_deflection * np.asarray(direction, float))
    consts, _ = s._kernel_consts()
    consts = kernel.with_target(consts, r.position + 1e-3 * s.length_scale * 1e-3)
    x, rt = r.x.copy(), r.rotation.copy()
    model, data, fid = vm.model, s.kin.data, vm.frame_id
    rot = s._ir.size > 0
    from vjm_pin.solver import equilibrium as eqmod

    dummy = eqmod._KERNEL_DUMMY[:8]
    lwa = pin.LOCAL_WORLD_ALIGNED
    zero3 = np.zeros(3)

    def make(fn):
        def one():
            j6 = pin.computeFrameJacobian(model, data, x, fid, lwa)
            mo = data.oMf[fid]
            erot = pin.log3(rt @ mo.rotation.T) if rot else zero3
            return fn(j6, mo.translation, erot, x, True, True, True, False, dummy, consts)

        return one

    return {"bare_compiled": make(kernel._load_compiled()), "bare_numpy": make(kernel.iterate_numpy)}


def bench_curve_point_vs_release(k: int, steps: int, repeats: int) -> dict:
    """Marginal cost of one point of the Model C compression curve (``trace_curve``: equilibrium,
    stability, stiffness, critical points) with the release and the current code, interleaved:
    ``(T(steps) − T(steps/4)) / (steps − steps/4)`` over the same deflection range, so the solver
    construction, the cold first point and the critical-point location, common to both curves,
    cancel. Also the whole ``steps``-point curve time.

    The release side is the whole released package (:func:`release_package`: its own
    ``trace_curve``, solver and model loader on the same URDF, ``"release": "package"``). Where git
    or the release commit is unavailable it is the frozen release solver under today's tracer with
    the tracer's per-point work as released (every point by the generic eq. (30) inverse and
    ``check_stability_held``, ``dμ/ds`` by a second evaluation: ``curve._fast_points = False``;
    ``"release": "frozen solver"``), which leaves today's leaner tracer bookkeeping on the release
    side too; the current side by ``vjm_pin.analysis.point_kernel``."""
    from vjm_pin.analysis import curve as curve_mod
    from vjm_pin.analysis.curve import trace_curve

    vm = paper_model(k)
    md = default_max_deflection(vm)
    short = max(steps // 4, 2)
    rel = release_package()

    def curve(cls, n):
        return lambda: _curve_summary(trace_curve(vm, DIRECTION, md, steps=n, solver=cls(vm)))

    @contextlib.contextmanager
    def released_points():
        old = curve_mod._fast_points
        curve_mod._fast_points = False
        try:
            yield
        finally:
            curve_mod._fast_points = old

    if rel is not None:
        rvm = rel.model.load_vjm(vm.urdf)

        def release_curve(n):
            return lambda: _curve_summary(rel.solver.curve.trace_curve(rvm, DIRECTION, md, steps=n))

        release, release_short = (contextlib.nullcontext, release_curve(steps)), (contextlib.nullcontext, release_curve(short))
    else:
        Release = release_solver_class()
        release, release_short = (released_points, curve(Release, steps)), (released_points, curve(Release, short))
    r = side_by_side(
        {
            "release": release,
            "now": (contextlib.nullcontext, curve(EquilibriumSolver, steps)),
            "release_short": release_short,
            "now_short": (contextlib.nullcontext, curve(EquilibriumSolver, short)),
        },
        repeats,
    )
    marg = {v: max(r[v]["min"] - r[v + "_short"]["min"], 1e-9) / (steps - short) for v in ("release", "now")}
    return {
        "k": k,
        "n_theta": int(vm.n_theta),
        "steps": steps,
        "short_steps": short,
        "release": "package" if rel is not None else "frozen solver",
        "curve_s": {"release": r["release"]["min"], "now": r["now"]["min"]},
        "per_point_s": marg,
        "speedup": marg["release"] / marg["now"],
        "curve_speedup": r["release"]["min"] / r["now"]["min"],
        "agreement": _agreement(r["release"]["value"], r["now"]["value"]),
        "critical": r["now"]["value"]["critical"],
    }


_RELEASE_PACKAGE = []  # [module or None] once tried (release_package)


def release_package():
    """The package as of :data:`RELEASE_COMMIT` (``git archive``), importable next to today's as
    ``vjm_pin_release`` (its own imports renamed), or None when git or the commit is unavailable
    or it does not import. Tried once per process."""
    if _RELEASE_PACKAGE:
        return _RELEASE_PACKAGE[0]
    mod = None
    d = _release_package_dir()
    if d is not None:
        import importlib
        import re

        src, dst = Path(d) / "vjm_pin", Path(d) / "vjm_pin_release"
        try:
            src.rename(dst)
            for f in dst.rglob("*.py"):
                f.write_text(re.sub(r"\bvjm_pin\b", "vjm_pin_release", f.read_text(encoding="utf-8")), encoding="utf-8")
            sys.path.insert(0, d)
            mod = importlib.import_module("vjm_pin_release")
            for sub in ("model", "solver.curve"):
                importlib.import_module("vjm_pin_release." + sub)
        except Exception:  # noqa: BLE001 - any failure: the frozen solver instead
            mod = None
    _RELEASE_PACKAGE.append(mod)
    return mod


#: The release the "release" columns compare with (before issue 14's kernel and import work).
RELEASE_COMMIT = "dbe652d01b31500ab43be497eb59e8523571ec7e"


def _release_package_dir() -> str | None:
    """A temporary directory holding ``vjm_pin`` as of :data:`RELEASE_COMMIT` (``git archive``),
    or None when git or the commit is unavailable."""
    import io
    import subprocess
    import tarfile
    import tempfile

    try:
        out = subprocess.run(["git", "-C", str(HERE.parent), "archive", "--format=tar", RELEASE_COMMIT, "vjm_pin"],
                             capture_output=True, check=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    d = tempfile.mkdtemp(prefix="vjm_release_")
    with tarfile.open(fileobj=io.BytesIO(out)) as tf:
        try:
            tf.extractall(d, filter="data")
        except TypeError:  # Python without extraction filters (our own repository's archive)
            tf.extractall(d)  # noqa: S202
    return d


def bench_import_wall(repeats: int = 5) -> dict:
    """Wall time of ``vjm-pin analyze ur5 --wrench 0 0 -100`` (in-process entry point, a fresh
    interpreter) against ``python -c "import pinocchio"``, now and as released (the package of
    :data:`RELEASE_COMMIT` first on ``PYTHONPATH``), interleaved subprocesses, min of
    ``repeats``. Byte-code caching is allowed (in a temporary ``PYTHONPYCACHEPREFIX``, warmed
    once) even when the environment disables it, as for an installed package. ``VJM_PIN_JIT`` is
    removed from the subprocesses' environment (the default kernel choice, as a user runs it)."""
    import subprocess
    import tempfile

    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    # a one-shot command as users run it: the kernel choice by default (``auto``), not this run's
    # ``VJM_PIN_JIT`` (``=1`` would import numba and load every compiled kernel: ~1 s)
    env.pop("VJM_PIN_JIT", None)
    env["PYTHONPYCACHEPREFIX"] = tempfile.mkdtemp(prefix="vjm_bench_pyc_")
    analyze = "import sys; from vjm_pin.cli import main; sys.exit(main(['analyze', 'ur5', '--wrench', '0', '0', '-100']))"
    cmds = {
        "import pinocchio": ([sys.executable, "-c", "import pinocchio"], env),
        "analyze ur5": ([sys.executable, "-c", analyze], env),
        "python": ([sys.executable, "-c", "pass"], env),
    }
    rel = _release_package_dir()
    if rel is not None:
        env_rel = dict(env, PYTHONPATH=rel + os.pathsep + env.get("PYTHONPATH", ""))
        cmds["analyze ur5 (release)"] = ([sys.executable, "-c", analyze], env_rel)
    for c, e in cmds.values():  # warm the byte-code cache and the file cache
        subprocess.run(c, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=e, check=False)
    best = {k: float("inf") for k in cmds}
    for _ in range(repeats):
        for k, (c, e) in cmds.items():
            t = time.perf_counter()
            p = subprocess.run(c, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=e, check=False)
            if p.returncode != 0:
                return {"skipped": f"{k} failed: {p.stderr.decode()[-300:]}"}
            best[k] = min(best[k], time.perf_counter() - t)
    out = {"wall_s": best, "ratio": best["analyze ur5"] / best["import pinocchio"], "repeats": repeats}
    if rel is not None:
        out["release_ratio"] = best["analyze ur5 (release)"] / best["import pinocchio"]
    return out


def _map_cpu_s() -> float:
    """CPU seconds of this process and of its finished children (map workers: the local pool is
    joined, the local Dask cluster's workers are killed and reaped when a map ends)."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def _frame_jacobian_cpu_s(vm: VjmModel, xs: np.ndarray, number: int = 2000) -> float:
    """CPU seconds of one ``pin.computeFrameJacobian`` (LOCAL_WORLD_ALIGNED) at the configurations
    ``xs`` (the unit of a map pose's cost in issue 14), min of 3 rounds. This thread's CPU
    (``thread_time``): with a running Dask cluster the scheduler's threads live in this process,
    and their CPU would inflate the unit (and flatter the Dask row)."""
    model, data, fid = vm.model, vm.model.createData(), vm.frame_id
    best = math.inf
    for _ in range(3):
        t = time.thread_time()
        for k in range(number):
            pin.computeFrameJacobian(model, data, xs[k % len(xs)], fid, pin.LOCAL_WORLD_ALIGNED)
        best = min(best, (time.thread_time() - t) / number)
    return best


@contextlib.contextmanager
def _dask_cluster(workers: int):
    """A local Dask cluster of ``workers`` processes (one thread each, no statistical profiler, as
    the map's own) kept for several maps, and a function returning the CPU seconds of this process
    (client, scheduler) plus its workers' so far: yields ``(address, cpu)``. For the per-pose
    marginal cost on Dask without the workers' start-up (1–2 s of CPU each, which varies by
    several tenths of a second from one start to the next) in the difference."""
    import logging
    import os
    import resource

    from distributed import Client, LocalCluster

    old = os.environ.get("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED")
    os.environ["DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"] = "False"
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR)
    finally:
        if old is None:
            os.environ.pop("DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED", None)
        else:
            os.environ["DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED"] = old
    client = Client(cluster)

    def _worker_cpu():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    def cpu() -> float:
        a = resource.getrusage(resource.RUSAGE_SELF)
        return a.ru_utime + a.ru_stime + sum(client.run(_worker_cpu).values())

    try:
        yield cluster.scheduler_address, cpu
    finally:
        with contextlib.suppress(Exception):
            client.close(timeout=5)
        with contextlib.suppress(Exception):
            cluster.close(timeout=5)


def bench_map_rate(n: int, repeats: int, backends=("serial", "local", "dask", "dask cluster"), workers: int = 2, n_link: int | None = None) -> dict:
    """Map throughput of ``run_map`` (the map as users run it: batched lockstep poses, compiled
    kernels from ``maps.JIT_MIN_POSES`` poses on), ur5 with actuator springs and with 6-D link
    springs (``n_link`` poses, default ``n // 3``), loaded by 100 N along −z, on each backend with
    ``workers`` processes (``serial``: one).

    Per backend and model: ``poses_per_s`` (wall, best of ``repeats``, workers' start-up included),
    ``poses_per_cpu_s`` (CPU of this process and its workers), and the marginal cost of a pose
    from the maps of ``n`` and ``n // 4`` poses differenced (start-up cancels; the short map has
    at least ``maps.JIT_MIN_POSES`` poses where ``n`` allows it, so both maps take the same
    arithmetic: below that size fresh Dask workers skip the compiled kernels and their 1–2 s
    import, which would otherwise land in the difference): ``marginal_poses_per_s``
    (wall) and ``jacobian_evals_per_pose`` = marginal CPU per pose / CPU of one
    ``pin.computeFrameJacobian``, timed in this process between the runs (interleaved). Wall times
    on a shared machine are inflated by the other load; the CPU ratios much less (say the load).

    ``dask`` starts a local cluster for each map (as ``run_map`` does without a scheduler), so its
    marginal cost carries the scatter of two workers' start-ups (±0.3 s of CPU over a few thousand
    poses: tens of evaluations per pose); ``dask cluster`` runs the maps on one running local
    cluster (``run_map(..., scheduler=address)``, as on a user's cluster; warmed by one map first)
    and counts this process's CPU and the workers' own (``client.run``): the per-pose cost on Dask."""
    import os

    try:
        from vjm_pin.analysis.batched import BatchedChain
        from vjm_pin.analysis.maps import JIT_MIN_POSES, run_map, sample_poses
        from vjm_pin.model.robots import build_robot
    except ImportError as e:
        return {"skipped": str(e)}
    out = {"load_average": list(os.getloadavg()), "workers": workers}
    w = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    sizes = {"ur5 actuator springs": n, "ur5 + 6-D link springs": n_link or max(1, n // 3)}
    for label, make in (("ur5 actuator springs", lambda: build_robot("ur5").vm), ("ur5 + 6-D link springs", ur5_model)):
        try:
            vm = make()
            n = sizes[label]
            short = max(1, n // 4) if n < 2 * JIT_MIN_POSES else max(n // 4, JIT_MIN_POSES)
            names, poses = sample_poses(vm, n, seed=0)
            xs = BatchedChain(vm)._start(names, poses[:16])[0]
            run_map(vm, names, poses, w, backend="serial")  # warm: imports, kernels compiled or loaded
            rows = {}
            for b in backends:
                runs = {}
                with _dask_cluster(workers) if b == "dask cluster" else contextlib.nullcontext((None, _map_cpu_s)) as (
                    address,
                    cpu_s,
                ):
                    kw = {"backend": "dask", "scheduler": address} if address else {"backend": b}
                    if address:  # warm the workers: model, kernels
                        run_map(vm, names, poses[:short], w, workers=workers, **kw)
                    for _ in range(repeats):
                        for m in (short, n):
                            jac = _frame_jacobian_cpu_s(vm, xs)
                            c0, t0 = cpu_s(), time.perf_counter()
                            res = run_map(vm, names, poses[:m], w, workers=1 if b == "serial" else workers, **kw)
                            wall, cpu = time.perf_counter() - t0, cpu_s() - c0
                            best = runs.get(m)
                            if best is None or wall < best["wall"]:
                                runs[m] = {"wall": wall, "cpu": cpu, "jac": jac, "ok": int(np.sum(res.status == "ok"))}
                small, big = runs[short], runs[n]
                dm = n - short
                marg_cpu = max(big["cpu"] - small["cpu"], 1e-12) / dm
                marg_wall = (big["wall"] - small["wall"]) / dm  # ≤ 0: lost in the start-up's scatter
                jac = min(small["jac"], big["jac"])
                rows[b] = {
                    "poses": n,
                    "short_poses": short,
                    "poses_per_s": n / big["wall"],
                    "poses_per_cpu_s": n / big["cpu"],
                    "marginal_poses_per_s": 1.0 / marg_wall if marg_wall > 0 else None,
                    "start_s": max(big["wall"] - n * max(marg_wall, 0.0), 0.0),
                    "marginal_cpu_per_pose_s": marg_cpu,
                    "frame_jacobian_s": jac,
                    "jacobian_evals_per_pose": marg_cpu / jac,
                    "ok": big["ok"],
                }
        except Exception as e:  # noqa: BLE001 - example-robot-data or dask missing, API change, ...
            out[label] = {"skipped": f"{type(e).__name__}: {e}"}
            continue
        out[label] = rows
    out["load_average_after"] = list(os.getloadavg())
    return out


_AXES = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


def chain_jacobian_without_data(model: pin.Model, frame_id: int, x: np.ndarray) -> KinematicState:
    """End-frame placement and ``LOCAL_WORLD_ALIGNED`` Jacobian of a chain of 1-DoF revolute /
    prismatic joints by forward kinematics on ``pin.SE3`` alone: ``pin.Data`` of a model with
    nv ≈ 1,000 allocates nv³ second-order-derivative tensors (tens of GB), so the longest chains
    of :func:`bench_chain_algebra` cannot create one. Equal to Pinocchio's to rounding where both
    run (the benchmark checks it at the first size)."""
    omi = [pin.SE3.Identity() for _ in range(model.njoints)]
    twist = {}
    for j in range(1, model.njoints):
        jm = model.joints[j]
        name = jm.shortname()
        ax = np.asarray(jm.extract().axis, float) if "Unaligned" in name else _AXES[name[-1]]
        prismatic = name.startswith("JointModelP")
        q = x[jm.idx_q]
        mot = np.concatenate([ax * q, np.zeros(3)] if prismatic else [np.zeros(3), ax * q])
        omi[j] = omi[model.parents[j]] * model.jointPlacements[j] * pin.exp6(pin.Motion(mot))
        twist[j] = (omi[j].rotation @ ax, omi[j].translation.copy(), prismatic)
    frame = model.frames[frame_id]
    omf = omi[frame.parentJoint] * frame.placement
    p = omf.translation
    jac = np.zeros((6, model.nv))
    j = frame.parentJoint
    while j > 0:
        a, o, prismatic = twist[j]
        iv = model.joints[j].idx_v
        if prismatic:
            jac[:3, iv] = a
        else:
            jac[:3, iv] = np.cross(a, p - o)
            jac[3:, iv] = a
        j = model.parents[j]
    return KinematicState(omf.translation.copy(), omf.rotation.copy(), jac, None)


def _chain_algebra_row(k: int, repeats: int, check_jacobian: bool) -> dict:
    """One size of :func:`bench_chain_algebra`: Model C subdivided ``k`` times."""
    import dataclasses

    from vjm_pin.solver import chain_algebra as ca
    from vjm_pin.solver.blocks import evaluate_blocks
    from vjm_pin.solver.stability import check_stability
    from vjm_pin.solver.threads import single_blas_thread

    vm = paper_model(k)
    kin = Kinematics(vm.model, vm.frame_id)
    x = vm.reference + np.random.default_rng(k).uniform(-0.02, 0.02, vm.model.nq)
    # half the Euler load of the column, a lateral force and a moment (a stable equilibrium)
    w = np.array([-0.5, 0.05, 0.02, 0.01, -0.02, 0.01]) * euler_load_c()
    state = chain_jacobian_without_data(vm.model, vm.frame_id, x)
    jac = state.jacobian
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    lay.k_norm2()

    def dense():
        kin._blocks_last = None  # no kept blocks: each repeat evaluates H
        b = dataclasses.replace(evaluate_blocks(vm, kin, x, w, state), chain=None)  # the dense eq. (30)
        stab = check_stability(b)
        return stiffness_eq30(b, vm.task).task_stiffness, stab.stable, -float(stab.eigenvalues.max())

    def chain():
        kc = ca.ChainKKT(lay, jac, w, vm.task).stiffness()[0]
        return kc, ca.chain_stability(lay, jac, w, vm.task).stable

    def eigmin():
        return ca.smallest_reduced_eigenvalue(lay, jac, w, vm.task)

    chain()  # compile (first use) / warm
    ts = {"dense": [], "chain": [], "eigmin": []}
    out = {}
    with single_blas_thread():  # the solver's BLAS policy (vjm_pin.solver.threads)
        for _ in range(repeats):
            for name, fn in (("dense", dense), ("chain", chain), ("eigmin", eigmin)):
                t = time.perf_counter()
                out[name] = fn()
                ts[name].append(time.perf_counter() - t)
    kd, kc = out["dense"][0], out["chain"][0]
    row = {
        "k": k,
        "n_theta": int(vm.n_theta),
        "dense_s": min(ts["dense"]),
        "chain_s": min(ts["chain"]),
        "speedup": min(ts["dense"]) / min(ts["chain"]),
        "kc_rel_diff": float(np.abs(kd - kc).max() / np.abs(kd).max()),
        "same_verdict": bool(out["dense"][1] == out["chain"][1]),
        "stable": bool(out["dense"][1]),
        "eigmin_chain_s": min(ts["eigmin"]),
        "eigmin_rel_diff": abs(out["eigmin"] - out["dense"][2]) / abs(out["dense"][2]),
    }
    if check_jacobian:
        row["jacobian_check"] = float(np.abs(kin.evaluate(x, hessian=False).jacobian - jac).max())
    return row


def bench_chain_algebra(ks=(1, 2, 4, 8, 16, 32, 64), repeats: int = 5) -> dict:
    """Per-point linear algebra of the Model C column, O(n) chain recursion against dense.

    At each nθ = 18k, from the same Jacobian, under half the Euler load, a lateral force and a
    moment: ``dense`` = the screw-form Hessian ``H`` (nθ×nθ), K_C by eq. (30)
    (:func:`stiffness_eq30`) and the eq. (23) verdict (:func:`check_stability`: null space,
    reduced matrix, eigenvalues); ``chain`` = :class:`vjm_pin.solver.chain_algebra.ChainKKT`
    (factor of the bordered matrix, K_C by refined solves) and
    :func:`~vjm_pin.solver.chain_algebra.chain_stability` (a second factorisation, of the
    symmetric part, the Sturm count at the threshold). Interleaved repeats, min; fitted
    exponents of ``t ∝ nθ^p`` over nθ ≥ 72; the agreement of K_C and of the verdict; and the
    time of :func:`~vjm_pin.solver.chain_algebra.smallest_reduced_eigenvalue` (whose dense
    counterpart is part of ``dense``). The Jacobian comes from :func:`chain_jacobian_without_data`
    (checked against Pinocchio at the first size): ``pin.Data`` cannot be created at nv ≈ 1,000."""
    from vjm_pin.solver import chain_algebra as ca

    rows = [_chain_algebra_row(k, repeats, i == 0) for i, k in enumerate(ks)]
    n = np.array([r["n_theta"] for r in rows], float)
    fit = {}
    for key in ("dense", "chain"):
        t = np.array([r[key + "_s"] for r in rows])
        big = n >= 72
        fit[key + "_exponent"] = float(np.polyfit(np.log(n[big]), np.log(t[big]), 1)[0]) if big.sum() >= 2 else None
    cross = next((r["n_theta"] for r in rows if r["chain_s"] < r["dense_s"]), None)
    return {"rows": rows, **fit, "crossover_n_theta": cross, "backend": "numba" if ca._use_numba() else "numpy"}


def format_chain_algebra(c: dict) -> str:
    """Rows of :func:`bench_chain_algebra` for the issue 14 table."""
    lines = ["Chain algebra per point (factor + solve + stability verdict + K_C), dense vs O(n) chain;",
             "smallest eigenvalue of eq. (23) by Sturm bisection + inverse iteration (dense: in check_stability):",
             "   nθ    dense (ms)   chain (ms)   speed-up   K_C rel. diff   same verdict   λmin chain (ms)  rel. diff"]
    for r in c["rows"]:
        lines.append(f"{r['n_theta']:6d} {1e3 * r['dense_s']:12.2f} {1e3 * r['chain_s']:12.2f} {r['speedup']:9.1f}x"
                     f" {r['kc_rel_diff']:14.1e}   {r['same_verdict']!s:>12} {1e3 * r['eigmin_chain_s']:16.2f}"
                     f" {r['eigmin_rel_diff']:10.1e}")
    de, ce = c.get("dense_exponent"), c.get("chain_exponent")
    if de is not None and ce is not None:
        lines.append(f"  fitted t ∝ nθ^p (nθ ≥ 72): dense p = {de:.2f}, chain p = {ce:.2f} ({c['backend']});"
                     f" chain faster from nθ = {c['crossover_n_theta']}")
    return "\n".join(lines)


def bench_orthoglide_table(quick: bool = False, jobs: int = 2) -> dict:
    """Issue 14's Orthoglide target: ``scripts/reproduce_orthoglide.py`` (all variants, Table 2 and
    Fig. 7) as a subprocess on ``jobs`` worker processes, wall time against 60 s, CPU time of the
    process tree, the load average before and after. ``quick``: the folded model's Q0 curve with
    the platform free (one task of the table) in this process instead."""
    import resource
    import subprocess
    import tempfile

    out = {"load_average": list(os.getloadavg()), "jobs": jobs, "quick": bool(quick)}
    if quick:
        if str(HERE) not in sys.path:
            sys.path.insert(0, str(HERE))
        import reproduce_orthoglide as ro

        vm = load_vjm(HERE.parent / "models" / "urdf" / "orthoglide-q0.urdf")
        t0, c0 = time.perf_counter(), time.process_time()
        row = ro.curve_row(vm, ro.MechanismSolver(vm), "free", "-u", 6e-3, 24)
        out.update(task="folded Q0 free -u curve", wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0,
                   critical_force=row["crit"].force if row["crit"] is not None else math.nan)
        out["load_average_after"] = list(os.getloadavg())
        return out
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, str(HERE / "reproduce_orthoglide.py"), "--jobs", str(jobs), "--figure", str(Path(tmp) / "fig7.png")],
            capture_output=True, text=True,
        )
        wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        return {"skipped": f"reproduce_orthoglide.py exited {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]}"}
    out.update(task="the whole table (15 models, 60 tasks)", wall_s=wall,
               cpu_s=(after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime))
    out["load_average_after"] = list(os.getloadavg())
    return out


def format_orthoglide_table(o: dict | None) -> list[str]:
    """The Orthoglide row of the issue-14 report (:func:`bench_orthoglide_table`)."""
    if not o:
        return []
    if "skipped" in o:
        return [f"  Orthoglide table: skipped ({o['skipped']})"]
    line = (
        f"  Orthoglide table, scripts/reproduce_orthoglide.py: {o['task']} in {o['wall_s']:.1f} s wall, {o['cpu_s']:.1f} s CPU "
        f"({'in one process' if o['quick'] else str(o['jobs']) + ' workers'}; load average {o['load_average'][0]:.1f} before, "
        f"{o['load_average_after'][0]:.1f} after)"
    )
    if not o["quick"]:
        line += f" (target < 60 s on 2 cores: {'MET' if o['wall_s'] < 60 else 'NOT MET'})"
    return [line]


def run_issue14(quick: bool = False, repeats: int = 5, orthoglide: bool = True) -> dict:
    """Every target of issue 14 this script can measure, as ratios measured side by side
    (``orthoglide`` False: without the Orthoglide table, minutes of its own)."""
    reps = 2 if quick else repeats
    vm_c = paper_model(1)
    out = {
        "newton_model_c": bench_newton_vs_floor("Model C (paper-c-s)", vm_c, DIRECTION, default_max_deflection(vm_c), 20 if quick else 100, reps, 20 if quick else 200),
        # (the k = 1 curves take 25-200 ms: more interleaved repeats for a steadier minimum, ~4 s)
        "curve_k1": bench_curve_point_vs_release(1, 20 if quick else 200, reps if quick else max(reps, 15)),
        "curve_k8": bench_curve_point_vs_release(2 if quick else 8, 10 if quick else 100, 1 if quick else max(2, reps // 2)),
    }
    try:
        vm_u = ur5_model()
        out["newton_ur5"] = bench_newton_vs_floor("ur5 + 6-D link springs", vm_u, UR5_DIRECTION, 1e-3, 20 if quick else 100, reps, 20 if quick else 200)
    except Exception as e:  # noqa: BLE001 - example-robot-data missing
        out["newton_ur5"] = {"skipped": f"{type(e).__name__}: {e}"}
    k1, k8 = out["curve_k1"], out["curve_k8"]
    out["k8_over_k1"] = {
        "release": k8["per_point_s"]["release"] / k1["per_point_s"]["release"],
        "now": k8["per_point_s"]["now"] / k1["per_point_s"]["now"],
        "k": k8["k"],
    }
    out["import"] = bench_import_wall(2 if quick else repeats)
    out["map"] = bench_map_rate(40 if quick else 20000, 1 if quick else 2, backends=("serial",) if quick else ("serial", "local", "dask", "dask cluster"))
    out["opensees_k8"] = bench_opensees_same_accuracy(8, repeats=1 if quick else max(3, reps))
    out["chain_algebra"] = bench_chain_algebra((1, 2, 4, 8) if quick else (1, 2, 4, 8, 16, 32, 64), repeats=2 if quick else reps)
    out["orthoglide_table"] = bench_orthoglide_table(quick) if orthoglide else {"skipped": "not asked for (--no-orthoglide-table)"}
    return out


_MAP_BACKEND_LABEL = {
    "dask": "dask (a local cluster started per map)",
    "dask cluster": "dask (one running local cluster, its workers warm)",
}


def format_map_rate(mp: dict | None) -> list[str]:
    """The map rows of the issue-14 report (:func:`bench_map_rate`)."""
    if not isinstance(mp, dict) or "skipped" in mp or not any(k.startswith("ur5") for k in mp):
        return [f"  maps: skipped ({(mp or {}).get('skipped', 'not run')})"]
    la = mp.get("load_average", [math.nan])[0]
    lines = [f"  maps (run_map, 100 N along -z; {mp.get('workers', 2)} workers; load average {la:.1f} before the runs):"]
    for label, target in (("ur5 actuator springs", 5000), ("ur5 + 6-D link springs", 1000)):
        rows = mp.get(label)
        if rows is None:
            continue
        if "skipped" in rows:
            lines.append(f"    {label}: skipped ({rows['skipped']})")
            continue
        for b, m in rows.items():
            lines.append(
                f"    {label}, {_MAP_BACKEND_LABEL.get(b, b)}, {m['poses']} poses: {m['poses_per_s']:.0f} poses/s wall (marginal vs {m.get('short_poses', '?')} poses "
                f"{format(m['marginal_poses_per_s'], '.0f') + '/s' if m['marginal_poses_per_s'] else 'lost in the start-up scatter'}, "
                f"start {m['start_s']:.1f} s), {m['poses_per_cpu_s']:.0f} poses per CPU-second; marginal "
                f"{m['marginal_cpu_per_pose_s'] * 1e6:.1f} µs CPU = {m['jacobian_evals_per_pose']:.1f} frame-Jacobian evaluations "
                f"({m['frame_jacobian_s'] * 1e6:.2f} µs) per pose (target <= 30: {'MET' if m['jacobian_evals_per_pose'] <= 30 else 'NOT MET'})"
                + (f"; target >= {target} poses/s on 2 cores: {'MET' if m['poses_per_s'] >= target else 'NOT MET'}" if b != "serial" else "")
            )
    return lines


def format_opensees_same_accuracy(o: dict | None) -> list[str]:
    """Report lines of :func:`bench_opensees_same_accuracy` (issue 14's OpenSees target)."""
    if not o:
        return []
    if "skipped" in o:
        return [f"  critical force vs OpenSees: skipped ({o['skipped']})"]
    r = o["results"]
    v, p, ve, pl = r["vjm_curve"], r["opensees"], r["vjm_eig"], r["opensees_linear"]
    tol = 100 * o["tol"]
    lines = [
        (f"  critical force, Model C k={o['k']} (nθ={o['n_theta']}) vs OpenSees, each within {tol:g} % of Euler's "
         f"π²EI_y/(3L)² = {o['euler_load']:.6f} N (CPU time, min of {o['repeats']} interleaved; load avg {o['loadavg'][0]:.1f}):"),
        (f"    vjm_pin trace_curve ({o['vjm_steps']} step to {o['range_factor']:g}x the Euler shortening, critical point by root finding) "
        f"{v['critical_force']:.6f} N ({100 * v['rel_err']:+.2f} %{'' if o['vjm_within_tol'] else ', NOT within tolerance'}) in {v['cpu_s']:.3f} s; "
        f"OpenSees {o['opensees_elements']} corotational elements (coarsest within {tol:g} %), displacement control "
        f"{o['opensees_steps']} steps, knee {p['critical_force']:.6f} N ({100 * p['rel_err']:+.2f} %) in {p['cpu_s']:.3f} s: "
        f"{o['speedup']:.2f}x (target >= 10x: {'MET' if o['speedup'] >= 10 and o['vjm_within_tol'] else 'NOT MET'})"),
    ]
    extra = []
    if "vjm_critical" in r:
        c, ok = r["vjm_critical"], o["vjm_critical_within_tol"]
        lines.insert(1, (
            f"    vjm_pin critical_load (direct: linearised estimate + Newton on the margin, VJM_PIN_JIT={o.get('jit', '?')}) "
            f"{c['critical_force']:.6f} N ({100 * c['rel_err']:+.2f} %{'' if ok else ', NOT within tolerance'}; "
            f"{o['critical_vs_curve']:+.1e} from trace_curve's) in {c['cpu_s'] * 1e3:.1f} ms vs OpenSees {p['cpu_s'] * 1e3:.1f} ms: "
            f"{o['speedup_critical']:.2f}x (target >= 10x: {'MET' if o['speedup_critical'] >= 10 and ok else 'NOT MET'})"))
    if "speedup_matched" in o:
        m = r["opensees_matched"]
        extra.append(f"OpenSees at vjm_pin's accuracy ({o['opensees_matched_elements']} elements, {100 * m['rel_err']:+.2f} %) "
                     f"{m['cpu_s']:.3f} s: {o['speedup_matched']:.2f}x")
    extra.append(f"linearised buckling: vjm_pin eq. (23) eigenproblem {ve['cpu_s'] * 1e3:.1f} ms ({100 * ve['rel_err']:+.2f} %) vs "
                 f"OpenSees printA tangents + eig {pl['cpu_s'] * 1e3:.1f} ms ({100 * pl['rel_err']:+.2f} %): {o['speedup_linear']:.2f}x "
                 f"(vs OpenSees' nonlinear run: {o['speedup_eig_vs_nonlinear']:.1f}x; the eigenproblem is the benchmark's, "
                 f"not a library call); "
                 f"vjm_pin model load (URDF, not timed above) {o['vjm_model_load_cpu_s']:.3f} s")
    lines.append("    " + "; ".join(extra))
    return lines


def format_issue14(q: dict, machine: dict) -> str:
    us = 1e6
    lines = [
        "issue 14 targets, measured side by side in this run (min of interleaved repeats; 'release' = the",
        "frozen copy of the solver before issue 14's kernel work, scripts/release_solver/)",
        f"machine: {machine['cores']} cores, {machine['cpu']}; BLAS {machine['blas']}",
    ]
    for key in ("newton_model_c", "newton_ur5"):
        n = q.get(key, {})
        if "skipped" in n:
            lines.append(f"  Newton iteration {key}: skipped ({n['skipped']})")
            continue
        lines.append(
            f"  Newton iteration, {n['label']} (nv={n['nv']}, {n['solves']} warm-started solves): floor {n['floor_s'] * us:.1f} µs; "
            f"release {n['per_iteration_s']['release'] * us:.1f} µs = {n['over_floor']['release']:.1f}x floor; "
            f"now {n['per_iteration_s']['now'] * us:.1f} µs = {n['over_floor']['now']:.1f}x floor "
            f"(target <= 3x: {'MET' if n['over_floor']['now'] <= 3 else 'NOT MET'}; compiled kernel{'' if n.get('compiled', True) else ' UNAVAILABLE'}); "
            + (f"numpy fallback {n['per_iteration_s']['numpy'] * us:.1f} µs = {n['over_floor']['numpy']:.1f}x floor; " if "numpy" in n['per_iteration_s'] else "")
            + f"{n['speedup']:.2f}x faster; "
            f"iterations {n['iterations']['release']} / {n['iterations']['now']}; forces agree to {n['force_agreement']:.1e}"
        )
    for key in ("curve_k1", "curve_k8"):
        c = q[key]
        lines.append(
            f"  curve point, Model C k={c['k']} (nθ={c['n_theta']}, {c['steps']} points): release ({c.get('release', 'frozen solver')}) {c['per_point_s']['release'] * 1e3:.2f} ms, "
            f"now {c['per_point_s']['now'] * 1e3:.2f} ms (marginal): {c['speedup']:.2f}x; whole curve {c['curve_s']['release']:.2f} -> {c['curve_s']['now']:.2f} s"
            + (f" (target >= 10x: {'MET' if c['speedup'] >= 10 else 'NOT MET'})" if c["k"] == 1 else "")
            + f"; forces and critical points agree to {c['agreement']:.1e}"
        )
    r = q["k8_over_k1"]
    lines.append(
        f"  per-point cost k={r['k']} / k=1: release {r['release']:.1f}x, now {r['now']:.1f}x"
        + (f" (target <= 12x: {'MET' if r['now'] <= 12 else 'NOT MET'})" if r["k"] == 8 else "")
    )
    lines += format_opensees_same_accuracy(q.get("opensees_k8"))
    im = q["import"]
    if "skipped" in im:
        lines.append(f"  analyze ur5 vs import pinocchio: skipped ({im['skipped']})")
    else:
        w = im["wall_s"]
        lines.append(
            f"  `vjm-pin analyze ur5 --wrench 0 0 -100` {w['analyze ur5']:.3f} s vs `import pinocchio` {w['import pinocchio']:.3f} s "
            f"(bare python {w['python']:.3f} s): {im['ratio']:.2f}x (target <= 2x: {'MET' if im['ratio'] <= 2 else 'NOT MET'})"
            + (f"; as released {w['analyze ur5 (release)']:.3f} s = {im['release_ratio']:.2f}x" if "release_ratio" in im else "")
        )
    lines += format_map_rate(q.get("map"))
    lines += format_orthoglide_table(q.get("orthoglide_table"))
    if q.get("chain_algebra"):
        lines += ["  " + line for line in format_chain_algebra(q["chain_algebra"]).splitlines()]
    return "\n".join(lines)


# --------------------------------------------------------------------------- report
def targets(report: dict) -> list[dict]:
    rows = []
    fl = report["floor"]["floor"]["min"]
    nw = report["newton"]["per_iteration"]["min"]
    rows.append({"target": "Newton iteration <= 3x floor", "measured": nw / fl, "unit": "x floor", "met": nw / fl <= TARGETS["newton_over_floor"]})
    cu = report["curve"]
    t200 = cu["time"]["min"] * 200 / cu["steps"]
    rows.append({"target": "200-point curve <= 0.2 s", "measured": t200, "unit": "s", "met": t200 <= TARGETS["curve_200_s"]})
    if "fd" in cu:
        sp = cu["fd"]["speedup"]
        rows.append({"target": ">= 20x faster than FD baseline", "measured": sp, "unit": "x", "met": sp >= TARGETS["speedup_over_fd"]})
    op = report.get("opensees", {})
    if "rel_err" in op:
        rows.append({"target": "F_cr within 2% of OpenSees (eq.23 eig)", "measured": 100 * op["rel_err"], "unit": "%", "met": op["rel_err"] <= TARGETS["opensees_rel_err"]})
        rows.append({"target": "OpenSees >= 100x slower (eq.23 eig)", "measured": op["slowdown"], "unit": "x", "met": op["slowdown"] >= TARGETS["opensees_slowdown"]})
    if "curve_rel_err" in op:
        rows.append({"target": "F_cr within 2% of OpenSees (curve)", "measured": 100 * op["curve_rel_err"], "unit": "%", "met": op["curve_rel_err"] <= TARGETS["opensees_rel_err"]})
        rows.append({"target": "OpenSees >= 100x slower (curve)", "measured": op["curve_slowdown"], "unit": "x", "met": op["curve_slowdown"] >= TARGETS["opensees_slowdown"]})
    o14 = report.get("issue14", {}).get("opensees_k8") or {}
    if "speedup_critical" in o14:  # issue 14: k = 8 F_cr >= 10x faster than OpenSees, both within 1 % of Euler
        rows.append({"target": "k=8 F_cr >= 10x faster than OpenSees, same accuracy (critical_load)", "measured": o14["speedup_critical"],
                     "unit": "x", "met": o14["speedup_critical"] >= 10 and o14["vjm_critical_within_tol"]})
        rows.append({"target": "k=8 F_cr >= 10x faster than OpenSees, same accuracy (trace_curve)", "measured": o14["speedup"],
                     "unit": "x", "met": o14["speedup"] >= 10 and o14["vjm_within_tol"]})
    return rows


def format_report(report: dict) -> str:
    ms = 1e3
    m = report["machine"]
    lines = [
        f"machine: {m['cores']} cores ({m['cpu']}), numpy {m['numpy']} BLAS {m['blas']}, pinocchio {m['pinocchio']}",
        f"model: {report['model']['name']}  nv={report['model']['nv']} nθ={report['model']['n_theta']}  (min / median ms)",
        "",
    ]

    def row(name, t, scale=ms, unit="ms"):
        lines.append(f"  {name:<44} {t['min'] * scale:10.4f} / {t['median'] * scale:10.4f} {unit}")

    row("floor (J + kinematic Hessian)", report["floor"]["floor"])
    row("Kinematics.evaluate", report["floor"]["kinematics_evaluate"])
    row(f"Newton iteration ({report['newton']['iterations']} its)", report["newton"]["per_iteration"])
    row("equilibrium solve (warm start)", report["newton"]["per_solve"])
    for k in ("blocks", "eq30", "eq32", "eq33", "stability"):
        v = report["stiffness"][k]
        if "error" in v:
            lines.append(f"  {k:<44} {v['error']}")
        else:
            row(k, v)
    cu = report["curve"]
    row(f"curve, {cu['steps']} points [{cu['engine'][:20]}]", cu["time"])
    row("  per point", cu["per_point"])
    lines.append(f"  iterations per point: mean {cu['iterations_per_point']['mean']:.2f}, max {cu['iterations_per_point']['max']}")
    if "fd" in cu:
        fd = cu["fd"]
        lines.append(f"  FD baseline, same {fd['steps']}-point curve: {fd['time']:.3f} s ({fd['iterations']} its) vs Pinocchio {fd['pinocchio_time']['min']:.4f} / {fd['pinocchio_time']['median']:.4f} s ({fd['pinocchio_iterations']} its): speed-up {fd['speedup']:.1f}x (vs median); max force diff {fd['max_force_diff_rel']:.2e} (rel)")
    sc = report.get("scaling")
    if sc:
        lines.append("")
        lines.append(f"scaling (Euler load {sc['euler_load']:.5f} N):   k   nθ   ms/point (min/median)   its/point   F_cr (N)")
        for r in sc["rows"]:
            lines.append(f"  {r['k']:>28} {r['n_theta']:>5}   {r['per_point']['min'] * ms:8.3f} / {r['per_point']['median'] * ms:8.3f}   {r['iterations_per_point']:8.2f}   {r['critical_force']:.5f}")
        lines.append(f"  fitted exponent: time per point ∝ nθ^{sc['exponent']:.2f}")
    op = report.get("opensees")
    if op:
        lines.append("")
        if "skipped" in op:
            lines.append(f"OpenSees peer: skipped ({op['skipped']})")
        else:
            lines.append(f"OpenSees peer ({op['elements_per_link']} el/link): F_cr {op['critical_force']:.6f} N in {op['wall_time']['min']:.3f} s (Euler {op['euler_load']:.6f} N)")
            if "vjm" in op:
                v = op["vjm"]
                lines.append(f"vjm_pin eq. (23) eigenproblem (k={v['k']}, nθ={v['n_theta']}): F_cr {v['critical_force']:.6f} N in {v['time']['min'] * ms:.3f} / {v['time']['median'] * ms:.3f} ms: {100 * op['rel_err']:.2f} % off, {op['slowdown']:.0f}x faster")
            if "vjm_curve" in op:
                v = op["vjm_curve"]
                lines.append(f"vjm_pin trace_curve (k={v['k']}, nθ={v['n_theta']}, {v['steps']} pts + bisection): F_cr {v['critical_force']:.6f} N in {v['time']['min']:.3f} / {v['time']['median']:.3f} s: {100 * op['curve_rel_err']:.2f} % off, {op['curve_slowdown']:.2f}x faster")
    u = report.get("ur5", {})
    if u and "skipped" not in u:
        lines.append("")
        lines.append(f"ur5 with 6-D link springs (nv={u['nv']}, nθ={u['n_theta']}):")
        row("floor (J + kinematic Hessian)", u["floor"])
        row("eq30", u["eq30"])
        row("stability", u["stability"])
        cu = u["curve"]
        row(f"curve, {cu['steps']} points (solve + eq30)", cu["time"])
        lines.append(f"  iterations: {cu['iterations']}")
    mp = report.get("map", {})
    if mp and "skipped" not in mp:
        lines.append(f"map throughput ({mp['model']}, {mp['poses']} poses): serial {mp['serial']['poses_per_s']:.1f} poses/s, "
                     f"local ({mp['local']['workers']} cores) {mp['local']['poses_per_s']:.1f} poses/s")
    for key in ("ur5", "map"):
        if key in report and "skipped" in report[key]:
            lines.append(f"{key}: skipped ({report[key]['skipped']})")
    lines.append("")
    lines.append("targets:")
    for t in report["targets"]:
        lines.append(f"  {t['target']:<40} {t['measured']:10.3f} {t['unit']:<8} {'MET' if t['met'] else 'NOT MET'}")
    return "\n".join(lines)


def run(quick: bool = False, repeats: int = 5, opensees: bool = True, scaling_ks=(1, 2, 4, 8, 16), opensees_k: int = 8) -> dict:
    vm = paper_model(1)
    md = default_max_deflection(vm)
    report = {
        "machine": machine_info(),
        "model": {"name": vm.name, "nv": int(vm.model.nv), "n_theta": int(vm.n_theta), "task": list(vm.task)},
        "max_deflection": md,
    }
    report["floor"] = bench_floor(vm, repeats=repeats, number=50 if quick else 300)
    report["newton"] = bench_newton(vm, md, steps=20 if quick else 200, repeats=repeats)
    report["stiffness"] = bench_stiffness(vm, 0.5 * md, repeats=repeats, number=20 if quick else 200)
    report["curve"] = bench_curve(vm, md, steps=200, repeats=repeats, fd=True, fd_steps=20 if quick else 200)
    report["scaling"] = bench_scaling(scaling_ks[:3] if quick else scaling_ks, steps=10 if quick else 20, repeats=1 if quick else 3)
    if opensees:
        vc = vjm_critical_force(opensees_k, repeats=1 if quick else 3)
        ve = vjm_eigen_critical(opensees_k, repeats=3 if quick else 7)
        report["opensees"] = bench_opensees(opensees_k, ve, vjm_curve=vc)
    report["ur5"] = bench_ur5(repeats=1 if quick else 3)
    report["map"] = bench_map(n=40 if quick else 200)
    report["quick_wins"] = run_quick_wins(quick, repeats=3)
    report["issue14"] = run_issue14(quick, repeats=3 if quick else repeats)
    report["targets"] = targets(report)
    return report


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    return float(o)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer points and repeats")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default="benchmark.json", help="output JSON path")
    ap.add_argument("--no-opensees", action="store_true")
    ap.add_argument("--opensees-k", type=int, default=8, help="elements (and VJM subdivisions) per link for the peer")
    ap.add_argument("--quick-wins-only", action="store_true", help="only the before/after table of issue 14's quick wins")
    ap.add_argument("--issue14-only", action="store_true", help="only the issue 14 targets (release solver vs now, side by side)")
    ap.add_argument("--no-orthoglide-table", action="store_true", help="issue 14 targets without the Orthoglide table (minutes)")
    args = ap.parse_args(argv)
    if args.issue14_only:
        machine = machine_info()
        q = run_issue14(args.quick, repeats=args.repeats, orthoglide=not args.no_orthoglide_table)
        print(format_issue14(q, machine))
        Path(args.json).write_text(json.dumps({"machine": machine, "issue14": q}, indent=1, default=_json_default))
        print(f"\nJSON: {args.json}")
        return 0
    if args.quick_wins_only:
        machine = machine_info()
        q = run_quick_wins(args.quick, repeats=args.repeats)
        print(format_quick_wins(q, machine))
        Path(args.json).write_text(json.dumps({"machine": machine, "quick_wins": q}, indent=1, default=_json_default))
        print(f"\nJSON: {args.json}")
        return 0
    report = run(quick=args.quick, repeats=args.repeats, opensees=not args.no_opensees, opensees_k=args.opensees_k)
    print(format_report(report))
    print()
    print(format_quick_wins(report["quick_wins"], report["machine"]))
    print()
    print(format_issue14(report["issue14"], report["machine"]))
    Path(args.json).write_text(json.dumps(report, indent=1, default=_json_default))
    print(f"\nJSON: {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
