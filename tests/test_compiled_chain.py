"""The compiled forward kinematics of a chain of 1-DoF joints (vjm_pin.kinematics.compiled_chain) and
the solver's use of it with the compiled kernel (issue 14).

- the end placement and the ``LOCAL_WORLD_ALIGNED`` frame Jacobian against Pinocchio's at random
  configurations (Model C, Model C subdivided 8 times, ur5 with 6-D link springs, random chains with
  prismatic and unaligned axes, a branched tree whose other branch is off the frame's support path);
- ``log3`` against ``pin.log3`` (random rotations, near the identity, near and at π; near π the
  logarithm is ill-conditioned and the tolerance follows its condition);
- the table refuses models that are not chains of 1-DoF joints (free-flyer, spherical, planar);
- whole solves (Model C through its buckling escape, ur5 with link springs) with the compiled kernel
  and kinematics against the numpy twin (Pinocchio's kinematics) and against the compiled kernel with
  Pinocchio's kinematics; the compiled restoration against the numpy one.

The first test that needs numba compiles the functions (cached on disk next to the modules)."""

import math

import numpy as np
import pinocchio as pin
import pytest

from tests.columns import COMPRESSION, max_deflection
from vjm_pin.kinematics import compiled_chain
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import equilibrium as eqmod
from vjm_pin.solver import kernel
from vjm_pin.solver.equilibrium import EquilibriumSolver

from .chains import random_vjm, ur5_link_springs, warm_sequence

numba = pytest.importorskip("numba")


@pytest.fixture(scope="module")
def fns():
    got = compiled_chain.compiled()
    assert got is not None, "numba is installed: the compiled kinematics must load"
    return got


def _random_placement(rng):
    return pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3) * 0.3)


def _unaligned_tree(seed=0):
    """A tree of every supported joint kind with random placements and unaligned axes: a main
    chain to the frame ``tip`` and a side branch (off the frame's support path)."""
    rng = np.random.default_rng(seed)
    model = pin.Model()
    kinds = [lambda: pin.JointModelRevoluteUnaligned(*(rng.normal(size=3) / np.linalg.norm(rng.normal(size=3)))),
             pin.JointModelRX, pin.JointModelPY, lambda: pin.JointModelPrismaticUnaligned(*rng.normal(size=3)),
             pin.JointModelRZ, pin.JointModelPX, pin.JointModelRY, pin.JointModelPZ]
    parent = 0
    for i, make in enumerate(kinds):
        jm = make()
        if hasattr(jm, "axis") and isinstance(jm, (pin.JointModelRevoluteUnaligned, pin.JointModelPrismaticUnaligned)):
            jm.axis = jm.axis / np.linalg.norm(jm.axis)
        parent = model.addJoint(parent, jm, _random_placement(rng), f"j{i}")
        if i == 2:  # a side branch from the third joint
            model.addJoint(parent, pin.JointModelRY(), _random_placement(rng), "side")
    fid = model.addFrame(pin.Frame("tip", parent, 0, _random_placement(rng), pin.FrameType.OP_FRAME))
    return model, fid


def _of(vm):
    return vm.model, vm.frame_id


MODELS = {
    "model-c": lambda: _of(resolve_model("paper-c-s")),
    "model-c-k8": lambda: _of(load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=8))),
    "ur5-link-springs": lambda: _of(ur5_link_springs()),
    "random-prismatic": lambda: _of(random_vjm(3, n_joints=6, n_passive=1, link_springs=2)),
    "unaligned-tree": _unaligned_tree,
}


@pytest.mark.parametrize("case", list(MODELS))
def test_forward_kinematics_matches_pinocchio(case, fns):
    model, fid = MODELS[case]()
    table = compiled_chain.chain_table(model, fid)
    assert table is not None
    data = model.createData()
    rng = np.random.default_rng(1)
    forward = fns[0]
    j6 = np.full((6, model.nv), np.nan)
    pos, rot = np.empty(3), np.empty((3, 3))
    for amp in (0.0, 0.1, 1.0, 3.0):
        x = pin.neutral(model) + amp * rng.standard_normal(model.nq)
        jac = pin.computeFrameJacobian(model, data, x, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, model.nv)
        mo = data.oMf[fid]
        forward(x, table.geo, table.jinfo, j6, pos, rot)
        scale = max(1.0, np.abs(mo.translation).max())
        # rounding: a few ulps per joint of the product of placements
        tol = 64 * np.finfo(float).eps * model.nv
        assert np.abs(pos - mo.translation).max() <= tol * scale
        assert np.abs(rot - mo.rotation).max() <= tol
        assert np.abs(j6 - jac).max() <= tol * max(scale, np.abs(jac).max())
        off = [c for c in range(model.nv) if not np.any(jac[:, c])]
        assert not np.any(j6[:, off])  # off the support path: exactly zero, as Pinocchio's
    # the Python twin (numba not involved) computes the same numbers as the compiled function
    x = pin.neutral(model) + rng.standard_normal(model.nq)
    j6b, posb, rotb = np.empty((6, model.nv)), np.empty(3), np.empty((3, 3))
    forward(x, table.geo, table.jinfo, j6, pos, rot)
    compiled_chain.forward.py_func(x, table.geo, table.jinfo, j6b, posb, rotb)
    np.testing.assert_allclose(j6b, j6, rtol=0, atol=1e-14)
    np.testing.assert_allclose(posb, pos, rtol=0, atol=1e-14)


