"""The critical load along a direction, directly (vjm_pin/analysis/critical.py, vjm-pin critical).

Checked against code paths other than its own:
- ``trace_curve``'s first critical point (force, deflection, kind) on the paper models (Model C
  S with k = 1 and 2 sub-links per link, the Z and Π postures, Model A Z, Model B S and Z, the
  imperfect kind) and on a half von Mises truss (a limit point);
- closed forms: Model A S (rigid start, ``Kθ/L``, eq. 35) and the truss's force maximum
  ``F* = k (y*/ℓ* − y*)``, ``ℓ* = cos(φ₀)^(2/3)``;
- equilibria re-solved by the plain solver just before and after the critical deflection: the
  force-control margin (from the blocks with ``check_stability_held``) changes sign; the mode
  against an eigenvector computed here from SVD null spaces and ``reduced_matrix``;
- bad input, no critical point, a search budget too small (reported, not hidden); the CLI;
- the mechanism path (loop closures, dead loads, gravity, ``free``): ``trace_curve``'s first
  critical point and closed forms: the portal frame's sway buckling ``F = 4k/h − 2P₀`` under dead
  column loads ``P₀`` and ``4k/h − W`` under the beam's weight ``W`` (gravity), the four-bar's
  limit point under two crank-tip pushes, the two-column parallel robot's in-plane and
  out-of-plane buckling deflections (tests/test_parallel.py), the Orthoglide (re-solved
  equilibria either side), a serial chain through the mechanism solver against the serial path.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from vjm_pin.analysis.critical import critical_load
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError, NoCriticalPoint
from vjm_pin.kinematics.dead_loads import STANDARD_GRAVITY, Load
from vjm_pin.model.format import load_vjm
from vjm_pin.model.registry import bundled_models, resolve_model
from vjm_pin.model.subdivide import subdivide_model
from vjm_pin.solver import EquilibriumSolver, MechanismSolver, blocks_at
from vjm_pin.solver.stability import check_stability_held, null_space, reduced_matrix

X = [-1.0, 0.0, 0.0]
RANGES = {"a": 1.0, "b": 0.5, "c": 0.5}  # the paper study (scripts/reproduce_paper.py)

PHI0, K_BAR = 0.3, 100.0  # the half truss: bar angle at rest (rad), axial spring (N/m)
TRUSS = f"""<robot xmlns:vjm="urn:vjm-pin:1" name="half-truss">
  <link name="base"/><link name="bar"/><link name="slider"/><link name="end"/>
  <joint name="phi" type="revolute"><parent link="base"/><child link="bar"/><axis xyz="0 0 1"/>
    <limit lower="-10" upper="10" effort="0" velocity="0"/></joint>
  <joint name="u" type="prismatic"><parent link="bar"/><child link="slider"/><axis xyz="1 0 0"/>
    <limit lower="-10" upper="10" effort="0" velocity="0"/></joint>
  <joint name="end_joint" type="fixed"><parent link="slider"/><child link="end"/><origin xyz="1 0 0"/></joint>
  <vjm:task frame="end" components="x y"/>
  <vjm:joint name="phi" role="passive" position="{PHI0}"/>
  <vjm:joint name="u" role="actuated" stiffness="{K_BAR}" position="0.0"/>
