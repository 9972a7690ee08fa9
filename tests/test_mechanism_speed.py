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


def _loaded_targets(ms, rng, size=2e-3):
    from vjm_pin.kinematics.chain import displace

    d = np.zeros(6)
    d[[c for c in ms.task if c < 3]] = size * rng.standard_normal(len([c for c in ms.task if c < 3]))
    return displace(ms.p0, ms.r0, d)


@pytest.mark.parametrize("which", ["orthoglide-loop", "rssr-weld"])
def test_line_search_trial_placements_equal_the_full_evaluation(which):
    """The line search's trial points use placements only (no Jacobians): the closure residual,
    the held rows' right-hand side and the task frame placement equal the full evaluation's."""
    vm = _orthoglide_loop() if which == "orthoglide-loop" else spatial_rssr(3, weld=True, task=("x", "y", "z"))[1]
    ms = MechanismSolver(vm)
    rng = np.random.default_rng(5)
    for hrows in (list(range(len(ms.task))), [0], []):
        x = _random_x(vm, rng)
        p_t, r_t = _loaded_targets(ms, rng)
        end, b = ms._trial(x, hrows, p_t, r_t)
        ms.frames._last = None
        full = ms._state(x, hrows, np.zeros(6), p_t, r_t, 1.0, False)
        assert np.abs(b - full.b).max() <= 1e-14 * max(np.abs(full.b).max(), 1.0)
        assert np.abs(end.position - full.end.position).max() <= 1e-15
        assert np.abs(end.rotation - full.end.rotation).max() <= 1e-15
        placements = {f: (st.position, st.rotation) for f, st in ms.frames.evaluate(x, hessian=False).items()}
        assert np.abs(ms.closures.residual_from(placements) - ms.closures.evaluate(x, False).residual).max() <= 1e-15


@pytest.mark.parametrize("which", ["four-bar", "rssr-weld"])
def test_descent_with_second_order_correction_reaches_the_equilibrium_without_it(which):
    """The branch switch's descents try a rejected trial point again with the second-order
    correction (``_newton(soc=True)``): from far starts it converges to the same equilibrium as
    the plain descent."""
    from vjm_pin.kinematics.chain import displace
    from vjm_pin.solver.mechanism import STALL_WINDOW

    vm = resolve_model("four-bar") if which == "four-bar" else spatial_rssr(3, weld=True, task=("x", "y", "z"))[1]
    ms = MechanismSolver(vm)
    rng = np.random.default_rng(3)
    p_t, r_t = displace(ms.p0, ms.r0, np.zeros(6))
    hrows = list(range(len(ms.task)))
    for _ in range(3):
        x0 = vm.reference.copy()
        x0[ms.free] += 0.3 * rng.standard_normal(len(ms.free))
        budget = DESCENT_ITER_FACTOR * ms.max_iter
        xa, _, oka, _ = ms._newton(x0, hrows, np.zeros(6), p_t, r_t, 1.0, budget, stall=STALL_WINDOW)
        xb, _, okb, sb = ms._newton(x0, hrows, np.zeros(6), p_t, r_t, 1.0, budget, stall=STALL_WINDOW, soc=True)
        assert oka and okb
        assert np.abs((xa - xb)[ms.free] / ms.var_scale).max() <= 1e-8
        res = ms._result(xb, 0, True, hrows, np.zeros(6), p_t, r_t, "", state=sb)
        assert res.residual() <= 1e-8


def test_null_basis_from_one_svd_has_the_rank_of_constraint_rank():
    """``_null_basis`` takes the rank from its own SVD of the row-normalised matrix: the same
    rank as :func:`constraint_rank` (redundant and zero rows included) and an orthonormal basis
    of the null space."""
    from vjm_pin.kinematics.closures import constraint_rank
    from vjm_pin.solver.mechanism import _null_basis

    rng = np.random.default_rng(4)
    for m, n, dep in ((5, 12, 0), (8, 12, 3), (6, 6, 2), (4, 9, 0)):
        a = rng.standard_normal((m, n)) * np.array([1e-3, 1.0, 10.0, 1.0, 1.0, 1.0, 1.0, 1.0][:m])[:, None]
        for i in range(dep):  # redundant rows: combinations of the first ones
            a[m - 1 - i] = rng.standard_normal(2) @ a[:2]
        a[0, :] = 0.0 if m == 4 else a[0, :]  # an identically zero row
        z, rank = _null_basis(a, 1e-10)
        assert rank == constraint_rank(a, rtol=1e-10).rank
        assert z.shape == (n, n - rank)
        assert np.abs(z.T @ z - np.eye(n - rank)).max() <= 1e-12
        assert np.abs(a @ z).max() <= 1e-10 * np.abs(a).max()


def test_mechanism_tracer_margin_alone_equals_the_full_evaluation():
    """``evaluate(mu_only=True)`` (the margin's derivative and the rigid-start search) returns the
    margin μ of the full evaluation."""
    from vjm_pin.analysis.mechanism_curve import MechanismTracer

    vm = _orthoglide_loop()
    ms = MechanismSolver(vm)
    d = np.array([1.0, -1.0, 1.0, 0.0, 0.0, 0.0]) / np.sqrt(3)
    rng = np.random.default_rng(12)
    for free in (True, False):
        tr = MechanismTracer(vm, d, 5e-3, ms, 1e-6, free)
        lin = tr.run.linearize(_random_x(vm, rng, 5e-3), tr.hrows, tr.wdead)
        full = tr.evaluate(lin, need_tangent=False)
        alone = tr.evaluate(lin, need_tangent=False, mu_only=True)
        assert alone[0] == pytest.approx(full[0], rel=1e-12, abs=1e-12 * ms.kscale)


