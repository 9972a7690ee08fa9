"""Loop closures, dead loads anywhere and the closed-loop models (issue 13, groundwork).

Every derivative against central finite differences; residuals against Pinocchio's own SE(3)
algebra; the portal frame against its closed form (tests/portal_frame.py); the bundled models
against their generator."""

from __future__ import annotations

import importlib.util
import itertools
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin import load_vjm
from vjm_pin.kinematics.closures import (
    ClosureSet,
    constraint_rank,
    jlog3,
    jlog3_derivative,
    min_norm_multipliers,
)
from vjm_pin.kinematics.dead_loads import DeadLoads, Load, parse_load_args
from vjm_pin.exceptions import (
    ArgumentError,
    ClosureViolated,
    FrameNotFound,
    InputError,
    ModelError,
    UnknownVjmTag,
)
from vjm_pin.kinematics.frames import FrameKinematics
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.model.format import COMPONENTS, Closure

from . import portal_frame as pf
from .chains import random_chain_urdf
from .urdf_compare import urdf_differences

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models" / "urdf"
H = 1e-5  # central-difference step (m, rad): truncation ~1e-10, round-off ~1e-11


def _script():
    spec = importlib.util.spec_from_file_location(
        "make_closed_models", ROOT / "scripts" / "make_closed_models.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


GEN = _script()
PORTAL = load_vjm(MODELS / "portal-frame.urdf")
PORTAL6 = load_vjm(MODELS / "portal-frame-6.urdf")
FOUR_BAR = load_vjm(MODELS / "four-bar.urdf")
K, HEIGHT, SPAN = GEN.PORTAL["k"], GEN.PORTAL["height"], GEN.PORTAL["span"]


def rel(a, b, floor=1e-3):
    return float(np.abs(np.asarray(a) - b).max() / max(np.abs(b).max(), floor))


def fd_columns(fun, x, h=H):
    """Central differences of ``fun`` (x -> array) along every coordinate: (..., nv)."""
    cols = []
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        cols.append((fun(xp) - fun(xm)) / (2 * h))
    return np.stack(cols, axis=-1)


def pin_relative(model, x, fa, fb):
    """(6,) placement of frame fa relative to fb from Pinocchio's SE3 algebra."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, x)
    m = data.oMf[fb].inverse() * data.oMf[fa]
    return np.concatenate([m.translation, pin.log3(m.rotation)])


def planar_chain_urdf(rng, n_joints=5) -> str:
    """A random planar chain in the x–z plane (joint axes +y), frames ``l1 … ln`` and ``tool``."""
    parts = ['<robot name="planar">', '  <link name="base"/>']
    for i in range(n_joints):
        xyz = (rng.uniform(0.2, 0.6), 0.0, rng.uniform(-0.3, 0.3))
        parent = "base" if i == 0 else f"l{i}"
        kind = "prismatic" if rng.random() < 0.2 else "revolute"
        axis = "1 0 0" if kind == "prismatic" else "0 1 0"
        parts.append(f'  <link name="l{i + 1}"/>')
        parts.append(
            f'  <joint name="j{i + 1}" type="{kind}"><parent link="{parent}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{xyz[0]!r} 0 {xyz[2]!r}" rpy="0 {rng.uniform(-1, 1)!r} 0"/><axis xyz="{axis}"/>'
            '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
    parts.append('  <link name="tool"/>')
    parts.append(
        f'  <joint name="tool_joint" type="fixed"><parent link="l{n_joints}"/><child link="tool"/>'
        f'<origin xyz="0.3 0 0.1" rpy="0 0.4 0"/></joint>'
    )
    return "\n".join(parts + ["</robot>"])


def random_loop(seed: int, planar: bool):
    """A random chain with one closure between two of its frames (random components in a
    random order), at a random configuration (not assembled: the derivatives do not care)."""
    rng = np.random.default_rng(seed)
    text = planar_chain_urdf(rng) if planar else random_chain_urdf(rng, 6)
    model = pin.buildModelFromXML(text)
    links = [f"l{i}" for i in range(1, 6)] + ["tool"]
    fb = ["base", str(rng.choice(links[:3]))][seed % 2]
    fa = str(rng.choice(links[3:]))
    n = int(rng.integers(1, 7))
    comps = tuple(str(c) for c in rng.permutation(COMPONENTS)[:n])
    closure = Closure(f"loop{seed}", fa, fb, comps)
    x = rng.uniform(-1.2, 1.2, model.nq)
    return model, closure, x, rng


# --------------------------------------------------------------------------- log3 pieces
@pytest.mark.parametrize("t", [0.0, 1e-7, 5e-4, 0.05, 0.0999, 0.1001, 0.7, 2.5])
def test_jlog3_and_its_derivative(t):
    rng = np.random.default_rng(int(t * 1e4) + 3)
    theta = rng.standard_normal(3)
    theta *= t / np.linalg.norm(theta)
    lam = rng.standard_normal(3)
    # Pinocchio's Jlog3 is exact away from its small-angle switch (pin 4.1: ~4e-10 off near 5e-4)
    assert np.abs(jlog3(theta) - pin.Jlog3(pin.exp3(theta))).max() < (
        1e-9 if 1e-4 < t < 5e-3 else 1e-14
    )
    # the definition: log3(R exp3(δ)) = θ + Jlog3 δ + O(δ²)
    d = 1e-7 * rng.standard_normal(3)
    step = (pin.log3(pin.exp3(theta) @ pin.exp3(d)) - pin.log3(pin.exp3(theta) @ pin.exp3(-d))) / 2
    assert np.abs(step - jlog3(theta) @ d).max() < 1e-13
    fd = fd_columns(lambda th: jlog3(th) @ lam, theta, 1e-5)
    assert np.abs(jlog3_derivative(theta, lam) - fd).max() < 1e-9


# --------------------------------------------------------------------------- residual, Jacobian, Hessian
@pytest.mark.parametrize("seed,planar", [(s, p) for s in range(6) for p in (False, True)])
def test_closure_residual_jacobian_hessian_against_finite_differences(seed, planar):
    model, closure, x, rng = random_loop(seed, planar)
    cs = ClosureSet(model, [closure])
    st = cs.evaluate(x)
    fa, fb = model.getFrameId(closure.frame_a), model.getFrameId(closure.frame_b)
    assert np.abs(st.residual - pin_relative(model, x, fa, fb)[list(closure.indices)]).max() < 1e-13
    assert st.labels == tuple(f"{closure.name}.{c}" for c in closure.components)

    fd_j = fd_columns(lambda y: cs.evaluate(y, hessian=False).residual, x)
    assert rel(st.jacobian, fd_j) < 1e-7, "∂c/∂x"

    lam = rng.standard_normal(len(closure.components)) * 10
    hes = st.hessian(lam)
    fd_h = fd_columns(lambda y: cs.evaluate(y, hessian=False).jacobian.T @ lam, x)
    assert rel(hes, fd_h) < 1e-6, "∂(Cᵀλ)/∂x"
    assert np.abs(hes - hes.T).max() <= 1e-12 * max(np.abs(hes).max(), 1.0), (
        "the Hessian of λᵀc is symmetric"
    )


@pytest.mark.parametrize("seed", range(4))
def test_reaction_wrenches_are_a_pair_of_dead_wrenches(seed):
    """Cᵀλ = J_aᵀW_a + J_bᵀW_b with Pinocchio's own frame Jacobians; the pair is equal and
    opposite (zero resultant, zero moment about any point)."""
    model, closure, x, rng = random_loop(seed, planar=False)
    st = ClosureSet(model, [closure]).evaluate(x)
    lam = rng.standard_normal(len(closure.components))
    w_a, w_b = st.reaction_wrenches(lam)[closure.name]
    data = model.createData()
    fa, fb = model.getFrameId(closure.frame_a), model.getFrameId(closure.frame_b)
    ja = pin.computeFrameJacobian(model, data, x, fa, pin.LOCAL_WORLD_ALIGNED)
    jb = pin.computeFrameJacobian(model, data, x, fb, pin.LOCAL_WORLD_ALIGNED)
    assert rel(ja.T @ w_a + jb.T @ w_b, st.generalized_force(lam)) < 1e-12
    pa, pb = data.oMf[fa].translation, data.oMf[fb].translation
    assert np.abs(w_a[:3] + w_b[:3]).max() < 1e-12
    moment_at_origin = w_a[3:] + np.cross(pa, w_a[:3]) + w_b[3:] + np.cross(pb, w_b[:3])
    assert np.abs(moment_at_origin).max() < 1e-12 * max(1.0, np.abs(w_a).max())


def test_two_closures_share_one_frame_pass_and_stack_in_order():
    model, c1, x, rng = random_loop(7, planar=False)
    c2 = Closure("second", "l2", "tool", ("rz", "x"))
    frames = FrameKinematics(
        model, [model.getFrameId(n) for n in ("l2", "tool", c1.frame_a, c1.frame_b)]
    )
    both = ClosureSet(model, [c1, c2], frames=frames)
    st = both.evaluate(x)
    alone = [ClosureSet(model, [c]).evaluate(x) for c in (c1, c2)]
    assert np.array_equal(st.residual, np.concatenate([a.residual for a in alone]))
    assert np.array_equal(st.jacobian, np.vstack([a.jacobian for a in alone]))
    assert st.labels[-2:] == ("second.rz", "second.x")
    lam = rng.standard_normal(both.n_rows)
    n1 = len(c1.components)
    assert rel(st.hessian(lam), alone[0].hessian(lam[:n1]) + alone[1].hessian(lam[n1:])) < 1e-14
    fd = fd_columns(lambda y: both.evaluate(y, hessian=False).jacobian.T @ lam, x)
    assert rel(st.hessian(lam), fd) < 1e-6
    assert frames.evaluate(x) is frames.evaluate(x.copy()), (
        "same configuration: no new Pinocchio pass"
    )


@pytest.mark.parametrize("vm", [PORTAL, PORTAL6, FOUR_BAR], ids=["portal", "portal6", "four-bar"])
def test_assembled_models_near_the_reference(vm):
    """Near an assembled configuration the relative rotation is small (log3 series branch)."""
    cs = ClosureSet(vm)
    assert np.abs(cs.evaluate(vm.reference).residual).max() < 1e-15
    rng = np.random.default_rng(11)
    for scale in (0.0, 5e-4, 0.2):
        x = vm.reference + scale * rng.standard_normal(vm.model.nq)
        st = cs.evaluate(x)
        assert (
            rel(st.jacobian, fd_columns(lambda y: cs.evaluate(y, hessian=False).residual, x)) < 1e-7
        )
        lam = rng.standard_normal(cs.n_rows) * 100
        fd = fd_columns(lambda y, lam=lam: cs.evaluate(y, hessian=False).jacobian.T @ lam, x)
        assert rel(st.hessian(lam), fd) < 1e-6


def test_out_of_plane_rows_of_a_planar_loop_are_identically_zero():
    """Closed in six components, the planar portal's y, rx, rz rows vanish with their
    Hessians: any multiplier on them does nothing (why they are redundant)."""
    cs = ClosureSet(PORTAL6)
    rng = np.random.default_rng(5)
    x = PORTAL6.reference + 0.3 * rng.standard_normal(4)
    st = cs.evaluate(x)
    out = [st.labels.index(f"right_foot.{c}") for c in ("y", "rx", "rz")]
    assert np.abs(st.jacobian[out]).max() == 0.0
    lam = np.zeros(6)
    lam[out] = rng.standard_normal(3) * 1e3
    assert np.abs(st.hessian(lam)).max() < 1e-12


# --------------------------------------------------------------------------- rank and multipliers
def _stacked(vm, x):
    """Closure rows then the held task row(s) (translation rows of the task frame Jacobian)."""
    st = ClosureSet(vm).evaluate(x)
    jt = Kinematics(vm.model, vm.frame_id).evaluate(x, hessian=False).jacobian[list(vm.task)]
    return np.vstack([st.jacobian, jt]), st.labels + tuple(f"task.{c}" for c in vm.task_names)


@pytest.mark.parametrize("phi", [0.0, 0.3])
def test_portal_frame_closed_in_six_components_has_three_redundant_rows(phi):
    """Expectation: a planar loop has 3 independent closure rows; the held task x adds one
    (it moves along the sway): rank 4 of 7 rows, the out-of-plane rows are redundant."""
    jac, labels = _stacked(PORTAL6, pf.configuration(PORTAL6, phi))
    r = constraint_rank(jac, labels)
    assert (r.rank, r.n_redundant) == (4, 3)
    assert set(r.redundant_labels) == {"right_foot.y", "right_foot.rx", "right_foot.rz"}
    assert np.linalg.matrix_rank(jac) == 4 == np.linalg.matrix_rank(jac[list(r.independent)])
    jac3, labels3 = _stacked(PORTAL, pf.configuration(PORTAL, phi))
    r3 = constraint_rank(jac3, labels3)
    assert (r3.rank, r3.n_redundant) == (4, 0)


def test_closure_null_space_is_the_sway_mode():
    for vm in (PORTAL, PORTAL6):
        st = ClosureSet(vm).evaluate(vm.reference)
        z = pf.sway_direction(vm)
        _, s, vt = np.linalg.svd(st.jacobian)
        null = vt[int(np.sum(s > 1e-10 * s[0])) :]
        assert null.shape[0] == 1, "one degree of freedom: the sway"
        assert abs(abs(null[0] @ z) / np.linalg.norm(z) - 1) < 1e-14
        assert np.abs(st.jacobian @ z).max() < 1e-15


@pytest.mark.parametrize("seed", range(5))
def test_constraint_rank_on_built_dependencies(seed):
    rng = np.random.default_rng(seed)
    nv, r = 9, int(rng.integers(2, 7))
    base = rng.standard_normal((r, nv)) * rng.uniform(1e-3, 1e3, (r, 1))  # rows of mixed units
    combos = rng.standard_normal((3, r)) @ base
    rows = np.vstack([base, combos, np.zeros((1, nv))])
    order = rng.permutation(rows.shape[0])
    res = constraint_rank(rows[order])
    assert res.rank == r and res.n_redundant == rows.shape[0] - r
    assert np.linalg.matrix_rank(rows[order][list(res.independent)]) == r
    assert sorted(res.independent + res.redundant) == list(range(rows.shape[0]))


def test_constraint_rank_keeps_the_earlier_of_two_equal_rows():
    c_twice = [
        Closure("pivot", "foot", "anchor", ("x", "z")),
        Closure("again", "foot", "anchor", ("z",)),
    ]
    st = ClosureSet(FOUR_BAR, c_twice).evaluate(FOUR_BAR.reference)
    res = constraint_rank(st.jacobian, st.labels)
    assert res.rank == 2 and res.redundant_labels == ("again.z",)


def test_constraint_rank_input_errors():
    with pytest.raises(InputError, match="finite"):
        constraint_rank(np.array([[np.nan, 1.0]]))
    with pytest.raises(InputError, match="labels has 1 names for 2 rows"):
        constraint_rank(np.eye(2), ["a"])
    assert constraint_rank(np.zeros((2, 3))).rank == 0


def test_min_norm_multipliers():
    rng = np.random.default_rng(3)
    c = rng.standard_normal((4, 6))
    lam = rng.standard_normal(4)
    m = min_norm_multipliers(c, c.T @ lam)
    assert np.abs(m.lam - lam).max() < 1e-12 and m.rank == 4
    c_red = np.vstack([c, c[:2].sum(axis=0)])  # one redundant row: a family of solutions
    m = min_norm_multipliers(c_red, c.T @ lam)
    assert np.abs(m.residual).max() < 1e-12 and m.rank == 4
    null = np.linalg.svd(c_red.T)[2][-1]  # the null space of C_redᵀ
    assert abs(m.lam @ null) < 1e-12, "no component along the null space of Cᵀ"
    assert np.linalg.norm(m.lam) < np.linalg.norm(np.concatenate([lam, [0.0]])) + 1e-12
    g_out = rng.standard_normal(6)  # generally not in the range of Cᵀ
    assert np.abs(min_norm_multipliers(c, g_out).residual).max() > 1e-3
    with pytest.raises(InputError):
        min_norm_multipliers(c, np.zeros(5))


# --------------------------------------------------------------------------- portal frame vs closed form
def _portal_loads(H_force, P):
    return [
        Load("top", [H_force, 0.0, 0.0]),
        Load("top_left", [0.0, 0.0, -P]),
        Load("top_right", [0.0, 0.0, -P]),
    ]


def _total(vm, loads, x):
    """Total potential V (J), its gradient and Hessian from the library (springs + DeadLoads)."""
    ls = DeadLoads(vm, loads).evaluate(x)
    kfull = np.zeros((vm.model.nv, vm.model.nv))
    kfull[np.ix_(vm.theta_idx, vm.theta_idx)] = vm.K_theta
    dth = x[vm.theta_idx] - vm.theta0
    v = 0.5 * dth @ vm.K_theta @ dth + ls.potential
    return v, kfull @ (x - vm.reference) - ls.force, kfull - ls.derivative


def test_portal_closed_form_is_consistent_with_itself():
    k, h, P = K, HEIGHT, 0.4 * pf.critical_load(K, HEIGHT)
    for phi in (-0.4, 0.05, 0.3, 0.9):
        fd = (
            pf.potential(phi + 1e-6, k, h, 30.0, P) - pf.potential(phi - 1e-6, k, h, 30.0, P)
        ) / 2e-6
        assert abs(fd - pf.dpotential(phi, k, h, 30.0, P)) < 1e-7
        d = pf.deflection
        fd_k = (pf.force(phi + 1e-6, k, h, P) - pf.force(phi - 1e-6, k, h, P)) / (
            d(phi + 1e-6, h) - d(phi - 1e-6, h)
        )
        assert abs(fd_k / pf.stiffness(phi, k, h, P) - 1) < 1e-8
        fd_dk = (pf.stiffness(phi + 1e-6, k, h, P) - pf.stiffness(phi - 1e-6, k, h, P)) / (
            d(phi + 1e-6, h) - d(phi - 1e-6, h)
        )
        assert abs(fd_dk - pf.stiffness_derivative(phi, k, h, P)) < 1e-6 * max(1.0, abs(fd_dk))
        H_f = pf.force(phi, k, h, P)
        assert abs(pf.dpotential(phi, k, h, H_f, P)) < 1e-12 * k
    assert pf.stiffness(0.0, k, h, pf.critical_load(k, h)) == pytest.approx(0.0, abs=1e-12)
    assert pf.d2potential(0.0, k, h, 0.0, pf.critical_load(k, h)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("vm", [PORTAL, PORTAL6], ids=["closure-3", "closure-6"])
@pytest.mark.parametrize("H_force,P_ratio", [(20.0, 0.0), (60.0, 0.5), (-35.0, 0.9)])
def test_portal_library_pieces_reproduce_the_closed_form(vm, H_force, P_ratio):
    """Along the sway the closures hold exactly, the task deflection is h sin φ, the library's
    total potential is 2kφ² − H h sin φ − 2Ph(1 − cos φ), the closed-form equilibrium is a
    constrained stationary point (∇V = Cᵀλ), and the Hessian of the Lagrangian on the constraint
    null space is V″(φ). Same with the closure in six components (λ = 0 on its redundant rows)."""
    P = P_ratio * pf.critical_load(K, HEIGHT)
    loads = _portal_loads(H_force, P)
    cs = ClosureSet(vm)
    kin = Kinematics(vm.model, vm.frame_id)
    p0, _ = kin.placement(vm.reference)
    v0, _, _ = _total(vm, loads, vm.reference)  # dead-load potentials are absolute (−Σ f·p)
    for phi in (-0.3, 0.2, 0.7):
        x = pf.configuration(vm, phi)
        assert np.abs(cs.evaluate(x).residual).max() < 1e-15
        p, _ = kin.placement(x)
        assert (
            np.abs((p - p0) - [HEIGHT * math.sin(phi), 0, -HEIGHT * (1 - math.cos(phi))]).max()
            < 1e-15
        )
        v, _, _ = _total(vm, loads, x)
        assert v - v0 == pytest.approx(
            pf.potential(phi, K, HEIGHT, H_force, P), rel=1e-13, abs=1e-12
        )

    phi = pf.sway(H_force, K, HEIGHT, P)
    x = pf.configuration(vm, phi)
    _, grad, hess = _total(vm, loads, x)
    st = cs.evaluate(x)
    m = min_norm_multipliers(st.jacobian, grad)
    assert np.abs(m.residual).max() < 1e-10 * np.abs(grad).max(), "∇V = Cᵀλ at the closed-form sway"
    z = pf.sway_direction(vm)
    lag = hess - st.hessian(m.lam)
    assert z @ lag @ z == pytest.approx(
        pf.d2potential(phi, K, HEIGHT, H_force, P), rel=1e-9, abs=1e-9
    )
    if vm is PORTAL6:
        m3 = min_norm_multipliers(ClosureSet(PORTAL).evaluate(x).jacobian, grad)
        rows = [st.labels.index(f"right_foot.{c}") for c in ("x", "z", "ry")]
        assert np.abs(m.lam[rows] - m3.lam).max() < 1e-9 * np.abs(m3.lam).max()
        assert np.abs(np.delete(m.lam, rows)).max() < 1e-12


def test_portal_sway_buckling_load_is_where_the_null_space_hessian_vanishes():
    z = pf.sway_direction(PORTAL)
    pc = pf.critical_load(K, HEIGHT)
    for ratio in (0.5, 1.0, 1.5):
        _, _, hess = _total(PORTAL, _portal_loads(0.0, ratio * pc), PORTAL.reference)
        assert z @ hess @ z == pytest.approx(4 * K * (1 - ratio), abs=1e-9)


# --------------------------------------------------------------------------- four-bar
def test_four_bar_reassembles_like_its_geometry():
    """Turn the crank, re-close the loop with Newton on the passive joints (closure residual and
    Jacobian only); the joint angles are those of the four-bar's circle intersection."""
    vm = FOUR_BAR
    cs = ClosureSet(vm)
    i_crank, free = vm.joint_index("crank"), [vm.joint_index("elbow"), vm.joint_index("knee")]
    for delta in (-0.3, 0.1, 0.25):
        x = vm.reference.copy()
        x[i_crank] -= delta  # crank direction angle + delta
        for _ in range(30):
            st = cs.evaluate(x, hessian=False)
            if np.abs(st.residual).max() < 1e-14:
                break
            x[free] -= np.linalg.solve(st.jacobian[:, free], st.residual)
        p = dict(GEN.FOUR_BAR, crank_angle=GEN.FOUR_BAR["crank_angle"] + delta)
        ab, bc, cd = GEN.four_bar_angles(p)
        assert x[free] == pytest.approx([-(bc - ab), -(cd - bc)], abs=1e-12)


# --------------------------------------------------------------------------- dead loads
def _random_loads(model, rng, n=3, moments=True):
    names = [f.name for f in model.frames if f.name not in ("universe",)]
    loads = []
    for _ in range(n):
        w = rng.standard_normal(6) * 10
        if not moments:
            w[3:] = 0
        loads.append(Load(str(rng.choice(names)), w))
    return loads


@pytest.mark.parametrize("seed", range(5))
def test_dead_loads_force_and_derivative(seed):
    model, _, x, rng = random_loop(seed, planar=bool(seed % 2))
    loads = _random_loads(model, rng)
    dl = DeadLoads(model, loads)
    st = dl.evaluate(x)
    data = model.createData()
    expect = sum(
        pin.computeFrameJacobian(
            model, data, x, model.getFrameId(ld.frame), pin.LOCAL_WORLD_ALIGNED
        ).T
        @ ld.wrench
        for ld in loads
    )
    assert rel(st.force, expect) < 1e-13
    fd = fd_columns(lambda y: dl.evaluate(y, hessian=False).force, x)
    assert rel(st.derivative, fd) < 1e-6, "∂Q/∂x (eq. 16 contraction)"
    assert st.potential is None, "dead moments have no potential"
    asym = np.abs(st.derivative - st.derivative.T).max()
    if seed % 2:  # planar chain: moments about the plane normal are conservative
        assert asym < 1e-12 * np.abs(st.derivative).max()
    else:
        assert asym > 1e-6, "spatial dead moments make ∂Q/∂x non-symmetric (footnote 2)"


@pytest.mark.parametrize("seed", range(3))
def test_dead_forces_have_a_potential(seed):
    model, _, x, rng = random_loop(seed, planar=False)
    dl = DeadLoads(model, _random_loads(model, rng, moments=False), gravity=[0.0, 0.0, -9.81])
    st = dl.evaluate(x)
    assert (
        rel(-fd_columns(lambda y: np.array(dl.evaluate(y, hessian=False).potential), x), st.force)
        < 1e-7
    )
    assert np.abs(st.derivative - st.derivative.T).max() < 1e-10 * np.abs(st.derivative).max()


def test_a_load_at_the_end_frame_is_the_end_wrench_of_eq_16():
    rng = np.random.default_rng(2)
    vm = FOUR_BAR
    x = vm.reference + 0.1 * rng.standard_normal(vm.model.nq)
    w = rng.standard_normal(6)
    ks = Kinematics(vm.model, vm.frame_id).evaluate(x)
    st = DeadLoads(vm, [Load(vm.frame, w)]).evaluate(x)
    assert np.array_equal(st.force, ks.jacobian.T @ w)
    assert rel(st.derivative, ks.psi_hessian(w)) < 1e-15


def _urdf_with_masses(rng, n=4):
    """A chain whose links carry masses, each with a massless child frame ``com_i`` at its
    centre of mass."""
    parts = ['<robot name="masses">', '  <link name="base"/>']
    for i in range(1, n + 1):
        c = rng.uniform(-0.2, 0.4, 3)
        xyz = " ".join(repr(float(v)) for v in c)
        parent = "base" if i == 1 else f"l{i - 1}"
        axis = " ".join(repr(float(v)) for v in rng.standard_normal(3))
        parts += [
            (
                f'  <link name="l{i}"><inertial><origin xyz="{xyz}"/><mass value="{rng.uniform(0.5, 3)!r}"/>'
                '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
            ),
            (
                f'  <joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/>'
                f'<origin xyz="0.3 0.1 0.2" rpy="0.2 -0.1 0.3"/><axis xyz="{axis}"/>'
                '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
            ),
            f'  <link name="com{i}"/>',
            (
                f'  <joint name="com{i}_joint" type="fixed"><parent link="l{i}"/><child link="com{i}"/>'
                f'<origin xyz="{xyz}"/></joint>'
            ),
        ]
    return "\n".join(parts + ["</robot>"])


def test_link_weights_are_forces_at_the_centres_of_mass():
    rng = np.random.default_rng(8)
    model = pin.buildModelFromXML(_urdf_with_masses(rng))
    g = np.array([0.3, -1.0, -9.7])
    x = rng.uniform(-1, 1, model.nq)
    st = DeadLoads(model, gravity=g).evaluate(x)
    masses = {f"com{i}": model.inertias[model.getJointId(f"j{i}")].mass for i in range(1, 5)}
    as_loads = DeadLoads(model, [Load(f, m * g) for f, m in masses.items()]).evaluate(x)
    assert rel(st.force, as_loads.force) < 1e-12
    assert rel(st.derivative, as_loads.derivative) < 1e-12
    assert st.potential == pytest.approx(as_loads.potential, rel=1e-12)

    assert model.gravity.linear @ g != pytest.approx(g @ g), (
        "the caller's model keeps its own gravity"
    )


def test_load_values_and_errors():
    assert np.array_equal(Load("a", [1, 2, 3]).wrench, [1, 2, 3, 0, 0, 0])
    assert np.allclose(Load.weight("tool", 2.0).wrench, [0, 0, -2 * 9.80665, 0, 0, 0])
    with pytest.raises(InputError, match="3 or 6 finite numbers"):
        Load("a", [1, 2])
    with pytest.raises(InputError, match="finite"):
        Load("a", [1, 2, np.inf])
    with pytest.raises(ArgumentError, match="frame name"):
        Load(3, [1, 2, 3])
    with pytest.raises(InputError, match="non-negative"):
        Load.weight("a", -1)
    with pytest.raises(FrameNotFound, match="'ghost'"):
        DeadLoads(PORTAL, [Load("ghost", [1, 0, 0])])
    with pytest.raises(ArgumentError):
        DeadLoads(PORTAL, ["top 1 0 0"])
    with pytest.raises(InputError, match="gravity"):
        DeadLoads(PORTAL, gravity=[0, 0])


def test_parse_load_args():
    loads = parse_load_args(
        [["top", "1", "0", "-2.5"], ["top_left", "0", "0", "-10", "0", "1e-3", "0"]]
    )
    assert [ld.frame for ld in loads] == ["top", "top_left"]
    assert np.array_equal(loads[0].wrench, [1, 0, -2.5, 0, 0, 0])
    assert np.array_equal(loads[1].wrench, [0, 0, -10, 0, 1e-3, 0])
    assert parse_load_args(["top", "1", "2", "3"])[0].frame == "top"
    assert parse_load_args(None) == ()
    for bad, match in [
        ([["top", "1", "2"]], "got 2 numbers"),
        ([["top", "1", "2", "3", "4"]], "got 4 numbers"),
        ([["top", "1", "x", "3"]], "'x' is not a number"),
        ([["top", "1", "nan", "3"]], "not finite"),
    ]:
        with pytest.raises(InputError, match=match) as info:
            parse_load_args(bad)
        assert (
            "\n" not in str(info.value) and "FRAME FX FY FZ" in str(info.value) or "finite" in match
        )


# --------------------------------------------------------------------------- the model layer
def _portal_text(**kw):
    return GEN.portal_frame_urdf(**kw)


def _with_closure(text, attrs: str) -> str:
    """The portal frame with its closure element's attributes replaced by ``attrs``."""
    old = '<vjm:closure name="right_foot" frame_a="foot" frame_b="anchor" components="x z ry" />'
    assert old in text
    return text.replace(old, f"<vjm:closure {attrs} />")


def test_closures_are_read_in_the_order_written():
    vm = load_vjm(
        _with_closure(_portal_text(), 'name="c" frame_a="foot" frame_b="anchor" components="ry x"')
    )
    assert vm.closures == (Closure("c", "foot", "anchor", ("ry", "x")),)
    assert vm.closures[0].indices == (4, 0)
    st = ClosureSet(vm).evaluate(pf.configuration(vm, 0.2))
    assert st.labels == ("c.ry", "c.x")
    default = load_vjm(_with_closure(_portal_text(), 'name="c" frame_a="foot" frame_b="anchor"'))
    assert default.closures[0].components == COMPONENTS
    assert load_vjm(MODELS / "paper-a-s.urdf").closures == ()


@pytest.mark.parametrize(
    "attrs,error,match",
    [
        (
            'name="c" frame_a="ghost" frame_b="anchor"',
            FrameNotFound,
            "'ghost' \\(closure 'c' frame_a\\)",
        ),
        ('name="c" frame_a="foot" frame_b="nowhere"', FrameNotFound, "closure 'c' frame_b"),
        ('name="c" frame_a="foot" frame_b="anchor" components="x q"', ModelError, "component 'q'"),
        ('name="c" frame_a="foot" frame_b="anchor" components="x x"', ModelError, "distinct"),
        ('name="c" frame_a="foot" frame_b="anchor" components=""', ModelError, "non-empty"),
        ('name="c" frame_a="foot" frame_b="foot"', ModelError, "same frame 'foot'"),
        ('frame_a="foot" frame_b="anchor"', ModelError, "without 'name'"),
        ('name="c" frame_b="anchor"', ModelError, "no 'frame_a'"),
        (
            'name="c" frame_a="foot" frame_b="anchor" component="x"',
            UnknownVjmTag,
            "did you mean 'components'",
        ),
    ],
)
def test_bad_closures_are_refused(attrs, error, match):
    with pytest.raises(error, match=match) as info:
        load_vjm(_with_closure(_portal_text(), attrs))
    assert "\n" not in str(info.value)


def test_two_closures_with_one_name_are_refused():
    text = _portal_text().replace(
        "</robot>",
        '<vjm:closure name="right_foot" frame_a="foot" frame_b="anchor" components="x"/></robot>',
    )
    with pytest.raises(ModelError, match="two <vjm:closure> elements named 'right_foot'"):
        load_vjm(text)


def test_a_closure_violated_at_the_reference_is_refused():
    """The anchor 2e-9 m off the foot: refused, naming closure, component and violation; 5e-10
    m is within the assembly tolerance; a violation in a component not held is no violation."""
    good = _portal_text()
    for off, comp in ((2e-9, "x"), (-3e-6, "x")):
        text = good.replace(
            '<origin xyz="1.5 0.0 0.0" rpy="0 0 0" />\n  </joint>\n  <joint name="top_joint"',
            f'<origin xyz="{1.5 + off!r} 0.0 0.0" rpy="0 0 0" />\n  </joint>\n  <joint name="top_joint"',
        )
        assert text != good
        with pytest.raises(ClosureViolated) as info:
            load_vjm(text)
        err = info.value
        assert (err.closure, err.component) == (
            "right_foot",
            comp,
        ) and err.violation == pytest.approx(-off, rel=1e-3)
        assert (
            "closure 'right_foot'" in str(err)
            and f"'{comp}'" in str(err)
            and isinstance(err, ModelError)
        )
    small = good.replace(
        '<origin xyz="1.5 0.0 0.0" rpy="0 0 0" />\n  </joint>\n  <joint name="top_joint"',
        '<origin xyz="1.5000000005 0.0 0.0" rpy="0 0 0" />\n  </joint>\n  <joint name="top_joint"',
    )
    assert load_vjm(small).closures
    lifted = good.replace(
        'name="anchor_joint" type="fixed">\n    <parent link="base" />\n    <child link="anchor" />\n    <origin xyz="1.5 0.0 0.0"',
        'name="anchor_joint" type="fixed">\n    <parent link="base" />\n    <child link="anchor" />\n    <origin xyz="1.5 0.0 0.25"',
    )
    assert lifted != good
    with pytest.raises(ClosureViolated, match="'z' is -0.25 m"):
        load_vjm(lifted)
    assert load_vjm(
        _with_closure(lifted, 'name="c" frame_a="foot" frame_b="anchor" components="x ry"')
    ).closures


def test_closure_objects_validate_themselves():
    assert Closure("c", "a", "b", "x rz").components == ("x", "rz")
    with pytest.raises(ModelError, match="'w'"):
        Closure("c", "a", "b", ("w",))
    with pytest.raises(FrameNotFound, match="'nope'"):
        ClosureSet(PORTAL, [Closure("c", "nope", "anchor", ("x",))])
    with pytest.raises(ArgumentError):
        ClosureSet(PORTAL.model)
    with pytest.raises(InputError, match="3 finite numbers"):
        ClosureSet(PORTAL).evaluate(PORTAL.reference).hessian(np.zeros(2))
    with pytest.raises(InputError, match="without Hessians"):
        ClosureSet(PORTAL).evaluate(PORTAL.reference, hessian=False).hessian(np.ones(3))


# --------------------------------------------------------------------------- bundled models
def test_committed_closed_models_match_the_generator():
    for name, text in GEN.closed_models().items():
        path = MODELS / name
        assert path.is_file(), f"{name} missing: run scripts/make_closed_models.py"
        diffs = urdf_differences(path.read_text(), text)
        assert not diffs, (
            f"{name} differs from the generator: {diffs}; run scripts/make_closed_models.py"
        )


@pytest.mark.parametrize("name", ["portal-frame", "portal-frame-6", "four-bar"])
def test_stock_pinocchio_loads_the_closed_models_as_trees(name):
    model = pin.buildModelFromUrdf(str(MODELS / f"{name}.urdf"))
    vm = load_vjm(MODELS / f"{name}.urdf")
    assert model.nq == vm.model.nq and len(vm.closures) == 1
    cs = ClosureSet(vm)
    st = cs.evaluate(vm.reference)
    expected_dof = {"portal-frame": 1, "portal-frame-6": 1, "four-bar": vm.model.nv - 2}[name]
    assert vm.model.nv - constraint_rank(st.jacobian).rank == expected_dof


def test_portal_generator_parameters_reach_the_file():
    for h, k in itertools.product((0.5, 2.0), (10.0, 300.0)):
        vm = load_vjm(GEN.portal_frame_urdf(height=h, k=k))
        assert np.allclose(np.diag(vm.K_theta), k) and vm.n_theta == 4 and vm.n_q == 0
        p, _ = Kinematics(vm.model, vm.frame_id).placement(vm.reference)
        assert p == pytest.approx([0.75, 0.0, h])


def test_the_tree_solver_refuses_closed_models():
    """The open-chain solver would ignore the closures (a silent wrong stiffness): it refuses
    models with closures by name; every command resolves them and solves them with the
    mechanism solver."""
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver, MechanismSolver

    vm = resolve_model("portal-frame")
    with pytest.raises(ModelError, match="loop closures \\(right_foot\\)"):
        EquilibriumSolver(vm)
    assert MechanismSolver(vm).solve(wrench=[1.0, 0, 0]).converged
    assert resolve_model("paper-a-s").closures == ()


def test_closures_loads_and_end_frame_share_one_frame_pass():
    vm = FOUR_BAR
    cs0 = ClosureSet(vm)
    loads = [Load("coupler_point", [1.0, 0.0, -2.0]), Load("crank_link", [0.0, 0.0, -1.0, 0.0, 0.3, 0.0])]
    ids = [vm.frame_id, *cs0.frame_ids, *(vm.model.getFrameId(ld.frame) for ld in loads)]
    frames = FrameKinematics(vm.model, ids)
    cs, dl = ClosureSet(vm, frames=frames), DeadLoads(vm, loads, frames=frames)
    x = vm.reference + 0.05
    states = frames.evaluate(x)
    assert dl.frames is cs.frames is frames and frames.evaluate(x) is states
    assert np.array_equal(cs.evaluate(x).jacobian, cs0.evaluate(x).jacobian)
    assert np.array_equal(dl.evaluate(x).force, DeadLoads(vm, loads).evaluate(x).force)
    assert np.array_equal(states[vm.frame_id].jacobian, Kinematics(vm.model, vm.frame_id).evaluate(x).jacobian)
    with pytest.raises(ArgumentError, match="does not evaluate every load frame"):
        DeadLoads(vm, [Load("rocker_link", [1, 0, 0])], frames=frames)
    with pytest.raises(ArgumentError, match="frame indices"):
        FrameKinematics(vm.model, [vm.model.nframes])
