"""Equilibrium, stability and stiffness against closed forms, general forms and re-solved equilibria."""

import numpy as np
import pytest

from vjm_pin import (
    EquilibriumSolver,
    NoEquilibrium,
    load_vjm,
    loaded_stiffness,
    unloaded_stiffness,
)
from vjm_pin.model.paper_models import paper_model_urdf
from vjm_pin.solver import (
    blocks_at,
    check_stability,
    stiffness_eq30,
    stiffness_eq32,
    stiffness_eq33,
)

from .chains import random_vjm


def rel(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


def loaded_equilibrium(vm, seed, size=0.02, **solver_kw):
    """A converged, stable loaded equilibrium of ``vm`` at a random deflection."""
    rng = np.random.default_rng(seed)
    solver = EquilibriumSolver(vm, tol=1e-12, **solver_kw)
    d = np.zeros(6)
    d[list(vm.task)] = rng.standard_normal(len(vm.task)) * size
    res = solver.solve(d)
    assert res.converged and res.stable, res.path
    return solver, res


# --------------------------------------------------------------------------- eq. 35
@pytest.mark.parametrize("delta", [1e-4, 0.01, 0.1, 0.3, 0.6, 1.0])
def test_model_a_stable_branch_matches_eq35(delta):
    """Model A, S posture: F = (Kθ/L) φ/sin φ, φ = arccos(1 − δ/2) (eq. 35), Kθ = 1 N·m/rad, L = 1 m."""
    vm = load_vjm(paper_model_urdf("a", "s"))
    res = EquilibriumSolver(vm, tol=1e-12).solve([-delta, 0, 0])
    phi = np.arccos(1 - delta / 2)
    f_analytic = phi / np.sin(phi)
    assert res.converged and res.stable
    assert abs(-res.wrench[0] - f_analytic) / f_analytic < 1e-6, (res.wrench, f_analytic)
    assert abs(res.wrench[1]) < 1e-9
    # the stable shape is the symmetric trapezoid: θ1 = θ2 = ∓φ
    assert np.allclose(np.abs(res.theta), phi, atol=1e-8)


def test_fixed_point_eq10_and_newton_agree_far_from_buckling():
    vm = load_vjm(paper_model_urdf("a", "pi"))
    d = [-0.05, 0.02, 0]
    a = EquilibriumSolver(vm, method="newton", tol=1e-12).solve(d)
    b = EquilibriumSolver(vm, method="fixed-point", tol=1e-12, max_iter=500).solve(d)
    assert a.converged and b.converged
    assert b.path.startswith("fixed-point") and a.path.startswith("newton")
    assert np.allclose(a.x, b.x, atol=1e-8)
    assert rel(a.wrench, b.wrench) < 1e-8


# --------------------------------------------------------------------------- eq. 30/32/33
@pytest.mark.parametrize("seed", range(6))
def test_eq30_eq32_eq33_agree_at_loaded_stable_equilibria(seed):
    vm = random_vjm(
        seed,
        n_joints=5,
        n_passive=seed % 3,
        link_springs=2,
        spring_dofs=["x", "y", "z", "rx", "ry", "rz"],
    )
    solver, res = loaded_equilibrium(vm, seed)
    assert np.abs(res.wrench).max() > 1e-3  # really loaded
    b = blocks_at(vm, res.x, res.wrench)
    k30 = stiffness_eq30(b, vm.task)
    k32 = stiffness_eq32(b, vm.task)
    k33 = stiffness_eq33(b, vm.task)
    assert rel(k32.stiffness, k30.stiffness) < 1e-8
    assert rel(k33.stiffness, k30.stiffness) < 1e-8
    assert rel(k32.dq_dt, k30.dq_dt) < 1e-8 if vm.n_q else True
    assert rel(k33.dtheta_dt, k30.dtheta_dt) < 1e-8
    assert rel(k32.dtheta_dt, k30.dtheta_dt) < 1e-8


@pytest.mark.parametrize("seed", range(3))
def test_eq30_eq32_eq33_agree_on_loaded_model_c(seed):
    beam = dict(section="rectangle", a=0.02, b=0.05, E=2e11, nu=0.3)
    vm = load_vjm(paper_model_urdf("c", ["s", "pi", "z"][seed], beam=beam))
    res = EquilibriumSolver(vm, tol=1e-12).solve([-2e-4 * (seed + 1), 1e-4, 0])
    assert res.converged and res.stable
    b = blocks_at(vm, res.x, res.wrench)
    k = [f(b, vm.task).stiffness for f in (stiffness_eq30, stiffness_eq32, stiffness_eq33)]
    assert rel(k[1], k[0]) < 1e-8 and rel(k[2], k[0]) < 1e-8


# --------------------------------------------------------------------------- Table 1
def test_unloaded_salisbury_for_actuated_chain():
    """Non-redundant chain, elasticity in the actuators only: K_C = J⁻ᵀ K_θ J⁻¹ (Salisbury)."""
    vm = random_vjm(11, n_joints=6, n_passive=0, link_springs=0)
    b = blocks_at(vm, vm.reference, np.zeros(6))
    j = b.J_theta
    k_sal = np.linalg.inv(j).T @ vm.K_theta @ np.linalg.inv(j)
    for method in ("eq30", "eq32", "eq33"):
        assert rel(unloaded_stiffness(vm, method).stiffness, k_sal) < 1e-8, method


@pytest.mark.parametrize("seed", range(4))
def test_unloaded_with_passive_joints_matches_table1(seed):
    """[[J_θ K_θ⁻¹ J_θᵀ, J_q], [J_qᵀ, 0]]⁻¹, upper-left block (Pashkevich et al. [49])."""
    vm = random_vjm(
        20 + seed,
        n_joints=5,
        n_passive=1 + seed % 2,
        link_springs=2,
        spring_dofs=["x", "y", "z", "rx", "ry", "rz"],
    )
    b = blocks_at(vm, vm.reference, np.zeros(6))
    m = 6
    big = np.block(
        [
            [b.J_theta @ np.linalg.inv(vm.K_theta) @ b.J_theta.T, b.J_q],
            [b.J_q.T, np.zeros((vm.n_q, vm.n_q))],
        ]
    )
    k_tab = np.linalg.inv(big)[:m, :m]
    k = unloaded_stiffness(vm).stiffness
    assert rel(k, k_tab) < 1e-8
    # rank-deficient by the number of passive joints (each lets the end move freely)
    ev = np.linalg.eigvalsh(0.5 * (k + k.T))
    assert np.sum(np.abs(ev) < 1e-9 * np.abs(ev).max()) == vm.n_q


# --------------------------------------------------------------------------- loaded consistency
def check_fd_consistency(vm, solver, res, rng, n_dirs=3, h=1e-6):
    kc = loaded_stiffness(vm, res).stiffness
    task = list(vm.task)
    for _ in range(n_dirs):
        d = np.zeros(6)
        d[task] = rng.standard_normal(len(task))
        d *= h / np.linalg.norm(d)
        from vjm_pin.kinematics.chain import displace

        outs = []
        for s in (+1, -1):
            p, r = displace(res.position, res.rotation, s * d)
            outs.append(solver.solve(target=(p, r), x0=res.x, wrench0=res.wrench))
        assert all(o.converged for o in outs)
        df = (outs[0].wrench - outs[1].wrench) / 2
        assert rel(kc @ d, df) < 1e-4, (kc @ d, df)


@pytest.mark.parametrize("seed", range(5))
def test_loaded_stiffness_matches_resolved_equilibria(seed):
    """K_C δt ≈ F(t + δt) − F(t) from re-solved equilibria, with forces and moments (dead load)."""
    vm = random_vjm(40 + seed, n_joints=5, n_passive=seed % 3, link_springs=2)
    solver, res = loaded_equilibrium(vm, seed, size=0.05)
    check_fd_consistency(vm, solver, res, np.random.default_rng(seed))


def test_loaded_stiffness_model_c_postbuckling_matches_resolved_equilibria():
    beam = dict(section="rectangle", a=0.02, b=0.05, E=2e11, nu=0.3)
    vm = load_vjm(paper_model_urdf("c", "s", beam=beam))
    solver = EquilibriumSolver(vm, tol=1e-13)
    res = solver.solve([-1e-3, 0, 0])
    assert res.converged and res.stable
    assert abs(res.x[vm.joint_index("base_y")]) > 1e-3  # buckled out of plane
    check_fd_consistency(vm, solver, res, np.random.default_rng(7))


# --------------------------------------------------------------------------- stability
def test_straight_chain_beyond_critical_is_unstable_and_solver_leaves_it():
    vm = load_vjm(paper_model_urdf("a", "s"))
    # straight configuration under a compressive force above Kθ/L: unstable (eq. 23)
    st = check_stability(blocks_at(vm, vm.reference, np.array([-1.5, 0, 0, 0, 0, 0])))
    assert not st.stable and st.eigenvalues.max() > 0
    st = check_stability(blocks_at(vm, vm.reference, np.array([-0.5, 0, 0, 0, 0, 0])))
    assert st.stable


# --------------------------------------------------------------------------- dual problem
@pytest.mark.parametrize("seed", range(3))
def test_wrench_driven_equals_displacement_driven(seed):
    vm = random_vjm(60 + seed, n_joints=6, n_passive=0, link_springs=2)
    solver, res = loaded_equilibrium(vm, seed, size=0.03)
    back = solver.solve_wrench(res.wrench)
    assert back.converged
    assert np.allclose(back.deflection, res.deflection, atol=1e-8)
    assert rel(back.wrench, res.wrench) < 1e-8


def test_wrench_driven_with_passive_joints_needs_no_regular_stiffness():
    """A passive base makes K_C singular (eq. 11 was impossible); the total-potential Newton
    solves it: the Π chain under a small pull is a stable equilibrium whose wrench is the load."""
    vm = load_vjm(paper_model_urdf("a", "pi"))
    ev = np.linalg.eigvalsh(unloaded_stiffness(vm).task_stiffness)
    assert np.abs(ev).min() < 1e-9 * np.abs(ev).max()  # K_C⁻¹ of eq. 11 does not exist
    res = EquilibriumSolver(vm, tol=1e-12).solve_wrench([0.1, 0.0, 0, 0, 0, 0])
    assert res.converged and res.stable and res.stable_end_held
    assert np.allclose(res.wrench, [0.1, 0, 0, 0, 0, 0], atol=1e-15)
    assert res.deflection[0] > 1e-3  # the chain moved along the pull


def test_non_convergence_is_reported():
    vm = load_vjm(paper_model_urdf("a", "s"))
    solver = EquilibriumSolver(vm, max_iter=1, restarts=0)
    with pytest.raises(NoEquilibrium) as err:
        solver.solve([-2.5, 0, 0])  # δ = 2.5 needs a strongly folded chain
    assert err.value.result is not None and not err.value.result.converged
    res = solver.solve([-2.5, 0, 0], raise_on_failure=False)
    assert not res.converged


def test_fast_fail_makes_one_attempt():
    """``fast_fail`` (trial points of line searches): no perturbed restarts, so from the straight
    Model C chain past buckling it returns the unstable equilibrium a full solve leaves, in a
    fraction of the iterations; an impossible target raises without continuation."""
    from vjm_pin.model.registry import resolve_model

    vm = resolve_model("paper-c-s")
    solver = EquilibriumSolver(vm)
    d = [-0.02, 0, 0]
    full = solver.solve(d)
    fast = solver.solve(d, fast_fail=True)
    assert full.stable and ("restart" in full.path or "escape" in full.path)
    assert fast.converged and fast.stable is False and fast.path == "newton"
    assert fast.iterations < full.iterations / 10
    with pytest.raises(NoEquilibrium):
        EquilibriumSolver(load_vjm(paper_model_urdf("a", "s")), max_iter=1).solve(
            [-2.5, 0, 0], fast_fail=True
        )


# --------------------------------------------------------------------------- safeguarded path
@pytest.mark.parametrize("e0,slope,c", [(1.0, -2.0, 5.0), (1.0, -2.0, 0.5), (1.0, -1e-6, 100.0), (0.0, -3.0, 1.0)])
def test_backtrack_is_the_quadratic_minimiser_within_its_bounds(e0, slope, c):
    """The safeguarded line search's next trial after a rejected ``alpha``: the minimiser of the
    quadratic through E(0), E'(0) and E(alpha), kept in [0.1, 0.5]·alpha."""
    from vjm_pin.solver.equilibrium import _backtrack

    for alpha in (1.0, 0.25):
        en = e0 + slope * alpha + c * alpha**2  # the energy along the step is this quadratic
        got = _backtrack(alpha, e0, slope, en)
        want = -slope / (2 * c)
        assert 0.1 * alpha <= got <= 0.5 * alpha
        if 0.1 * alpha <= want <= 0.5 * alpha:
            assert got == pytest.approx(want, rel=1e-12)
        else:
            assert got == (0.1 * alpha if want < 0.1 * alpha else 0.5 * alpha)


def test_backtrack_halves_without_a_model():
    from vjm_pin.solver.equilibrium import _backtrack

    assert _backtrack(0.5, 1.0, -1.0, None) == 0.25  # restoration failed: no energy
    assert _backtrack(0.5, 1.0, 0.0, 2.0) == 0.25  # not a descent direction
    assert _backtrack(0.5, 1.0, -1.0, 0.4) == 0.25  # the quadratic has no minimum (c <= 0)


def test_lowest_energy_with_ties_to_the_first_found():
    from dataclasses import replace

    from vjm_pin.model.registry import resolve_model

    solver = EquilibriumSolver(resolve_model("paper-c-s"))
    r = solver.solve([-1e-5, 0, 0])
    found = [replace(r, energy=e, path=str(i)) for i, e in enumerate((1.0, 1.0 - 1e-13, 0.5))]
    assert solver._lowest(found).path == "2"
    assert solver._lowest(found[:2]).path == "0"  # equal to rounding: the first found
    assert solver._lowest([replace(r, energy=1.0, path="a"), replace(r, energy=0.9, path="b")]).path == "b"


def _crossing(vm, direction, span, n):
    """(solver, start result, deflection) of the warm-started solve along ``direction`` that leaves
    the straight column by an escape (the buckling crossing)."""
    s = EquilibriumSolver(vm)
    prev = None
    for t in np.linspace(span / n, span, n):
        r = s.solve(t * direction, x0=None if prev is None else prev.x, wrench0=None if prev is None else prev.wrench)
        if "escape" in r.path and prev is not None:
            return s, prev, t * direction
        prev = r
    raise AssertionError("no escape along the path")


def test_crossing_interpolated_line_search_finds_the_same_equilibria_with_fewer_restorations(monkeypatch):
    """The buckling crossing of Model C (an escape from the straight unstable column along both signs
    of its unstable mode): the interpolating line search reaches the same buckled equilibrium (up to
    the mirror image: the two signs tie in energy) as halving, with fewer restorations."""
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import equilibrium as eqmod

    vm = resolve_model("paper-c-s")
    direction = np.array([-1.0, 0, 0, 0, 0, 0])
    _, prev, d = _crossing(vm, direction, 2e-4, 8)
    calls = {"n": 0}
    restore = EquilibriumSolver._restore

    def counted(self, *a, **k):
        calls["n"] += 1
        return restore(self, *a, **k)

    monkeypatch.setattr(EquilibriumSolver, "_restore", counted)
    out = {}
    for shortcuts in (False, True):
        monkeypatch.setattr(eqmod, "_safeguard_shortcuts", shortcuts)
        calls["n"] = 0
        r = EquilibriumSolver(vm).solve(d, x0=prev.x, wrench0=prev.wrench)
        out[shortcuts] = (r, calls["n"])
    (a, na), (b, nb) = out[False], out[True]
    assert a.converged and b.converged and a.stable and b.stable
    assert "escape" in a.path and "escape" in b.path
    assert nb < na
    scale = np.abs(a.x).max()
    assert np.minimum(np.abs(a.x - b.x), np.abs(a.x + b.x)).max() <= 1e-9 * scale  # same or mirrored
    assert abs(a.wrench @ direction - b.wrench @ direction) <= 1e-9 * abs(a.wrench @ direction)
    assert abs(a.energy - b.energy) <= 1e-9 * a.energy
    assert np.abs(a.stability.eigenvalues - b.stability.eigenvalues).max() <= 1e-9 * np.abs(a.stability.eigenvalues).max()
