"""Mixed control (held / loaded task components), the two stability verdicts, the checked
equilibrium and the solver's input validation — against Pinocchio directly, finite
differences of the total potential and re-solved equilibria."""

import json
import math

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin import (
    EquilibriumCheckError,
    EquilibriumSolver,
    InputError,
    NoEquilibrium,
    load_vjm,
    loaded_stiffness,
)
from vjm_pin.cli import main
from vjm_pin.kinematics.chain import displace
from vjm_pin.model.paper_models import paper_model_urdf
from vjm_pin.model.registry import resolve_model

from .chains import random_vjm

NAMES = ("x", "y", "z", "rx", "ry", "rz")


# --------------------------------------------------------------------------- independent references
def pin_statics(vm, x, wrench):
    """Eq. (5) residual over (θ, q), per row, from Pinocchio directly: ``K_θ(θ−θ₀) − J_θᵀw``,
    ``−J_qᵀw``, with the full 6-D wrench and the LOCAL_WORLD_ALIGNED frame Jacobian."""
    data = vm.model.createData()
    jac = pin.computeFrameJacobian(vm.model, data, np.asarray(x, float), vm.frame_id, pin.LOCAL_WORLD_ALIGNED)
    gen = jac.reshape(6, -1).T @ np.asarray(wrench, float)
    r_t = vm.K_theta @ (x[vm.theta_idx] - vm.theta0) - gen[vm.theta_idx]
    return np.concatenate([r_t, -gen[vm.q_idx]]), np.abs(vm.K_theta @ (x[vm.theta_idx] - vm.theta0))


def pin_pose(vm, x):
    data = vm.model.createData()
    pin.framesForwardKinematics(vm.model, data, np.asarray(x, float))
    m = data.oMf[vm.frame_id]
    return m.translation.copy(), m.rotation.copy()


def pin_deflection(vm, x):
    p0, r0 = pin_pose(vm, vm.reference)
    p, r = pin_pose(vm, x)
    return np.concatenate([p - p0, pin.log3(r @ r0.T)])


def assert_statics(vm, res, rel=1e-8):
    r, tau = pin_statics(vm, res.x, res.wrench)
    scale = max(tau.max() if tau.size else 0.0, np.abs(res.wrench).max(), 1e-12)
    assert np.abs(r).max() <= rel * scale, (np.abs(r).max(), scale)


def fd_verdict(vm, res, h=1e-5):
    """Stability for the control of ``res`` from finite differences: the Hessian of the
    Lagrangian ``E(θ) − Fᵀp(x)`` (pure force loads: an exact potential; the reactions of the
    held rows are F's held part) restricted to the null space of the held position rows of
    the Jacobian (Pinocchio, LOCAL_WORLD_ALIGNED). Returns (smallest eigenvalue, scale)."""
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    f = np.asarray(res.wrench[:3], float)

    def lag(z):
        x = res.x.copy()
        x[free] = z
        p, _ = pin_pose(vm, x)
        d = x[vm.theta_idx] - vm.theta0
        return 0.5 * d @ vm.K_theta @ d - f @ p

    z0 = res.x[free].copy()
    n = z0.size
    hes = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            e_i = np.zeros(n)
            e_j = np.zeros(n)
            e_i[i] = h
            e_j[j] = h
            v = (lag(z0 + e_i + e_j) - lag(z0 + e_i - e_j) - lag(z0 - e_i + e_j) + lag(z0 - e_i - e_j)) / (4 * h * h)
            hes[i, j] = hes[j, i] = v
    held = [c for c in res.held]
    if held:
        data = vm.model.createData()
        jac = pin.computeFrameJacobian(vm.model, data, res.x, vm.frame_id, pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)
        a = jac[held][:, free]
        _, s, vt = np.linalg.svd(a)
        rank = int(np.sum(s > 1e-10 * s.max()))
        basis = vt[rank:].T
    else:
        basis = np.eye(n)
    red = basis.T @ hes @ basis
    return float(np.linalg.eigvalsh(0.5 * (red + red.T)).min()), float(np.abs(hes).max())


