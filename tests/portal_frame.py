"""Closed form of the planar portal frame (issue 13 acceptance), for the tests only.

Two rigid columns of height ``h`` hinged to the ground, a rigid beam on top, rotational
springs ``k`` (N·m/rad) at the four corners (``models/urdf/portal-frame.urdf``). Loads: a
horizontal dead force ``H`` (N, +x) at the top and a vertical dead load ``P`` (N, downward)
on each column top. One degree of freedom, the sway ``φ`` (rad): both columns turn by ``φ``
about +y, the beam translates by ``(h sin φ, 0, −h(1 − cos φ))`` without turning, the corner
springs turn by ``(φ, −φ, φ, −φ)`` (joints ``corner_bl, corner_tl, corner_tr, corner_br``).

Total potential (J)::

    V(φ) = 2kφ² − H h sin φ − 2P h (1 − cos φ)

Equilibrium ``V′(φ) = 0``; under force control it is stable iff ``V″(φ) > 0``; at ``φ = 0`` this
fails from ``P = 2k/h`` per column (the sway buckling load). With the top's horizontal
deflection ``Δ = h sin φ`` (m) as the task coordinate, the force-deflection curve, the
stiffness ``K_C = dH/dΔ`` (N/m) and its derivative ``dK_C/dΔ`` (N/m²) follow below.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

CORNER_SIGNS = np.array([1.0, -1.0, 1.0, -1.0])


def potential(phi: float, k: float, h: float, H: float = 0.0, P: float = 0.0) -> float:
    """``V(φ)`` (J)."""
    return 2 * k * phi**2 - H * h * math.sin(phi) - 2 * P * h * (1 - math.cos(phi))


def dpotential(phi: float, k: float, h: float, H: float = 0.0, P: float = 0.0) -> float:
    """``V′(φ)`` (N·m)."""
    return 4 * k * phi - H * h * math.cos(phi) - 2 * P * h * math.sin(phi)


def d2potential(phi: float, k: float, h: float, H: float = 0.0, P: float = 0.0) -> float:
    """``V″(φ)`` (N·m/rad): positive where the equilibrium is stable under force control."""
    return 4 * k + H * h * math.sin(phi) - 2 * P * h * math.cos(phi)


def critical_load(k: float, h: float) -> float:
    """Sway buckling load per column (N): ``P = 2k/h``."""
    return 2 * k / h


def deflection(phi: float, h: float) -> float:
    """Horizontal deflection of the top (m): ``Δ = h sin φ``."""
    return h * math.sin(phi)


def force(phi: float, k: float, h: float, P: float = 0.0) -> float:
    """Horizontal force (N) in equilibrium at sway ``φ``: ``H = (4kφ − 2Ph sin φ)/(h cos φ)``."""
    return (4 * k * phi - 2 * P * h * math.sin(phi)) / (h * math.cos(phi))


def stiffness(phi: float, k: float, h: float, P: float = 0.0) -> float:
    """``K_C = dH/dΔ = (4k cos φ + 4kφ sin φ − 2Ph)/(h² cos³ φ)`` (N/m)."""
    return (4 * k * math.cos(phi) + 4 * k * phi * math.sin(phi) - 2 * P * h) / (
        h**2 * math.cos(phi) ** 3
    )


def stiffness_derivative(phi: float, k: float, h: float, P: float = 0.0) -> float:
    """``dK_C/dΔ = (4kφ cos² φ + 3N sin φ)/(h³ cos⁵ φ)`` with ``N = 4k cos φ + 4kφ sin φ − 2Ph`` (N/m²)."""
    n = 4 * k * math.cos(phi) + 4 * k * phi * math.sin(phi) - 2 * P * h
    return (4 * k * phi * math.cos(phi) ** 2 + 3 * n * math.sin(phi)) / (h**3 * math.cos(phi) ** 5)


def sway(H: float, k: float, h: float, P: float = 0.0) -> float:
    """The equilibrium sway (rad) under force control on the branch from ``φ = 0``: the root of
    ``V′`` nearest zero on the side of ``H`` (the first sign change of ``V′`` walking away from
    zero). Raises ValueError if there is none before ±π/2."""
    if H == 0.0:
        return 0.0
    s = 1.0 if H > 0 else -1.0
    grid = s * np.linspace(0.0, math.pi / 2 - 1e-6, 2001)
    vals = [dpotential(p, k, h, H, P) for p in grid]
    for i in range(len(grid) - 1):
        if vals[i] == 0.0:
            return float(grid[i])
        if vals[i] * vals[i + 1] < 0:
            return float(
                brentq(dpotential, grid[i], grid[i + 1], args=(k, h, H, P), xtol=1e-15, rtol=1e-15)
            )
    raise ValueError(f"no equilibrium on the sway branch for H = {H} N, P = {P} N")


def configuration(vm, phi: float) -> np.ndarray:
    """The model's configuration (nq,) at sway ``φ``: corners ``(φ, −φ, φ, −φ)``."""
    x = vm.reference.copy()
    for name, sign in zip(("corner_bl", "corner_tl", "corner_tr", "corner_br"), CORNER_SIGNS):
        x[vm.joint_index(name)] += sign * phi
    return x


def sway_direction(vm) -> np.ndarray:
    """(nv,) ``dx/dφ``: the sway mode (a constant vector: the sway is linear in the joints)."""
    return configuration(vm, 1.0) - configuration(vm, 0.0)
