"""One curve tracer for every model kind (issue 13; vjm_pin/analysis/curve.py on the mechanism
solver, vjm_pin/analysis/mechanism_curve.py).

Checked against:
- the portal frame's closed form (tests/portal_frame.py), closure in three and in all six
  components: the horizontal push under vertical dead loads P per column (force, tangent
  stiffness and force-control margin along the whole curve; below P = 2k/h no critical point,
  above it the margin is negative at the start and turns positive where the closed form's V″
  does), and the vertical push (the sway buckling: critical force ``4k/h − 2P`` at zero
  deflection, then the post-buckled branch ``F = 4kφ/(h sin φ) − 2P``), with the top held only
  along the push (``free=True``) and with a task of that one component;
- re-solved equilibria of the four-bar (``MechanismSolver.solve`` from the reference) at every
  curve point, its tangent stiffness against central differences of re-solved forces, and its
  limit point (the force maximum of re-solved equilibria) for three step counts;
- the serial tracer: a serial chain traced through the mechanism solver gives the same curve.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from vjm_pin import load_vjm
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.exceptions import InputError
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver
from vjm_pin.solver.mechanism import MechanismResult, MechanismSolver

from . import portal_frame as pf
from .test_mechanism import FOUR_BAR, PORTAL, PORTAL6, crank_tip_push, pin_placement

MODELS = Path(__file__).resolve().parent.parent / "models" / "urdf"
K = float(PORTAL.K_theta[0, 0])
HEIGHT = 1.0
PC = pf.critical_load(K, HEIGHT)


def column_loads(P):
    return [Load("top_left", [0.0, 0.0, -P]), Load("top_right", [0.0, 0.0, -P])]


def portal_with_task(tmp_path, name: str, components: str):
    """The bundled portal frame (``name``) with another task on the beam's middle."""
    text = (MODELS / f"{name}.urdf").read_text()
    old = '<vjm:task frame="top" components="x" />'
    assert old in text
    path = tmp_path / f"{name}-{components.replace(' ', '')}.urdf"
    path.write_text(text.replace(old, f'<vjm:task frame="top" components="{components}" />'))
    return load_vjm(path)


# --------------------------------------------------------------------------- portal: horizontal push
@pytest.mark.parametrize("name", ["portal-frame", "portal-frame-6"])
@pytest.mark.parametrize("P_ratio", [0.5, 1.3])
def test_portal_push_curve_is_the_closed_form(name, P_ratio):
    vm = PORTAL if name == "portal-frame" else PORTAL6
    P = P_ratio * PC
    c = trace_curve(vm, [1, 0, 0], 0.8, 8, loads=column_loads(P))
    assert len(c.points) == 9 and c.points[-1].deflection == pytest.approx(0.8)
    assert len(c.loads) == 2 and not c.free
    for p in c.points:
        phi = math.asin(p.deflection / HEIGHT)
        assert isinstance(p.equilibrium, MechanismResult) and p.equilibrium.converged
        assert p.force == pytest.approx(pf.force(phi, K, HEIGHT, P), rel=1e-8, abs=1e-9 * K)
        assert p.stiffness == pytest.approx(pf.stiffness(phi, K, HEIGHT, P), rel=1e-8)
        # one sway mode, |dx/dφ|² = 4: the margin is V″/4 with the curve's own force
        assert p.force_control_margin == pytest.approx(
            pf.d2potential(phi, K, HEIGHT, p.force, P) / 4, rel=1e-8, abs=1e-9 * K
        )
        assert p.stable and p.stable_end_held  # the top held: one dof, fixed
    margins = np.array([p.force_control_margin for p in c.points])
    if P_ratio < 1:
        # K_C = (4k(cos φ + φ sin φ) − 2Ph)/(h² cos³ φ) > 0 on [0, h): no critical point
        assert c.critical == () and margins.min() > 0
    else:
        # unstable under force control from the start; stability regained (not a critical
        # point) where cos φ* + φ* sin φ* = Ph/2k
        phi_star = pf.brentq(lambda t: math.cos(t) + t * math.sin(t) - P * HEIGHT / (2 * K), 0.0, 1.5)
        s_star = HEIGHT * math.sin(phi_star)
        assert c.critical == ()
        for p, m in zip(c.points, margins):
            if abs(p.deflection - s_star) > 1e-3:
                assert bool(m > 0) == (p.deflection > s_star)


