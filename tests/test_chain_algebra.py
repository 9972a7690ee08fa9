"""O(n) chain algebra (vjm_pin.solver.chain_algebra) against dense numpy and the dense solver paths."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import chain_algebra as ca
from vjm_pin.solver.blocks import evaluate_blocks
from vjm_pin.solver.stability import check_stability, null_space
from vjm_pin.solver.stiffness import stiffness_eq30

from .chains import random_vjm

BACKENDS = ("numpy", "numba")


@pytest.fixture(autouse=True)
def _numba_allowed(monkeypatch):
    """The suite runs with ``VJM_PIN_JIT=0`` (tests/conftest.py), which switches the compiled
    recursion off at import; these tests choose the backend themselves."""
    monkeypatch.setattr(ca, "_NO_NUMBA", False)


@pytest.fixture(params=BACKENDS)
def backend(request, monkeypatch):
    if request.param == "numba":
        pytest.importorskip("numba")
    monkeypatch.setattr(ca, "BACKEND", request.param)
    monkeypatch.setattr(ca, "_NO_NUMBA", False)
    from vjm_pin.solver import blocks

    # the integration tests exercise the chain path with either recursion
    monkeypatch.setattr(blocks, "CHAIN_MIN_N_NUMPY", blocks.CHAIN_MIN_N)
    return request.param


def rel(a, b):
    return float(np.abs(np.asarray(a) - b).max() / max(np.abs(b).max(), 1e-300))


def random_quasi(rng, sizes, r, s, symmetric, shift=3.0):
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n, b = int(starts[-1]), max(sizes)
    g = 0.7 / np.sqrt(n)  # generators small enough for a well-conditioned (indefinite) matrix
    u, v = g * rng.standard_normal((n, r)), g * rng.standard_normal((n, r))
    p, q = g * rng.standard_normal((n, s)), g * rng.standard_normal((n, s))
    diag = np.zeros((n, b))
    for k in range(len(sizes)):
        a, e = starts[k], starts[k + 1]
        blk = 0.3 * rng.standard_normal((e - a, e - a))
        blk = (blk + blk.T if symmetric else blk) + np.diag(rng.choice([-shift, shift], e - a))
        diag[a:e, : e - a] = blk
    if symmetric:
        p, q = v, u
    return ca.QuasiMatrix(starts, diag, u, v, p, q)


# --------------------------------------------------------------------------- the generic recursion
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("symmetric", [False, True])
def test_factor_matches_dense(seed, symmetric, backend):
    rng = np.random.default_rng(seed)
    sizes = list(rng.integers(1, 7, size=12 + 5 * seed))
    m = random_quasi(rng, sizes, 3 + seed % 4, 3 if symmetric else 2 + seed % 5, symmetric)
    a = m.dense()
    assert np.linalg.cond(a) < 1e4
    x = rng.standard_normal((m.n, 3))
    assert rel(m.matvec(x), a @ x) < 1e-13
    f = ca.factor(m, symmetric)
    assert f.reliable
    assert rel(f.solve(x), np.linalg.solve(a, x)) < 1e-10
    assert rel(f.solve(x[:, 0]), np.linalg.solve(a, x[:, 0])) < 1e-10
    sign, logdet = np.linalg.slogdet(a)
    assert f.sign == sign
    assert abs(f.logabsdet - logdet) < 1e-9 * max(1.0, abs(logdet))
    if symmetric:
        ev = np.linalg.eigvalsh(a)
        assert f.inertia == (int((ev > 0).sum()), int((ev < 0).sum()), 0)
        assert ev.min() < 0 < ev.max()  # an indefinite case, so the count means something
    else:
        assert f.inertia is None


def test_numba_and_numpy_factors_agree(monkeypatch):
    pytest.importorskip("numba")
    rng = np.random.default_rng(7)
    m = random_quasi(rng, list(rng.integers(1, 7, size=40)), 6, 6, True)
    got = {}
    for be in BACKENDS:
        monkeypatch.setattr(ca, "BACKEND", be)
        got[be] = ca.factor(m, True)
    a, b = got["numpy"], got["numba"]
    for name in ("pinv", "x", "y"):
        assert rel(getattr(b, name), getattr(a, name)) < 1e-11
    assert a.inertia == b.inertia and a.sign == b.sign
    assert abs(a.logabsdet - b.logabsdet) < 1e-10 * abs(a.logabsdet)


def test_singular_leading_block_is_reported(backend):
    rng = np.random.default_rng(3)
    m = random_quasi(rng, [2, 3, 1, 4], 3, 3, True)
    diag = m.diag.copy()
    diag[0, :2] = diag[1, :2] = 0.0  # a zero first block: the whole matrix stays regular
    m0 = ca.QuasiMatrix(m.starts, diag, m.u, m.v, m.p, m.q)
    assert abs(np.linalg.det(m0.dense())) > 1e-8
    f = ca.factor(m0, True)
    assert not f.reliable
    assert f.worst == 0 or f.sign == 0
    # nearly singular: a rank-one first block
    diag[0, :2] = diag[1, :2] = 1.0
    diag[1, 1] += 1e-15
    f = ca.factor(ca.QuasiMatrix(m.starts, diag, m.u, m.v, m.p, m.q), True)
    assert not f.reliable and f.rcond < ca.PIVOT_RCOND


# --------------------------------------------------------------------------- VJM chains
def paper(model: str, k: int):
    return load_vjm(paper_model_urdf(model, "s", beam=PAPER_BEAM, subdivide=k) if model != "a" else paper_model_urdf("a", "s"))


def chain_cases():
    cases = [("paper-c", k) for k in (1, 2, 4, 8, 16)] + [("paper-b", 4), ("paper-a", 1)]
    cases += [(f"random-{s}", s) for s in range(8)]
    return cases


def build(case):
    name, k = case
    if name.startswith("paper"):
        return paper(name[-1], k)
    task = ("x", "y", "z", "rx", "ry", "rz") if k % 2 else ("x", "y", "z")
    return random_vjm(
        k, n_joints=5 + k % 4, n_passive=k % 3, task=task, link_springs=2 + k % 2, spring_dofs=None
    )


def configurations(vm, seed, count=3):
    """Random poses near the reference and random wrenches: zero, a force, a force and a moment."""
    rng = np.random.default_rng(seed)
    ksc = float(np.abs(vm.K_theta).max())
    for c in range(count):
        x = vm.reference + rng.uniform(-0.3, 0.3, vm.model.nq)
        w = np.zeros(6)
        if c >= 1:
            w[:3] = rng.standard_normal(3) * 0.05 * ksc
        if c >= 2:
            w[3:] = rng.standard_normal(3) * 0.05 * ksc
        yield x, w


def dense_w(vm, b):
    nt = len(vm.theta_idx)
    h = np.block([[b.H_tt, b.H_tq], [b.H_qt, b.H_qq]])
    k = np.zeros_like(h)
    k[:nt, :nt] = vm.K_theta
    return k - h


@pytest.mark.parametrize("case", chain_cases(), ids=lambda c: f"{c[0]}-{c[1]}")
def test_chain_matrix_is_k_minus_h(case):
    vm = build(case)
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    free = np.concatenate([vm.theta_idx, vm.q_idx])
    assert np.array_equal(free[lay.order], lay.cols) and np.all(np.diff(lay.cols) > 0)
    for x, w in configurations(vm, 11):
        b = evaluate_blocks(vm, kin, x, w)
        ref = dense_w(vm, b)[np.ix_(lay.order, lay.order)]
        assert rel(ca.chain_matrix(lay, b.state.jacobian, w).dense(), ref) < 1e-12
        assert rel(ca.chain_matrix(lay, b.state.jacobian, w, symmetric=True).dense(), 0.5 * (ref + ref.T)) < 1e-12


@pytest.mark.parametrize("case", chain_cases(), ids=lambda c: f"{c[0]}-{c[1]}")
def test_kkt_solve_stiffness_and_counts_match_dense(case, backend):
    vm = build(case)
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    rng = np.random.default_rng(23)
    checked_counts = 0
    for x, w in configurations(vm, 29):
        b = evaluate_blocks(vm, kin, x, w)
        jac = b.state.jacobian
        # eq. (30): K_C and the joint sensitivities
        kkt = ca.ChainKKT(lay, jac, w, vm.task)
        assert kkt.reliable
        kc, dxdt, res = kkt.stiffness()
        ref = stiffness_eq30(b, vm.task)
        assert res < ca.SOLVE_RTOL
        assert rel(kc, ref.task_stiffness) < 1e-9
        t = list(vm.task)
        assert rel(dxdt, np.vstack([ref.dtheta_dt[:, t], ref.dq_dt[:, t]])) < 1e-9
        # a general KKT solve against dense numpy
        n, m = lay.n, len(vm.task)
        wd = dense_w(vm, b)[np.ix_(lay.order, lay.order)]
        jt = jac[np.ix_(t, lay.cols)]
        big = np.block([[wd, jt.T], [jt, np.zeros((m, m))]])
        rhs = rng.standard_normal((n + m, 2))
        xs, lam, res = kkt.solve(rhs[:n], rhs[n:])
        assert rel(np.vstack([xs, lam]), np.linalg.solve(big, rhs)) < 1e-10
        # eq. (23): Sturm counts of the reduced matrix below random shifts
        ev = np.sort(-check_stability(b).eigenvalues)
        zb = null_space(jt[:, :], np.zeros((m, 0)))
        ev2 = np.linalg.eigvalsh(zb.T @ (0.5 * (wd + wd.T)) @ zb)
        assert rel(ev2, ev) < 1e-8
        sym = ca.ChainKKT(lay, jac, w, vm.task, symmetric=True)
        pos, neg, zero = sym.reduced_inertia()
        assert (pos, neg, zero) == (int((ev > 0).sum()), int((ev < 0).sum()), 0)
        span = max(abs(ev).max(), 1.0)
        edges = np.concatenate([[ev[0] - 0.5 * span], ev, [ev[-1] + 0.5 * span]])
        for _ in range(4):
            i = rng.integers(0, len(ev) + 1)  # sigma between eigenvalues i−1 and i: count i
            if edges[i + 1] - edges[i] < 1e-6 * span:
                continue
            sigma = edges[i] + rng.uniform(0.1, 0.9) * (edges[i + 1] - edges[i])
            assert ca.count_below(lay, jac, w, vm.task, sigma) == i
            checked_counts += 1
    assert checked_counts >= 3


@pytest.mark.parametrize("case", [("paper-c", 4), ("random-1", 1), ("random-4", 4)], ids=lambda c: f"{c[0]}-{c[1]}")
def test_smallest_reduced_eigenvalue_matches_dense(case, backend):
    vm = build(case)
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    for x, w in configurations(vm, 5):
        b = evaluate_blocks(vm, kin, x, w)
        ev = np.sort(-check_stability(b).eigenvalues)
        got = ca.smallest_reduced_eigenvalue(lay, b.state.jacobian, w, vm.task, rtol=1e-12)
        assert abs(got - ev[0]) <= 1e-8 * max(abs(ev).max(), 1.0)


def test_rank_deficient_task_is_reported(backend):
    vm = build(("random-3", 3))
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    x, w = next(iter(configurations(vm, 2, 2)))
    b = evaluate_blocks(vm, kin, x, w)
    kkt = ca.ChainKKT(lay, b.state.jacobian, w, (0, 1, 0), symmetric=True)  # a repeated task row
    assert not kkt.reliable or kkt.reduced_inertia() is None
    assert ca.count_below(lay, b.state.jacobian, w, (0, 1, 0), 0.0) is None


def test_layout_blocks_are_the_springs():
    vm = build(("paper-c", 2))
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    st = lay.starts
    blk = lay.block_ids()
    free = np.concatenate([vm.theta_idx, vm.q_idx])
    nt = len(vm.theta_idx)
    kf = np.zeros((len(free),) * 2)
    kf[:nt, :nt] = vm.K_theta
    kc = kf[np.ix_(lay.order, lay.order)]
    # no coupling across blocks, and every block is connected (not splittable further)
    assert not np.any(kc[blk[:, None] != blk[None, :]])
    for k in range(len(st) - 1):
        sub = kc[st[k] : st[k + 1], st[k] : st[k + 1]] != 0
        for c in range(1, st[k + 1] - st[k]):
            assert sub[:c, c:].any(), "a block that K does not couple"
    assert lay.starts is ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx).starts  # kept per model


def test_short_chain_stiffness_does_not_import_numba():
    code = (
        "import sys, numpy as np\n"
        "from vjm_pin.model.paper_models import paper_model_urdf\n"
        "from vjm_pin.model.format import load_vjm\n"
        "from vjm_pin.kinematics.chain import Kinematics\n"
        "from vjm_pin.solver.blocks import evaluate_blocks\n"
        "from vjm_pin.solver.stiffness import stiffness_eq30\n"
        "from vjm_pin.solver.stability import check_stability\n"
        "vm = load_vjm(paper_model_urdf('a', 's'))\n"
        "kin = Kinematics(vm.model, vm.frame_id)\n"
        "b = evaluate_blocks(vm, kin, vm.reference + 0.3, np.array([1.0, 2, 0, 0, 0, 0]))\n"
        "stiffness_eq30(b, vm.task); check_stability(b)\n"
        "import vjm_pin.solver.chain_algebra\n"
        "assert 'numba' not in sys.modules, 'numba imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


# --------------------------------------------------------------------------- integration
def long_chain_points(k=6, seed=3):
    """Model C subdivided k times (nθ + nq ≥ CHAIN_MIN_N) at random poses under end wrenches
    from zero to several times the Euler load: stable and unstable equilibria."""
    from vjm_pin.solver.blocks import CHAIN_MIN_N

    vm = paper("c", k)
    assert len(vm.theta_idx) + len(vm.q_idx) >= CHAIN_MIN_N
    kin = Kinematics(vm.model, vm.frame_id)
    rng = np.random.default_rng(seed)
    pe = 0.11  # ~ the Euler load of the paper column (N), order of magnitude
    for scale in (0.0, 0.05, 0.5, 3.0, 30.0):
        x = vm.reference + rng.uniform(-0.05, 0.05, vm.model.nq)
        w = np.concatenate([[-scale * pe], rng.standard_normal(2) * 0.1 * scale * pe, rng.standard_normal(3) * 0.05 * scale * pe])
        yield vm, kin, x, w


def test_eq30_on_a_long_chain_takes_the_chain_path_and_matches_dense(monkeypatch, backend):
    import dataclasses

    from vjm_pin.solver import stiffness as stf

    taken = []
    real = stf._eq30_chain

    def spy(b):
        r = real(b)
        taken.append(r is not None)
        return r

    monkeypatch.setattr(stf, "_eq30_chain", spy)
    for vm, kin, x, w in long_chain_points():
        b = evaluate_blocks(vm, kin, x, w)
        assert b.chain is not None
        fast = stf.stiffness_eq30(b, vm.task)
        dense = stf.stiffness_eq30(dataclasses.replace(b, chain=None), vm.task)
        assert rel(fast.stiffness, dense.stiffness) < 1e-9
        assert rel(fast.dq_dt, dense.dq_dt) < 1e-9
        assert rel(fast.dtheta_dt, dense.dtheta_dt) < 1e-9
    assert sum(taken) >= 4


def test_eq30_falls_back_to_dense_when_the_chain_is_not_trusted(monkeypatch):
    import dataclasses

    from vjm_pin.solver import stiffness as stf

    monkeypatch.setattr(stf, "CHAIN_TRUST_RCOND", 2.0)  # no pivot is that well conditioned
    vm, kin, x, w = next(iter(long_chain_points()))
    b = evaluate_blocks(vm, kin, x, w)
    assert stf._eq30_chain(b) is None
    got = stf.stiffness_eq30(b, vm.task)
    ref = stf.stiffness_eq30(dataclasses.replace(b, chain=None), vm.task)
    assert rel(got.stiffness, ref.stiffness) < 1e-14


def test_stability_verdict_on_a_long_chain_matches_check_stability(monkeypatch, backend):
    from vjm_pin.solver import stability as stb

    calls = []
    real = ca.chain_stability

    def spy(*a, **kw):
        r = real(*a, **kw)
        calls.append(r)
        return r

    monkeypatch.setattr(ca, "chain_stability", spy)
    verdicts = []
    for vm, kin, x, w in long_chain_points(seed=8):
        b = evaluate_blocks(vm, kin, x, w)
        ref = check_stability(b)
        got = stb.stability_verdict(b)
        assert got == ref.stable
        assert calls[-1] is not None and calls[-1].unstable_count == int((ref.eigenvalues > -ref.tolerance).sum())
        verdicts.append(got)
    assert True in verdicts and False in verdicts


def test_short_chains_keep_the_dense_path():
    vm = paper("c", 2)
    kin = Kinematics(vm.model, vm.frame_id)
    b = evaluate_blocks(vm, kin, vm.reference + 0.01, np.array([-0.05, 0, 0, 0, 0, 0]))
    assert b.chain is None


# --------------------------------------------------------------------------- benchmark smoke
def _bench_module():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "benchmark.py"
    spec = importlib.util.spec_from_file_location("vjm_benchmark_chain", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["vjm_benchmark_chain"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_benchmark_jacobian_without_data_matches_pinocchio():
    bench = _bench_module()
    for seed in range(4):
        vm = random_vjm(seed, n_joints=6)
        kin = Kinematics(vm.model, vm.frame_id)
        x = vm.reference + np.random.default_rng(seed).uniform(-0.5, 0.5, vm.model.nq)
        ref = kin.evaluate(x, hessian=False)
        got = bench.chain_jacobian_without_data(vm.model, vm.frame_id, x)
        np.testing.assert_allclose(got.jacobian, ref.jacobian, atol=1e-13, err_msg="Jacobian (m/rad, m/m)")
        np.testing.assert_allclose(got.position, ref.position, atol=1e-13, err_msg="end position (m)")


def test_benchmark_chain_algebra_smoke():
    bench = _bench_module()
    r = bench.bench_chain_algebra(ks=(1, 6), repeats=1)
    assert [row["n_theta"] for row in r["rows"]] == [18, 108]
    for row in r["rows"]:
        assert row["kc_rel_diff"] < 1e-9 and row["same_verdict"] and row["eigmin_rel_diff"] < 1e-8
    assert r["rows"][0]["jacobian_check"] < 1e-13
    assert "nθ" in bench.format_chain_algebra(r)


def test_solve_free_is_the_newton_system_in_solver_order(backend):
    vm = build(("random-5", 5))
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    rng = np.random.default_rng(4)
    for x, w in configurations(vm, 31):
        b = evaluate_blocks(vm, kin, x, w)
        jt = np.hstack([b.J_theta, b.J_q])  # (θ, q) order
        n, m = jt.shape[1], jt.shape[0]
        big = np.block([[dense_w(vm, b), jt.T], [jt, np.zeros((m, m))]])
        r, e = rng.standard_normal(n), rng.standard_normal(m)
        dx, lam, res = ca.ChainKKT(lay, b.state.jacobian, w, vm.task).solve_free(r, e)
        assert dx.shape == (n,) and lam.shape == (m,) and res < ca.SOLVE_RTOL
        assert rel(np.concatenate([dx, lam]), np.linalg.solve(big, np.concatenate([r, e]))) < 1e-10


@pytest.mark.parametrize("case", [("paper-c", 2), ("random-2", 2), ("random-7", 7)], ids=lambda c: f"{c[0]}-{c[1]}")
def test_smallest_reduced_eigenpair_is_an_eigenpair(case, backend):
    vm = build(case)
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    for x, w in configurations(vm, 17):
        b = evaluate_blocks(vm, kin, x, w)
        ev = np.sort(-check_stability(b).eigenvalues)
        lam, vec = ca.smallest_reduced_eigenpair(lay, b.state.jacobian, w, vm.task)
        span = max(abs(ev).max(), 1.0)
        assert abs(lam - ev[0]) <= 1e-9 * span
        for guess in (ev[0] * 1.3 + 0.1, ev[0] * 0.7 - 0.1, ev[-1] * 10.0, -ev[-1] * 10.0):  # warm starts
            assert abs(ca.smallest_reduced_eigenvalue(lay, b.state.jacobian, w, vm.task, guess=guess) - ev[0]) <= 1e-9 * span
        jt = np.hstack([b.J_theta, b.J_q])
        wd = dense_w(vm, b)
        ws = 0.5 * (wd + wd.T)
        assert abs(np.linalg.norm(vec) - 1) < 1e-12
        assert np.abs(jt @ vec).max() < 1e-9 * np.abs(jt).max()  # keeps the end fixed
        # (Zᵀ W_s Z − λ) y = 0  ⇔  W_s x − λ x ∈ range(Jᵀ)
        zb = null_space(jt, np.zeros((jt.shape[0], 0)))
        resid = zb.T @ (ws @ vec - lam * vec)
        if len(ev) > 1 and ev[1] - ev[0] > 1e-6 * span:  # a simple eigenvalue: the vector is determined
            assert np.abs(resid).max() < 1e-6 * span


@pytest.mark.parametrize("case", [("paper-c", 2), ("random-3", 3), ("random-6", 6)], ids=lambda c: f"{c[0]}-{c[1]}")
def test_held_combinations_match_check_stability_held(case, backend):
    """Mixed control (the curve tracer's margin μ): the end held only in some combinations of
    the task rows, including none (pure force control: W itself)."""
    from vjm_pin.solver.stability import check_stability_held

    vm = build(case)
    kin = Kinematics(vm.model, vm.frame_id)
    lay = ca.chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    rng = np.random.default_rng(41)
    m = len(vm.task)
    eye_task = np.eye(6)[list(vm.task)]
    for x, w in configurations(vm, 13):
        b = evaluate_blocks(vm, kin, x, w)
        for k in (0, 1, m - 1):
            held = rng.standard_normal((k, m))
            ref = check_stability_held(b, held)
            ev = np.sort(-ref.eigenvalues)
            rows6 = held @ eye_task
            kkt = ca.ChainKKT(lay, b.state.jacobian, w, rows6, symmetric=True)
            span = max(abs(ev).max(), 1.0)
            if np.abs(ev).min() < 1e-9 * span:  # a singular reduced matrix (an unloaded mechanism)
                assert kkt.reduced_inertia() is None
                continue
            assert kkt.reduced_inertia() == (int((ev > 0).sum()), int((ev < 0).sum()), 0)
            lam, vec = ca.smallest_reduced_eigenpair(lay, b.state.jacobian, w, rows6)
            assert abs(lam - ev[0]) <= 1e-9 * span
            jt = np.hstack([b.J_theta, b.J_q])
            assert k == 0 or np.abs(held @ jt @ vec).max() < 1e-9 * np.abs(jt).max()


def test_without_numba_only_very_long_chains_take_the_chain_path(monkeypatch):
    monkeypatch.setattr(ca, "BACKEND", "numpy")
    assert not ca.compiled_available()
    vm = paper("c", 6)  # 110 free coordinates: dense is faster than the numpy recursion
    kin = Kinematics(vm.model, vm.frame_id)
    assert evaluate_blocks(vm, kin, vm.reference + 0.01, np.array([-0.05, 0, 0, 0, 0, 0])).chain is None


def test_layout_pseudo_inverse_is_the_blocks_pseudo_inverse():
    """``K_θ``'s block pseudo-inverses (one stacked ``pinv`` per block size) against block-by-block
    ``np.linalg.pinv`` and the Moore–Penrose conditions, with zero, singular and mixed-size blocks."""
    rng = np.random.default_rng(3)
    sizes = [1, 3, 6, 1, 5, 3, 3, 6, 2, 1]
    starts = np.concatenate([[0], np.cumsum(sizes)])
    n = int(starts[-1])
    kd = np.zeros((n, 6))
    for i, sz in enumerate(sizes):
        g = rng.standard_normal((sz, sz)) * 10.0 ** rng.uniform(-2, 6)
        blk = g @ g.T
        if i in (3, 8):
            blk[:] = 0.0  # a passive joint, a decoupled pair with no springs
        if i == 5:
            blk[0, :] = blk[:, 0] = 0.0  # singular
        kd[starts[i]:starts[i + 1], :sz] = blk
    lay = ca.ChainLayout(np.arange(n), np.arange(n), starts, kd)
    kp = lay._k_pinv
    for i, sz in enumerate(sizes):
        blk = kd[starts[i]:starts[i + 1], :sz]
        got = kp[starts[i]:starts[i + 1], :sz]
        assert not kp[starts[i]:starts[i + 1], sz:].any()
        if not blk.any():
            assert not got.any()
            continue
        ref = np.linalg.pinv(blk)
        assert np.abs(got - ref).max() <= 1e-15 * np.abs(ref).max()
        scale = np.abs(blk).max() * np.abs(got).max()
        assert np.abs(blk @ got @ blk - blk).max() <= 1e-9 * np.abs(blk).max() * scale
        assert np.abs(got @ blk @ got - got).max() <= 1e-9 * np.abs(got).max() * scale