def _log3_tolerance(theta):
    """Rounding of ``log3`` at angle ``θ``: a few ε, amplified near π by ``π / (π − θ)²`` (the
    derivative of ``θ/sin θ`` times the rounding of the trace), capped where the singular branch
    takes over (``π − θ`` ≲ 3.5e-3)."""
    d = max(math.pi - theta, 3e-3)
    return 16 * np.finfo(float).eps * (1.0 + math.pi / d**2)


def test_log3_matches_pinocchio(fns):
    log3 = fns[1]
    rng = np.random.default_rng(7)
    out = np.empty(3)
    cases = []
    for _ in range(300):
        cases.append(rng.uniform(0.0, math.pi))  # random
        cases.append(10.0 ** rng.uniform(-16, -4))  # near the identity (the Taylor branch below ~6e-6)
        cases.append(math.pi - 10.0 ** rng.uniform(-12, -1))  # near π (both branches)
    cases += [0.0, math.pi]
    for theta in cases:
        axis = rng.standard_normal(3)
        axis /= np.linalg.norm(axis)
        r = pin.exp3(theta * axis)
        if rng.uniform() < 0.3:  # not exactly orthogonal (both renormalise)
            r = r + 1e-12 * rng.standard_normal((3, 3))
        ref = pin.log3(r)
        log3(r, out)
        assert np.abs(out - ref).max() <= _log3_tolerance(theta), theta
        if theta < math.pi - 1e-2:
            assert np.linalg.norm(out) == pytest.approx(theta, abs=1e-9)
    log3(np.eye(3), out)
    assert not np.any(out)
    # rotation_error = log3(R* Rᵀ)
    r1, r2 = pin.exp3(rng.standard_normal(3)), pin.exp3(rng.standard_normal(3))
    fns[2](r1, r2, out)
    np.testing.assert_allclose(out, pin.log3(r1 @ r2.T), rtol=0, atol=1e-14)