# --------------------------------------------------------------------------- A: option validation
@pytest.mark.parametrize(
    "kwargs,name",
    [
        ({"tol": 1.0}, "tol"),
        ({"tol": 0.0}, "tol"),
        ({"tol": float("nan")}, "tol"),
        ({"tol": 1e-3}, "tol"),
        ({"max_iter": 0}, "max_iter"),
        ({"max_iter": 2.5}, "max_iter"),
        ({"restarts": -1}, "restarts"),
        ({"perturbation": 0.0}, "perturbation"),
        ({"perturbation": float("inf")}, "perturbation"),
        ({"seed": -3}, "seed"),
        ({"method": "bogus"}, "method"),
        ({"follow_stable": "yes"}, "follow_stable"),
    ],
)
def test_solver_options_out_of_range_are_refused_by_name(kwargs, name):
    vm = load_vjm(paper_model_urdf("a", "s"))
    with pytest.raises(InputError, match=name) as err:
        EquilibriumSolver(vm, **kwargs)
    if name == "method":
        assert "newton" in str(err.value) and "fixed-point" in str(err.value)
    elif name == "follow_stable":
        assert "True or False" in str(err.value)
    else:
        assert "[" in str(err.value)  # the allowed range is stated


def test_a_loose_tolerance_cannot_pass_a_zero_deflection_off_as_an_equilibrium():
    """tol=1.0 would accept the unloaded chain under any load: it is refused."""
    vm = load_vjm(paper_model_urdf("a", "pi"))
    with pytest.raises(InputError, match="tol"):
        EquilibriumSolver(vm, tol=1.0)
    res = EquilibriumSolver(vm, tol=1e-4).solve_wrench([0.3, 0.0])
    assert_statics(vm, res, rel=1e-3)
    assert np.abs(res.deflection).max() > 1e-3


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda s: s.solve([0.1, 0.0, 0.0, 0.0]), "components"),
        (lambda s: s.solve([np.nan, 0.0, 0.0]), "NaN"),
        (lambda s: s.solve_wrench([0.0, np.inf]), "NaN"),
        (lambda s: s.solve_wrench([1.0, 0.0, 0.0, 0.0, 0.0, 1.0]), "not constrained"),
        (lambda s: s.solve([-0.1, 0.0, 0.0], wrench0=[1.0, 2.0, 3.0]), "wrench0"),
        (lambda s: s.solve([-0.1, 0.0, 0.0], x0=np.zeros(2)), "x0"),
        (lambda s: s.solve_mixed([0.0, -0.1], held=("q",)), "unknown task component"),
        (lambda s: s.solve_mixed([0.0, -0.1], held=("z",)), "not in the task"),
        (lambda s: s.solve_mixed([-0.1, 0.1], held=("y",)), "loaded components"),
        (lambda s: s.solve_mixed(wrench=[1.0, 0.0], held=("x",)), "held components"),
    ],
)
def test_solve_arguments_are_validated(call, match):
    vm = load_vjm(paper_model_urdf("a", "pi"))  # task x y
    with pytest.raises(InputError, match=match):
        call(EquilibriumSolver(vm))


def test_loaded_stiffness_of_an_unconverged_result_raises():
    vm = load_vjm(paper_model_urdf("a", "s"))
    res = EquilibriumSolver(vm, max_iter=1, restarts=0).solve([-2.5, 0, 0], raise_on_failure=False)
    assert not res.converged
    with pytest.raises(NoEquilibrium, match="did not converge"):
        loaded_stiffness(vm, res)


# --------------------------------------------------------------------------- B: force and mixed control
@pytest.mark.parametrize("seed", range(6))
def test_force_control_residual_recomputed_with_pinocchio(seed):
    task = [("x", "y", "z", "rx", "ry", "rz"), ("x", "y", "z"), ("x", "z", "ry")][seed % 3]
    vm = random_vjm(100 + seed, n_joints=5, n_passive=seed % 2, task=task, link_springs=2)
    rng = np.random.default_rng(seed)
    w = np.zeros(6)
    w[list(vm.task)] = rng.standard_normal(len(vm.task)) * 0.5
    res = EquilibriumSolver(vm, tol=1e-12).solve_wrench(w)
    assert res.converged and res.held == ()
    assert np.array_equal(res.wrench, w)  # all components loaded: the wrench is the load
    assert_statics(vm, res)
    assert np.allclose(res.deflection, pin_deflection(vm, res.x), atol=1e-14)


