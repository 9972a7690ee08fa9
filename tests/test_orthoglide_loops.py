"""The Orthoglide with its parallelograms as true loops (``orthoglide-loop-qK``, issue 13;
``scripts/make_orthoglide.py`` variant ``loop``, ``docs/orthoglide.md`` "Loop variant")."""

from __future__ import annotations

import importlib.util
import math
import re
from pathlib import Path

import numpy as np
import pytest

from vjm_pin.exceptions import ClosureViolated
from vjm_pin.kinematics.closures import ClosureSet, constraint_rank
from vjm_pin.model.format import ASSEMBLY_TOLERANCE, load_vjm
from vjm_pin.model.registry import bundled_models
from vjm_pin.solver.mechanism import MechanismSolver

from .urdf_compare import urdf_differences

ROOT = Path(__file__).resolve().parent.parent
U3 = np.ones(3) / math.sqrt(3)
POINTS = ("q0", "q1", "q2", "q3", "q4")
#: Largest relative difference (max entry / max entry) allowed between the translational
#: compliance blocks C_tt of the loop and the folded model. Both models have the same
#: translational springs (actuator, foot, the bars' axial 2EA/L and common bending); they differ
#: in the rotation of the parallelogram coupler (in-plane φz: dropped by the folded model,
#: differential stretching of the bars in the loop) and in how the two bars are tied (at every
#: segment node in the folded spring, at the axles only in the loop). Those enter C_tt only
#: through the translation–rotation coupling of the platform, which is second order with the
#: R2 joints at the platform point (r = 0: the leg forces pass through P). Measured ≤ 3e-5
#: (docs/orthoglide.md); 1e-3 leaves room for round-off and still fails at a real change (at Q0
#: C_tt is the diagonal of the three legs' axial compliances: 1 % on one leg moves it by 1e-2).
CTT_RTOL = 1e-3


def _load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


MO = _load(ROOT / "scripts" / "make_orthoglide.py")
_CACHE: dict = {}


def _vm(point: str, variant: str = "loop"):
    key = (point, variant)
    if key not in _CACHE:
        if variant == "loop":
            _CACHE[key] = load_vjm(ROOT / "models" / "urdf" / f"orthoglide-loop-{point}.urdf")
        else:
            _CACHE[key] = load_vjm(MO.orthoglide_urdf(point, variant, platform="closures"))
    return _CACHE[key]


def _solver(point: str, variant: str = "loop") -> MechanismSolver:
    # not cached: a pinocchio Data of the 231-coordinate loop model takes ~260 MB (its
    # second-order derivative buffers grow as nv³), and each solver holds one
    return MechanismSolver(_vm(point, variant))


def _kc(point: str, variant: str = "loop") -> np.ndarray:
    s = _solver(point, variant)
    return s.stiffness(s.solve(wrench=np.zeros(6))).stiffness


def test_committed_loop_models_match_the_generator():
    generated = MO.orthoglide_loop_models()
    assert sorted(generated) == [f"orthoglide-loop-{p}.urdf" for p in POINTS]
    bundled = bundled_models()
    for name, text in generated.items():
        path = ROOT / "models" / "urdf" / name
        assert path.is_file(), f"{name} missing: run scripts/make_orthoglide.py"
        diff = urdf_differences(path.read_text(), text)
        assert not diff, (
            f"{name} differs from the generator (rtol 1e-12): {diff}; run scripts/make_orthoglide.py"
        )
        assert name[:-5] in bundled  # the registry (vjm-pin models) finds it
        # explicit closures only: no <vjm:leg> shorthand, no <vjm:platform>
        assert "<vjm:leg " not in text and "<vjm:platform " not in text
        assert text.count("<vjm:closure ") == 5


@pytest.mark.parametrize("point", POINTS)
def test_loop_model_is_assembled(point):
    vm = _vm(point)
    names = [c.name for c in vm.closures]
    assert sorted(names) == sorted(
        [
            "leg1_parallelogram",
            "leg2_parallelogram",
            "leg3_parallelogram",
            "leg2_platform",
            "leg3_platform",
        ]
    )
    assert all(c.components == ("x", "y", "z", "rx", "ry", "rz") for c in vm.closures)
    res = ClosureSet(vm).evaluate(vm.reference, hessian=False).residual
    assert res.shape == (30,)
    assert np.abs(res).max() <= ASSEMBLY_TOLERANCE
    # both bars of every parallelogram are there, each with its own segment springs and Pa joints
    for leg in ("leg1", "leg2", "leg3"):
        for bar in "ab":
            assert vm.roles[f"{leg}{bar}_Pa1"] == vm.roles[f"{leg}{bar}_Pa2"] == "passive"
            assert sum(g.name.startswith(f"{leg}{bar}_bar") for g in vm.springs) == MO.BAR_SEGMENTS


def test_a_disassembled_loop_file_is_refused():
    """The assembly check can fail: bar b's first joint turned by 1e-6 rad opens the loop."""
    text = (ROOT / "models" / "urdf" / "orthoglide-loop-q3.urdf").read_text()
    m = re.search(r'<vjm:joint name="leg2b_Pa1" role="passive" position="([^"]+)"', text)
    bad = text.replace(m.group(0), m.group(0).replace(m.group(1), repr(float(m.group(1)) + 1e-6)))
    with pytest.raises(ClosureViolated, match="leg2_parallelogram"):
        load_vjm(bad)


