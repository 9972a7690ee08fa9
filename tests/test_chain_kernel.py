"""The compiled O(n) chain kernels (vjm_pin.solver.chain_kernel) against the dense compiled kernels
they replace for long chains: the fused Newton iteration (statuses, steps, multipliers, the
factorisation handed back, eq. (23)'s largest eigenvalue and verdict) and the curve's point
kernel (tangent stiffness, tangent, μ, dμ/ds) on Model C with k = 2, 4, 8 sub-links, at
equilibria of the compression curve before, next to and after buckling, perturbed (not
converged) and under extra lateral forces and moments; the interpreted twin of the loops on a
short chain; the dense fallback; the symmetric inertia of the pivot blocks; whole k = 8 curves
with and without the chain kernels.

The first test compiles the kernels (numba, cached on disk next to the module)."""

import importlib.util

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.analysis import point_kernel as pkmod
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import blocks_at, chain_kernel, kernel
from vjm_pin.solver.equilibrium import _KERNEL_DUMMY, EquilibriumSolver
from vjm_pin.solver.stiffness import _ruiz, eq28_matrix

numba = pytest.importorskip("numba")

DIRECTION = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
MAX_DEFLECTION = 6e-4  # m: ~5.5 × the shortening at the Euler load (buckling, then post-buckling)


@pytest.fixture(autouse=True)
def _jit_on(monkeypatch):
    monkeypatch.setenv("VJM_PIN_JIT", "1")


@pytest.fixture(scope="module")
def dense():
    fn = kernel._load_compiled()
    assert fn, "numba is installed: the compiled kernel must load"
    assert chain_kernel._load() is not None
    return fn


_MODELS: dict = {}


def model(k):
    """Model C (S posture), links subdivided k times, its solver and its compression curve
    (traced with the dense kernels: the reference states)."""
    if k not in _MODELS:
        vm = load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=k))
        s = EquilibriumSolver(vm)
        old = chain_kernel.ITERATE_MIN_N, chain_kernel.POINT_MIN_N
        chain_kernel.ITERATE_MIN_N = chain_kernel.POINT_MIN_N = 10**9
        try:
            c = trace_curve(vm, DIRECTION, MAX_DEFLECTION, steps=16, solver=EquilibriumSolver(vm))
        finally:
            chain_kernel.ITERATE_MIN_N, chain_kernel.POINT_MIN_N = old
        _MODELS[k] = (vm, s, c)
    return _MODELS[k]


def states(k):
    """Equilibria of the curve: the first points, the last before and the first after the
    critical point (next to buckling), the post-buckling end, and the critical point itself."""
    vm, s, c = model(k)
    assert c.critical, "the column buckles within the traced range"
    i = c.critical[0].index
    picks = sorted({1, 3, i - 1, i, min(i + 1, len(c.points) - 1), len(c.points) - 1})
    eqs = [c.points[j].equilibrium for j in picks]
    crit = s.solve(c.critical[0].deflection * DIRECTION)
    return vm, s, eqs + [crit]


def kernel_args(s, x, p_t, follow=True):
    solver = s if follow else s._sibling(follow_stable=False)
    consts, thr = solver._kernel_consts()
    kin = s.kin
    j6 = np.ascontiguousarray(pin.computeFrameJacobian(kin.model, kin.data, x, kin.frame_id, pin.LOCAL_WORLD_ALIGNED))
    pos = kin.data.oMf[kin.frame_id].translation.copy()
    return (j6, pos, np.zeros(3), x), kernel.with_target(consts, p_t), thr


def reduced_cond(s, fact):
    """Condition number of ``ZᵀWZ`` (the matrix the Newton step is solved with)."""
    jac, hz = fact[0], fact[6]
    q, _ = np.linalg.qr(jac.T, mode="complete")
    z = q[:, jac.shape[0]:]
    return np.linalg.cond(z.T @ (s._kz - hz) @ z)


def rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(b).max(), 1e-300)