</robot>"""


def _model(name):
    if name == "c-s-k2":
        return subdivide_model(bundled_models()["paper-c-s"], 2), 0.5
    if name == "truss":
        return load_vjm(TRUSS), 0.6
    if name == "c-s+x":  # pulled: the S posture buckles too (trace_curve agrees)
        return resolve_model("paper-c-s"), 1e-3
    return resolve_model(f"paper-{name}"), RANGES[name[0]]


def _direction(name):
    return {"truss": [0.0, -1.0, 0.0], "c-s+x": [1.0, 0.0, 0.0]}.get(name, X)


def _margin(vm, eq, d) -> float:
    """μ: the largest eigenvalue with the task rows orthogonal to ``d`` held (check_stability_held)."""
    dt = np.asarray(d, float)[list(vm.task)]
    dt = dt / np.linalg.norm(dt)
    held = np.linalg.svd(dt.reshape(-1, 1))[0][:, 1:].T
    return float(check_stability_held(blocks_at(vm, eq.x, eq.wrench), held).eigenvalues.max())


@pytest.mark.parametrize(
    "name", ["c-s", "c-s-k2", "c-s+x", "c-z", "c-pi", "a-z", "b-s", "b-z", "truss"]
)
def test_agrees_with_the_first_critical_point_of_trace_curve(name):
    vm, rng = _model(name)
    d = _direction(name)
    r = critical_load(vm, d)
    cp = trace_curve(vm, d, rng, steps=5).critical[0]
    assert r.converged and r.check(1e-6), r
    assert r.kind == cp.kind
    assert r.force == pytest.approx(cp.force, rel=1e-6), "force (N)"
    assert r.deflection == pytest.approx(cp.deflection, rel=1e-5), "deflection (m)"
    assert r.force == pytest.approx(float(np.asarray(r.direction[:3]) @ r.wrench[:3]), rel=1e-12)
    assert r.equilibrium.converged and np.array_equal(r.x, r.equilibrium.x)


def test_model_a_s_rigid_start_closed_form():
    """A straight chain of rigid links with rotational springs Kθ = 1 N·m/rad, links L = 1 m:
    P_cr = Kθ/L (eq. 35) at deflection 0, as trace_curve reports it."""
    r = critical_load(resolve_model("paper-a-s"), X)
    assert r.force == pytest.approx(1.0, rel=1e-9), "Kθ/L (N)"
    assert r.deflection == 0.0 and r.kind == "bifurcation" and r.converged
    # the mode bends the chain: it moves the spring coordinates, not only the passive joint
    vm = resolve_model("paper-a-s")
    assert np.linalg.norm(r.mode[vm.theta_idx]) > 0.1


def test_limit_point_of_the_half_truss_closed_form():
    """The half von Mises truss (bar through a pinned base, axial spring k, end held in x):
    F(y) = k (y/ℓ − y), ℓ = √(c² + y²), c = cos φ₀; its maximum at ℓ* = c^(2/3) (snap-through)."""
    vm = load_vjm(TRUSS)
    r = critical_load(vm, [0.0, -1.0, 0.0])
    c = np.cos(PHI0)
    ell = c ** (2.0 / 3.0)
    y = np.sqrt(ell * ell - c * c)
    assert r.kind == "limit"
    assert r.force == pytest.approx(K_BAR * (y / ell - y), rel=1e-9), "F* (N)"
    assert r.deflection == pytest.approx(np.sin(PHI0) - y, rel=1e-7), "deflection (m)"
    assert abs(r.stiffness) < 1e-5 * K_BAR  # dF/ds = 0 at a limit point
    # the mode of a limit point: the motion along the path with x held (dφ/ds, du/ds)
    # = (−c/ℓ², −y/ℓ) (φ = atan2(y, c), u = ℓ − 1, y = sin φ₀ − s), normalised
    t = np.zeros(vm.model.nq)
    t[vm.q_idx] = -c / ell**2
    t[vm.theta_idx] = -y / ell
    assert abs(float(r.mode @ t)) / np.linalg.norm(t) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("name", ["c-s", "truss"])
def test_re_solved_equilibria_are_singular_there(name):
    """Equilibria re-solved by the plain solver, warm-started along the branch from the
    unloaded state: the margin μ changes sign across the critical deflection and is ~0 at it;
    the mode is the critical eigenvector computed here from SVD null spaces."""
    vm, _ = _model(name)
    d = np.concatenate([_direction(name), np.zeros(3)])
    r = critical_load(vm, d)
    sol = EquilibriumSolver(vm, follow_stable=False, restarts=0)
    eq = sol.solve(0.0 * d)
    for s in np.linspace(0.0, r.deflection, 21)[1:]:
        eq = sol.solve(s * d, x0=eq.x, wrench0=eq.wrench)
        assert eq.converged
    assert float(d @ eq.wrench) == pytest.approx(r.force, rel=1e-7)
    delta = 1e-3 * r.deflection
    before = sol.solve((r.deflection - delta) * d, x0=eq.x, wrench0=eq.wrench)
    after = sol.solve((r.deflection + delta) * d, x0=eq.x, wrench0=eq.wrench)
    m0, mb, ma = _margin(vm, eq, d), _margin(vm, before, d), _margin(vm, after, d)
    assert mb < 0 < ma
    assert abs(m0) < 0.01 * min(-mb, ma)
    # the mode: the critical eigenvector of eq. (23) at a bifurcation, of the force-control
    # matrix at a limit point (computed here with SVD bases)
    b = blocks_at(vm, r.x, r.wrench)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    if r.kind == "bifurcation":
        z = null_space(b.J_theta, b.J_q)
    else:
        dt = d[list(vm.task)]
        p = np.linalg.svd(dt.reshape(-1, 1))[0][:, 1:].T
        z = null_space(p @ b.J_theta, p @ b.J_q)
    ev, u = np.linalg.eigh(reduced_matrix(b, z))
    assert abs(ev[-1]) < 1e-6 * np.linalg.norm(vm.K_theta, 2)  # singular there
    if ev.size > 1:
        assert ev[-2] < -1e3 * abs(ev[-1])  # a simple critical eigenvalue: the mode is defined
    w = z @ u[:, -1]
    assert abs(float(w @ r.mode[free])) == pytest.approx(1.0, abs=1e-8)
    assert np.all(r.mode[np.setdiff1d(np.arange(vm.model.nq), free)] == 0)


def test_mode_is_a_zero_energy_direction_by_finite_differences():
    """Model C S at its critical point: the second difference of the total potential
    ``½θᵀKθ − Fᵀ(p − p₀)`` (the critical force kept fixed) along the buckling mode, a motion that
    keeps the end fixed to first order, vanishes (neutral equilibrium: the reduced matrix of
    eq. 23 is singular along it), while along the other such motions it is positive (stable)."""
    vm = resolve_model("paper-c-s")
    r = critical_load(vm, X)
    b = blocks_at(vm, r.x, r.wrench)
    z = null_space(b.J_theta, b.J_q)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    sol = EquilibriumSolver(vm)
    assert not np.any(r.wrench[3:])  # a pure force: its potential is −Fᵀp

    def potential(x):
        th = x[vm.theta_idx] - vm.theta0
        p, _ = sol.kin.placement(x)
        return 0.5 * th @ vm.K_theta @ th - r.wrench[:3] @ (p - sol.p0)

    def second(v, h=1e-4):
        xp, xm = r.x.copy(), r.x.copy()
        xp[free] += h * v
        xm[free] -= h * v
        return (potential(xp) - 2 * potential(r.x) + potential(xm)) / h**2

    mode = r.mode[free]
    others = [z[:, j] - (z[:, j] @ mode) * mode for j in range(z.shape[1])]
    others = [v / np.linalg.norm(v) for v in others if np.linalg.norm(v) > 0.5]
    stiff = min(second(v) for v in others)
    assert stiff > 0
    assert abs(second(mode)) < 1e-4 * stiff


def test_no_critical_point_and_bad_input():
    vm = resolve_model("paper-c-s")
    for name in ("paper-a-pi", "paper-b-pi"):  # paper §6.1: no sudden buckling in the Π posture
        with pytest.raises(NoCriticalPoint, match="stays stable"):
            critical_load(resolve_model(name), X, max_deflection=RANGES[name[6]])
    for bad, match in (
        ([0.0, 0.0, 0.0], "must not be zero"),
        ([1.0, 0.0], "3 or 6"),
        ([np.nan, 0.0, 0.0], "finite|NaN"),
        ([1.0, 0.0, 0.0, 1.0, 0.0, 0.0], "outside the task"),
    ):
        with pytest.raises(InputError, match=match):
            critical_load(vm, bad)
    with pytest.raises(InputError, match="outside the task"):
        critical_load(resolve_model("paper-a-s"), [0.0, 0.0, 1.0])
    for kw, match in (
        ({"rtol": 0.0}, "rtol"),
        ({"max_iter": 0}, "max_iter"),
        ({"max_deflection": -1.0}, "max_deflection"),
    ):
        with pytest.raises(InputError, match=match):
            critical_load(vm, X, **kw)
    with pytest.raises(InputError, match="another model"):
        critical_load(vm, X, solver=EquilibriumSolver(resolve_model("paper-c-z")))
    # the mechanism path's own checks
    with pytest.raises(InputError, match="mechanism solver"):
        critical_load(vm, X, solver=EquilibriumSolver(vm), loads=[Load(vm.frame, [0.0, 0.0, -1.0])])
    with pytest.raises(InputError, match="not twice"):
        critical_load(vm, X, solver=MechanismSolver(vm), gravity=(0.0, 0.0, -9.81))
    with pytest.raises(InputError, match="another model"):
        critical_load(vm, X, solver=MechanismSolver(resolve_model("paper-c-z")))
    with pytest.raises(InputError, match="translation"):
        critical_load(resolve_model("ur5"), [0, 0, 0, 0, 1, 0], free=True)
    with pytest.raises(InputError, match="needs an EquilibriumSolver or a MechanismSolver"):
        critical_load(vm, X, solver=object())


def test_search_budget_too_small_is_reported_not_hidden():
    vm = resolve_model("paper-a-z")
    full = critical_load(vm, X)
    short = critical_load(vm, X, max_iter=2)
    assert full.converged and full.check()
    assert not short.converged and not short.check() and short.message
    assert short.iterations <= 2
    assert abs(short.force / full.force - 1) > 1e-6  # the point reached, not the answer


def test_a_given_solver_and_range_give_the_same_point():
    vm = resolve_model("paper-c-z")
    a = critical_load(vm, X)
    b = critical_load(vm, X, solver=EquilibriumSolver(vm), max_deflection=0.5, rtol=1e-10)
    assert b.force == pytest.approx(a.force, rel=1e-7)
    assert b.residuals["location"] <= 1e-10


def test_cli_json_and_text(capsys):
    assert main(["critical", "paper-c-s", "--direction", "-1", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)  # validated against the schema by conftest
    r = critical_load(resolve_model("paper-c-s"), X)
    assert out["command"] == "critical" and out["kind"] == "bifurcation" and out["converged"]
    assert out["force"] == pytest.approx(r.force, rel=1e-12)
    assert out["deflection"] == pytest.approx(r.deflection, rel=1e-12)
    assert out["units"]["force"].startswith("N")
    assert main(["critical", "paper-c-s", "--direction", "-1", "0", "0"]) == 0
    text = capsys.readouterr().out
    assert "mN" in text and "mm" in text and "bifurcation" in text
    value = float(text.split("critical load ")[1].split(" mN")[0])
    assert value == pytest.approx(1e3 * r.force, rel=1e-7)


#: ``critical four-bar --direction -1 0 0 --load``: the words of a ``--load`` follow.
FOUR_BAR_LOAD = ["critical", "four-bar", "--direction", "-1", "0", "0", "--load"]


@pytest.mark.parametrize(
    "argv, status, needle",
    [
        (["critical", "paper-c-s", "--direction", "0", "0", "0"], 2, "must not be zero"),
        (["critical", "paper-c-s", "--direction", "-1", "0", "0", "--rtol", "1"], 2, "--rtol"),
        (["critical", "no-such-model", "--direction", "-1", "0", "0"], 2, "unknown model"),
        (FOUR_BAR_LOAD + ["nowhere", "0", "0", "1"], 2, "nowhere"),
        (FOUR_BAR_LOAD + ["coupler_link", "0", "1"], 2, "got 2 numbers"),
        (
            ["critical", "ur5", "--direction", "0", "0", "0", "0", "1", "0", "--free"],
            2,
            "translation",
        ),
        (["critical", "portal-frame", "--direction", "1", "0", "0"], 3, "stays stable"),
        (["critical", "paper-a-pi", "--direction", "-1", "0", "0"], 3, "no critical point"),
    ],
)
def test_cli_errors_are_one_line(argv, status, needle, capsys):
    assert main(argv) == status
    err = capsys.readouterr().err.strip()
    assert err.startswith("vjm-pin: error:") and len(err.splitlines()) == 1 and needle in err


# --------------------------------------------------------------------------- mechanisms
def _agrees_with_trace_curve(r, curve, rel=1e-6):
    """``r`` is ``curve``'s first critical point: force, deflection and kind."""
    assert curve.critical, "trace_curve found no critical point"
    cp = curve.critical[0]
    assert r.converged and r.check(1e-6), r.message
    assert r.kind == cp.kind
    assert r.force == pytest.approx(cp.force, rel=rel)
    assert r.deflection == pytest.approx(cp.deflection, rel=rel, abs=1e-12)
    return cp