# --------------------------------------------------------------------------- portal: sway buckling
@pytest.mark.parametrize("name", ["portal-frame", "portal-frame-6"])
@pytest.mark.parametrize("components,free", [("z", False), ("x z", True)])
def test_portal_vertical_push_buckles_at_the_closed_form_load(tmp_path, name, components, free):
    """Vertical push ``F`` on the beam's middle plus dead loads ``P0`` per column: per column
    ``P0 + F/2`` meets ``2k/h`` at ``F = 4k/h − 2P0``, at zero deflection (the top cannot move
    down to first order: a rigid start); past it the sway branch ``F = 4kφ/(h sin φ) − 2P0``
    (``s = h(1 − cos φ)``), whose slope leaves ``4k/(3h²)``. The same critical force for two
    step counts, and with the top held only along the push (``free``) or a task of ``z`` alone."""
    vm = portal_with_task(tmp_path, name, components)
    P0 = 0.5 * PC
    f_c = 4 * K / HEIGHT - 2 * P0
    forces = []
    for steps in (3, 7):
        c = trace_curve(vm, [0, 0, -1], 0.3, steps, loads=column_loads(P0), free=free)
        assert c.free is free
        assert len(c.critical) == 1
        cp = c.critical[0]
        assert cp.kind == "bifurcation" and cp.deflection == 0.0 and cp.index == 1
        assert cp.force == pytest.approx(f_c, rel=1e-8)
        assert cp.stiffness_before == math.inf
        assert cp.stiffness_after == pytest.approx(4 * K / (3 * HEIGHT**2), rel=1e-3)
        forces.append(cp.force)
        for p in c.points[1:]:
            phi = math.acos(1 - p.deflection / HEIGHT)
            assert p.force == pytest.approx(4 * K * phi / (HEIGHT * math.sin(phi)) - 2 * P0, rel=1e-8)
            assert p.stable and p.force_control_margin > 0
            sway = abs(p.equilibrium.x[vm.joint_index("corner_bl")] - vm.reference[vm.joint_index("corner_bl")])
            assert sway == pytest.approx(phi, rel=1e-8)
            if free:  # the other task component carries no load
                assert abs(p.wrench[0]) < 1e-9 * K
    assert forces[0] == pytest.approx(forces[1], rel=1e-10)


# --------------------------------------------------------------------------- four-bar
FB_LOADS = [Load("coupler_point", [10.0, 0.0, -100.0])]


@pytest.mark.parametrize("direction", [[1, 0, 0], [0, 0, -1]])
def test_four_bar_curve_points_are_re_solved_equilibria(direction):
    d = np.array(direction + [0, 0, 0], float)
    c = trace_curve(FOUR_BAR, d, 0.03, 4, loads=FB_LOADS)
    ms = MechanismSolver(FOUR_BAR, FB_LOADS)
    assert c.critical == ()
    for p in c.points:
        t = (p.deflection * d)[[0, 2]]
        ref = ms.solve(deflection=t)  # from the reference, its own continuation
        assert np.abs(ref.x - p.equilibrium.x).max() < 1e-9
        assert np.abs(ref.wrench - p.wrench).max() <= 1e-8 * max(1.0, np.abs(ref.wrench).max())
        assert p.force == pytest.approx(d @ ref.wrench, rel=1e-8)
        assert np.abs(p.equilibrium.deflection[[0, 2]] - t).max() < 1e-12
        assert p.stable is ref.stable and p.stable_end_held is ref.stable_end_held
        # the tangent stiffness against central differences of re-solved forces
        h = 1e-6
        fp = d @ ms.solve(deflection=t + h * d[[0, 2]], x0=ref.x).wrench
        fm = d @ ms.solve(deflection=t - h * d[[0, 2]], x0=ref.x).wrench
        assert p.stiffness == pytest.approx((fp - fm) / (2 * h), rel=1e-5)