# --------------------------------------------------------------------------- the iteration
@pytest.mark.parametrize("k", [2, 4, 8])
def test_iteration_matches_the_dense_kernel(k, dense):
    vm, s, eqs = states(k)
    rng = np.random.default_rng(k)
    kscale = np.abs(vm.K_theta).max()
    seen = set()
    for ie, eq in enumerate(eqs):
        # the last state is the critical point itself, where ZᵀWZ is singular to rounding: the chain
        # kernel may hand it to the dense one there (whose numbers are then compared as well)
        at_critical = ie == len(eqs) - 1
        p_eq = s.kin.evaluate(eq.x, hessian=False).position
        for amp in (0.0, 1e-5, 1e-3):
            x = eq.x.copy()
            x[s.free] += amp * rng.standard_normal(len(s.free))
            p_t = p_eq + (amp * 1e-2 * rng.standard_normal(3) if amp else 0.0)
            for follow in (True, False):
                for polish in (True, False):
                    head, consts, thr = kernel_args(s, x, p_t, follow)
                    a = head + (True, polish, True, True, _KERNEL_DUMMY[:8], consts)
                    d = dense(*a)
                    c = chain_kernel.iterate(
                        *a, dense=dense if at_critical else lambda *z: pytest.fail("dense fallback at a regular point"))
                    assert c[0] == d[0], (amp, follow, polish)
                    seen.add(d[0])
                    assert c[1:5] == pytest.approx(d[1:5], rel=1e-13, abs=0)  # kkt, ep, er, rs
                    # the factorisation: the same arithmetic (jac, R, F, r, ∇E, H, F6)
                    for i in (0, 2, 3, 4, 5, 6, 7):
                        assert rel(c[5][i], d[5][i]) <= 1e-14
                    if d[0] in (kernel.CONTINUE, kernel.POLISH):
                        # both solve with ZᵀWZ (rounding ~1e-16·cond): 1e-10, or 1e-15·cond where larger
                        tol = max(1e-10, 1e-15 * reduced_cond(s, d[5]))
                        assert rel(c[6], d[6]) <= tol
                        assert rel(c[7], d[7]) <= tol
                    if d[0] == kernel.CONVERGED:
                        top = d[8].max()
                        # the top eigenvalue alone (the dense kernel's whole spectrum where it decided)
                        assert c[8].shape == (1,) or (at_critical and c[8].shape == d[8].shape)
                        assert abs(c[8].max() - top) <= 1e-10 * abs(top) + 1e-14 * kscale
                        assert (c[8].max() < -thr) == (top < -thr)
    assert {kernel.CONTINUE, kernel.CONVERGED} <= seen


def test_untrustworthy_chain_results_fall_back_to_the_dense_kernels(dense, monkeypatch):
    """Every pivot treated as doubtful (the interpreted twin with ``TRUST_RCOND`` above any
    reciprocal condition) hands the iteration and the point to the dense kernels, whose results
    are returned as they are; so does a factorisation made by the dense kernel."""
    py = _python_twin()
    py.TRUST_RCOND = 2.0
    monkeypatch.setattr(chain_kernel, "_COMPILED", [(py._iterate_chain, py._point_chain)])
    vm, s, eqs = states(2)
    eq = eqs[1]
    p_eq = s.kin.evaluate(eq.x, hessian=False).position
    x = eq.x.copy()
    x[s.free] += 1e-4
    calls = []

    def spy(*z):
        calls.append(1)
        return dense(*z)

    for xx in (x, eq.x):
        head, consts, _ = kernel_args(s, xx, p_eq)
        a = head + (True, True, True, True, _KERNEL_DUMMY[:8], consts)
        out = chain_kernel.iterate(*a, dense=spy)
        ref = dense(*a)
        assert len(calls) and out[0] == ref[0]
        assert np.array_equal(out[6], ref[6]) and np.array_equal(out[8], ref[8])
        calls.clear()
        # a factorisation made by the dense kernel (no Jacobian rows appended): dense decides
        b = head + (False, True, True, True, ref[5], consts)
        out = chain_kernel.iterate(*b, dense=spy)
        assert len(calls) and out[0] == dense(*b)[0]
        calls.clear()
    task = np.asarray(vm.task)
    pk = pkmod.PointKernel(vm.K_theta, s.free, DIRECTION[task], task)
    mask = s.kin.support_mask(s.free)
    b = blocks_at(vm, eq.x, eq.wrench, s.kin)
    assert chain_kernel.point(pk, b, mask, eq.wrench, pkmod.FAST_RANK) is None
    monkeypatch.setattr(chain_kernel, "POINT_MIN_N", 1)
    got = pk.point(b, mask, eq.wrench, pkmod.compiled())
    monkeypatch.setattr(chain_kernel, "POINT_MIN_N", 10**9)
    ref = pk.point(b, mask, eq.wrench, pkmod.compiled())
    assert got[0] == ref[0] and np.array_equal(got[1], ref[1]) and got[3:] == ref[3:]