def test_table_refuses_other_joints():
    for jm in (pin.JointModelFreeFlyer(), pin.JointModelSpherical(), pin.JointModelPlanar(),
               pin.JointModelRUBX()):
        model = pin.Model()
        j = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "a")
        j = model.addJoint(j, jm, pin.SE3.Random(), "b")
        j = model.addJoint(j, pin.JointModelRY(), pin.SE3.Random(), "c")
        fid = model.addFrame(pin.Frame("tip", j, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        assert compiled_chain.chain_table(model, fid) is None, jm.shortname()
    # a joint of another kind off the frame's path refuses it too (the solver's screw-form Hessian
    # needs every joint 1-DoF)
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "a")
    model.addJoint(j, pin.JointModelSpherical(), pin.SE3.Random(), "b")
    fid = model.addFrame(pin.Frame("tip", j, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    assert compiled_chain.chain_table(model, fid) is None


SOLVES = {
    # through the buckling of the straight column: the lean path gives way, an escape, restorations
    "model-c": (lambda: resolve_model("paper-c-s"), COMPRESSION, max_deflection(), 30),
    "ur5": (ur5_link_springs, np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0]), 1e-3, 12),
}


def _agree(a, b, tol):
    assert a.converged and b.converged
    assert a.path == b.path and a.stable == b.stable
    scale = max(np.abs(b.x).max(), 1.0)
    assert np.abs(a.x - b.x).max() <= tol * scale
    assert np.abs(a.position - b.position).max() <= tol * scale
    assert np.abs(a.rotation - b.rotation).max() <= tol
    assert np.abs(a.wrench - b.wrench).max() <= tol * max(np.abs(b.wrench).max(), 1.0) * 1e3


@pytest.mark.parametrize("case", list(SOLVES))
def test_solves_with_compiled_kinematics_match(case, fns, monkeypatch):
    """The compiled kernel with its compiled kinematics (one compiled call per local iteration and per
    restoration) against the numpy twin (Pinocchio's kinematics, VJM_PIN_JIT=0) and against the
    compiled kernel with Pinocchio's kinematics: the same equilibria (the convergence test's
    tolerance: 1e-10 relative; the wrench by the solver's statics tolerance), paths and verdicts."""
    make, direction, top, steps = SOLVES[case]
    vm = make()
    assert kernel.looped() is not None and kernel.restore_looped() is not None
    monkeypatch.setenv("VJM_PIN_JIT", "0")
    twin = warm_sequence(vm, direction, top, steps)
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    calls = []
    looped = kernel.looped()

    def counting(*a):
        calls.append(1)
        return looped(*a)

    orig = EquilibriumSolver._compiled_chain

    def spy(self, ctx):
        ck = orig(self, ctx)
        if ck is not None and ck[0] is looped:
            ck = (counting,) + ck[1:]
            ctx[8] = ck
        return ck

    monkeypatch.setattr(EquilibriumSolver, "_compiled_chain", spy)
    fast = warm_sequence(vm, direction, top, steps)
    monkeypatch.undo()
    monkeypatch.setenv("VJM_PIN_JIT", "1")
    monkeypatch.setattr(eqmod, "_compiled_kinematics", False)
    pinned = warm_sequence(vm, direction, top, steps)
    assert len(calls) >= steps - 1  # the warm-started solves ran the compiled loop
    if case == "model-c":
        assert any("escape" in r.path for r in fast)
    for a, b, c in zip(fast, twin, pinned):
        _agree(a, b, 1e-8)
        _agree(a, c, 1e-9)
        assert a.iterations == c.iterations


def test_restoration_with_compiled_kinematics(fns, monkeypatch):
    """``_restore`` in one compiled call (kinematics included) against its numpy loop (Pinocchio's
    kinematics) from configurations pushed off an equilibrium and from a far start: the same
    iterate to rounding and the same verdict; the state returned is the kinematics at that iterate."""
    vm = ur5_link_springs()
    s = EquilibriumSolver(vm)
    d = np.zeros(6)
    d[2] = -1e-4
    r = s.solve(d)
    p_t, r_t = s._target_pose(d * 1.05)
    rng = np.random.default_rng(3)
    for amp in (1e-3, 3e-2, 1.0):
        x0 = r.x.copy()
        x0[s.free] += amp * rng.standard_normal(len(s.free))
        got = {}
        for jit in ("0", "1"):
            monkeypatch.setenv("VJM_PIN_JIT", jit)
            s.kin._last = None
            got[jit] = s._restore(x0.copy(), None, p_t, r_t)
        (xa, _, oka), (xb, stb, okb) = got["0"], got["1"]
        assert oka == okb
        assert np.abs(xb - xa).max() <= (1e-12 if amp < 1.0 else 1e-10) * np.abs(xa).max()
        ref = s.kin.model.createData()
        jac = pin.computeFrameJacobian(s.kin.model, ref, xb, s.kin.frame_id, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(stb.jacobian, jac, rtol=0, atol=1e-13)
        np.testing.assert_allclose(stb.position, ref.oMf[s.kin.frame_id].translation, rtol=0, atol=1e-14)


def test_table_is_kept_while_the_model_is_unchanged():
    """A second solver of the same model gets the same table object; a model edited in place
    (a joint placement, the end frame's placement, a joint replaced) gets a new table, equal to
    one read afresh from the edited model."""
    model, fid = _unaligned_tree()
    first = compiled_chain.chain_table(model, fid)
    assert compiled_chain.chain_table(model, fid) is first
    assert compiled_chain.chain_table(pin.Model(model), fid) is not first  # another object: read

    def fresh():
        return compiled_chain._read_table(model, fid)

    def edits():
        model.jointPlacements[2].translation[1] += 1e-12  # in place, through the reference
        yield "joint placement"
        frame = model.frames[fid]
        pl = frame.placement
        pl.rotation = pl.rotation @ pin.exp3(np.array([0.0, 0.0, 1e-9]))
        frame.placement = pl
        model.frames[fid] = frame
        yield "frame placement"
        model.joints[1] = pin.JointModelRY()
        model.joints[1].setIndexes(1, model.idx_qs[1], model.idx_vs[1])
        yield "joint model"

    prev = first
    for what in edits():
        got = compiled_chain.chain_table(model, fid)
        ref = fresh()
        assert got is not prev, what
        assert np.array_equal(got.geo, ref.geo) and np.array_equal(got.jinfo, ref.jinfo), what
        assert not np.array_equal(got.geo, prev.geo) or not np.array_equal(got.jinfo, prev.jinfo), what
        assert compiled_chain.chain_table(model, fid) is got, what
        prev = got
