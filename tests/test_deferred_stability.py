"""Long chains solved by the O(n) chain kernel report the whole eq. (23) spectrum: the kernel
certifies the verdict from the largest eigenvalue alone and the rest is computed when first read
(:class:`vjm_pin.solver.stability.DeferredStability`)."""

import pickle

import numpy as np
import pytest

from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import chain_kernel, kernel
from vjm_pin.solver.blocks import evaluate_blocks
from vjm_pin.solver.equilibrium import EquilibriumSolver
from vjm_pin.solver.stability import DeferredStability, StabilityResult, check_stability

pytest.importorskip("numba")

# k = 4 sub-links: 76 free coordinates, above chain_kernel.ITERATE_MIN_N
VM = load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=4))
TARGETS = (np.array([-2e-5, 0.0, 0.0]), np.array([-2e-4, 3e-5, 0.0]), np.array([-5e-4, 0.0, 0.0]))


def _solve(monkeypatch, jit: str, target):
    monkeypatch.setenv("VJM_PIN_JIT", jit)
    return EquilibriumSolver(VM).solve(target)


@pytest.mark.parametrize("target", TARGETS, ids=["small", "lateral", "post-buckling"])
def test_chain_solves_report_every_eigenvalue_of_eq23(monkeypatch, target):
    assert len(VM.theta_idx) + len(VM.q_idx) >= chain_kernel.ITERATE_MIN_N
    assert kernel._load_compiled()
    r = _solve(monkeypatch, "1", target)
    assert r.converged
    st = r.stability
    assert isinstance(st, DeferredStability), "the chain kernel ran: its verdict comes with the largest eigenvalue only"
    margin = st.margin  # known before the spectrum is read
    fresh = check_stability(evaluate_blocks(VM, EquilibriumSolver(VM).kin, r.x, r.wrench))
    ev = st.eigenvalues
    assert ev.shape == fresh.eigenvalues.shape == (st.null_dim,)
    scale = np.abs(fresh.eigenvalues).max()
    assert np.abs(ev - fresh.eigenvalues).max() <= 1e-9 * scale
    assert abs(-margin - ev.max()) <= 1e-9 * scale
    assert st.stable == fresh.stable == bool(ev.max() < -st.tolerance)
    # the numpy path (dense kernel, every eigenvalue at once) gives the same spectrum
    d = _solve(monkeypatch, "0", target)
    assert type(d.stability) is StabilityResult
    assert np.abs(d.stability.eigenvalues - ev).max() <= 1e-8 * scale
    # pickled (a map worker, Dask) as a plain StabilityResult with the spectrum
    back = pickle.loads(pickle.dumps(st))
    assert type(back) is StabilityResult and np.array_equal(back.eigenvalues, ev) and back.stable == st.stable


def test_spectrum_later_stable_now_is_the_constructors_verdict():
    """``SpectrumLater.stable_now`` (the warm-started solve's verdict, fields set at once) is the
    object ``SpectrumLater(True, ...)`` builds: the same fields, eigenvalues when first read (then the
    matrix dropped), the same pickle."""
    from vjm_pin.solver.stability import SpectrumLater

    rng = np.random.default_rng(3)
    a = rng.standard_normal((5, 5))
    sym = -(a @ a.T) - np.eye(5)
    got = SpectrumLater.stable_now(np.int64(5), np.float64(1e-9), sym.copy(), np.linalg.eigvalsh)
    want = SpectrumLater(True, 5, 1e-9, sym.copy(), np.linalg.eigvalsh)
    assert got.__dict__.keys() == want.__dict__.keys()
    assert {k: v for k, v in got.__dict__.items() if k != "_matrix"} == {
        k: v for k, v in want.__dict__.items() if k != "_matrix"}
    assert type(got.null_dim) is int and type(got.tolerance) is float and got._spectrum is None
    np.testing.assert_array_equal(got.eigenvalues, want.eigenvalues)
    assert got._matrix is None and got.margin == want.margin
    back = pickle.loads(pickle.dumps(got))
    assert type(back) is StabilityResult and back.stable and back.null_dim == 5
    np.testing.assert_array_equal(back.eigenvalues, want.eigenvalues)