def test_chain_factorisation_is_reused_by_both_kernels(dense):
    """The factorisation a chain iteration returns is accepted by the dense kernel (the reflectors
    come first; the appended Jacobian rows are never read) with the same result."""
    vm, s, eqs = states(4)
    eq = eqs[0]
    p_eq = s.kin.evaluate(eq.x, hessian=False).position
    head, consts, _ = kernel_args(s, eq.x, p_eq)
    a = head + (True, False, True, True, _KERNEL_DUMMY[:8], consts)
    c = chain_kernel.iterate(*a, dense=dense)
    assert c[0] == kernel.CONVERGED
    b = head + (False, False, True, True, c[5], consts)
    d = dense(*b)
    assert d[0] == kernel.CONVERGED
    assert abs(c[8][0] - d[8].max()) <= 1e-10 * abs(d[8].max()) + 1e-14 * np.abs(vm.K_theta).max()
    again = chain_kernel.iterate(*b, dense=lambda *z: pytest.fail("its own factorisation"))
    assert again[8][0] == pytest.approx(c[8][0], rel=1e-12, abs=1e-14 * np.abs(vm.K_theta).max())


def test_compiled_dispatch_uses_the_chain_kernel_for_long_chains(dense):
    vm, s, eqs = states(8)
    assert len(s.free) >= chain_kernel.ITERATE_MIN_N
    p_eq = s.kin.evaluate(eqs[0].x, hessian=False).position
    head, consts, _ = kernel_args(s, eqs[0].x, p_eq)
    a = head + (True, False, True, False, _KERNEL_DUMMY[:8], consts)
    out = kernel._load_compiled()(*a)
    ref = dense.dispatcher(*a[:9], *consts)
    assert out[0] == ref[0] == kernel.CONVERGED
    assert out[8].shape == (1,) and ref[8].size == len(s.free) - len(s.task)
    assert abs(out[8][0] - ref[8].max()) <= 1e-10 * abs(ref[8].max()) + 1e-14 * np.abs(vm.K_theta).max()


