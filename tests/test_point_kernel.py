"""The per-point algebra of a serial curve (vjm_pin.analysis.point_kernel) against the generic path.

- the tangent stiffness, the tangent of eq. (29) and the force-control margin μ of the kernel
  (numpy and compiled) against stiffness_eq30 and check_stability_held on the same blocks;
- the analytic dμ/ds (first-order perturbation of the constrained eigenvalue) against central
  differences of the generic μ along the tangent, re-evaluated from the kinematics;
- near-singular points are left to the generic path;
- whole curves with the kernel against curves with every point by the generic path.
"""

from __future__ import annotations

import os
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from tests.exact_eq28 import eq28_exact
from vjm_pin.analysis import curve as curve_mod
from vjm_pin.analysis import point_kernel as pk
from vjm_pin.analysis.curve import _complement_rows, _direction, _stiffness_along, trace_curve
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver, blocks_at
from vjm_pin.solver.stability import check_stability_held
from vjm_pin.solver.stiffness import _ruiz


def _generic_mu(vm, d, b) -> float:
    return float(check_stability_held(b, _complement_rows(vm, d)).eigenvalues.max())


def _scale(vm, d, b) -> float:
    """Magnitude of the matrices μ is an eigenvalue of (for absolute tolerances on μ)."""
    ev = check_stability_held(b, _complement_rows(vm, d)).eigenvalues
    return max(float(np.abs(ev).max()), float(np.abs(vm.K_theta).max()))


def _kernels():
    out = [("numpy", None)]
    fn = pk.compiled()
    if fn:
        out.append(("compiled", fn))
    return out


def _equilibria(name, direction, max_deflection, steps):
    """The model, its unit direction, its solver and the equilibria of a short curve (s > 0)."""
    vm = resolve_model(name)
    solver = EquilibriumSolver(vm)
    c = trace_curve(vm, direction, max_deflection, steps=steps, solver=solver)
    return vm, _direction(vm, direction), solver, [p.equilibrium for p in c.points[1:]]


CASES = [
    # straight column before and after buckling (no moment in the wrench)
    ("paper-c-s", [-1.0, 0.0, 0.0], 6e-4, 6),
    # imperfect column (Z posture)
    ("paper-b-z", [-1.0, 0.0, 0.0], 0.1, 4),
    # a robot: 6-D task, moments in the end wrench (the ω×m terms of the screw Hessian)
    ("ur5", [1.0, 0.0, 0.0], 5e-3, 3),
]


@pytest.fixture(scope="module", params=CASES, ids=[c[0] for c in CASES])
def case(request):
    return _equilibria(*request.param)


def _kernel(vm, solver, d):
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    task = np.asarray(vm.task, int)
    mask = solver.kin.support_mask(free) if solver.kin.uses_screw else None
    return pk.PointKernel(vm.K_theta, free, d[task], task), mask, free, task


@pytest.mark.parametrize("kind,fn", _kernels())
def test_kernel_matches_the_generic_stiffness_tangent_and_margin(case, kind, fn):
    vm, d, solver, eqs = case
    kern, mask, _, task = _kernel(vm, solver, d)
    used = 0
    for eq in eqs:
        b = blocks_at(vm, eq.x, eq.wrench, solver.kin)
        got = kern.point(b, mask, eq.wrench, fn)
        k_ref, st = _stiffness_along(vm, b, d)
        if got is None:  # left to the generic path: only where eq. (28) is not safely regular
            continue
        used += 1
        k, xd, fd, mu, _ = got
        assert st is not None
        assert k == pytest.approx(k_ref, rel=1e-9)
        xd_ref = np.concatenate([st.dtheta_dt @ d, st.dq_dt @ d])
        assert np.allclose(xd, xd_ref, rtol=1e-8, atol=1e-10 * np.abs(xd_ref).max())
        assert np.allclose(fd, (st.stiffness @ d)[task], rtol=1e-8, atol=1e-10 * abs(k_ref))
        mu_ref = _generic_mu(vm, d, b)
        assert abs(mu - mu_ref) <= 1e-10 * _scale(vm, d, b)
    assert used >= len(eqs) - 1  # the shortcut is the rule, not the exception


