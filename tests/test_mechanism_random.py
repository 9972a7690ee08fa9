"""Random closed-loop mechanisms through the mechanism solver (issue 13 acceptance).

Planar four- and five-bar linkages and spatial R–S–S–R loops (tests/mechanisms.py: URDF text
written in the test, loops closed exactly at the reference), springs from 1-D to coupled 6-D,
passive joints, prismatic spring coordinates, random dead loads anywhere (forces and moments),
link weights, random held/loaded task components. Checked against:

- eq. (5) over every free coordinate with the reported reaction wrenches and Pinocchio's own
  frame Jacobians and generalised gravity (here), and with multipliers recomputed from scratch
  (``MechanismSolver.verify``: Pinocchio placements/Jacobians, weights from the inertias);
- K_C (all four formulas) against central differences of the task wrench of re-solved
  equilibria over small task deflections (every column);
- both stability verdicts against a central-difference Hessian of the constrained gradient on
  the null space of the stacked constraint Jacobian (``verify``);
- a planar loop closed in three and in all six components: the same equilibrium and K_C, the
  minimum-norm multipliers zero on the redundant rows, the same reactions.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.solver.mechanism import COMPONENTS, MechanismSolver
from vjm_pin.solver.mechanism_checks import held_deflection

from .mechanisms import planar_frames, planar_loop, spatial_rssr

SIX = ("x", "y", "z", "rx", "ry", "rz")
GRAVITY = (0.0, 0.0, -9.81)

# (builder, options, seed, gravity): every seed draws its own geometry, springs, loads and control
CASES = [
    (planar_loop, {"n_bars": 4}, 11, False),
    (planar_loop, {"n_bars": 4, "task": ("x", "z", "ry")}, 12, True),
    (planar_loop, {"n_bars": 5}, 13, True),
    (planar_loop, {"n_bars": 5, "cut": "rigid", "n_passive": 3}, 14, False),
    (planar_loop, {"n_bars": 4, "cut": "rigid", "closure": SIX}, 15, True),
    (spatial_rssr, {}, 16, True),
    (spatial_rssr, {"weld": True, "task": SIX, "passive_ball": False, "tool_on_coupler_root": True}, 17, False),
    (spatial_rssr, {"weld": True}, 18, True),
]


def random_control(rng, vm, planar: bool, factor: float = 1.0):
    """Random dead loads at random links (in-plane for planar models), held task components
    with a small deflection, dead wrench on the loaded ones."""
    frames = planar_frames(vm)
    loads = []
    for frame in rng.choice(frames, size=2, replace=False):
        w = factor * rng.uniform(-1, 1, 6) * np.array([15, 15, 15, 2, 2, 2])
        if planar:
            w[[1, 3, 5]] = 0.0
        elif rng.random() < 0.5:
            w[3:] = 0.0
        loads.append(Load(str(frame), w))
    task = list(vm.task)
    held = [c for c in task if rng.random() < 0.5]
    d, w = np.zeros(6), np.zeros(6)
    for c in task:
        if c in held:
            d[c] = rng.uniform(-4e-3, 4e-3)
        else:
            w[c] = factor * (rng.uniform(-10, 10) if c < 3 else rng.uniform(-1, 1))
    return loads, tuple(COMPONENTS[c] for c in held), d, w


def frame_jacobian(vm, x, frame):
    data = vm.model.createData()
    return pin.computeFrameJacobian(vm.model, data, x, vm.model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED)


def statics_error(vm, res, loads, gravity):
    """Largest eq. (5) residual over the free coordinates with the reported wrenches (task
    wrench, reaction wrench pairs) and Pinocchio's generalised gravity, relative to the largest
    term."""
    x = res.x
    parts = [frame_jacobian(vm, x, vm.frame).T @ res.wrench]
    parts += [frame_jacobian(vm, x, ld.frame).T @ ld.wrench for ld in loads]
    for c in vm.closures:
        wa, wb = res.reaction_wrenches[c.name]
        parts.append(frame_jacobian(vm, x, c.frame_a).T @ wa + frame_jacobian(vm, x, c.frame_b).T @ wb)
    if gravity:
        model = vm.model.copy()
        model.gravity.linear = np.array(GRAVITY)
        parts.append(-pin.computeGeneralizedGravity(model, model.createData(), x))
    gen = np.sum(parts, axis=0)
    tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    scale = max(np.abs(tau).max(), max(np.abs(p).max() for p in parts))
    err = max(np.abs(tau - gen[vm.theta_idx]).max(), np.abs(gen[vm.q_idx]).max() if vm.n_q else 0.0)
    return err / scale


def fd_stiffness(ms, res, h):
    """K_C by central differences of the task wrench of re-solved equilibria (every task
    component held) at the task frame of ``res`` moved by ±h along each task component."""
    task = list(ms.task)
    out = np.zeros((len(task), len(task)))
    for i, c in enumerate(task):
        ws = []
        for sgn in (1.0, -1.0):
            dt = np.zeros(6)
            dt[c] = sgn * h * (ms.length_scale if c < 3 else 1.0)
            rr = ms.solve(deflection=held_deflection(ms, res, dt), held=tuple(task), x0=res.x)
            ws.append(rr.wrench[task])
        out[:, i] = (ws[0] - ws[1]) / (2 * h * (ms.length_scale if c < 3 else 1.0))
    return out


@pytest.mark.parametrize("builder,options,seed,gravity", CASES,
                         ids=[f"{b.__name__}-{s}" for b, _, s, _ in CASES])
def test_random_mechanism(builder, options, seed, gravity):
    _, vm = builder(seed, **options)
    rng = np.random.default_rng(1000 + seed)
    planar = builder is planar_loop
    loads, held, d, w = random_control(rng, vm, planar)
    ms = MechanismSolver(vm, loads, GRAVITY if gravity else None, tol=1e-12)
    res = ms.solve(deflection=d, wrench=w, held=held)
    assert res.converged
    hc = list(res.held)
    assert np.abs(res.deflection[hc] - d[hc]).max(initial=0.0) < 1e-11
    # eq. 5 with the reported reactions (Pinocchio Jacobians and gravity) ...
    assert statics_error(vm, res, loads, gravity) < 1e-9
    # ... and with multipliers recomputed from scratch; closures; held rows; the FD Hessian
    check = ms.verify(res, deflection=d, stiffness=False)
    assert check.statics_relative < 1e-9 and check.statics_ok
    assert check.multipliers_relative < 1e-8 and check.reaction_relative < 1e-9
    assert check.closure_position_m < 1e-11 and check.closure_orientation_rad < 1e-11
    assert check.position_m < 1e-11 and check.orientation_rad < 1e-11
    assert check.stability_ok and check.hessian_relative < 1e-6
    assert check.stable is res.stable and check.stable_end_held is res.stable_end_held
    assert res.stability.null_dim == check.eigenvalues.size
    # K_C: the four formulas agree, and agree with re-solved equilibria
    ks = {m: ms.stiffness(res, m) for m in ("eq28", "eq30", "eq32", "eq33")}
    ref = ks["eq28"]
    kmax = np.abs(ref.stiffness).max()
    for m, k in ks.items():
        assert k.method == f"{m}-closures"
        assert np.abs(k.stiffness - ref.stiffness).max() <= 1e-9 * kmax, m
        for a, b in ((k.dq_dt, ref.dq_dt), (k.dtheta_dt, ref.dtheta_dt)):
            assert np.abs(a - b).max(initial=0.0) <= 1e-9 * max(np.abs(b).max(initial=0.0), 1e-300) + 1e-15, m
    # h = 1e-7 (×L_c for translations): the O(h²) truncation reaches ~3e-6 at h = 1e-6 for
    # stiff coupled springs in the spatial loops, while the re-solved wrenches are exact to ~1e-12
    fd = fd_stiffness(ms, res, 1e-7)
    assert np.abs(ref.task_stiffness - fd).max() <= 1e-6 * np.abs(fd).max()


@pytest.mark.parametrize("n_bars,seed", [(4, 21), (5, 22)])
def test_planar_loop_closed_in_six_components_is_the_same_mechanism(n_bars, seed):
    """Three redundant rows (y, rx, rz of a planar loop): same equilibrium and K_C, the
    minimum-norm multipliers are the planar ones padded with zeros, the same reactions."""
    rng = np.random.default_rng(seed)
    _, vm3 = planar_loop(seed, n_bars=n_bars, cut="rigid", closure=("x", "z", "ry"), task=("x", "z", "ry"))
    _, vm6 = planar_loop(seed, n_bars=n_bars, cut="rigid", closure=SIX, task=("x", "z", "ry"))
    loads, held, d, w = random_control(rng, vm3, True)
    r3 = MechanismSolver(vm3, loads, GRAVITY, tol=1e-12).solve(deflection=d, wrench=w, held=held)
    ms6 = MechanismSolver(vm6, loads, GRAVITY, tol=1e-12)
    r6 = ms6.solve(deflection=d, wrench=w, held=held)
    assert r3.converged and r6.converged
    assert r3.redundant == () and r6.redundant == ("loop.y", "loop.rx", "loop.rz")
    assert "minimum-norm" in r6.multipliers_note
    assert np.abs(r6.x - r3.x).max() < 1e-10
    assert np.allclose(r6.wrench, r3.wrench, rtol=1e-9, atol=1e-9)
    rows = [r6.closure_labels.index(f"loop.{c}") for c in ("x", "z", "ry")]
    mu_scale = np.abs(r3.closure_multipliers).max()
    assert np.abs(r6.closure_multipliers[rows] - r3.closure_multipliers).max() <= 1e-9 * mu_scale
    assert np.abs(np.delete(r6.closure_multipliers, rows)).max() <= 1e-12 * mu_scale
    for wa, wb in zip(r3.reaction_wrenches["loop"], r6.reaction_wrenches["loop"]):
        assert np.abs(wa - wb).max() <= 1e-9 * mu_scale
    k3 = MechanismSolver(vm3, loads, GRAVITY).stiffness(r3).task_stiffness
    for m in ("eq28", "eq30", "eq32", "eq33"):
        k6 = ms6.stiffness(r6, m).task_stiffness
        assert np.abs(k6 - k3).max() <= 1e-9 * np.abs(k3).max(), m
    assert r6.stable is r3.stable and r6.stable_end_held is r3.stable_end_held
    assert np.allclose(r6.stability.eigenvalues, r3.stability.eigenvalues, rtol=1e-9)
    check = ms6.verify(r6, deflection=d)
    assert check.ok and check.multipliers_relative < 1e-9


@pytest.mark.parametrize("n_bars,seed", [(4, 31), (5, 32)])
@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_crank_push_verdicts_against_the_fd_hessian(n_bars, seed, ratio):
    """A dead force at the crank tip towards the crank pivot leaves the reference an equilibrium;
    the mechanism's rigid motions load only the crank spring, so under force control (task
    loaded with zero wrench) it is unstable above k/L, stable below; with the task frame held
    it stays stable. Both verdicts and their eigenvalues against the FD Hessian (``verify``)."""
    t, vm = planar_loop(seed, n_bars=n_bars, masses=False)
    pivot = np.zeros(3)
    data = vm.model.createData()
    pin.framesForwardKinematics(vm.model, data, vm.reference)
    tip = data.oMf[vm.model.getFrameId("b2")].translation
    k = t.roles["r1"][1]
    crank = np.linalg.norm(tip - pivot)
    push = Load("b2", ratio * k / crank * (pivot - tip) / crank)
    ms = MechanismSolver(vm, [push], tol=1e-12)
    res = ms.solve(wrench=np.zeros(6))
    assert res.converged and np.abs(res.x - vm.reference).max() < 1e-12
    assert res.stable is (ratio < 1) and res.stable_end_held is True
    check = ms.verify(res)
    assert check.ok and check.stable is (ratio < 1) and check.stable_end_held is True
    assert check.hessian_relative < 1e-6
    # the softest mode of the free mechanism is (1 − ratio)·k times its crank-angle share
    assert np.sign(check.eigenvalues.max()) == np.sign(ratio - 1)
