"""The compiled paths of the batched lockstep maps (vjm_pin.analysis.batched) against their plain
references: the same numbers, bit for bit, where they are built to take the same operations in the
same order (the blocked Cholesky factorisation and triangular solves, the compiled joint origins,
the kernel's in-place outputs whatever the block), and the same verdicts as the numpy twin."""

import glob
import math
from pathlib import Path

import numpy as np
import pytest

from vjm_pin.analysis import batched
from vjm_pin.analysis.batched import BatchedChain
from vjm_pin.analysis.maps import sample_poses
from vjm_pin.model.robots import build_robot

pytest.importorskip("numba")

LINK = {
    "links": {
        "upper_arm_link": {"beam": {"section": "tube", "outer_diameter": 0.09, "wall": 0.004, "E": 7e10, "nu": 0.33}},
        "forearm_link": {"beam": {"section": "tube", "outer_diameter": 0.07, "wall": 0.0035, "E": 7e10, "nu": 0.33}},
    }
}
MODELS = Path(__file__).resolve().parents[1] / "models" / "urdf"


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module", params=["actuators", "links"])
def ur5(request):
    return build_robot("ur5", springs=LINK if request.param == "links" else None).vm


@pytest.fixture(scope="module")
def compiled():
    assert batched.kernel() is not None
    return batched


def _cholesky_reference(a, shift):
    """The unblocked dot-product Cholesky, one entry at a time, in Python floats."""
    n = len(a)
    a = np.asarray(a, float).tolist()
    lo = [[0.0] * n for _ in range(n)]
    for j in range(n):
        s = a[j][j] - shift
        for k in range(j):
            s -= lo[j][k] * lo[j][k]
        if not s > 0.0:
            return False, None
        dj = math.sqrt(s)
        lo[j][j] = dj
        for i in range(j + 1, n):
            t = a[i][j]
            for k in range(j):
                t -= lo[i][k] * lo[j][k]
            lo[i][j] = t / dj
    return True, np.array(lo)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7, 8, 13, 36])
def test_blocked_cholesky_and_forward_solves_are_the_plain_loops(compiled, n):
    rng = np.random.default_rng(n)
    x = rng.normal(size=(n, n))
    a = x @ x.T + 0.1 * np.eye(n)
    for shift in (0.0, 1e-3):
        ok, ref = _cholesky_reference(a, shift)
        lo = np.zeros((n, n))
        assert compiled._cholesky_loops(a, shift, lo) == ok
        if ok:
            assert _same_bits(np.tril(lo), ref)
    # not positive definite: the same verdict
    big = np.linalg.eigvalsh(a)[-1]
    assert compiled._cholesky_loops(a, big + 1.0, np.zeros((n, n))) is False
    assert _cholesky_reference(a, big + 1.0)[0] is False
    # L y = b for 1..4 right-hand sides at once, each the plain forward substitution
    lo = np.zeros((n, n))
    assert compiled._cholesky_loops(a, 0.0, lo)
    rhs = rng.normal(size=(5, n))
    ref = np.empty_like(rhs)
    ll = lo.tolist()
    for c in range(5):
        y = []
        for i in range(n):
            t = float(rhs[c, i])
            for k in range(i):
                t -= ll[i][k] * y[k]
            y.append(t / ll[i][i])
        ref[c] = y
    for nc in (1, 2, 3, 4):
        y = rhs.copy()
        compiled._forward_loops(lo, y, 1, nc)
        assert _same_bits(y[1 : 1 + nc], ref[1 : 1 + nc])
        assert _same_bits(y[[0, *range(1 + nc, 5)]], rhs[[0, *range(1 + nc, 5)]])  # others untouched


def _prismatic_chains():
    """Models of the repository whose set joints include prismatic ones (their closures do not
    matter to the joint origins), as (vm, names, poses)."""
    from vjm_pin.model.format import load_vjm

    out = []
    for path in sorted(glob.glob(str(MODELS / "orthoglide-q*.urdf")))[:2]:
        vm = load_vjm(path)
        names, poses = sample_poses(vm, 40, seed=2)
        out.append((vm, names, poses))
    return out


def test_compiled_joint_origins_are_the_stacked_ones(ur5, compiled):
    chain = BatchedChain(ur5, jit=True)
    names, poses = sample_poses(ur5, 64, seed=9)
    poses = poses.copy()
    poses[:3] = 0.0
    poses[3:6] *= 40.0  # angles far beyond ±π
    for sub in (slice(None), slice(1, 3), slice(0, 1), slice(2, 6)):
        nm, ps = names[sub], np.ascontiguousarray(poses[:, sub])
        assert _same_bits(chain._joint_origins_jit(nm, ps), chain.joint_origins(nm, ps))


def test_compiled_joint_origins_with_prismatic_set_joints(compiled):
    chains = _prismatic_chains()
    if not chains:
        pytest.skip("no orthoglide model in models/urdf")
    for vm, names, poses in chains:
        chain = BatchedChain(vm, jit=True)
        steps, _ = chain._origin_plan(names)
        assert any(st[5] for st in steps)  # really a prismatic step
        assert _same_bits(chain._joint_origins_jit(names, poses), chain.joint_origins(names, poses))


@pytest.mark.parametrize("wrench", [[0, 0, -100, 0, 0, 0], [30, -20, -150, 4, -3, 2]])
def test_compiled_solves_do_not_depend_on_the_block(ur5, wrench, compiled, monkeypatch):
    """The kernel writes each pose's K − H, C and verdict into its own row of the block: blocks of
    any size (and a pose alone) give the same bits."""
    names, poses = sample_poses(ur5, 45, seed=13)
    w = np.array(wrench, float)
    chain = BatchedChain(ur5, jit=True)
    whole = chain.solve_arrays(names, poses, w)
    assert whole[0].sum() >= 40
    monkeypatch.setattr(batched, "BLOCK_JIT", 7)
    small = chain.solve_arrays(names, poses, w)
    for a, b in zip(whole, small):
        assert _same_bits(a, b)
    for i in (0, 22, 44):
        alone = chain.solve_arrays(names, poses[i : i + 1], w)
        for a, b in zip(whole, alone):
            assert _same_bits(a[i : i + 1], b)


@pytest.mark.parametrize("load", [-3e4, -3e6])
def test_compiled_verdicts_are_the_numpy_twins_under_heavy_loads(compiled, load):
    """Loads near and beyond what the chain carries: the kernel's stability verdicts (taken at
    the finishing iteration) and hand-backs are the numpy twin's, and the kept poses agree to
    rounding."""
    vm = build_robot("ur5", springs=LINK).vm
    names, poses = sample_poses(vm, 120, seed=5)
    w = np.array([0.0, 0.0, load, 0.0, 0.0, 0.0])
    twin = BatchedChain(vm).solve_arrays(names, poses, w)
    fast = BatchedChain(vm, jit=True).solve_arrays(names, poses, w)
    assert np.array_equal(twin[0], fast[0])
    keep = twin[0]
    if keep.any():
        np.testing.assert_array_equal(twin[1], fast[1])
        scale = np.abs(twin[2][keep]).max()
        np.testing.assert_allclose(fast[2][keep], twin[2][keep], rtol=0, atol=1e-10 * scale)
        for a, b in zip(fast[3:], twin[3:]):
            np.testing.assert_allclose(a[keep], b[keep], rtol=1e-8)