@pytest.mark.parametrize("seed", range(6))
def test_mixed_control_residual_and_held_deflection(seed):
    vm = random_vjm(200 + seed, n_joints=6, n_passive=seed % 3, link_springs=2)
    rng = np.random.default_rng(seed)
    held = tuple(sorted(rng.choice(6, size=1 + seed % 4, replace=False).tolist()))
    loaded = [c for c in range(6) if c not in held]
    d = np.zeros(6)
    d[list(held)] = rng.standard_normal(len(held)) * 0.02
    w = np.zeros(6)
    w[loaded] = rng.standard_normal(len(loaded)) * 0.3
    res = EquilibriumSolver(vm, tol=1e-12).solve_mixed(d, w, held=[NAMES[c] for c in held])
    assert res.converged and res.held == held
    assert np.array_equal(res.wrench[loaded], w[loaded])
    assert_statics(vm, res)
    defl = pin_deflection(vm, res.x)
    assert np.abs(defl[list(held)] - d[list(held)]).max() <= 1e-12


def test_force_control_agrees_with_deflection_control_at_the_same_equilibrium():
    """solve_wrench(w), then solve(deflection of that result): the same x and wrench."""
    checked = 0
    # random chains without passive joints (a dead load along a passive prismatic axis, or a
    # moment about a passive revolute one, has no equilibrium), and the paper's passive chains
    cases = [(random_vjm(300 + seed, n_joints=5, n_passive=0, link_springs=2), 0.4) for seed in range(6)]
    cases += [(resolve_model(name), 0.3) for name in ("paper-a-pi", "paper-b-z")]
    for seed, (vm, size) in enumerate(cases):
        rng = np.random.default_rng(seed)
        solver = EquilibriumSolver(vm, tol=1e-12)
        w = np.zeros(6)
        w[list(vm.task)] = rng.standard_normal(len(vm.task)) * size
        a = solver.solve_wrench(w)
        assert a.converged
        if not a.stable_end_held:  # a deflection-driven solve would leave it for a stable one
            continue
        d = np.zeros(6)
        d[list(vm.task)] = a.deflection[list(vm.task)]
        b = solver.solve(d)
        assert b.converged and b.stable
        assert np.allclose(b.x, a.x, atol=1e-8), np.abs(b.x - a.x).max()
        assert np.allclose(b.wrench, a.wrench, atol=1e-8 * max(1.0, np.abs(w).max()))
        checked += 1
    assert checked >= 4


# --------------------------------------------------------------------------- C: the two verdicts
@pytest.mark.parametrize("force,stable,end_held", [(-0.05, False, True), (-0.5, False, True), (2.0, True, True)])
def test_paper_a_s_pushed_at_a_laterally_free_end(force, stable, end_held):
    vm = resolve_model("paper-a-s")
    res = EquilibriumSolver(vm).solve_wrench([force, 0.0])
    assert res.converged
    assert res.stable is stable and res.stable_end_held is end_held
    assert bool(res.warnings) is (not stable)
    lam, scale = fd_verdict(vm, res)
    assert (lam > 1e-6 * scale) is stable