def test_closure_hessian_added_by_runs_of_columns_is_the_fancy_indexed_sum():
    """The multiplier Hessian accumulates each closure's block by slices over the contiguous runs
    of its columns (``_add_block``; ``np.ix_`` beyond three breaks): bit for bit the
    ``out[np.ix_(cols, cols)] += block`` sum, for the Orthoglide's closures and for column sets of
    one to many runs."""
    from vjm_pin.kinematics.closures import _add_block

    vm = _orthoglide_loop()
    ms = MechanismSolver(vm)
    rng = np.random.default_rng(5)
    for _ in range(3):
        cst = ms.closures.evaluate(_random_x(vm, rng), hessian=True)
        lam = 1e3 * rng.standard_normal(cst.residual.size)
        ref = np.zeros((vm.model.nv, vm.model.nv))
        for cf, lam6 in zip(cst.frames, cst._split(lam)):
            cols, block = cf.hessian_block(lam6)
            ref[np.ix_(cols, cols)] += block
        assert np.array_equal(cst.hessian(lam), ref)
    for cols in ([3, 4, 5], [0, 1, 5, 6, 9], [0, 2, 4, 6, 8, 10], list(range(7)) + [12, 13]):
        cols = np.array(cols)
        out = rng.standard_normal((14, 14))
        ref = out.copy()
        block = rng.standard_normal((len(cols), len(cols)))
        ref[np.ix_(cols, cols)] += block
        _add_block(out, cols, block)
        assert np.array_equal(out, ref)


def test_row_rank_is_the_rank_of_constraint_rank():
    """The solver's full-rank shortcut (``row_rank``: no pivoted QR when every row is independent)
    takes the rank of :func:`constraint_rank` itself, and refuses what it refuses."""
    from vjm_pin.exceptions import InputError
    from vjm_pin.kinematics.closures import constraint_rank, row_rank

    rng = np.random.default_rng(8)
    for m, dep in ((6, 0), (8, 3), (5, 1)):
        a = rng.standard_normal((m, 12)) * rng.uniform(1e-3, 1e3, (m, 1))
        for i in range(dep):
            a[m - 1 - i] = rng.standard_normal(2) @ a[:2]
        info = constraint_rank(a)
        assert row_rank(a)[4] == info.rank == m - dep
        assert np.array_equal(row_rank(a)[2], info.singular_values)
    with pytest.raises(InputError, match="finite"):
        row_rank(np.array([[np.inf, 1.0]]))


@pytest.mark.parametrize("free", [True, False])
def test_mechanism_tracer_point_judges_as_the_full_evaluation(free):
    """A tracer point computes μ, λ and both verdicts when first read: the numbers of
    :meth:`MechanismTracer.evaluate` on the same linearisation, bit for bit."""
    from vjm_pin.analysis.mechanism_curve import MechanismTracer

    vm = _orthoglide_loop()
    ms = MechanismSolver(vm)
    d = np.array([1.0, -1.0, 1.0, 0.0, 0.0, 0.0]) / np.sqrt(3)
    tr = MechanismTracer(vm, d, 5e-3, ms, 1e-6, free)
    eq = tr.solve(1e-3, vm.reference)
    lin = tr.run.linearize(eq.x, tr.hrows, tr.wdead)
    mu, lam, run, end, tan, k, z_run = tr.evaluate(lin)
    p = tr.point(eq, 1e-3, lin)
    assert p.k == k and np.array_equal(p.tan[0], tan[0])
    assert p.lam == lam and p.mu == mu
    assert np.array_equal(p.run.eigenvalues, run.eigenvalues) and np.array_equal(p.z_run, z_run)
    assert np.array_equal(p.end.eigenvalues, end.eigenvalues) and p.end.stable == end.stable


def test_newton_gives_up_beyond_its_radius():
    """``_newton(radius=...)``: an iterate farther than the radius from the start ends the attempt
    (not converged, no state); an unreachable radius changes nothing, bit for bit."""
    vm = resolve_model("four-bar")
    ms = MechanismSolver(vm)
    p_t, r_t = ms.p0 + np.array([2e-3, 0.0, 0.0]), ms.r0
    hrows = [ms.task.index(c) for c in ms.task]
    x0 = vm.reference.copy()
    plain = ms._newton(x0, hrows, np.zeros(6), p_t, r_t, 1.0, ms.max_iter)
    wide = ms._newton(x0, hrows, np.zeros(6), p_t, r_t, 1.0, ms.max_iter, radius=1e9)
    assert plain[2] and wide[2] and np.array_equal(plain[0], wide[0]) and plain[1] == wide[1]
    x, it, ok, st = ms._newton(x0, hrows, np.zeros(6), p_t, r_t, 1.0, ms.max_iter, radius=1e-9)
    assert not ok and st is None and it == 1
    assert np.abs((x - x0)[ms.free] / ms.var_scale).max() > 1e-9