@pytest.mark.parametrize("point", ("q0", "q3"))
def test_closure_rank_as_designed(point):
    """Elastic mechanism well posed: the 30 closure rows are independent on the free
    coordinates (θ, q). The rigid linkage (springs frozen, actuators locked) is the classical
    over-constrained Orthoglide: on the 18 passive joints the rows have rank 18 (no rigid
    mobility), so 12 of the 30 rows are redundant for it — the redundancy the springs absorb."""
    vm = _vm(point)
    cs = ClosureSet(vm)
    jac = cs.evaluate(vm.reference, hessian=False).jacobian
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    info = constraint_rank(jac[:, free], cs.labels)
    assert (info.rank, info.n_redundant) == (30, 0)
    assert vm.n_q == 18
    rigid = constraint_rank(jac[:, vm.q_idx], cs.labels)
    assert (rigid.rank, rigid.n_redundant) == (18, 12)
    # per leg, the parallelogram loop alone is planar for the passive joints: rank 3 of 6
    for leg in ("leg1", "leg2", "leg3"):
        rows = [i for i, lab in enumerate(cs.labels) if lab.startswith(f"{leg}_parallelogram.")]
        assert constraint_rank(jac[np.ix_(rows, vm.q_idx)]).rank == 3


# Q0 symmetric, Q1 the symmetric corner with the largest difference, Q3 an asymmetric corner
@pytest.mark.parametrize("point", ("q0", "q1", "q3"))
def test_unloaded_stiffness_agrees_with_the_folded_model(point):
    """Translational compliance (platform free to rotate) within :data:`CTT_RTOL` of the folded
    model; the platform rotation is much stiffer in the loop (the parallelogram holds the
    coupler), and softer than in the coupled model, whose folded spring ties the two bars at
    every segment node (a constrained loop: K_coupled − K_loop positive semi-definite)."""
    kl, kf, kc = _kc(point), _kc(point, "folded"), _kc(point, "coupled")
    cl, cf = np.linalg.inv(kl), np.linalg.inv(kf)
    assert np.abs(cl[:3, :3] - cf[:3, :3]).max() <= CTT_RTOL * np.abs(cf[:3, :3]).max()
    ku_l, ku_f = 1 / (U3 @ cl[:3, :3] @ U3), 1 / (U3 @ cf[:3, :3] @ U3)
    assert ku_l == pytest.approx(ku_f, rel=CTT_RTOL)
    # rotation: the folded platform is softer in every direction (C_rr,folded − C_rr,loop > 0)
    assert np.linalg.eigvalsh(cf[3:, 3:] - cl[3:, 3:]).min() > 0
    ev = np.linalg.eigvalsh(kc - kl)
    assert ev.min() >= -1e-9 * np.abs(kl).max()


def _free_gradient(vm, x, wrench):
    """Gradient of the total potential Π = ½(θ−θ₀)ᵀK_θ(θ−θ₀) − wᵀ·(platform displacement) over
    the free coordinates (θ, q) and the closure Jacobian there, straight from Pinocchio
    (independent of the solver's Newton)."""
    import pinocchio as pin

    model, data = vm.model, vm.model.createData()
    fid = vm.frame_id
    pin.computeJointJacobians(model, data, x)
    pin.updateFramePlacements(model, data)
    jp = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    g = -(jp.T @ wrench)
    g[vm.theta_idx] += vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    c = ClosureSet(vm).evaluate(x, hessian=False)
    return g[free], c.jacobian[:, free], c.residual


def test_loaded_equilibrium_is_re_found_from_a_perturbed_start():
    """Q3 (asymmetric), half the statics estimate of the critical force along −u: the
    equilibrium is stable, the closures hold, the total potential is stationary on the closure
    manifold (projected gradient from Pinocchio, not from the solver), and a solve from a
    perturbed start returns the same configuration. The platform translation agrees with the
    folded model's (same translational springs)."""
    point = "q3"
    f = (
        0.5
        * MO.F_CR_TABLE2_Q0
        / math.sqrt(3)
        / np.abs(MO.leg_coefficients(point, (-1, -1, -1))).max()
    )
    wrench = np.concatenate([-f * U3, np.zeros(3)])
    solver = _solver(point)
    vm = solver.vm
    res = solver.solve(wrench=wrench)
    assert res.converged and res.stable
    assert res.redundant == ()
    g, cj, cres = _free_gradient(vm, res.x, wrench)
    assert np.abs(cres).max() <= 1e-9
    _, s, vt = np.linalg.svd(cj)
    z = vt[np.sum(s > 1e-10 * s[0]) :].T  # null space of the closure Jacobian
    scale = np.abs(vm.K_theta @ (res.x[vm.theta_idx] - vm.theta0)).max()
    assert np.abs(z.T @ g).max() <= 1e-7 * scale
    # the multipliers balance the gradient: g = Cᵀμ (solver's closure reactions)
    assert np.allclose(g, cj.T @ res.closure_multipliers, atol=1e-7 * scale)
    rng = np.random.default_rng(13)
    x0 = res.x.copy()
    pert = rng.standard_normal(vm.model.nq) * 2e-3
    prism = np.array([j.shortname().startswith("JointModelP") for j in vm.model.joints[1:]])
    pert[prism] *= 1e-3
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    x0[free] += pert[free]
    assert (
        np.abs(solver.closures.evaluate(x0, hessian=False).residual).max() > 1e-3
    )  # really off the manifold
    again = solver.solve(wrench=wrench, x0=x0)
    assert again.converged and again.stable
    assert np.abs(again.x - res.x).max() <= 1e-7
    assert np.allclose(again.deflection, res.deflection, rtol=0, atol=1e-10)
    folded = _solver(point, "folded").solve(wrench=wrench)
    assert (
        np.abs(res.deflection[:3] - folded.deflection[:3]).max()
        <= CTT_RTOL * np.abs(folded.deflection[:3]).max()
    )