# --------------------------------------------------------------------------- the point kernel
@pytest.mark.parametrize("k", [2, 4, 8])
def test_point_matches_the_dense_kernel(k, dense):
    vm, s, eqs = states(k)
    fn = pkmod.compiled()
    task = np.asarray(vm.task)
    pk = pkmod.PointKernel(vm.K_theta, s.free, DIRECTION[task], task)
    mask = s.kin.support_mask(s.free)
    kscale = np.abs(vm.K_theta).max()
    rng = np.random.default_rng(10 + k)
    compared = 0
    k0 = None
    for eq in eqs:
        for extra in range(3):
            x, w = eq.x.copy(), eq.wrench.copy()
            if extra:
                x[s.free] += 1e-3 * rng.standard_normal(len(s.free))
                w[:3] += 0.1 * abs(w[0]) * rng.standard_normal(3)
            if extra == 2:
                w[3:] = 0.05 * abs(w[0]) * rng.standard_normal(3)  # a moment: W not symmetric
            b = blocks_at(vm, x, w, s.kin)
            old = chain_kernel.POINT_MIN_N
            chain_kernel.POINT_MIN_N = 10**9
            try:
                d = pk.point(b, mask, w, fn)
            finally:
                chain_kernel.POINT_MIN_N = old
            c = chain_kernel.point(pk, b, mask, w, pkmod.FAST_RANK)
            if d is None:  # the generic path decides there; the chain kernel must not answer
                assert c is None
                continue
            if c is None:  # a doubtful chain factorisation next to a critical point: dense decides
                continue
            compared += 1
            kd, xd, fd, mu, rate = d
            # both solve eq. (28) (rounding ~1e-16·cond of the equilibrated matrix, large next to
            # a critical point): 1e-10, or 1e-15·cond where larger
            tol = max(1e-10, 1e-15 * np.linalg.cond(_ruiz(eq28_matrix(b))[0]))
            if k0 is None:
                k0 = abs(kd)  # the unloaded column's stiffness: δF, k are differences of terms this size
            assert rel(c[1], xd) <= tol
            assert np.abs(c[2] - fd).max() <= tol * max(np.abs(fd).max(), k0)
            assert c[0] == pytest.approx(kd, rel=tol, abs=tol * k0)
            assert abs(c[3] - mu) <= 1e-10 * abs(mu) + 1e-14 * kscale
            assert c[4] == pytest.approx(rate, rel=1e-8, abs=1e-12 * kscale)
            nomask = chain_kernel.point(pk, b, mask, w, pkmod.FAST_RANK)
            assert nomask[3] == pytest.approx(c[3], rel=1e-12, abs=1e-14 * kscale)
    assert compared >= 2 * len(eqs)


def test_long_random_chain_with_orientation_rows(dense):
    """A random chain (passive, prismatic and revolute joints, 6-D/3-D/1-D link springs) held in
    all six task rows: multipliers with moments make ``W`` unsymmetric; steps, verdicts and the
    point kernel against the dense kernels."""
    from .chains import random_vjm

    vm = random_vjm(5, n_joints=12, n_passive=2, link_springs=9)
    s = EquilibriumSolver(vm)
    assert len(s.free) >= 40 and len(s.task) == 6
    kin = s.kin
    kscale = np.abs(vm.K_theta).max()
    rng = np.random.default_rng(4)
    seen = set()
    consts0, thr = s._kernel_consts()
    for amp in (1e-3, 2e-2):
        for _ in range(3):
            x = vm.reference + rng.uniform(-amp, amp, vm.model.nq)
            p_t, r_t = kin.placement(vm.reference + rng.uniform(-amp, amp, vm.model.nq))
            j6 = np.ascontiguousarray(
                pin.computeFrameJacobian(kin.model, kin.data, x, kin.frame_id, pin.LOCAL_WORLD_ALIGNED))
            mo = kin.data.oMf[kin.frame_id]
            erot = pin.log3(r_t @ mo.rotation.T)
            a = (j6, mo.translation.copy(), erot, x, True, True, True, True, _KERNEL_DUMMY[:8],
                 kernel.with_target(consts0, p_t))
            d = dense(*a)
            c = chain_kernel.iterate(*a, dense=dense)
            assert c[0] == d[0]
            seen.add(d[0])
            if d[0] in (kernel.CONTINUE, kernel.POLISH):
                assert rel(c[6], d[6]) <= max(1e-10, 1e-15 * reduced_cond(s, d[5]))
            if d[0] == kernel.CONVERGED:
                assert abs(c[8][0] - d[8].max()) <= 1e-10 * abs(d[8].max()) + 1e-14 * kscale
    eq = s.solve(np.array([1e-3, -5e-4, 2e-4, 0.01, -0.02, 0.005]))
    assert kernel.CONTINUE in seen
    p_eq = kin.placement(eq.x)[0]
    j6 = np.ascontiguousarray(pin.computeFrameJacobian(kin.model, kin.data, eq.x, kin.frame_id, pin.LOCAL_WORLD_ALIGNED))
    a = (j6, kin.data.oMf[kin.frame_id].translation.copy(), np.zeros(3), eq.x, True, False, True, True,
         _KERNEL_DUMMY[:8], kernel.with_target(consts0, p_eq))
    d, c = dense(*a), chain_kernel.iterate(*a, dense=dense)
    assert c[0] == d[0] == kernel.CONVERGED and np.abs(eq.wrench[3:]).max() > 0
    assert abs(c[8][0] - d[8].max()) <= 1e-10 * abs(d[8].max()) + 1e-14 * kscale
    assert (c[8][0] < -thr) == (d[8].max() < -thr)
    direction = np.array([0.3, -0.2, 0.9, 0.1, 0.0, -0.2])
    task = np.asarray(vm.task)
    pk = pkmod.PointKernel(vm.K_theta, s.free, direction[task], task)
    mask = kin.support_mask(s.free)
    b = blocks_at(vm, eq.x, eq.wrench, kin)
    got = chain_kernel.point(pk, b, mask, eq.wrench, pkmod.FAST_RANK)
    old = chain_kernel.POINT_MIN_N
    chain_kernel.POINT_MIN_N = 10**9
    try:
        ref = pk.point(b, mask, eq.wrench, pkmod.compiled())
    finally:
        chain_kernel.POINT_MIN_N = old
    assert got is not None and ref is not None
    assert rel(got[1], ref[1]) <= 1e-9 and rel(got[2], ref[2]) <= 1e-9
    assert abs(got[3] - ref[3]) <= 1e-10 * abs(ref[3]) + 1e-14 * kscale
    assert got[4] == pytest.approx(ref[4], rel=1e-7, abs=1e-12 * kscale)