@pytest.mark.parametrize("kind,fn", _kernels())
def test_analytic_margin_rate_matches_central_differences(case, kind, fn):
    """dμ/ds = wᵀH'w − 2gᵀJ'w against (μ(x + hδx, F + hδF) − μ(x − hδx, F − hδF)) / 2h with the
    generic μ, the kinematics re-evaluated at both configurations (two step sizes: the
    difference converges to the analytic value)."""
    vm, d, solver, eqs = case
    kern, mask, free, task = _kernel(vm, solver, d)
    assert mask is not None  # these models take the screw form
    checked = 0
    for eq in eqs:
        b = blocks_at(vm, eq.x, eq.wrench, solver.kin)
        got = kern.point(b, mask, eq.wrench, fn)
        if got is None:
            continue
        _, xd, fd, _, rate = got
        x_dot = np.zeros_like(eq.x)
        x_dot[free] = xd
        w_dot = np.zeros(6)
        w_dot[task] = fd
        sc = np.abs(xd / solver.var_scale).max()

        def mu_at(h, eq=eq, x_dot=x_dot, w_dot=w_dot):
            return _generic_mu(vm, d, blocks_at(vm, eq.x + h * x_dot, eq.wrench + h * w_dot, solver.kin))

        # central differences and their Richardson extrapolation over a range of steps: μ is
        # strongly curved on the straight column (small steps needed) and tiny past buckling
        # (rounding dominates small steps); the differences converge to the analytic value
        best = np.inf
        for step in (1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
            h = step / sc
            d1 = (mu_at(h) - mu_at(-h)) / (2 * h)
            d2 = (mu_at(h / 2) - mu_at(-h / 2)) / h
            best = min(best, abs(d1 - rate), abs((4 * d2 - d1) / 3 - rate))
        assert best <= 2e-5 * abs(rate), (kind, rate, best)
        checked += 1
    assert checked >= 2


def test_compiled_and_numpy_kernels_agree():
    fn = pk.compiled()
    if not fn:
        pytest.skip("numba is not importable here: the numpy path is the only one")
    vm, d, solver, eqs = _equilibria("paper-c-s", [-1.0, 0.0, 0.0], 6e-4, 4)
    kern, mask, _, _ = _kernel(vm, solver, d)
    for eq in eqs:
        b = blocks_at(vm, eq.x, eq.wrench, solver.kin)
        a, c = kern.point(b, mask, eq.wrench, None), kern.point(b, mask, eq.wrench, fn)
        assert (a is None) == (c is None)
        if a is None:
            continue
        assert c[0] == pytest.approx(a[0], rel=1e-10)
        assert np.allclose(c[1], a[1], rtol=1e-10, atol=1e-12 * np.abs(a[1]).max())
        assert np.allclose(c[2], a[2], rtol=1e-10, atol=1e-12 * np.abs(a[2]).max())
        scale = _scale(vm, d, b)
        assert abs(c[3] - a[3]) <= 1e-12 * scale
        assert c[4] == pytest.approx(a[4], rel=1e-6, abs=1e-12 * scale)


def test_kernel_on_the_solvers_k_theta_block_is_the_kernel_on_its_own():
    """The tracer hands the point kernel the solver's ``K_θ ⊕ 0`` (no copy): the same points as a
    kernel that builds its own, bit for bit; a block of another shape or type is refused."""
    vm, d, solver, eqs = _equilibria("paper-c-s", [-1.0, 0.0, 0.0], 6e-4, 3)
    dt = d[np.asarray(vm.task)]
    own = pk.PointKernel(vm.K_theta, solver.free, dt, vm.task)
    shared = pk.PointKernel(vm.K_theta, solver.free, dt, vm.task, kz=solver._kz)
    assert np.array_equal(own.kz, shared.kz)
    mask = solver.kin.support_mask(solver.free)
    for eq in eqs:
        b = blocks_at(vm, eq.x, eq.wrench, solver.kin)
        for fn in (None, pk.compiled() or None):
            a, c = own.point(b, mask, eq.wrench, fn), shared.point(b, mask, eq.wrench, fn)
            assert (a is None) == (c is None)
            if a is not None:
                assert all(np.array_equal(u, v) for u, v in zip(a, c) if u is not None)
    n = len(solver.free)
    for bad in (np.zeros((n - 1, n)), np.zeros((n, n), np.float32)):
        with pytest.raises(ValueError, match="kz must be"):
            pk.PointKernel(vm.K_theta, solver.free, dt, vm.task, kz=bad)


@pytest.mark.parametrize("kind,fn", _kernels())
def test_rigid_start_is_left_to_the_generic_path(kind, fn):
    """Model A S unloaded: the straight chain of rigid links cannot move along x to first order
    (J rank deficient, eq. 28 singular): the kernel declines and the generic path says ``inf``."""
    vm = resolve_model("paper-a-s")
    solver = EquilibriumSolver(vm)
    d = _direction(vm, [-1.0, 0.0, 0.0])
    kern, mask, _, _ = _kernel(vm, solver, d)
    b = blocks_at(vm, vm.reference, np.zeros(6), solver.kin)
    assert kern.point(b, mask, np.zeros(6), fn) is None
    assert np.isinf(_stiffness_along(vm, b, d)[0])


def _trace_both(name, direction, max_deflection, steps):
    """The curve with every point by the generic path and with the kernel, both with the
    first-order predictor (the second-order one changes the Newton iterates: its own test in
    tests/test_curve.py)."""
    vm = resolve_model(name)
    old, old2 = curve_mod._fast_points, curve_mod._second_order
    try:
        curve_mod._second_order = False
        curve_mod._fast_points = False
        generic = trace_curve(vm, direction, max_deflection, steps=steps)
        curve_mod._fast_points = old
        fast = trace_curve(vm, direction, max_deflection, steps=steps)
    finally:
        curve_mod._fast_points, curve_mod._second_order = old, old2
    return generic, fast


@pytest.mark.parametrize(
    "name,direction,max_deflection,steps,crit_rel",
    [
        ("paper-c-s", [-1.0, 0.0, 0.0], 0.5, 12, 1e-9),
        ("paper-a-s", [-1.0, 0.0, 0.0], 1.0, 8, 1e-9),
        # an imperfect point is the root of dμ/ds at a flat maximum of μ: it moves with the
        # rounding of μ (by ~1e-7 already between two runs of the generic path whose μ differ
        # by rounding only), and the forward difference it used had an O(h) bias
        ("paper-b-z", [-1.0, 0.0, 0.0], 0.1, 6, 1e-6),
        ("ur5", [0.0, 0.0, -1.0], 1e-3, 6, 1e-9),
        # Model A Z: the margin's top eigenvalue alone far below ‖T‖ (a Laguerre iterate that overshot
        # it once gave μ off by 1/8 at two points of this curve)
        ("paper-a-z", [-1.0, 0.0, 0.0], 0.2, 15, 1e-9),
    ],
)
def test_curves_match_the_generic_per_point_path(name, direction, max_deflection, steps, crit_rel):
    generic, fast = _trace_both(name, direction, max_deflection, steps)
    assert len(fast.points) == len(generic.points)
    scale = np.abs(generic.forces).max()
    assert np.abs(fast.forces - generic.forces).max() <= 1e-9 * scale
    mscale = max(abs(p.force_control_margin) for p in generic.points)
    for p, q in zip(generic.points, fast.points):
        assert (p.stable, p.stable_end_held) == (q.stable, q.stable_end_held)
        assert (p.force_control_margin > 0) == (q.force_control_margin > 0)
        assert abs(p.force_control_margin - q.force_control_margin) <= 1e-9 * mscale
        if np.isfinite(p.stiffness):
            assert q.stiffness == pytest.approx(p.stiffness, rel=1e-8, abs=1e-12 * scale / max_deflection)
        else:
            assert np.isinf(p.stiffness) == np.isinf(q.stiffness)
    assert [c.kind for c in fast.critical] == [c.kind for c in generic.critical]
    for a, c in zip(generic.critical, fast.critical):
        assert c.force == pytest.approx(a.force, rel=crit_rel)
        assert c.index == a.index


def test_curve_module_does_not_import_numba_and_jit_off_never_does():
    code = (
        "import sys\n"
        "import vjm_pin.analysis.curve as c\n"
        "assert 'numba' not in sys.modules, 'imported at module import'\n"
        "from vjm_pin.model.registry import resolve_model\n"
        "c.trace_curve(resolve_model('paper-c-s'), [-1, 0, 0], 0.5, steps=12)\n"
        "assert 'numba' not in sys.modules, 'imported with VJM_PIN_JIT=0'\n"
    )
    env = dict(os.environ, VJM_PIN_JIT="0")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0, r.stderr


def _symmetric_cases():
    rng = np.random.default_rng(7)
    out = []
    for n in (1, 2, 3, 6, 20, 37):
        a = rng.standard_normal((n, n))
        out.append(a + a.T)
        g = np.diag(np.logspace(-6, 6, n)) @ (a + a.T) @ np.diag(np.logspace(-6, 6, n))
        out.append(g)  # graded: eigenvalues over ~24 decades
    b = rng.standard_normal((8, 8))
    q, _ = np.linalg.qr(b)
    out.append(q @ np.diag([3.0, 3.0, 1.0, 0.5, -1.0, -2.0, -4.0, -9.0]) @ q.T)  # a double top eigenvalue
    blk = np.zeros((6, 6))
    blk[:3, :3] = np.diag([1.0, -2.0, 0.5])
    blk[3:, 3:] = np.array([[2.0, 1.0, 0.0], [1.0, -1.0, 0.3], [0.0, 0.3, 0.7]])
    out.append(blk)  # decoupled: the tridiagonal form splits
    out.append(np.zeros((4, 4)))
    out.append(-np.eye(5))  # every eigenvalue equal
    return out


@pytest.mark.parametrize("compiled_", [False, True], ids=["python", "compiled"])
def test_top_eigenpair_matches_lapack(compiled_):
    """The compiled kernel's largest eigenpair (tridiagonalisation, Sturm bisection, inverse
    iteration) against LAPACK's full decomposition: the value to a few ε‖a‖, the vector a unit
    eigenvector (residual ε‖a‖; inside the eigenspace for a multiple eigenvalue)."""
    if compiled_:
        if not pk.compiled():
            pytest.skip("numba is not importable here")
        fn = pk._top_eigpair  # compiled() replaced the module global by its compiled twin
        assert hasattr(fn, "py_func")
    else:
        fn = getattr(pk._top_eigpair, "py_func", pk._top_eigpair)
    for a in _symmetric_cases():
        ev = np.linalg.eigvalsh(a)
        lam, v = fn(a.copy())
        scale = max(np.abs(ev).max(), 1e-300)
        assert abs(lam - ev[-1]) <= 1e-14 * scale * max(1, a.shape[0] / 4), (a.shape, lam, ev[-1])
        assert abs(np.linalg.norm(v) - 1.0) <= 1e-13
        assert np.linalg.norm(a @ v - lam * v) <= 1e-13 * scale * a.shape[0], a.shape


# --------------------------------------------------------------------------- the corrector's own QR
def _corrector_points(name, direction, max_deflection, steps, monkeypatch):
    """The compiled tracer's converged corrector answers of a short curve (each with the prediction it
    started from and the continuity limit), the tracer and the curve."""
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    from vjm_pin.solver.equilibrium import EquilibriumSolver as Solver

    raws = []
    original = Solver._corrector

    def corrector(self, ctx, p_t, r_t, x, flushed=False):
        raw = original(self, ctx, p_t, r_t, x, flushed)
        if raw is not None:
            # (the loop's (QᵀWQ)ᵀ is valid until the next call: kept as it was at this convergence)
            raws.append((raw[:8] + (None if raw[8] is None else raw[8].copy(),), np.array(x, float)))
        return raw

    monkeypatch.setattr(Solver, "_corrector", corrector)
    # the three calls with Python between them (the merged step, bit for bit the same, does not go
    # through _corrector: tests/test_merged_step.py)
    monkeypatch.setattr(curve_mod, "_merged", False)
    vm = resolve_model(name)
    solver = EquilibriumSolver(vm)
    c = trace_curve(vm, direction, max_deflection, steps=steps, solver=solver)
    monkeypatch.setattr(Solver, "_corrector", original)
    tr = curve_mod._Tracer(vm, _direction(vm, direction), max_deflection, solver, 1e-4)
    tr._reuse_setup()
    return vm, tr, raws, c


#: The serial models whose curves take the fused corrector (a null space: m < n; a 6-D robot with n = m
#: has none): buckling, the imperfect column, the knee of Model C Z.
REUSE_CASES = [("paper-c-s", [-1.0, 0.0, 0.0], 0.004, 8), ("paper-b-z", [-1.0, 0.0, 0.0], 0.1, 4),
               ("paper-c-z", [-1.0, 0.0, 0.0], 0.012, 6)]


@pytest.mark.parametrize("name,direction,max_deflection,steps", REUSE_CASES, ids=[c[0] for c in REUSE_CASES])
def test_point_on_the_correctors_qr_matches_the_recomputing_kernels(name, direction, max_deflection, steps,
                                                                     monkeypatch):
    """The fused step's point on the converged Newton iteration's own Householder reflectors
    (``_reuse_point_loops``) against eq. (28) solved exactly (the tangent: the null-space solve is at least
    as close as the recomputing kernel's inverse) and the compiled kernel that factors ``J`` again
    (``_point_loops``: μ and dμ/ds to rounding) and the numpy kernel on the equilibrium's Blocks; the
    force ``dᵀF``, the tangent's layout, and the status of a strayed corrector and of a declined rank test."""
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    vm, tr, raws, _ = _corrector_points(name, direction, max_deflection, steps, monkeypatch)
    assert tr._reuse and len(raws) >= steps
    fn, ci, cfl, kz, mask = tr._rargs
    kern, nq = tr.kernel, vm.model.nq
    checked = 0
    errs = []  # (|k − k_exact| here, the same for the recomputing kernel, |δF|)
    for raw, x_pred in raws:
        x, kf, j6 = raw[0], raw[4], raw[3].jacobian
        assert kf[1].shape == (kern.m + 1, kern.n)  # the compiled corrector's reflectors
        out = np.full(nq + 6, np.nan)
        st, k, mu, rate, force = fn(x, x_pred, np.inf, j6, kf[1], kf[6], kf[7], curve_mod._NO_WT, ci, cfl, kz, mask,
                                    out)
        assert force == pytest.approx(float(tr.d @ kf[7]), rel=1e-15, abs=1e-300)
        jfree = np.ascontiguousarray(j6.take(tr.free, axis=1))
        want = pk.compiled()(jfree, kf[6], kz, kern.task, kern.dt, mask, kf[7], kern.nt, True, pk.FAST_RANK,
                             curve_mod.SINGULAR_RCOND)
        # the same decision, except that a point the equilibrated inverse's regularity bound declines
        # (eq. 28 near-singular: at the straight column's buckling) may be solved here when the
        # refinement confirms it (then checked against the exact solution only)
        assert st == want[0] or (st, want[0]) == (0, 1)
        b = blocks_at(vm, x, kf[7], tr.kin)
        ref = kern.point(b, mask, kf[7], None)  # numpy, on the Blocks
        if st:
            continue
        checked += 1
        beyond = want[0] == 1
        # the tangent (null-space solve on the corrector's QR, refined) against eq. (28) solved exactly
        # from the same J, H and K: within the forward error bound of a backward-stable solve, and over
        # the curve as close as the recomputing kernel's equilibrated inverse
        jac = jfree[kern.task]
        xe, fe = eq28_exact(jac, kf[6] - kz, kern.dt)
        ke = float(sum(Fraction(float(v)) * f for v, f in zip(kern.dt, fe)))
        xs = np.array([float(v) for v in xe])
        fs = np.array([float(v) for v in fe])
        # a backward-stable solve's forward error, norm-wise in the equilibrated unknowns y = D⁻¹(δF, δx)
        # of eq. (28) (as both kernels scale it): |Δy| ≲ ε·cond·|y|, so |Δk| ≲ ε·cond·|y|·Σ|d_t D_F|
        m_ = len(kern.task)
        big = np.block([[np.zeros((m_, m_)), jac], [jac.T, kf[6] - kz]])
        s_eq, dg = _ruiz(big)
        y = np.concatenate([fs, xs]) / dg
        tol = 100.0 * np.finfo(float).eps * np.linalg.cond(s_eq) * np.abs(y).max()
        kscale = float(np.abs(fs).max())
        assert abs(k - ke) <= tol * np.abs(kern.dt * dg[:m_]).sum(), (k, ke)
        assert np.abs((out[:nq][tr.free] - xs) / dg[m_:]).max() <= tol
        assert np.abs((out[nq:][tr.task] - fs) / dg[:m_]).max() <= tol
        assert not out[:nq][np.setdiff1d(np.arange(nq), tr.free)].any()
        assert not out[nq:][np.setdiff1d(np.arange(6), kern.task)].any()
        if beyond:
            continue
        errs.append((abs(k - ke), abs(want[1] - ke), kscale))
        scale = max(_scale(vm, tr.d, b), abs(mu))
        assert abs(mu - want[4]) <= 1e-12 * scale
        assert rate == pytest.approx(want[5], rel=1e-9, abs=1e-12 * scale)
        assert ref is not None
        assert abs(k - ref[0]) <= 2.0 * tol * np.abs(kern.dt * dg[:m_]).sum()
        assert abs(mu - ref[3]) <= 1e-10 * scale
        assert rate == pytest.approx(ref[4], rel=1e-6, abs=1e-12 * scale)
        # a corrector that strayed: nothing else done (out untouched)
        out2 = np.full(nq + 6, np.nan)
        corr = float(np.abs((x - x_pred)[tr.free] / tr.var_scale).max())
        if corr > 0:
            assert fn(x, x_pred, corr * (1 - 1e-12), j6, kf[1], kf[6], kf[7], curve_mod._NO_WT, ci, cfl, kz, mask,
                      out2)[0] == -1
            assert np.isnan(out2).all()
        # a rank test that cannot pass: declined
        cfl2 = cfl.copy()
        cfl2[0] = 2.0  # σ_min > 2 σ_max never holds
        assert fn(x, x_pred, np.inf, j6, kf[1], kf[6], kf[7], curve_mod._NO_WT, ci, cfl2, kz, mask, out2)[0] == 1
    assert checked >= len(raws) - 2
    new_err, old_err, ks = np.array(errs).T
    # as accurate as the equilibrated inverse: the two round differently (their largest errors over a
    # curve were within a factor 3 of each other either way, the medians within 2); each point is
    # bounded above by ε·cond
    floor = 1e-15 * ks.max()
    assert new_err.max() <= 4.0 * old_err.max() + floor, (new_err.max(), old_err.max())
    assert np.median(new_err) <= 2.0 * np.median(old_err) + floor, (np.median(new_err), np.median(old_err))


def test_rate_on_the_correctors_qr_matches_central_differences(monkeypatch):
    """dμ/ds of ``_reuse_point_loops`` against central differences of the generic μ along its own
    tangent (the kinematics re-evaluated at both ends; Richardson over a range of steps)."""
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    # before buckling (μ strongly curved) and past it (the bent branch: a small rate)
    vm, tr, raws, _ = _corrector_points("paper-c-s", [-1.0, 0.0, 0.0], 6e-4, 6, monkeypatch)
    fn, ci, cfl, kz, mask = tr._rargs
    nq = vm.model.nq
    rates = []
    for raw, x_pred in raws:
        x, kf, j6 = raw[0], raw[4], raw[3].jacobian
        out = np.empty(nq + 6)
        st, _, _, rate, _ = fn(x, x_pred, np.inf, j6, kf[1], kf[6], kf[7], curve_mod._NO_WT, ci, cfl, kz, mask, out)
        if st:
            continue
        x_dot, w_dot = out[:nq], out[nq:]
        sc = np.abs(x_dot[tr.free] / tr.var_scale).max()

        def mu_at(h, x=x, kf=kf, x_dot=x_dot, w_dot=w_dot):
            return _generic_mu(vm, tr.d, blocks_at(vm, x + h * x_dot, kf[7] + h * w_dot, tr.kin))

        best = np.inf
        for step in (1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
            h = step / sc
            d1 = (mu_at(h) - mu_at(-h)) / (2 * h)
            d2 = (mu_at(h / 2) - mu_at(-h / 2)) / h
            best = min(best, abs(d1 - rate), abs((4 * d2 - d1) / 3 - rate))
        rates.append((rate, best))
    # relative to the rate, and to the largest rate for the small ones (past buckling dμ/ds is ~1e-4 of
    # its size before it; the differences' rounding is the same in absolute terms)
    big = max(abs(r) for r, _ in rates)
    for rate, best in rates:
        assert best <= 2e-5 * abs(rate) + 2e-9 * big, (rate, best)
    assert len(rates) >= 4 and min(abs(r) for r, _ in rates) < 1e-3 * big  # both kinds checked


@pytest.mark.parametrize("name,direction,max_deflection,steps", REUSE_CASES, ids=[c[0] for c in REUSE_CASES])
def test_point_on_the_correctors_own_qwq_is_the_recomputing_point(name, direction, max_deflection, steps,
                                                                   monkeypatch):
    """The converged corrector hands the point kernel its ``(Qᵀ(K − H)Q)ᵀ`` (``ws[11]``, the raw
    equilibrium's last item): it is bit for bit the matrix computed again from the reflectors, ``H(F)``
    and ``K`` kept with it (``kernel._qwq_t``), and the point kernel gives the same status, stiffness,
    μ, dμ/ds, force and tangent with it as without it (every number, bit for bit)."""
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    from vjm_pin.solver import kernel

    vm, tr, raws, _ = _corrector_points(name, direction, max_deflection, steps, monkeypatch)
    fn, ci, cfl, kz, mask = tr._rargs
    nq, n, m = vm.model.nq, tr.kernel.n, tr.kernel.m
    given = 0
    for raw, x_pred in raws:
        x, kf, j6, wt = raw[0], raw[4], raw[3].jacobian, raw[8]
        if wt is None:
            continue
        given += 1
        assert wt.shape == (n, n)
        again = np.empty((n, n))
        kernel._qwq_t(kf[1], kf[6], kz, m, n, again)
        assert np.array_equal(wt, again)
        # and that matrix is (Qᵀ(K − H)Q)ᵀ: Q from the reflectors, applied to the identity
        q = np.eye(n)
        for c in range(n):
            kernel._q_vector(kf[1], q[:, c], m, n, False)
        assert np.abs(again - (q.T @ (kz - kf[6]) @ q).T).max() <= 1e-12 * np.abs(kz - kf[6]).max()
        outs = []
        for w in (wt, curve_mod._NO_WT):
            out = np.full(nq + 6, np.nan)
            outs.append((fn(x, x_pred, np.inf, j6, kf[1], kf[6], kf[7], w, ci, cfl, kz, mask, out), out))
        (a, oa), (b, ob) = outs
        assert a[0] == b[0] and np.array_equal(np.array(a[1:]), np.array(b[1:]), equal_nan=True)
        assert np.array_equal(oa, ob, equal_nan=True)
        assert np.array_equal(wt, again)  # read only: the corrector's buffer is not written by the point
    assert given >= steps


def test_curve_on_the_correctors_own_qwq_is_the_recomputing_curve(monkeypatch):
    """A whole compiled curve with the point kernel reading the corrector's ``(QᵀWQ)ᵀ`` and with it
    computing the matrix again (private switch ``curve._reuse_wt``): every point and critical point bit
    for bit."""
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    vm = resolve_model("paper-c-s")
    on = trace_curve(vm, [-1, 0, 0], 0.004, steps=40, solver=EquilibriumSolver(vm))
    monkeypatch.setattr(curve_mod, "_reuse_wt", False)
    off = trace_curve(vm, [-1, 0, 0], 0.004, steps=40, solver=EquilibriumSolver(vm))
    assert len(on.points) == len(off.points) == 41
    for p, q in zip(on.points, off.points):
        assert np.array_equal(p.equilibrium.x, q.equilibrium.x) and np.array_equal(p.wrench, q.wrench)
        assert (p.stiffness, p.force_control_margin, p.stable) == (q.stiffness, q.force_control_margin, q.stable)
    assert [(c.force, c.deflection, c.kind) for c in on.critical] == [(c.force, c.deflection, c.kind)
                                                                      for c in off.critical]
    assert on.critical


@pytest.mark.parametrize("name,direction,md,steps", [("paper-c-s", [-1, 0, 0], 0.004, 40),
                                                     ("paper-b-z", [-1, 0, 0], 0.1, 20)], ids=["c-s", "b-z"])
def test_curve_on_the_correctors_qr_is_the_recomputing_curve(name, direction, md, steps, monkeypatch):
    """Whole compiled curves with the fused step's point on the corrector's QR and with it factored
    again (private switch ``curve._reuse_qr``): the same points and critical points to rounding, and the
    reusing kernel is the one that ran."""
    if not pk.compiled():
        pytest.skip("numba is not importable here")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    vm = resolve_model(name)
    calls = {"n": 0}
    original = pk.reuse()

    def counted(*args):
        calls["n"] += 1
        return original(*args)

    monkeypatch.setattr(pk, "_reuse", counted)
    monkeypatch.setattr(curve_mod, "_merged", False)  # (the merged step calls the compiled one inside)
    on = trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    assert calls["n"] >= steps
    monkeypatch.setattr(curve_mod, "_reuse_qr", False)
    calls["n"] = 0
    off = trace_curve(vm, direction, md, steps=steps, solver=EquilibriumSolver(vm))
    assert calls["n"] == 0
    assert len(on.points) == len(off.points)
    scale = np.abs(off.forces).max()
    assert np.abs(on.forces - off.forces).max() <= 1e-10 * scale
    for p, q in zip(on.points, off.points):
        assert (p.stable, p.stable_end_held) == (q.stable, q.stable_end_held)
        assert p.stiffness == pytest.approx(q.stiffness, rel=1e-9)
        assert p.force_control_margin == pytest.approx(q.force_control_margin, rel=1e-8, abs=1e-10 * scale)
    assert [c.kind for c in on.critical] == [c.kind for c in off.critical]
    for a, c in zip(on.critical, off.critical):
        # an imperfect point (b-z) sits at a flat maximum of μ: it moves with the rounding of μ
        assert a.force == pytest.approx(c.force, rel=1e-9 if c.kind != "imperfect" else 1e-6)
        assert a.index == c.index