@pytest.mark.parametrize("name", ["portal-frame", "portal-frame-6"])
@pytest.mark.parametrize("components,free", [("z", False), ("x z", True)])
def test_portal_sway_buckling_closed_form_with_dead_loads(tmp_path, name, components, free):
    """Vertical push on the beam's middle plus dead loads ``P₀`` on each column top: the sway
    buckling of ``P₀ + F/2 = 2k/h`` per column (tests/portal_frame.py) at ``F = 4k/h − 2P₀``, a rigid
    start (zero deflection); the dead load moves it, and trace_curve reports the same point."""
    from . import portal_frame as pf
    from .test_curve_mechanism import HEIGHT, K, column_loads, portal_with_task

    vm = portal_with_task(tmp_path, name, components)
    forces = []
    for ratio in (0.0, 0.5):
        p0 = ratio * pf.critical_load(K, HEIGHT)
        loads = column_loads(p0)
        r = critical_load(vm, [0, 0, -1], loads=loads, free=free)
        assert r.kind == "bifurcation" and r.deflection == 0.0
        assert r.force == pytest.approx(4 * K / HEIGHT - 2 * p0, rel=1e-8)
        assert r.stiffness == np.inf and abs(r.margin) <= 1e-6 * K
        _agrees_with_trace_curve(
            r, trace_curve(vm, [0, 0, -1], 0.3, 3, loads=loads, free=free), 1e-10
        )
        # the mode is the sway: the four corner springs turn by ±φ (equal magnitudes)
        corners = [vm.joint_index(j) for j in ("corner_bl", "corner_tl", "corner_tr", "corner_br")]
        m = np.abs(r.mode[corners])
        assert m.min() > 0.2 and np.ptp(m) <= 1e-6 * m.max()
        forces.append(r.force)
    assert forces[1] < forces[0]  # the dead load moved the critical point


