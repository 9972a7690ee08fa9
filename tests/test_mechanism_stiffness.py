"""``MechanismSolver.stiffness(method=...)`` (paper eq. 28–33 with closure rows) and
``MechanismSolver.verify`` on the bundled closed models and on serial chains.

The four formulas against each other (1e-9) and against the portal frame's closed form; without
closures against the serial ``loaded_stiffness`` of the same method; ``verify`` must catch a
corrupted result (each check could fail)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from vjm_pin import load_vjm
from vjm_pin.exceptions import InputError, NoEquilibrium, SingularStiffness
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.solver import EquilibriumSolver, loaded_stiffness
from vjm_pin.solver.mechanism import MechanismSolver

from . import portal_frame as pf
from .chains import random_vjm

MODELS = Path(__file__).resolve().parent.parent / "models" / "urdf"
PORTAL = load_vjm(MODELS / "portal-frame.urdf")
PORTAL6 = load_vjm(MODELS / "portal-frame-6.urdf")
FOUR_BAR = load_vjm(MODELS / "four-bar.urdf")
METHODS = ("eq28", "eq30", "eq32", "eq33")


def portal(vm, P):
    return MechanismSolver(vm, [Load("top_left", [0.0, 0.0, -P]), Load("top_right", [0.0, 0.0, -P])])


def assert_same(a, b, rel=1e-9):
    assert np.abs(a.stiffness - b.stiffness).max() <= rel * np.abs(b.stiffness).max()
    for x, y in ((a.dq_dt, b.dq_dt), (a.dtheta_dt, b.dtheta_dt)):
        assert x.shape == y.shape
        if y.size:
            assert np.abs(x - y).max() <= rel * max(np.abs(y).max(), 1e-300)


@pytest.mark.parametrize("vm", [PORTAL, PORTAL6], ids=["closure-3", "closure-6"])
@pytest.mark.parametrize("H,P_ratio", [(40.0, 0.0), (-60.0, 0.7), (90.0, 1.2)])
def test_portal_methods_agree_with_the_closed_form(vm, H, P_ratio):
    P = P_ratio * pf.critical_load(float(PORTAL.K_theta[0, 0]), 1.0)
    ms = portal(vm, P)
    res = ms.solve(wrench=[H])
    phi = pf.sway(H, float(PORTAL.K_theta[0, 0]), 1.0, P)
    ks = {m: ms.stiffness(res, m) for m in METHODS}
    for m, k in ks.items():
        assert k.method == f"{m}-closures" and k.task == (0,)
        assert k.task_stiffness[0, 0] == pytest.approx(pf.stiffness(phi, float(PORTAL.K_theta[0, 0]), 1.0, P), rel=1e-8)
        assert_same(k, ks["eq28"])


@pytest.mark.parametrize(
    "kind,loads",
    [("loaded", [Load("coupler_point", [10.0, 0.0, -100.0])]),
     ("mixed", [Load("coupler_link", [20.0, 0.0, 5.0, 0.0, 3.0, 0.0])])],
)
def test_four_bar_methods_agree_and_eq33_says_why_it_does_not_apply(kind, loads):
    ms = MechanismSolver(FOUR_BAR, loads, (0.0, 0.0, -9.81))
    res = ms.solve(wrench=[30.0, -50.0]) if kind == "loaded" else ms.solve([0.004, 0.0], [0.0, -40.0], held="x")
    ref = ms.stiffness(res)
    for m in ("eq30", "eq32"):
        assert_same(ms.stiffness(res, m), ref)
    # the coupler point moves by the crank spring only: J_θ k J_θᵀ (2×2) has rank 1
    with pytest.raises(SingularStiffness, match=r"eq\. 33"):
        ms.stiffness(res, "eq33")


@pytest.mark.parametrize("seed,n_passive", [(501, 0), (502, 1), (503, 2)])
@pytest.mark.parametrize("method", ("eq30", "eq32", "eq33"))
def test_without_closures_each_method_is_the_serial_one(seed, n_passive, method):
    vm = random_vjm(seed, n_joints=5, n_passive=n_passive, task=("x", "y", "z"), link_springs=2)
    w = np.array([3.0, -2.0, 1.5])
    a = EquilibriumSolver(vm).solve_mixed(wrench=w, held=())
    ms = MechanismSolver(vm)
    b = ms.solve(wrench=w)
    assert np.abs(a.x - b.x).max() < 1e-9
    try:
        ka = loaded_stiffness(vm, a, method)
    except SingularStiffness as exc:
        with pytest.raises(SingularStiffness):
            ms.stiffness(b, method)
        assert "eq. 3" in str(exc)
        return
    kb = ms.stiffness(b, method)
    assert_same(kb, ka, rel=1e-8)
    assert_same(ms.stiffness(b), ka, rel=1e-8)


def test_stiffness_bad_method_and_unconverged_result():
    ms = MechanismSolver(FOUR_BAR)
    res = ms.solve(wrench=[1.0, 0.0])
    with pytest.raises(InputError, match="unknown stiffness method 'eq31'"):
        ms.stiffness(res, "eq31")
    bad = dataclasses.replace(res, converged=False)
    with pytest.raises(NoEquilibrium):
        ms.stiffness(bad, "eq30")
    with pytest.raises(NoEquilibrium):
        ms.verify(bad)


def test_verify_passes_a_good_result_and_catches_corrupted_ones():
    ms = portal(PORTAL6, 20.0)
    res = ms.solve(wrench=[35.0])
    good = ms.verify(res)
    assert good.ok and good.stiffness_checked and good.stiffness_relative_error < 1e-6
    with pytest.raises(dataclasses.FrozenInstanceError):
        good.ok = False
    # reaction of the free task row, closure multipliers, configuration, verdict: each is caught
    mu = res.closure_multipliers.copy()
    mu[0] *= 1.01
    assert not ms.verify(dataclasses.replace(res, closure_multipliers=mu), stiffness=False).statics_ok
    x = res.x.copy()
    x[ms.free[0]] += 1e-6
    bad = ms.verify(dataclasses.replace(res, x=x), stiffness=False)
    assert not bad.statics_ok and not bad.ok
    flipped = dataclasses.replace(res.stability, stable=not res.stability.stable)
    assert not ms.verify(dataclasses.replace(res, stability=flipped), stiffness=False).stability_ok
    # a held deflection other than the one prescribed
    held = ms.solve(deflection=[0.01])
    assert ms.verify(held, deflection=[0.01], stiffness=False).geometry_ok
    assert not ms.verify(held, deflection=[0.0101], stiffness=False).geometry_ok


def test_verify_with_link_weights_and_moments_on_the_four_bar():
    loads = [Load("coupler_link", [20.0, 0.0, 5.0, 0.0, 2.0, 0.0]), Load("rocker_link", [0.0, 0.0, -40.0])]
    ms = MechanismSolver(FOUR_BAR, loads, (0.0, 0.0, -9.81))
    res = ms.solve([0.003, -0.002], held="x z")
    check = ms.verify(res, deflection=[0.003, -0.002], method="eq30")
    assert check.ok
    assert np.allclose(check.task_reaction[[0, 2]], res.wrench[[0, 2]], rtol=1e-9, atol=1e-9)
    assert np.allclose(check.closure_multipliers, res.closure_multipliers, rtol=1e-9, atol=1e-9)


def test_three_numbers_on_a_three_component_task_are_its_components():
    """Task (x, z, ry): a wrench of 3 numbers is (fx, fz, my) in task order, never read as a
    translation (which would put my into fz silently)."""
    from vjm_pin.model.registry import models_dir
    from vjm_pin.solver import MechanismSolver

    text = (models_dir() / "four-bar.urdf").read_text().replace(
        '<vjm:task frame="coupler_point" components="x z"', '<vjm:task frame="coupler_point" components="x z ry"'
    )
    vm = load_vjm(text)
    assert vm.task == (0, 2, 4)
    s = MechanismSolver(vm)
    short = s.solve(wrench=[10.0, 0.0, 5.0])
    full = s.solve(wrench=[10.0, 0.0, 0.0, 0.0, 5.0, 0.0])
    np.testing.assert_array_equal(short.x, full.x)
    assert short.wrench[4] == 5.0 and short.wrench[2] == 0.0
