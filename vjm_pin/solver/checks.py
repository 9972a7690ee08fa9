"""Checks shared by the serial and the mechanism ``verify`` (solver layer).

:meth:`vjm_pin.solver.EquilibriumSolver.verify` and
:func:`vjm_pin.solver.mechanism_checks.check_mechanism` recompute an equilibrium in their own
ways (serial blocks; Pinocchio with closure rows) and then judge it by the same rules, kept here
once:

- :func:`statics_relative`: the eq. (5) residual per row against its own scale;
- :func:`verdict_agrees`: a stability verdict against a recomputed one;
- :func:`softest_direction` and :func:`stiffness_fd_error`: ``K_C`` along its softest task
  direction against central differences of the task wrench of re-solved equilibria.

Pure functions on numpy arrays; the re-solve is the caller's (a callback).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Displacement steps of the central differences of :func:`stiffness_fd_error` (× L_c, m; rad
#: along rotations after the scaling of :func:`softest_direction`), tried in this order.
FD_STEPS = (1e-6, 1e-8, 1e-10)


def statics_relative(r, tau, prism, force, moment, length, floor=1e-300) -> float:
    """Largest eq. (5) residual ``|r_i|`` relative to its row's scale.

    The scale of a revolute row (N·m) is ``max(|τ_i|, F·L_c + M)``, of a prismatic row (N)
    ``max(|τ_i|, F + M/L_c)``, and at least ``1e-3·max|τ|`` and ``floor``.

    Args:
        r: (n,) residual of eq. (5) (N·m, N).
        tau: (n,) spring torques and forces ``K_θ(θ−θ₀)`` of the same rows (zero for passive
            rows) (N·m, N).
        prism: (n,) bool, the prismatic rows.
        force, moment: The largest force (N) and moment (N·m) of the wrenches involved.
        length: The length scale ``L_c`` of the chain (m).
        floor: The smallest scale (scalar or (n,)), for an unloaded equilibrium.
    """
    t = np.abs(tau)
    scale = np.where(
        prism, np.maximum(t, force + moment / length), np.maximum(t, force * length + moment)
    )
    scale = np.maximum(scale, 1e-3 * t.max() if t.size else 0.0)
    scale = np.maximum(scale, floor)
    return float((np.abs(r) / scale).max()) if np.size(r) else 0.0


def verdict_agrees(given, stable: bool, eigenvalues: np.ndarray, threshold: float) -> bool:
    """Whether the verdict ``given`` (a result's ``StabilityResult``, or None: nothing to
    check) agrees with the recomputed ``stable``, whose ``eigenvalues`` (stable iff all are
    below ``-threshold``, the convention of :mod:`vjm_pin.solver.stability`) decided it. A
    verdict whose deciding eigenvalue lies within 10× the threshold of zero is not contested."""
    if given is None:
        return True
    top = eigenvalues.max() if eigenvalues.size else -np.inf
    return bool(given.stable == stable or abs(top) <= 10 * threshold)


def softest_direction(k: np.ndarray, task, length: float) -> np.ndarray:
    """(m,) unit direction of the task (m along translations, rad along rotations) of the
    smallest |eigenvalue| of the symmetric part of ``k`` (m, m), rotations scaled by ``length``
    (L_c, m) so that both kinds of component weigh alike; unit in the scaled norm."""
    dsc = np.where(np.array(task) < 3, 1.0, 1.0 / length)  # rotations in units of L_c
    ks = dsc[:, None] * k * dsc[None, :]
    ev, vec = np.linalg.eigh(0.5 * (ks + ks.T))
    j = int(np.argmin(np.abs(ev)))
    u = vec[:, j] * dsc  # a (m,) direction: m for translations, rad for rotations
    u /= np.linalg.norm(u / dsc)
    return u


def stiffness_fd_error(
    k: np.ndarray,
    u: np.ndarray,
    task,
    length: float,
    task_wrench: Callable[[np.ndarray], np.ndarray | None],
    rtol: float,
) -> float:
    """Relative error of ``K_C u`` against the central difference of the task wrench.

    ``task_wrench(dt)`` re-solves the equilibrium with the task frame moved by ``dt`` (6,) (δp
    m, δφ rad, zero off the task) and returns its task wrench (m,) (N, N·m), or None when no
    equilibrium was found. Steps ``h`` = :data:`FD_STEPS` × ``length`` are tried in turn until
    the error is within ``rtol``; the smallest error is returned (inf when no step could be
    re-solved on both sides).
    """
    task = list(task)
    ku = k @ u
    best = np.inf
    for step in FD_STEPS:
        h = step * length
        fs = []
        for sgn in (1.0, -1.0):
            dt = np.zeros(6)
            dt[task] = sgn * h * u
            w = task_wrench(dt)
            if w is None:
                break
            fs.append(w)
        if len(fs) < 2:
            continue
        fd = (fs[0] - fs[1]) / (2 * h)
        den = max(np.linalg.norm(ku), np.linalg.norm(fd), 1e-12 * np.abs(k).max(), 1e-300)
        best = min(best, float(np.linalg.norm(ku - fd) / den))
        if best <= rtol:
            break
    return best


__all__ = [
    "FD_STEPS",
    "softest_direction",
    "statics_relative",
    "stiffness_fd_error",
    "verdict_agrees",
]