def test_portal_sway_buckling_under_gravity_closed_form(tmp_path):
    """The portal frame with a mass M on the beam (``--gravity``: its weight W = Mg acts at its
    centre of mass, which moves with the translating beam): the push buckles it at
    ``F = 4k/h − W``, as trace_curve finds; without gravity at ``4k/h``."""
    from .test_curve_mechanism import HEIGHT, MODELS, K

    mass = 5.0
    text = (MODELS / "portal-frame.urdf").read_text()
    text = text.replace(
        '<vjm:task frame="top" components="x" />', '<vjm:task frame="top" components="z" />'
    )
    inertial = (
        f'<link name="beam"><inertial><origin xyz="0.3 0 0.1"/><mass value="{mass}"/>'
        '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
    )
    assert '<link name="beam" />' in text
    path = tmp_path / "portal-mass.urdf"
    path.write_text(text.replace('<link name="beam" />', inertial))
    vm = load_vjm(path)
    g = (0.0, 0.0, -STANDARD_GRAVITY)
    r = critical_load(vm, [0, 0, -1], gravity=g)
    assert r.force == pytest.approx(4 * K / HEIGHT - mass * STANDARD_GRAVITY, rel=1e-8)
    _agrees_with_trace_curve(r, trace_curve(vm, [0, 0, -1], 0.3, 3, gravity=g), 1e-10)
    assert critical_load(vm, [0, 0, -1]).force == pytest.approx(4 * K / HEIGHT, rel=1e-8)


def test_four_bar_limit_point_moves_with_the_dead_load():
    """A dead push on the four-bar's crank tip (tests/test_mechanism.py) softens the linkage
    pulled along −x until the force peaks (a limit point at a finite deflection): for two pushes
    critical_load and trace_curve agree to their tolerance, the point moves with the push, and
    the force of equilibria re-solved by MechanismSolver on both sides is lower (a maximum)."""
    from .test_mechanism import FOUR_BAR, crank_tip_push, pin_placement

    k = float(FOUR_BAR.K_theta[list(FOUR_BAR.theta_idx).index(FOUR_BAR.joint_index("crank"))].max())
    tip = pin_placement(FOUR_BAR, FOUR_BAR.reference, "coupler_link")[0]
    d = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    found = []
    for ratio in (0.9, 0.8):
        loads = [crank_tip_push(ratio * k / np.linalg.norm(tip))]
        r = critical_load(FOUR_BAR, d, loads=loads)
        cp = _agrees_with_trace_curve(r, trace_curve(FOUR_BAR, d, 0.05, 8, loads=loads), 1e-6)
        assert (
            r.kind == "limit"
            and r.deflection > 0
            and abs(r.stiffness) < 1e-3 * abs(cp.stiffness_before) + 1e-9 * k
        )
        ms = MechanismSolver(FOUR_BAR, loads)
        at = ms.solve(deflection=(r.deflection * d)[[0, 2]])
        assert d @ at.wrench == pytest.approx(r.force, rel=1e-7)
        for ds in (-2e-3, 2e-3):
            side = ms.solve(deflection=((r.deflection + ds) * d)[[0, 2]], x0=at.x)
            assert d @ side.wrench < r.force
        found.append(r)
    assert abs(found[0].deflection - found[1].deflection) > 1e-3 * found[0].deflection


@pytest.mark.parametrize("free", [False, True])
def test_two_column_parallel_robot_buckling_closed_form(free):
    """The two-column parallel robot of tests/test_parallel.py pushed along −x: held across x,
    column A buckles in plane at the root δ_c of its closed-form margin; free across x, the
    platform sways out of plane first, where ``k_r/(L−δ)² + k_r/L² − k_a δ/(L−δ)`` vanishes.
    The force is the axial ``k_a δ_c`` (to the bending springs' share) and trace_curve agrees."""
    from scipy.optimize import brentq

    from .parallel_models import columns_xml
    from .test_parallel import _in_plane

    length, kr, ka = 1.0, 100.0, 1e5

    def sway(dd):
        return kr / (length - dd) ** 2 + kr / length**2 - ka * dd / (length - dd)

    d_c = brentq(sway if free else _in_plane, 0.0, 0.2, xtol=1e-15)
    vm = load_vjm(columns_xml(length, kr, ka))
    r = critical_load(vm, [-1, 0, 0], free=free)
    assert r.kind == "bifurcation"
    assert r.deflection == pytest.approx(d_c, rel=1e-6)
    assert r.force == pytest.approx(ka * d_c, rel=1e-3)
    curve = trace_curve(vm, [-1, 0, 0], 3.4e-3 if free else 7e-3, 7, free=free)
    _agrees_with_trace_curve(r, curve, 1e-6)
    # the buckling mode is column A's (held: in plane) with B's joints at rest to round-off
    legs = {lg.name: [vm.joint_index(j) for j in lg.joints] for lg in vm.legs}
    if not free:
        assert np.abs(r.mode[legs["B"]]).max() < 1e-6 * np.abs(r.mode[legs["A"]]).max()


