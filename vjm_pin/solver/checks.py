"""Checks shared by the serial and the mechanism ``verify`` (solver layer).

:meth:`vjm_pin.solver.EquilibriumSolver.verify` and
:func:`vjm_pin.solver.mechanism_checks.check_mechanism` recompute an equilibrium in their own
ways (serial blocks; Pinocchio with closure rows) and then judge it by the same rules, kept here
once:

- :func:`statics_relative`: the eq. (5) residual per row against its own scale;
- :func:`verdict_agrees`: a stability verdict against a recomputed one;
- :func:`softest_direction` and :func:`stiffness_fd_error`: ``K_C`` along its softest task
  direction against central differences of the task wrench of re-solved equilibria;
- :func:`rigid_reach`: whether a prescribed deflection lies beyond what the end frame can reach
  along a rigid task direction (one it cannot move along to first order: a straight chain of
  rigid links cannot be stretched), to second order.

Pure functions on numpy arrays; the re-solve is the caller's (a callback).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Displacement steps of the central differences of :func:`stiffness_fd_error` (× L_c, m; rad
#: along rotations after the scaling of :func:`softest_direction`), tried in this order.
FD_STEPS = (1e-6, 1e-8, 1e-10)
#: :func:`stiffness_fd_error` compares ``K_C u`` relative to the larger of it, the difference and this
#: fraction of the largest entry of ``K_C`` (rotations scaled by L_c): a stiffness below it is zero to
#: the check (an unloaded mechanism direction, Model B Π: ``K_C u = 0`` exactly while the re-solved
#: wrenches grow as ``h³``; against its own size alone that exact zero could never be confirmed).
ZERO_STIFFNESS = 1e-9


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
    re-solved on both sides). The error is relative to the larger of ``|K_C u|``, the difference's
    size and :data:`ZERO_STIFFNESS` × the largest entry of ``K_C`` (rotation rows and columns scaled
    by ``length``, as :func:`softest_direction` weighs them): a soft direction is checked against its
    own stiffness down to that floor, and an exactly zero one is confirmed to it.
    """
    task = list(task)
    ku = k @ u
    dsc = np.where(np.array(task) < 3, 1.0, 1.0 / length)
    floor = ZERO_STIFFNESS * float(np.abs(dsc[:, None] * k * dsc[None, :]).max()) if k.size else 0.0
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
        den = max(np.linalg.norm(ku), np.linalg.norm(fd), floor, 1e-300)
        best = min(best, float(np.linalg.norm(ku - fd) / den))
        if best <= rtol:
            break
    return best


#: :func:`rigid_reach`: a deflection is beyond the second-order reach along a rigid direction when
#: it asks for more than the reach plus this fraction of the reach's size (and of the deflection's).
REACH_MARGIN = 0.1


def rigid_reach(
    jacobian: np.ndarray,
    rigid: np.ndarray,
    hessian: Callable[[np.ndarray], np.ndarray],
    d: np.ndarray,
) -> tuple[np.ndarray, float, float] | None:
    """A rigid task direction along which the deflection ``d`` is out of reach, to second order.

    At a configuration where the end frame cannot move along the unit task direction ``ρ`` to
    first order (``ρᵀJ = 0``: a row of ``rigid``), a motion ``δx`` moves it along ``ρ`` by
    ``½ δxᵀ H_ρ δx`` (``H_ρ`` the Hessian of ``ρᵀt``, eq. 16 contracted with ``ρ``). With the
    other task components at their requested values (``J δx₀ = (I − RRᵀ) d``, ``δx₀`` the
    minimum-norm solution) and ``H_ρ`` negative definite on the null space ``N`` of ``J``, the
    largest reachable component is ``a = max_z ½ (δx₀ + N z)ᵀ H_ρ (δx₀ + N z)`` (a Schur
    complement; 0 for ``δx₀ = 0``: a straight chain cannot be stretched at all). ``d`` is out of
    reach along ``ρ`` when ``ρᵀd > a + REACH_MARGIN·|a|`` (and by more than rounding), i.e. it asks
    for more than the reach by a margin; both signs of ``ρ`` are tried. A second-order (local) test: the caller
    uses it to explain why no equilibrium was found, not to refuse a deflection up front.

    Args:
        jacobian: (m, n) task rows of ``[J_θ J_q]`` at the configuration.
        rigid: (r, m) orthonormal rigid task directions (``vjm_pin.solver.stiffness.rigid_directions``).
        hessian: ``hessian(ρ)`` → (n, n) Hessian of ``ρᵀt`` over the same columns (eq. 16 with
            the task wrench ``ρ``).
        d: (m,) the requested deflection on the task rows (m, rad).

    Returns:
        ``(ρ, asked, reach)``: the direction (signed so that the reach is a maximum), the component
        asked ``ρᵀd`` and the reach ``a``; None when ``d`` is within reach along every rigid
        direction (or the second order decides nothing: ``H_ρ`` not definite on ``N``).
    """
    j = np.asarray(jacobian, float)
    d = np.asarray(d, float)
    rig = np.asarray(rigid, float).reshape(-1, j.shape[0])
    if not rig.size:
        return None
    m, n = j.shape
    proj = np.eye(m) - rig.T @ rig
    dx0 = np.linalg.lstsq(j, proj @ d, rcond=None)[0] if j.size else np.zeros(n)
    _, sv, vt = np.linalg.svd(j) if j.size else (None, np.zeros(0), np.eye(n))
    rank = int(np.sum(sv > 1e-10 * max(sv.max() if sv.size else 0.0, 1e-300)))
    null = vt[rank:].T
    for rho in rig:
        h = np.asarray(hessian(rho), float)
        h = 0.5 * (h + h.T)
        for sgn in (1.0, -1.0):
            hs = sgn * h
            hn = null.T @ hs @ null
            if hn.size:
                ev = np.linalg.eigvalsh(hn)
                if not ev.max() < -1e-12 * max(np.abs(ev).max(), 1e-300):
                    continue  # not a maximum along ρ: the second order decides nothing
                g = null.T @ hs @ dx0
                reach = 0.5 * float(dx0 @ hs @ dx0 - g @ np.linalg.solve(hn, g))
            else:
                reach = 0.5 * float(dx0 @ hs @ dx0)
            asked = float(sgn * rho @ d)
            if asked > reach + REACH_MARGIN * abs(reach) and asked - reach > 1e-12 * max(np.abs(d).max(), 1e-300):
                return sgn * rho, asked, reach
    return None


__all__ = [
    "FD_STEPS",
    "REACH_MARGIN",
    "rigid_reach",
    "softest_direction",
    "statics_relative",
    "stiffness_fd_error",
    "verdict_agrees",
]