# --------------------------------------------------------------------------- the layout cache
def _variant(beam=None, sprung_base_y=False):
    """Model C (S, k = 2) rebuilt from its spec: another beam, or ``base_y`` made a 1-D spring
    (the same number of free coordinates, another split into springs and passive joints)."""
    from vjm_pin.model.generator import generate_vjm
    from vjm_pin.model.paper_models import paper_spec, rigid_chain_urdf

    spec = paper_spec("c", "s", beam=beam or PAPER_BEAM, subdivide=2)
    if sprung_base_y:
        spec["passive"] = ["base_z"]
        spec["actuators"] = {"base_y": 50.0}
    return load_vjm(generate_vjm(rigid_chain_urdf(1.0), spec))


def _solver_layout(s):
    consts, _ = s._kernel_consts()
    ci, kz, mask = consts[0], consts[2], consts[3]
    n, nt = int(ci[0]), int(ci[1])
    return chain_kernel._layout(ci, kz, ci[6:6 + n], nt, mask), consts


def _same_layout(a, b):
    return (a.ok == b.ok and a.kscale == b.kscale
            and all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("cols", "order", "starts", "dpos", "kd",
                                                                             "kp", "klo", "khi")))


def test_layouts_are_shared_by_content_and_only_between_equal_models(dense, monkeypatch):
    monkeypatch.setattr(chain_kernel, "_SHARED", {})
    monkeypatch.setattr(chain_kernel, "_LAYOUTS", {})
    stiff = dict(PAPER_BEAM, E=1.7 * PAPER_BEAM["E"])
    vms = {"base": _variant(), "again": _variant(), "stiffer": _variant(beam=stiff),
           "sprung": _variant(sprung_base_y=True)}
    solvers = {k: EquilibriumSolver(v) for k, v in vms.items()}
    n = {k: len(s.free) for k, s in solvers.items()}
    assert len(set(n.values())) == 1, n  # the same n: only the content tells them apart
    assert solvers["sprung"].nt == solvers["base"].nt + 1
    assert not np.array_equal(vms["stiffer"].K_theta, vms["base"].K_theta)
    lays = {k: _solver_layout(s)[0] for k, s in solvers.items()}
    # the same model rebuilt (other arrays, equal bytes) gets the cached layout; the point kernel
    # of a curve on it (its own zero-padded K, the support mask of the tracer) too
    assert lays["again"] is lays["base"]
    pk = pkmod.PointKernel(vms["again"].K_theta, solvers["again"].free, DIRECTION[:3], vms["again"].task)
    s = solvers["again"]
    assert chain_kernel._layout(pk.kz, pk.kz, pk.free, pk.nt, s.kin.support_mask(s.free)) is lays["base"]
    # different models never: each gets its own, equal to one built from scratch
    for k in ("stiffer", "sprung"):
        assert lays[k] is not lays["base"]
        c = _solver_layout(solvers[k])[1]
        fresh = chain_kernel._Layout(c[2], c[0][6:6 + n[k]], int(c[0][1]), c[3])
        assert _same_layout(lays[k], fresh) and lays[k].ok
        assert not np.array_equal(lays[k].kd, lays["base"].kd) or not np.array_equal(lays[k].cols, lays["base"].cols)
    # and the chain iteration with them agrees with the dense kernel on each model
    rng = np.random.default_rng(7)
    for k in ("base", "stiffer", "sprung", "again"):
        s = solvers[k]
        eq = s.solve(2e-5 * DIRECTION)
        assert eq.converged
        p_eq = s.kin.evaluate(eq.x, hessian=False).position
        x = eq.x.copy()
        x[s.free] += 1e-5 * rng.standard_normal(len(s.free))
        for xx in (eq.x, x):
            head, consts, thr = kernel_args(s, xx, p_eq)
            a = head + (True, False, True, True, _KERNEL_DUMMY[:8], consts)
            d = dense(*a)
            c = chain_kernel.iterate(*a, dense=lambda *z: pytest.fail("dense fallback at a regular point"))
            assert c[0] == d[0], k
            if d[0] in (kernel.CONTINUE, kernel.POLISH):
                assert rel(c[6], d[6]) <= max(1e-10, 1e-15 * reduced_cond(s, d[5])), k
            else:
                assert d[0] == kernel.CONVERGED
                top = d[8].max()
                assert abs(c[8][0] - top) <= 1e-10 * abs(top) + 1e-14 * lays[k].kscale, k
                assert (c[8][0] < -thr) == (top < -thr)


