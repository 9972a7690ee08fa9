"""The curve tracer's point (``vjm_pin.analysis.curve._Tracer.point``) on a long chain with the
compiled chain point kernel: it evaluates the kinematic state first and forms the Blocks (the
dense Hessian of Ψ) only when a path reads them (``_StateBlocks``). Checked against the point
computed from the full Blocks at the same equilibria (unloaded, before, next to and after
buckling), when the chain kernel decides and when it declines (the dense kernel reads the
Hessian then), and that no Blocks are formed where the chain kernel decides at a fresh
configuration."""

import numpy as np
import pytest

from vjm_pin.analysis import curve as curve_mod
from vjm_pin.analysis.curve import _direction, _Tracer, trace_curve
from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf
from vjm_pin.solver import blocks, chain_kernel
from vjm_pin.solver.equilibrium import EquilibriumSolver

pytest.importorskip("numba")

DIRECTION = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
MAX_DEFLECTION = 6e-4  # m: past the Euler load of Model C (buckling, then post-buckling)


@pytest.fixture(autouse=True)
def _jit_on(monkeypatch):
    monkeypatch.setenv("VJM_PIN_JIT", "1")


@pytest.fixture(scope="module")
def chain():
    vm = load_vjm(paper_model_urdf("c", "s", beam=PAPER_BEAM, subdivide=4))
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VJM_PIN_JIT", "1")
        c = trace_curve(vm, DIRECTION, MAX_DEFLECTION, steps=8, solver=EquilibriumSolver(vm))
    return vm, [p.equilibrium for p in c.points]


def _reference(tr, eq):
    """``(k, δx, δF, μ, dμ/ds)`` from the full Blocks (as before the state came first)."""
    b = tr.blocks(eq.x, eq.wrench)
    return tr.kernel.point(b, tr.mask, eq.wrench, tr._fn)


def _fresh(tr):
    tr.kin._blocks_last = None  # no Blocks kept: point() must evaluate the state itself


@pytest.mark.parametrize("decline", [False, True], ids=["chain-decides", "chain-declines"])
def test_point_from_the_state_matches_the_point_from_the_blocks(chain, decline, monkeypatch):
    vm, eqs = chain
    # the remembered eigenvectors (start vectors, kept per kernel object, oldest evicted first):
    # fresh, so that earlier tests' entries cannot evict one tracer's and not the other's
    monkeypatch.setattr(chain_kernel, "_GUESS", {})
    solver = EquilibriumSolver(vm)
    tr = _Tracer(vm, _direction(vm, DIRECTION), MAX_DEFLECTION, solver, 1e-4)
    # the reference on a tracer of its own: the chain kernel starts each eigenproblem from its
    # point kernel's last eigenvector, so both see the same sequence of points
    ref_tr = _Tracer(vm, _direction(vm, DIRECTION), MAX_DEFLECTION, EquilibriumSolver(vm), 1e-4)
    assert tr.kernel is not None and tr.kernel.n >= chain_kernel.POINT_MIN_N
    if decline:
        monkeypatch.setattr(chain_kernel, "point", lambda *a, **k: None)
    built = []
    real = blocks.evaluate_blocks

    def spy(*a, **k):
        built.append(1)
        return real(*a, **k)

    compared = 0
    checked = []
    for i, eq in enumerate(eqs):
        s = i * 1e-5  # (the label of the point only)
        _fresh(tr)
        monkeypatch.setattr(blocks, "evaluate_blocks", spy)
        built.clear()
        p = tr.point(eq, s)
        monkeypatch.setattr(blocks, "evaluate_blocks", real)
        assert tr._fn is not None and tr._chain_point
        verdict = getattr(eq, "stability_end_held", None) is not None or getattr(eq, "held", None) is None
        if not decline and p.st is None and verdict:
            assert not built, "the chain kernel decided: no Blocks (dense Hessian) formed"
            checked.append(i)
        ref_tr._fn = tr._fn  # the same compiled kernel
        _fresh(ref_tr)
        ref = _reference(ref_tr, eq)
        if ref is None:  # the generic path decides both times
            assert p.st is not None
            continue
        k, xd, fd, mu, rate = ref
        scale = max(abs(k), 1.0)
        assert p.k == pytest.approx(k, rel=1e-14, abs=1e-14 * scale)
        assert p.mu == pytest.approx(mu, rel=1e-14, abs=1e-14 * np.abs(vm.K_theta).max())
        np.testing.assert_allclose(p.tan[0][tr.free], xd, rtol=1e-14, atol=1e-300)
        np.testing.assert_allclose(p.tan[1][tr.task], fd, rtol=1e-14, atol=1e-14 * scale)
        if rate is not None and curve_mod._analytic_rate:
            assert p.dmu == pytest.approx(rate, rel=1e-14, abs=1e-300)
        compared += 1
    assert compared >= len(eqs) - 2
    assert decline or len(checked) >= len(eqs) - 2
