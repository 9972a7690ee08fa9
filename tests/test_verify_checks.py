"""The checks shared by the serial and the mechanism ``verify`` (vjm_pin/solver/checks.py):
properties on made-up data, and both verifies agreeing on one serial chain."""

from __future__ import annotations

import numpy as np
import pytest

from vjm_pin.solver.checks import (
    softest_direction,
    statics_relative,
    stiffness_fd_error,
    verdict_agrees,
)
from vjm_pin.solver.stability import StabilityResult


def test_statics_relative_does_not_depend_on_the_length_unit():
    """Metres to millimetres: moments and revolute rows (N·m) × 1000, L_c × 1000, forces and
    prismatic rows (N) unchanged: every row's residual/scale is a pure number."""
    rng = np.random.default_rng(3)
    prism = np.array([False, True, False, True, False])
    tau = rng.normal(size=5) * np.where(prism, 50.0, 3.0)  # N on prismatic rows, N·m on revolute
    r = 1e-9 * rng.normal(size=5) * np.where(prism, 50.0, 3.0)
    f, m, lc = 40.0, 2.5, 0.7
    si = statics_relative(r, tau, prism, f, m, lc)
    mm = np.where(prism, 1.0, 1e3)
    assert statics_relative(r * mm, tau * mm, prism, f, m * 1e3, lc * 1e3) == pytest.approx(
        si, rel=1e-12
    )
    # a residual grows the verdict in proportion; a zero residual is exact
    assert statics_relative(10 * r, tau, prism, f, m, lc) == pytest.approx(10 * si, rel=1e-12)
    assert statics_relative(0 * r, tau, prism, f, m, lc) == 0.0


def test_statics_relative_of_an_unloaded_row_uses_the_floor():
    """No torque, no wrench: only the floor scales the row (an unloaded equilibrium)."""
    r, z = np.array([1e-13]), np.zeros(1)
    assert statics_relative(r, z, np.array([False]), 0.0, 0.0, 1.0, floor=1e-9) == pytest.approx(
        1e-4
    )


def _verdict(eigs, thr=1e-6):
    eigs = np.asarray(eigs, float)
    return StabilityResult(
        stable=bool(eigs.max() < -thr), eigenvalues=eigs, null_dim=eigs.size, tolerance=thr
    )


@pytest.mark.parametrize(
    "fresh,contested", [([-3.0, -1.0], True), ([-3.0, -5e-6], False), ([-3.0, 2.0], True)]
)
def test_a_flipped_verdict_is_caught_unless_it_is_at_the_threshold(fresh, contested):
    thr = 1e-6
    fresh = np.array(fresh)
    stable = bool(fresh.max() < -thr)
    same = _verdict(fresh, thr)
    flipped = StabilityResult(
        stable=not stable, eigenvalues=fresh, null_dim=fresh.size, tolerance=thr
    )
    assert verdict_agrees(same, stable, fresh, thr)
    assert verdict_agrees(None, stable, fresh, thr)
    assert verdict_agrees(flipped, stable, fresh, thr) is (not contested)


def _linear_springs(k_true, task):
    """The task wrench of a linear spring K (m, m) moved by dt (6,): K dt[task]."""
    return lambda dt: k_true @ dt[list(task)]


@pytest.mark.parametrize("task", [(0, 1, 2), (0, 2, 4), (0, 1, 2, 3, 4, 5)])
def test_stiffness_fd_error_passes_the_true_stiffness_and_catches_a_wrong_one(task):
    rng = np.random.default_rng(len(task))
    m, lc = len(task), 0.8
    a = rng.normal(size=(m, m))
    k = a @ a.T + 0.05 * np.eye(m)
    k *= np.where(np.array(task) < 3, 1e4, 1e4 * lc)[:, None]  # N/m, N/rad, N·m/rad …
    k = 0.5 * (k + k.T)
    u = softest_direction(k, task, lc)
    assert np.linalg.norm(u / np.where(np.array(task) < 3, 1.0, 1.0 / lc)) == pytest.approx(1.0)
    exact = stiffness_fd_error(k, u, task, lc, _linear_springs(k, task), 1e-3)
    assert exact < 1e-6
    # K_C off by 1 % along u: the central difference sees it
    wrong = k + 0.01 * np.linalg.norm(k @ u) * np.outer(u, u) / (u @ u)
    assert stiffness_fd_error(wrong, u, task, lc, _linear_springs(k, task), 1e-3) > 1e-3
    # no re-solved equilibrium: nothing could be compared
    assert stiffness_fd_error(k, u, task, lc, lambda dt: None, 1e-3) == np.inf