def test_layout_cache_is_bounded(dense, monkeypatch):
    monkeypatch.setattr(chain_kernel, "_SHARED", {})
    monkeypatch.setattr(chain_kernel, "_LAYOUTS", {})
    monkeypatch.setattr(chain_kernel, "SHARED_MAX", 2)
    vms = [_variant(beam=dict(PAPER_BEAM, E=f * PAPER_BEAM["E"])) for f in (1.0, 1.3, 1.6)]
    lays = [_solver_layout(EquilibriumSolver(v))[0] for v in vms]
    assert len(chain_kernel._SHARED) == 2
    again = _solver_layout(EquilibriumSolver(vms[0]))[0]  # evicted (least recently used): rebuilt
    assert again is not lays[0] and _same_layout(again, lays[0])
    assert _solver_layout(EquilibriumSolver(vms[2]))[0] is lays[2]
    monkeypatch.setattr(chain_kernel, "SHARED_MAX_BYTES", 1)  # the newest entry is always kept
    assert _solver_layout(EquilibriumSolver(vms[1]))[0] is not lays[1]
    assert len(chain_kernel._SHARED) == 1


# --------------------------------------------------------------------------- pieces
def test_pivot_block_inertia_matches_eigenvalues(dense):
    """Sylvester's counts of a symmetric pivot block (Bunch–Parlett elimination) against its
    eigenvalues: random, with prescribed signs (tiny ones included), and a zero diagonal (2×2
    pivots only)."""
    rng = np.random.default_rng(3)
    cases = []
    for n in range(1, 8):
        a = rng.standard_normal((n, n))
        cases.append(a + a.T)
        q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        cases.append(q @ np.diag(rng.choice([-2.0, -1e-3, 1e-3, 3.0], n)) @ q.T)
        cases.append(np.ones((n, n)) - np.eye(n))  # eigenvalues n − 1 and −1
    for a in cases:
        n = a.shape[0]
        ref = np.linalg.eigvalsh(a)
        tiny = 1e-14 * n * np.abs(a).sum(axis=1).max()
        want = (int((ref > tiny).sum()), int((ref < -tiny).sum()), int((np.abs(ref) <= tiny).sum()))
        assert chain_kernel._inertia_small(a.copy(), n, tiny) == want, ref