def test_serial_chain_through_the_mechanism_solver_is_the_serial_result():
    """The same chain and direction through MechanismSolver (the mechanism path) and through the
    serial path: the same critical point; a dead force ``G`` at the end along the direction
    shifts the external force by ``−G`` and leaves the deflection."""
    vm = resolve_model("paper-c-s")
    a = critical_load(vm, X)
    b = critical_load(vm, X, solver=MechanismSolver(vm))
    assert b.converged and b.kind == a.kind == "bifurcation"
    assert b.force == pytest.approx(a.force, rel=1e-6)
    assert b.deflection == pytest.approx(a.deflection, rel=1e-6)
    g = 0.05
    c = critical_load(vm, X, loads=[Load(vm.frame, g * np.array(X))])
    assert c.deflection == pytest.approx(a.deflection, rel=1e-6)
    assert c.force == pytest.approx(a.force - g, rel=1e-6)


def test_mechanism_search_budget_too_small_is_reported_not_hidden():
    from .test_mechanism import FOUR_BAR, crank_tip_push, pin_placement

    k = float(FOUR_BAR.K_theta[list(FOUR_BAR.theta_idx).index(FOUR_BAR.joint_index("crank"))].max())
    tip = pin_placement(FOUR_BAR, FOUR_BAR.reference, "coupler_link")[0]
    loads = [crank_tip_push(0.9 * k / np.linalg.norm(tip))]
    full = critical_load(FOUR_BAR, X, loads=loads)
    short = critical_load(FOUR_BAR, X, loads=loads, max_iter=2)
    assert full.converged and full.check()
    assert not short.converged and not short.check() and short.message
    assert short.iterations <= 2
    assert abs(short.force / full.force - 1) > 1e-6