def test_stability_verdicts_against_finite_difference_hessian_of_the_total_potential():
    """Force loads (an exact potential), every mix of held position rows: the verdict
    ``stable`` agrees with the sign of the smallest eigenvalue of the finite-difference
    Hessian of the Lagrangian on the null space of the held rows, and ``stable_end_held``
    with the all-held one."""
    cases = [(resolve_model("paper-b-s"), [2.0, 0.0, 0.0]), (resolve_model("paper-b-s"), [0.1, 0.0, 0.0])]
    cases += [(resolve_model("paper-a-pi"), [0.2, 0.1, 0.0]), (resolve_model("paper-c-z"), [-0.05, 0.0, 0.0])]
    cases += [(resolve_model("paper-a-s"), [-0.5, 0.0, 0.0]), (resolve_model("paper-a-s"), [-1.5, 0.0, 0.0])]
    for seed in range(4):
        vm = random_vjm(400 + seed, n_joints=5, n_passive=seed % 2, task=("x", "y", "z"), link_springs=1)
        cases.append((vm, np.random.default_rng(seed).standard_normal(3) * 3.0))
    compared = {True: 0, False: 0}
    for vm, f in cases:
        solver = EquilibriumSolver(vm, tol=1e-12)
        for held in [(), (vm.task[0],), tuple(vm.task[:2])]:
            w = np.zeros(6)
            w[:3] = f
            w[list(held)] = 0.0
            res = solver.solve_mixed(np.zeros(6), w, held=held, raise_on_failure=False)
            if not res.converged:
                continue
            for verdict, control in ((res.stable, res.held), (res.stable_end_held, tuple(vm.task))):
                from dataclasses import replace

                lam, scale = fd_verdict(vm, replace(res, held=control))
                if abs(lam) <= 1e-5 + 1e-8 * scale:  # too close to neutral for a finite difference
                    continue
                assert verdict is (lam > 0), (vm.name, held, control, lam, verdict)
                compared[verdict] += 1
    assert compared[True] >= 5 and compared[False] >= 2, compared