def _python_twin():
    """The module's loops run by the interpreter (a fresh copy of the module, not compiled)."""
    spec = importlib.util.spec_from_file_location("_chain_kernel_python", chain_kernel.__file__)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_interpreted_twin_agrees_with_the_compiled_kernels(dense):
    py = _python_twin()
    vm, s, eqs = states(2)
    n = len(s.free)
    lay = chain_kernel._layout(s._kz, s._kz, s.free, s.nt, s.kin.support_mask(s.free))
    for eq in (eqs[0], eqs[-2]):
        p_eq = s.kin.evaluate(eq.x, hessian=False).position
        x = eq.x.copy()
        x[s.free] += 1e-4
        for xx in (eq.x, x):
            head, consts, _ = kernel_args(s, xx, p_eq)
            extra = (lay.cols, lay.order, lay.starts, lay.dpos, lay.kd, lay.kp, lay.kscale, lay.klo, lay.khi, False,
                     np.zeros(n))
            a = head + (True, False, True, True, _KERNEL_DUMMY[:8]) + tuple(consts) + extra
            c = chain_kernel._load()[0](*a)
            p = py._iterate_chain(*a)
            assert c[0] == p[0]
            if c[0] in (kernel.CONTINUE, kernel.POLISH):
                assert rel(c[6], p[6]) <= 1e-12
            if c[0] == kernel.CONVERGED:
                assert c[8][0] == pytest.approx(p[8][0], rel=1e-10, abs=1e-14 * lay.kscale)
        task = np.asarray(vm.task)
        w = eq.wrench.copy()
        w[3:] = [0.3, -0.2, 0.1]
        j6 = np.ascontiguousarray(s.kin.evaluate(eq.x, hessian=False).jacobian)
        prow = np.ascontiguousarray(np.linalg.svd(DIRECTION[task].reshape(-1, 1))[0][:, 1:].T)
        args = (j6, lay.cols, lay.order, task.astype(np.int64), DIRECTION[task].copy(), prow, lay.starts, lay.dpos,
                lay.kd, lay.kp, lay.kscale, w, True, pkmod.FAST_RANK, False, np.zeros(n))
        c = chain_kernel._load()[1](*args)
        p = py._point_chain(*args)
        assert c[0] == p[0] == 0
        assert rel(c[2], p[2]) <= 1e-12 and rel(c[3], p[3]) <= 1e-12
        assert c[4] == pytest.approx(p[4], rel=1e-10, abs=1e-14 * lay.kscale)
        assert c[5] == pytest.approx(p[5], rel=1e-8)


# --------------------------------------------------------------------------- whole curves
def test_k8_curve_matches_the_dense_kernels(dense):
    vm, _, _ = model(8)

    def run(chain):
        old = chain_kernel.ITERATE_MIN_N, chain_kernel.POINT_MIN_N
        if not chain:
            chain_kernel.ITERATE_MIN_N = chain_kernel.POINT_MIN_N = 10**9
        try:
            return trace_curve(vm, DIRECTION, MAX_DEFLECTION, steps=30, solver=EquilibriumSolver(vm))
        finally:
            chain_kernel.ITERATE_MIN_N, chain_kernel.POINT_MIN_N = old

    a, b = run(True), run(False)
    assert len(a.points) == len(b.points)
    scale = np.abs(b.forces).max()
    assert np.abs(a.forces - b.forces).max() <= 1e-9 * scale
    for p, q in zip(a.points, b.points):
        assert (p.stable, p.stable_end_held) == (q.stable, q.stable_end_held)
        assert p.stiffness == pytest.approx(q.stiffness, rel=1e-8, abs=1e-9 * scale / MAX_DEFLECTION)
        assert p.force_control_margin == pytest.approx(q.force_control_margin, rel=1e-8,
                                                       abs=1e-13 * np.abs(vm.K_theta).max())
    assert [c.kind for c in a.critical] == [c.kind for c in b.critical]
    assert a.critical
    for c, d in zip(a.critical, b.critical):
        assert c.force == pytest.approx(d.force, rel=1e-9)
        assert c.deflection == pytest.approx(d.deflection, rel=1e-9, abs=1e-12)
        assert c.index == d.index