def test_cli_mechanism_loads_json_and_text(capsys):
    """--load on a closed-loop model: the JSON (SI, the schema) is critical_load's answer and
    lists the dead load; the text names it."""
    from .test_mechanism import FOUR_BAR, crank_tip_push, pin_placement

    k = float(FOUR_BAR.K_theta[list(FOUR_BAR.theta_idx).index(FOUR_BAR.joint_index("crank"))].max())
    tip = pin_placement(FOUR_BAR, FOUR_BAR.reference, "coupler_link")[0]
    ld = crank_tip_push(0.9 * k / np.linalg.norm(tip))
    words = [repr(float(v)) for v in ld.wrench[:3]]
    argv = ["critical", "four-bar", "--direction", "-1", "0", "0", "--load", ld.frame, *words]
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)  # validated against the schema by conftest
    r = critical_load(resolve_model("four-bar"), X, loads=[ld])
    assert (
        out["kind"] == "limit"
        and out["converged"]
        and out["free"] is False
        and out["gravity"] is False
    )
    assert out["force"] == pytest.approx(r.force, rel=1e-12)
    assert out["loads"][0]["frame"] == ld.frame
    assert out["loads"][0]["wrench"] == pytest.approx(list(ld.wrench), rel=1e-12)
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "limit" in text and "dead load at 'coupler_link'" in text
    assert (
        main(["critical", "paper-c-s", "--direction", "-1", "0", "0", "--gravity", "--json"]) == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["gravity"] is True and out["converged"]


def test_orthoglide_agrees_with_trace_curve():
    """The bundled Orthoglide (three legs, closures at the platform) pushed along −x: the first
    critical point of trace_curve; a bifurcation: the equilibria re-solved by a plain
    MechanismSolver (no stable-branch following) 1 % before and after it are stable and unstable
    with the platform held (eq. 23 with the closures, the solver's own verdict), and the force
    along the path passes through the critical force there."""
    vm = resolve_model("orthoglide-q0")
    r = critical_load(vm, X)
    _agrees_with_trace_curve(r, trace_curve(vm, X, 3e-3, 6), 1e-6)
    assert r.kind == "bifurcation" and r.deflection > 0
    assert np.linalg.norm(r.mode) == pytest.approx(1.0, rel=1e-12)
    ms = MechanismSolver(vm, follow_stable=False)
    side = {}
    for f in (0.99, 1.01):
        e = ms.solve(deflection=(f * r.deflection * r.direction)[:3], x0=r.x)
        assert e.converged
        side[f] = e
    assert side[0.99].stable_end_held and not side[1.01].stable_end_held
    forces = [r.direction @ side[f].wrench for f in (0.99, 1.01)]
    assert forces[0] < r.force < forces[1]


# --------------------------------------------------------------------------- long chains (compiled)
# With VJM_PIN_JIT=1 a chain of ≥ POINT_MIN_N free coordinates solves the eigenproblems of the
# start, of the linearised estimate and of the mode by the O(n) chain algebra
# (vjm_pin/solver/chain_eigen.py); checked here against the dense routines the numpy path runs.


def _long_column(k=4, posture="s"):
    from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf

    return load_vjm(paper_model_urdf("c", posture, beam=PAPER_BEAM, subdivide=k))


def _chain_setup(vm, d=X):
    """A tracer as critical_load builds it, its start point (chain path) and the dense problem data."""
    from vjm_pin.analysis import critical as crit
    from vjm_pin.analysis.curve import _direction, _Tracer
    from vjm_pin.model.task import task_vector

    sol = EquilibriumSolver(vm)
    dd = _direction(vm, task_vector(d, vm.task, "direction", "m"))
    tr = _Tracer(vm, dd, sol.length_scale, sol, 1e-4)
    assert crit._chain(tr), "the compiled chain path applies to this model"
    return crit, sol, tr


def _dense_eigs(vm, x, wrench, rows=None):
    b = blocks_at(vm, x, wrench)
    z = null_space(b.J_theta, b.J_q) if rows is None else null_space(rows @ b.J_theta, rows @ b.J_q)
    return np.linalg.eigh(reduced_matrix(b, z)), z  # eigenvalues of eq. (23)'s matrix: −λ of K − H


@pytest.fixture
def jit_on(monkeypatch):
    pytest.importorskip("numba")
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    return monkeypatch


def test_chain_eigenproblems_match_dense_ones(jit_on):
    """HeldEigen (vjm_pin.solver.chain_eigen) at a loaded configuration of the k = 4 column, end
    held in every task row and in the rows orthogonal to d: the smallest eigenvalue of
    ``Zᵀ sym(K − H) Z`` and its eigenvector, the Sturm counts at shifts around the spectrum's
    low end, the Rayleigh quotient, and the pencil's largest root (against the dense generalized
    eigenproblem of linearised_load)."""
    from vjm_pin.solver.chain_eigen import held_eigen

    vm = _long_column(4)
    crit, sol, tr = _chain_setup(vm)
    eq = sol.solve(2e-5 * np.array([-1.0, 0, 0, 0, 0, 0]))  # compressed, before buckling
    assert eq.converged
    jac = tr.kin.evaluate(eq.x, hessian=False).jacobian
    for rows in (None, tr.P):
        he = held_eigen(tr.kernel, tr.mask, jac, rows)
        assert he is not None
        (ev, u), z = _dense_eigs(vm, eq.x, eq.wrench, rows)
        lam, y = he.smallest(eq.wrench)
        scale = np.linalg.norm(vm.K_theta, 2)
        assert lam == pytest.approx(-ev[-1], rel=1e-9, abs=1e-12 * scale)
        w = he.free_vector(y)
        assert abs(float(w @ (z @ u[:, -1]))) == pytest.approx(1.0, abs=1e-8)
        assert he.rayleigh(eq.wrench, y) == pytest.approx(lam, rel=1e-9)
        lam_d, y_d = he.smallest_definite(eq.wrench)  # positive definite before buckling
        assert (
            lam > 0
            and lam_d == pytest.approx(lam, rel=1e-9)
            and abs(y_d @ y) == pytest.approx(1.0, abs=1e-6)
        )
        for sigma in (0.5 * lam, 0.5 * (-ev[-1] - ev[-2]), 0.5 * (-ev[-3] - ev[-4])):
            assert he.count_below(eq.wrench, sigma) == int(np.sum(-ev < sigma))
        # warm-started from a perturbed vector: the same eigenpair
        lam2, y2 = he.smallest(eq.wrench, y + 1e-3 * np.sin(np.arange(he.n)))
        assert lam2 == pytest.approx(lam, rel=1e-10) and abs(y2 @ y) == pytest.approx(1.0, abs=1e-9)
    # the pencil at the unloaded start against the dense linearised estimate
    with jit_on.context() as mp:
        mp.setenv("VJM_PIN_JIT", "0")
        tr0 = crit._Tracer(vm, tr.d, sol.length_scale, EquilibriumSolver(vm), 1e-4)
        p0 = crit._start(vm, tr0, tr0.solver, tr0.d)
        dense = crit.linearised_load(tr0, p0)
    he = held_eigen(tr.kernel, tr.mask, tr.kin.evaluate(p0.eq.x, hessian=False).jacobian, tr.P)
    w1 = p0.tan[1] / p0.k
    start = he.smallest(p0.eq.wrench)[1]  # μ's eigenvector at the start (as critical_load starts)
    t, y, certified = he.pencil(p0.eq.wrench, w1, start, cert=1e-10)
    assert certified and t == pytest.approx(dense, rel=1e-10)
    assert he.count_below(p0.eq.wrench + 0.999 * t * w1) == 0  # no root before it
    assert he.count_below(p0.eq.wrench + 1.001 * t * w1) == 1  # one just after it


@pytest.mark.parametrize(
    "posture, d", [("s", X), ("z", X), ("s", [-1.0, 0.05, 0.0])], ids=["s", "z", "s-oblique"]
)
def test_chain_path_gives_the_dense_path_result(jit_on, posture, d):
    """critical_load on the k = 4 column with the compiled chain kernels against the numpy path:
    force, deflection, linearised estimate, kind and mode (the straight column, the bent Z
    posture, an oblique push); the reference's eq. (23) verdict; and against trace_curve's first
    critical point (straight column)."""
    from vjm_pin.analysis import critical as crit
    from vjm_pin.solver import chain_eigen

    vm = _long_column(4, posture)
    calls = []
    orig = chain_eigen.held_eigen

    def spy(*a, **k):  # the chain eigenproblems (reference, estimate, refined start, mode)
        got = orig(*a, **k)
        calls.append(got is not None)
        return got

    jit_on.setattr(crit, "held_eigen", spy)
    lin = []
    orig_lin = crit._linearised_chain
    jit_on.setattr(crit, "_linearised_chain", lambda *a: lin.append(orig_lin(*a)) or lin[-1])
    fast = critical_load(vm, d)
    assert calls and all(calls), "the chain eigenproblems ran"
    assert len(lin) == 1 and lin[0] is not None, "the linearised estimate by the chain algebra"
    with jit_on.context() as mp:
        mp.setenv("VJM_PIN_JIT", "0")
        n_before = len(calls)
        dense = critical_load(vm, d)
        assert len(calls) == n_before  # the numpy path solves no chain eigenproblem
    assert fast.converged and dense.converged and fast.kind == dense.kind == "bifurcation"
    assert fast.check(1e-7) and fast.iterations <= dense.iterations
    # both located to rtol = 1e-7 (the chain path may start nearer: _refined_start)
    assert fast.force == pytest.approx(dense.force, rel=1e-7)
    assert fast.deflection == pytest.approx(dense.deflection, rel=1e-6)
    assert fast.estimate == pytest.approx(dense.estimate, rel=1e-9)
    assert abs(float(fast.mode @ dense.mode)) == pytest.approx(1.0, abs=1e-8)
    assert fast.mode[np.argmax(np.abs(fast.mode))] > 0
    if posture == "s" and d is X:
        cp = trace_curve(vm, X, 6e-4, steps=4).critical[0]
        assert fast.force == pytest.approx(cp.force, rel=1e-7)
    # the unloaded reference: the chain's eq. (23) verdict and largest eigenvalue, the dense spectrum
    _, sol, tr = _chain_setup(vm)
    ref = crit._reference_chain(vm, sol, tr)
    (ev, _), z = _dense_eigs(vm, ref.x, ref.wrench)
    assert ref.stability.stable and ref.stability.null_dim == z.shape[1]
    assert -ref.stability.margin == pytest.approx(ev[-1], rel=1e-9)
    np.testing.assert_allclose(ref.stability.eigenvalues, ev, rtol=1e-9, atol=1e-12 * abs(ev).max())


def _k4_start_and_dense_estimate(jit_on):
    """The k = 4 column's chain setup, its unloaded start point, and the linearised critical load
    of the dense path (``VJM_PIN_JIT=0``) for reference: ``(critical module, tracer, start, estimate)``."""
    vm = _long_column(4)
    crit, sol, tr = _chain_setup(vm)
    p0 = crit._start(vm, tr, sol, tr.d)
    with jit_on.context() as mp:
        mp.setenv("VJM_PIN_JIT", "0")
        tr0 = crit._Tracer(vm, tr.d, sol.length_scale, EquilibriumSolver(vm), 1e-4)
        dense = crit.linearised_load(tr0, crit._start(vm, tr0, tr0.solver, tr0.d))
    return crit, tr, p0, dense


@pytest.mark.parametrize("broken", ["pencil", "uncertified"])
def test_linearised_chain_newton_when_the_pencil_gives_way(jit_on, broken):
    """Where the pencil's power iteration gives no certified root (no quotient, or a Sturm count
    that is not reliable) the linearised estimate comes from Newton on the certified smallest
    eigenvalue: the same value as the dense generalized eigenproblem."""
    from vjm_pin.solver import chain_eigen

    crit, tr, p0, dense = _k4_start_and_dense_estimate(jit_on)
    orig = chain_eigen.HeldEigen.pencil
    if broken == "pencil":
        jit_on.setattr(chain_eigen.HeldEigen, "pencil", lambda self, *a, **k: None)
    else:  # a quotient, not certified (as where the Sturm count is not reliable)
        jit_on.setattr(
            chain_eigen.HeldEigen,
            "pencil",
            lambda self, *a, **k: orig(self, *a, **k)[:2] + (False,),
        )
    got = crit._linearised_chain(tr, p0, p0.tan[1] / p0.k)
    assert got is not None and got == pytest.approx(dense, rel=1e-10)


def test_refined_start_one_confirming_evaluation(jit_on):
    """The straight k = 4 column: the frozen-geometry estimate repeated at its tangent prediction
    (_refined_start) puts the first equilibrium within rtol of the root, on the stable side: one
    evaluation, verified (μ < 0 there, one more Newton step below rtol), the force within rtol of
    the numpy path's (two evaluations) and of re-solved equilibria's sign change of μ. With a
    tolerance the refined estimate cannot promise (rtol = 1e-10) the search starts at the
    linearised estimate as the numpy path does, and agrees with it to that tolerance."""
    from vjm_pin.analysis import critical as crit

    vm = _long_column(4)
    fast = critical_load(vm, X)
    with jit_on.context() as mp:
        mp.setenv("VJM_PIN_JIT", "0")
        dense = critical_load(vm, X)
        tight_dense = critical_load(vm, X, rtol=1e-10)
    assert fast.iterations == 1 < dense.iterations
    assert fast.converged and fast.check(1e-7) and fast.margin < 0  # the stable side
    assert fast.force == pytest.approx(dense.force, rel=1e-7)
    assert fast.force <= dense.force * (1 + 1e-12)
    # μ changes sign between re-solved equilibria just before and after (1e-6 relative)
    sol = EquilibriumSolver(vm, follow_stable=False, restarts=0)
    d6 = np.array([-1.0, 0, 0, 0, 0, 0])
    ms = []
    for f in (1 - 1e-6, 1 + 1e-6):
        eq = sol.solve(f * fast.deflection * d6, x0=fast.x, wrench0=fast.wrench)
        assert eq.converged
        ms.append(_margin(vm, eq, d6))
    assert ms[0] < 0 < ms[1]
    calls = []
    orig = crit._refined_start
    jit_on.setattr(crit, "_refined_start", lambda *a: calls.append(orig(*a)) or calls[-1])
    tight = critical_load(vm, X, rtol=1e-10)
    assert calls == [None]
    assert tight.force == pytest.approx(tight_dense.force, rel=1e-10)


def test_held_eigen_setup_matches_numpy(jit_on):
    """held_eigen's compiled setup (chain_eigen._setup_loops) against the numpy expressions: the
    Jacobian columns in chain order (the same numbers), the held rows ``P·J`` (to rounding), and
    the rank test against numpy's singular values: declined for held rows of deficient rank or a
    ratio below RANK_RATIO, and for a non-finite Jacobian (the dense routine then decides)."""
    from vjm_pin.solver import chain_eigen

    vm = _long_column(4)
    _, sol, tr = _chain_setup(vm)
    x = vm.reference.copy()
    x[sol.free] += 1e-3 * np.sin(np.arange(len(sol.free)))
    jac = tr.kin.evaluate(x, hessian=False).jacobian
    task = tr.kernel.task
    for rows in (None, tr.P):
        he = chain_eigen.held_eigen(tr.kernel, tr.mask, jac, rows)
        jz = jac[:, he._lay.cols]
        cb = jz[task] if rows is None else rows @ jz[task]
        assert np.array_equal(he._jz, jz)
        np.testing.assert_allclose(he._cb, cb, rtol=0, atol=1e-14 * np.abs(cb).max())
        assert he.m == cb.shape[0] and he.n == jz.shape[1]
    p = tr.P
    for eps, ok in ((1e-5, True), (1e-9, False), (0.0, False)):
        rows = np.vstack([p[0], p[0] + eps * p[1]])
        sv = np.linalg.svd(rows @ jac[:, tr.free][task], compute_uv=False)
        assert (sv[-1] > chain_eigen.RANK_RATIO * sv[0]) == ok  # numpy's verdict, ...
        assert (chain_eigen.held_eigen(tr.kernel, tr.mask, jac, rows) is not None) == ok  # ... the setup's
    bad = jac.copy()
    bad[1, sol.free[7]] = np.nan
    assert chain_eigen.held_eigen(tr.kernel, tr.mask, bad) is None


def test_pencil_rayleigh_ritz_from_a_generic_start(jit_on):
    """HeldEigen.pencil (the power iteration accelerated by Rayleigh–Ritz on its Krylov space) from a
    generic start, not μ's eigenvector: the same certified root as the dense generalized
    eigenproblem; after a single solve the quotient lies between the root and the start's own
    quotient (the Ritz vector of a space that holds the start); one more step is no worse."""
    from vjm_pin.solver.chain_eigen import held_eigen

    crit, tr, p0, dense = _k4_start_and_dense_estimate(jit_on)
    he = held_eigen(tr.kernel, tr.mask, tr.kin.evaluate(p0.eq.x, hessian=False).jacobian, tr.P)
    w0, w1 = p0.eq.wrench, p0.tan[1] / p0.k
    start = np.cos(0.37 * np.arange(he.n)) + 0.1
    t, y, certified = he.pencil(w0, w1, start, cert=1e-10)
    assert certified and t == pytest.approx(dense, rel=1e-10)
    assert abs(np.linalg.norm(y) - 1.0) < 1e-12
    # the start's own quotient yᵀAy / yᵀBy (A = sym W(w₀), B = A − sym W(w₀ + w₁)), in the null space
    ys = he.pencil(w0, w1, start, max_steps=0)[1]  # the start projected, no solve
    r0, r1 = he.rayleigh(w0, ys), he.rayleigh(w0 + w1, ys)
    q0 = r0 / (r0 - r1)
    t1 = he.pencil(w0, w1, start, max_steps=1)[0]
    t2 = he.pencil(w0, w1, start, max_steps=2)[0]
    # (q0 by a difference of two quotients: to ~1e-11 here)
    assert dense * (1 - 1e-12) <= t2 <= t1 * (1 + 1e-12) and t1 <= q0 * (1 + 1e-9)
    assert he.pencil(w0, w1, start, max_steps=0)[0] == pytest.approx(q0, rel=1e-9)


def test_mode_from_the_correctors_certified_verdict(jit_on):
    """At a bifurcation the mode is the eigenvector of eq. (23) the corrector certified at the
    critical point's equilibrium when that is bit for bit the same problem (no eigenproblem of its
    own): the same mode as the mode's own eigenproblem, and the same point; the verdict is not
    taken for another wrench, Jacobian or layout."""
    from vjm_pin.analysis import critical as crit
    from vjm_pin.solver import chain_kernel

    vm = _long_column(4)
    used = []
    orig = crit._corrector_verdict
    jit_on.setattr(crit, "_corrector_verdict", lambda *a: used.append(orig(*a)) or used[-1])
    fast = critical_load(vm, X)
    assert fast.kind == "bifurcation" and used and used[-1] is not None
    jit_on.setattr(crit, "_corrector_verdict", lambda *a: None)
    own = critical_load(vm, X)
    assert own.force == fast.force and own.deflection == fast.deflection
    assert abs(float(own.mode @ fast.mode)) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(fast.mode, own.mode, atol=1e-9)
    # the record answers only for its own problem (bit for bit)
    key, rec = next(reversed(chain_kernel._VERDICT.values()))[0], next(reversed(chain_kernel._VERDICT.values()))
    _, lay, jz, task, w, lam, vec = rec
    got = chain_kernel.last_verdict(key, lay, jz, task, w)
    assert got is not None and got[0] == lam and got[1] is vec
    assert chain_kernel.last_verdict(key, lay, jz, task, w * (1 + 4e-16)) is None
    jz2 = jz.copy()
    jz2[0, 3] = np.nextafter(jz2[0, 3], np.inf)
    assert chain_kernel.last_verdict(key, lay, jz2, task, w) is None
    assert chain_kernel.last_verdict(key, lay, jz, task[::-1].copy(), w) is None
    assert chain_kernel.last_verdict(key.copy(), lay, jz, task, w) is None