def test_analyze_json_and_text_carry_both_verdicts(capsys):
    assert main(["analyze", "paper-a-s", "--wrench", "-0.05", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] is False and out["stable_end_held"] is True
    assert out["control"] == {"held": [], "loaded": ["x", "y"]}
    assert main(["analyze", "paper-a-s", "--wrench", "2", "0", "0"]) == 0
    text = capsys.readouterr().out
    assert "stable (as controlled): stable" in text and "stable_end_held (eq. 23): stable" in text


# --------------------------------------------------------------------------- D/E: just past buckling, checked
def straight_critical_deflection(vm):
    """The deflection at which the straight chain (followed by plain Newton, stable or not)
    loses stability with the end held: the root of the largest eigenvalue of eq. (23)."""
    straight = EquilibriumSolver(vm, follow_stable=False, restarts=0, tol=1e-13)

    def top(s):
        res = straight.solve([-s, 0.0, 0.0], x0=vm.reference)
        assert np.abs(res.x[vm.q_idx]).max() < 1e-9  # still straight
        return float(res.stability.eigenvalues.max())

    lo, hi = 1e-6, 1e-3
    assert top(lo) < 0 < top(hi)
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if top(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def test_just_past_buckling_a_stable_equilibrium_with_a_checked_stiffness():
    vm = resolve_model("paper-c-s")
    dc = straight_critical_deflection(vm)
    for factor in (0.999, 1.00015, 1.0002, 1.001, 1.01):
        solver = EquilibriumSolver(vm)
        res = solver.solve([-factor * dc, 0.0, 0.0])
        assert res.converged and res.stable, (factor, res.path)
        res = solver.verify(res)
        assert res.checks["stiffness_ok"] and res.checks["stiffness_relative_error"] <= 1e-3
        if factor > 1:  # buckled: out of the straight line
            assert np.abs(res.x[vm.q_idx]).max() > 1e-6
        # K_xx against central differences of re-solved equilibria, independently of verify
        k = loaded_stiffness(vm, res).stiffness[0, 0]
        h = 1e-10
        fp = solver.solve([-factor * dc + h, 0, 0], x0=res.x).wrench[0]
        fm = solver.solve([-factor * dc - h, 0, 0], x0=res.x).wrench[0]
        assert abs(k - (fp - fm) / (2 * h)) <= 1e-3 * abs(k), (factor, k, (fp - fm) / (2 * h))


def test_verify_never_passes_a_wrong_result():
    """A result whose wrench or verdict was tampered with is re-solved (or refused), never
    returned as it is."""
    from dataclasses import replace

    vm = resolve_model("paper-c-s")
    solver = EquilibriumSolver(vm)
    res = solver.solve([-2e-4, 0.0, 0.0])
    bad = replace(res, wrench=res.wrench * 1.01)
    try:
        out = solver.verify(bad)
    except EquilibriumCheckError as e:
        assert not e.checks["statics_ok"]
    else:
        assert out.checks["ok"] and "verified-retry" in out.path
        assert np.allclose(out.wrench, res.wrench, rtol=1e-8, atol=1e-12)
    flipped = replace(res.stability, stable=not res.stability.stable)
    bad = replace(res, stability=flipped, stability_end_held=flipped)
    try:
        out = solver.verify(bad)
    except EquilibriumCheckError as e:
        assert not e.checks["stability_ok"]
    else:
        assert out.stable is res.stable


# --------------------------------------------------------------------------- F: partial rotations, any task
@pytest.mark.parametrize("task", [("x", "z", "ry"), ("y", "rz"), ("rx", "ry"), ("y", "z", "rx", "rz")])
def test_partial_rotation_task_meets_the_requested_deflection(task):
    for seed in range(2):
        vm = random_vjm(500 + seed, n_joints=5, n_passive=seed, task=task, link_springs=2)
        rng = np.random.default_rng(seed)
        d = np.zeros(6)
        d[list(vm.task)] = rng.standard_normal(len(vm.task)) * 0.08
        solver = EquilibriumSolver(vm)
        res = solver.solve(d)
        assert res.converged
        defl = pin_deflection(vm, res.x)
        assert np.abs(defl[list(vm.task)] - d[list(vm.task)]).max() <= 1e-12
        # the reported wrench is the physical one (eq. 5 with the full wrench), zero off the task
        assert_statics(vm, res)
        assert not np.any(res.wrench[[c for c in range(6) if c not in vm.task]])
        # K_C is that of twists of the end (displace), as for full tasks
        k = loaded_stiffness(vm, res).stiffness
        u = np.zeros(6)
        u[list(vm.task)] = rng.standard_normal(len(vm.task))
        u *= 1e-6 / np.linalg.norm(u)
        fp = solver.solve(target=displace(res.position, res.rotation, u), x0=res.x, wrench0=res.wrench).wrench
        fm = solver.solve(target=displace(res.position, res.rotation, -u), x0=res.x, wrench0=res.wrench).wrench
        assert np.linalg.norm(k @ u - (fp - fm) / 2) <= 1e-4 * np.linalg.norm(k @ u)


@pytest.mark.parametrize("task", [("y", "rz"), ("x", "z"), ("z", "rx")])
def test_non_prefix_tasks_take_task_sized_vectors(task):
    vm = random_vjm(600, n_joints=4, n_passive=1, task=task, link_springs=1)
    solver = EquilibriumSolver(vm, tol=1e-12)
    d_task = np.array([0.01, -0.02])
    res = solver.solve(d_task)  # task-sized deflection (task order)
    assert res.converged
    assert np.abs(pin_deflection(vm, res.x)[list(vm.task)] - d_task).max() <= 1e-12
    # a task-sized starting wrench (as curve tracing passes it) is taken in task order
    again = solver.solve(d_task * 1.01, x0=res.x, wrench0=res.wrench[list(vm.task)])
    assert again.converged
    # and the wrench-driven solve in task-sized form returns the same equilibrium
    back = solver.solve_wrench(res.wrench[list(vm.task)], x0=res.x)
    assert np.allclose(back.x, res.x, atol=1e-8)


# --------------------------------------------------------------------------- parallel: buckling by name
def test_wrench_driven_orthoglide_above_its_critical_force_reports_buckling(capsys):
    f = 1.02 * 4880.0 / math.sqrt(3)  # 2 % above the folded model's critical force along −u
    assert main(["analyze", "orthoglide-q0", "--wrench", str(-f), str(-f), str(-f)]) == 3  # analysis failure
    err = capsys.readouterr().err
    assert "buckling" in err and len(err.strip().splitlines()) == 1
    g = 0.9 * 4880.0 / math.sqrt(3)
    assert main(["analyze", "orthoglide-q0", "--wrench", str(-g), str(-g), str(-g), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] is True and np.allclose(out["wrench"][:3], -g, rtol=1e-6)