def test_four_bar_limit_point_does_not_depend_on_the_steps():
    """A dead push on the crank tip at 0.9 k/L softens the linkage pulled along −x until the
    force along −x peaks (a limit point): the same critical force for 3, 8 and 17 steps, a
    maximum of the force of re-solved equilibria, the tangent stiffness changing sign."""
    k = float(FOUR_BAR.K_theta[list(FOUR_BAR.theta_idx).index(FOUR_BAR.joint_index("crank"))].max())
    tip = pin_placement(FOUR_BAR, FOUR_BAR.reference, "coupler_link")[0]
    loads = [crank_tip_push(0.9 * k / np.linalg.norm(tip))]
    d = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    crit = []
    for steps in (3, 8, 17):
        c = trace_curve(FOUR_BAR, d, 0.05, steps, loads=loads)
        assert len(c.critical) == 1 and c.critical[0].kind == "limit"
        crit.append(c.critical[0])
        assert c.points[c.critical[0].index - 1].deflection < c.critical[0].deflection
        assert c.points[c.critical[0].index].deflection >= c.critical[0].deflection
    f = np.array([cp.force for cp in crit])
    assert np.abs(f - f[0]).max() <= 1e-7 * abs(f[0])  # 1e-3·refine_tol
    s_c = crit[0].deflection
    k0 = abs(trace_curve(FOUR_BAR, d, 0.05, 1, loads=loads).points[0].stiffness)
    assert crit[0].stiffness_before > 0 > crit[0].stiffness_after
    assert abs(crit[0].stiffness_before) < 1e-3 * k0
    ms = MechanismSolver(FOUR_BAR, loads)
    at = ms.solve(deflection=(s_c * d)[[0, 2]])
    assert d @ at.wrench == pytest.approx(f[0], rel=1e-7)
    for ds in (-2e-3, 2e-3):  # a maximum of the force along the path
        side = ms.solve(deflection=((s_c + ds) * d)[[0, 2]], x0=at.x)
        assert d @ side.wrench < f[0]


# --------------------------------------------------------------------------- serial chains
@pytest.mark.parametrize("name,span", [("paper-b-s", 0.5), ("paper-a-s", 1.0)])
def test_serial_chain_through_the_mechanism_solver_is_the_serial_curve(name, span):
    """Same curve and critical point whichever solver: the serial path (EquilibriumSolver) and
    the mechanism path (MechanismSolver, a model without closures)."""
    vm = resolve_model(name)
    a = trace_curve(vm, [-1, 0, 0], span, steps=6)
    b = trace_curve(vm, [-1, 0, 0], span, steps=6, solver=MechanismSolver(vm))
    assert isinstance(a.points[1].equilibrium, type(EquilibriumSolver(vm).solve(np.zeros(6))))
    assert isinstance(b.points[1].equilibrium, MechanismResult)
    assert np.abs(a.forces - b.forces).max() <= 1e-9 * np.abs(a.forces).max()
    assert [p.stable for p in a.points] == [p.stable for p in b.points]
    assert len(a.critical) == len(b.critical) == 1
    assert a.critical[0].kind == b.critical[0].kind
    assert b.critical[0].force == pytest.approx(a.critical[0].force, rel=1e-7)


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"all_branches": True}, "all_branches"),
        ({"free": True, "direction": [0, 0, 0, 0, 1, 0]}, "free=True needs a translation"),
        ({"solver": "serial"}, "needs the mechanism solver"),
        ({"solver": "mechanism", "loads": FB_LOADS}, "not twice"),
    ],
)
def test_bad_curve_options_are_one_line_errors(tmp_path, kwargs, match):
    kwargs = dict(kwargs)
    direction = kwargs.pop("direction", [1, 0, 0])
    vm = PORTAL
    if kwargs.get("solver") == "serial":
        kwargs["solver"] = EquilibriumSolver(resolve_model("paper-b-s"))
    elif kwargs.get("solver") == "mechanism":
        kwargs["solver"] = MechanismSolver(vm)
    if kwargs.get("free"):
        vm = portal_with_task(tmp_path, "portal-frame", "x z ry")  # a task with a rotation
    with pytest.raises(InputError, match=match) as err:
        trace_curve(vm, direction, 0.1, 2, **kwargs)
    assert "\n" not in str(err.value)