def test_softest_direction_is_the_softest_scaled_eigenvector():
    """Rotations scaled by L_c: a rotational stiffness that is soft in N·m/rad can be the stiff
    direction once expressed per metre of arc at L_c."""
    lc = 0.01
    k = np.diag([1e3, 5.0])  # x: 1000 N/m; ry: 5 N·m/rad = 5e4 N/m at 1 cm
    u = softest_direction(k, (0, 4), lc)
    assert abs(u[0]) == pytest.approx(1.0) and u[1] == pytest.approx(0.0, abs=1e-12)
    u = softest_direction(k, (0, 4), 1.0)  # at 1 m: 5 N/m, the softest
    assert abs(u[1]) == pytest.approx(1.0) and u[0] == pytest.approx(0.0, abs=1e-12)


def test_serial_and_mechanism_verify_agree_on_a_chain():
    """The same equilibrium of a serial chain checked by both verifies (their own recomputation,
    the shared rules): both pass, and the K_C checks agree."""
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver
    from vjm_pin.solver.mechanism import MechanismSolver

    vm = resolve_model("paper-c-s")
    serial = EquilibriumSolver(vm).verify(EquilibriumSolver(vm).solve_wrench([-0.3, 0.05, 0.0]))
    ms = MechanismSolver(vm)
    mres = ms.solve(wrench=serial.wrench[list(vm.task)] if len(vm.task) != 6 else serial.wrench)
    check = ms.verify(mres, method="eq30")
    assert serial.checks["ok"] and check.ok
    assert serial.checks["statics_relative"] <= 1e-8 and check.statics_relative <= 1e-8
    assert (
        serial.checks["stiffness_relative_error"] <= 1e-3 and check.stiffness_relative_error <= 1e-3
    )
    np.testing.assert_allclose(mres.deflection, serial.deflection, rtol=1e-7, atol=1e-12)


def test_stiffness_fd_error_confirms_an_exactly_zero_stiffness_and_catches_a_small_wrong_one(monkeypatch):
    """An unloaded mechanism direction (Model B Π at zero load): ``K_C u = 0`` exactly while the
    re-solved wrench grows as ``h³`` (a cubic spring) and carries the re-solves' rounding (±1e-24 N,
    as measured there). Against a floor of 1e-12 of the largest entry that zero is not confirmed at
    any step; against :data:`ZERO_STIFFNESS` it is, and a stiffness of 1e-6 of the largest along that
    direction, where the truth is zero, is still caught."""
    from vjm_pin.solver import checks

    task, lc = (0, 1), 2.7
    k = np.diag([1.5, 0.0])
    cubic, noise = 3.0, 1e-24  # N/m³ along y; N
    calls = {"n": 0}

    def wrench(dt):
        calls["n"] += 1
        d = dt[list(task)]
        return k @ d + np.array([0.0, cubic * d[1] ** 3]) + noise * (-1.0) ** calls["n"]

    u = softest_direction(k, task, lc)
    assert abs(u[1]) == pytest.approx(1.0)
    assert stiffness_fd_error(k, u, task, lc, wrench, 1e-3) <= 1e-3
    wrong = k + 1e-6 * 1.5 * np.outer(u, u)
    assert stiffness_fd_error(wrong, u, task, lc, wrench, 1e-3) > 1e-3
    monkeypatch.setattr(checks, "ZERO_STIFFNESS", 1e-12)
    assert stiffness_fd_error(k, u, task, lc, wrench, 1e-3) > 1e-3


def test_unloaded_mechanism_directions_pass_the_check_through_the_cli():
    """Model B Π and C Π at zero load: K_C has an exactly zero entry (the unloaded chain turns
    freely about it to first order); ``vjm-pin analyze`` reports it, checked (exit 0), instead of
    refusing it, with ``K_C`` equal to the unloaded stiffness."""
    import contextlib
    import io
    import json

    from vjm_pin.cli import main

    for name in ("paper-b-pi", "paper-c-pi"):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            rc = main(["analyze", name, "--json"])
        assert rc == 0
        out = json.loads(buf.getvalue())
        kc, k0 = np.array(out["stiffness"], float), np.array(out["stiffness_unloaded"], float)
        t = out["task"] if isinstance(out["task"][0], int) else [["x", "y", "z", "rx", "ry", "rz"].index(c)
                                                                  for c in out["task"]]
        kt = kc[np.ix_(t, t)]
        assert np.abs(kt).max() > 0 and np.abs(np.diag(kt)).min() <= 1e-12 * np.abs(kt).max()
        assert np.allclose(kc, k0, rtol=1e-9, atol=1e-12 * np.abs(k0).max())
        assert out["checks"]["stiffness_checked"] and out["checks"]["stiffness_ok"]
