#!/usr/bin/env python
"""Finite-element peer (OpenSeesPy) for the buckling benchmark of ``vjm_pin``.

The structure is "Model C, S posture" of Pashkevich, Klimchik & Chablat,
*Enhanced stiffness modeling of manipulators with passive joints*, Mech. Mach.
Theory 46 (2011): a straight serial chain of three identical links of length
``L`` along the world x axis, base at the origin, end at ``(3L, 0, 0)``.  The two
actuated joints between the links are rigid, so the chain is one continuous
beam of length ``3L``.

* Links: solid rectangle ``a`` (along world z) × ``b`` (along world y), Young's
  modulus ``E``, shear modulus ``G = E / (2 (1 + nu))``, Saint-Venant torsion
  constant ``J = beta · b · a³`` (Timoshenko & Goodier series, see
  :func:`torsion_constant`).
* Base: passive universal joint -- translations fixed, rotation about x fixed,
  rotations about y and z free.
* End: passive spherical joint whose position is prescribed -- y and z fixed,
  all rotations free, x displacement imposed towards the base (compression).

The column is therefore pinned-pinned for bending about both y and z, and
buckles about the weak axis (world y, lateral deflection in z) at the Euler
load ``P_E = pi² E I_y / (3L)²`` with ``I_y = b a³ / 12``.

The model uses 3-D elastic beam-column elements (6 dof per node, Euler–Bernoulli,
no shear deformation) with a corotational geometric transformation, and traces
the force–deflection curve under displacement control of the end node along
-x.  Buckling is triggered by a small geometric imperfection: an initial bow
``z0(x) = imperfection · 3L · sin(pi x / 3L)`` (the first buckling mode), and
optionally a tiny lateral z load at mid-span proportional to the axial load.

This file is self-contained and does **not** import ``vjm_pin``.  OpenSeesPy is
an optional benchmark dependency (``pip install openseespy``); without it
:func:`load_opensees` raises :class:`RuntimeError`.

Run ``python scripts/opensees_peer.py --elements-per-link 1 2 4 8 16`` (or
``--elements 9 10 11 12``: total counts along the column) for a mesh-convergence
table, ``--json`` for machine-readable output.
"""

from __future__ import annotations

import argparse
import ctypes
import glob
import importlib
import importlib.util
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from types import ModuleType
from typing import Any

import numpy as np

__all__ = [
    "convergence_study",
    "critical_force",
    "euler_load",
    "linear_buckling_force",
    "load_opensees",
    "main",
    "section_properties",
    "torsion_constant",
]

_OPS: ModuleType | None = None

#: Load pattern / time series tag used for the reference end load.
_PATTERN = 1


# --------------------------------------------------------------------------- #
# OpenSeesPy import                                                           #
# --------------------------------------------------------------------------- #
def _preload_bundled_libraries() -> list[str]:
    """Preload the BLAS/LAPACK/gfortran libraries shipped with ``openseespylinux``.

    The Linux wheel of OpenSeesPy bundles ``libblas.so.3``, ``liblapack.so.3``,
    ``libgfortran.so.4`` ... in ``openseespylinux/lib`` but ``opensees.so`` has no
    RPATH to that folder, so the import fails unless the libraries are loaded
    first with ``RTLD_GLOBAL``.  Libraries that fail to load (a dependency not
    loaded yet) are retried until a pass makes no progress.

    Returns
    -------
    list of str
        Paths that could not be loaded (empty when all succeeded, or when the
        package/folder does not exist).
    """
    try:
        spec = importlib.util.find_spec("openseespylinux")  # does not execute it
    except (ImportError, ValueError):
        return []
    if spec is None or not spec.submodule_search_locations:
        return []
    pending: list[str] = []
    for root in spec.submodule_search_locations:
        pending += sorted(glob.glob(os.path.join(root, "lib", "*.so*")))
    while pending:
        failed = []
        for path in pending:
            try:
                ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
            except OSError:
                failed.append(path)
        if len(failed) == len(pending):  # no progress in this pass
            return failed
        pending = failed
    return []


def load_opensees() -> ModuleType:
    """Import and return ``openseespy.opensees`` (cached).

    Returns
    -------
    module
        The ``openseespy.opensees`` module.

    Raises
    ------
    RuntimeError
        If OpenSeesPy is not installed or its shared library cannot be loaded.
    """
    global _OPS
    if _OPS is not None:
        return _OPS
    if importlib.util.find_spec("openseespy") is None:
        raise RuntimeError(
            "OpenSeesPy is not installed; it is an optional benchmark dependency "
            "of vjm_pin: install it with `pip install openseespy`."
        )
    unloadable = _preload_bundled_libraries() if sys.platform.startswith("linux") else []
    try:
        ops = importlib.import_module("openseespy.opensees")
    except Exception as exc:  # openseespy raises a bare RuntimeError on failure
        detail = f"; could not preload: {', '.join(unloadable)}" if unloadable else ""
        raise RuntimeError(
            f"OpenSeesPy is installed but `import openseespy.opensees` failed ({exc}){detail}. "
            "Its bundled BLAS/LAPACK/gfortran libraries (openseespylinux/lib) must be "
            "loadable; reinstall with `pip install --force-reinstall openseespy`."
        ) from exc
    _OPS = ops
    return ops


# --------------------------------------------------------------------------- #
# Section and reference values                                                #
# --------------------------------------------------------------------------- #
def torsion_constant(a: float, b: float, terms: int = 50) -> float:
    """Saint-Venant torsion constant of a solid rectangle.

    ``J = beta · w · t³`` with ``t = min(a, b)``, ``w = max(a, b)`` and the
    series of Timoshenko & Goodier (Theory of Elasticity, §109)::

        beta = 1/3 · [1 - (192/pi⁵)(t/w) Σ_{n=1,3,5,...} tanh(n pi w / (2t)) / n⁵]

    (the usual table: beta = 0.141, 0.229, 0.249, 0.263, 0.312 for w/t = 1, 2,
    2.5, 3, 10).  Roark's fit ``beta = 1/3 (1 - 0.63 r + 0.052 r⁵)``, ``r = t/w``,
    agrees to about 0.2 %.

    Parameters
    ----------
    a, b : float
        Side lengths (m).
    terms : int
        Number of odd terms of the series.

    Returns
    -------
    float
        Torsion constant J (m⁴).
    """
    t, w = (a, b) if a <= b else (b, a)
    n = np.arange(1, 2 * terms, 2, dtype=float)
    s = float(np.sum(np.tanh(n * math.pi * w / (2.0 * t)) / n**5))
    beta = (1.0 - 192.0 / math.pi**5 * (t / w) * s) / 3.0
    return beta * w * t**3


def section_properties(a: float, b: float) -> dict[str, float]:
    """Properties of the ``a`` (along z) × ``b`` (along y) rectangle.

    Parameters
    ----------
    a : float
        Side along the world (and element-local) z axis (m).
    b : float
        Side along the world (and element-local) y axis (m).

    Returns
    -------
    dict
        ``A`` area (m²); ``Iy = b a³/12`` second moment about y (m⁴, weak axis,
        bending with deflection in z); ``Iz = a b³/12`` about z (m⁴);
        ``J`` torsion constant (m⁴).
    """
    return {
        "A": a * b,
        "Iy": b * a**3 / 12.0,
        "Iz": a * b**3 / 12.0,
        "J": torsion_constant(a, b),
    }


def euler_load(E: float = 2.1e11, L: float = 1.0, a: float = 0.02, b: float = 0.05) -> float:
    """Euler load of the pinned-pinned column of length ``3L`` about the weak axis.

    Parameters
    ----------
    E : float
        Young's modulus (Pa).
    L : float
        Length of one link (m); the column is ``3L`` long.
    a, b : float
        Section sides along z and y (m).

    Returns
    -------
    float
        ``pi² E I_y / (3L)²`` with ``I_y = b a³ / 12`` (N).
    """
    return math.pi**2 * E * (b * a**3 / 12.0) / (3.0 * L) ** 2


# --------------------------------------------------------------------------- #
# Model                                                                       #
# --------------------------------------------------------------------------- #
def _build_model(
    ops: ModuleType,
    *,
    E: float,
    nu: float,
    L: float,
    a: float,
    b: float,
    elements_per_link: int,
    imperfection: float,
    lateral_load_ratio: float,
    n_elements: int | None = None,
) -> tuple[int, int]:
    """Create the OpenSees model of the column (wipes the current domain).

    The column has ``n_elements`` equal elements (default ``3 · elements_per_link``):
    the two actuated joints are rigid, so element ends need not fall on them.

    Returns
    -------
    (end_node, mid_node) : tuple of int
        Tags of the end node and of the node nearest to mid-span.
    """
    n_el = 3 * elements_per_link if n_elements is None else int(n_elements)
    length = 3.0 * L
    w0 = imperfection * length
    sec = section_properties(a, b)
    G = E / (2.0 * (1.0 + nu))

    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 6)
    for i in range(n_el + 1):
        x = length * i / n_el
        ops.node(i + 1, x, 0.0, w0 * math.sin(math.pi * x / length))
    end, mid = n_el + 1, n_el // 2 + 1
    # base: universal joint (ux, uy, uz, rx fixed; ry, rz free)
    ops.fix(1, 1, 1, 1, 1, 0, 0)
    # end: spherical joint on a prescribed point (uy, uz fixed; ux driven; rotations free)
    ops.fix(end, 0, 1, 1, 0, 0, 0)
    # local x along the chain, local z (vecxz) along world z => local y = world y
    ops.geomTransf("Corotational", 1, 0.0, 0.0, 1.0)
    for e in range(n_el):
        ops.element(
            "elasticBeamColumn", e + 1, e + 1, e + 2,
            sec["A"], E, G, sec["J"], sec["Iy"], sec["Iz"], 1,
        )
    ops.timeSeries("Linear", _PATTERN)
    ops.pattern("Plain", _PATTERN, _PATTERN)
    ops.load(end, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # reference load: 1 N compression
    if lateral_load_ratio != 0.0:
        ops.load(mid, 0.0, 0.0, lateral_load_ratio, 0.0, 0.0, 0.0)
    return end, mid


def _static_analysis(ops: ModuleType, system: str, tol: float, max_iter: int) -> None:
    ops.constraints("Plain")
    ops.numberer("RCM" if system != "FullGeneral" else "Plain")
    ops.system(system)
    ops.test("NormDispIncr", tol, max_iter)
    ops.algorithm("Newton")


# --------------------------------------------------------------------------- #
# Nonlinear trace                                                             #
# --------------------------------------------------------------------------- #
def critical_force(
    E: float = 2.1e11,
    nu: float = 0.3,
    L: float = 1.0,
    a: float = 0.02,
    b: float = 0.05,
    elements_per_link: int = 8,
    max_deflection: float | None = None,
    steps: int = 200,
    imperfection: float = 1e-7,
    lateral_load_ratio: float = 0.0,
    knee_fraction: float = 0.01,
    max_cuts: int = 12,
    tol: float | None = None,
    linearized: bool = False,
    quiet: bool = True,
    n_elements: int | None = None,
) -> dict[str, Any]:
    """Trace the compression of the column and return its critical (buckling) force.

    The end node is driven along -x by a ``DisplacementControl`` integrator in
    ``steps`` equal increments up to ``max_deflection``; a step whose Newton
    iterations fail is retried with Newton + line search, then cut in half
    (repeatedly, up to ``max_cuts`` times), and the step size grows back after
    successes.  The force is the load factor of the 1 N reference end load,
    i.e. the compressive reaction along x.

    The linear system is solved by Cholesky (``BandSPD``), which fails when the
    tangent stiffness is not positive definite.  That makes the step-cutting
    also a stability check: with a tiny imperfection a large step can jump past
    the bifurcation onto the unstable, nearly straight equilibrium path (force
    still rising along ``EA / 3L``); such a step is rejected and cut until
    Newton follows the stable, buckled path.

    The curve is bilinear with a rounded knee: a stiff pre-buckling branch
    (axial stiffness ``k0 ≈ EA / 3L``) and an almost flat post-buckling plateau
    at the critical load.  ``critical_force`` is the force at the first traced
    point after which the tangent (secant of the step) stiffness has dropped
    below ``knee_fraction · k0``; since the curve is concave that point lies on
    the plateau, where the tangent is below ``knee_fraction · k0``, so the
    force there is below the bifurcation load of the perfect column by at most
    about ``(5 · imperfection² · (EA·3L/P_cr) · knee_fraction)^(1/3)`` (relative;
    ~0.02 % with the defaults, ~0.1 % with ``imperfection=1e-6``), whatever the
    step size.  ``critical_deflection`` is the end shortening at the knee
    of the bilinear idealisation, ``critical_force / k0``.

    Parameters
    ----------
    E : float
        Young's modulus (Pa).
    nu : float
        Poisson ratio (-); ``G = E / (2 (1 + nu))``.
    L : float
        Length of each of the three links (m).
    a : float
        Section side along world z (m); the paper uses ``0.02 L``.
    b : float
        Section side along world y (m); the paper uses ``0.05 L``.
    elements_per_link : int
        Beam elements per link (the model has ``3 · elements_per_link``).
    max_deflection : float, optional
        Final end shortening (m).  Default: 8 × the axial shortening of the
        straight column at the Euler load, ``8 · P_E · 3L / (E A)``, so the trace
        goes well onto the post-buckling plateau.
    steps : int
        Number of nominal displacement increments.
    imperfection : float
        Amplitude of the initial half-sine bow in z, as a fraction of the
        column length ``3L`` (-).  Must be non-zero unless ``lateral_load_ratio``
        is, otherwise the perfect column never leaves the straight path.
    lateral_load_ratio : float
        Optional lateral z force at the mid-span node, as a fraction of the
        axial force (-); grows with it.  Default 0 (imperfection only).
    knee_fraction : float
        Tangent stiffness ratio (to the initial stiffness) that marks the knee.
    max_cuts : int
        Maximum number of successive halvings of a failing step.
    tol : float, optional
        Tolerance of the ``NormDispIncr`` convergence test (m).
        Default ``1e-12 · L``.
    linearized : bool
        Also compute :func:`linear_buckling_force` for the same mesh (adds the
        keys ``linear_buckling_force`` and ``linear_relative_error``).
    quiet : bool
        Send OpenSees messages (warnings of failed, then cut, steps) to the
        null device instead of stderr.  OpenSees' log is process-wide, so this
        stays in force after the call.
    n_elements : int, optional
        Total number of equal elements along the column, overriding
        ``3 · elements_per_link`` (any count >= 1: the actuated joints are
        rigid, so element ends need not fall on them).

    Returns
    -------
    dict
        ``critical_force`` (N; NaN if no knee was traced), ``critical_deflection``
        (m), ``buckled`` (bool), ``euler_load`` (N), ``relative_error``
        (``critical_force / euler_load - 1``), ``deflection`` (m, end
        shortening, positive in compression, starts at 0), ``force`` (N,
        compressive), ``lateral_z`` and ``lateral_y`` (m, largest nodal
        deflection in z and y), ``initial_stiffness`` (N/m), ``knee_index``
        (index into the arrays, -1 if none), ``completed`` (bool, the trace
        reached ``max_deflection``), ``n_steps`` (converged steps), ``n_cuts``
        (step halvings), ``wall_time`` (s, OpenSees model build and analysis
        only), ``n_elements``, ``n_nodes``, ``elements_per_link`` (None when
        ``n_elements`` is not a multiple of 3), the input
        parameters, and ``base_reaction_x`` (N, check: equals the last force).

    Raises
    ------
    RuntimeError
        If OpenSeesPy cannot be imported.
    ValueError
        On non-physical input.
    """
    if min(E, L, a, b) <= 0.0 or not (-1.0 < nu < 0.5):
        raise ValueError("need E, L, a, b > 0 and -1 < nu < 0.5")
    if elements_per_link < 1 or steps < 1 or (n_elements is not None and n_elements < 1):
        raise ValueError("need elements_per_link >= 1, n_elements >= 1 and steps >= 1")
    if not 0.0 < knee_fraction < 1.0:
        raise ValueError("need 0 < knee_fraction < 1")
    if imperfection == 0.0 and lateral_load_ratio == 0.0:
        raise ValueError("a perfect column never buckles in the trace: give a non-zero "
                         "imperfection or lateral_load_ratio")
    ops = load_opensees()

    sec = section_properties(a, b)
    p_euler = euler_load(E, L, a, b)
    if max_deflection is None:
        max_deflection = 8.0 * p_euler * 3.0 * L / (E * sec["A"])
    if max_deflection <= 0.0:
        raise ValueError("max_deflection must be positive")
    if tol is None:
        tol = 1e-12 * L
    n_el = 3 * elements_per_link if n_elements is None else int(n_elements)

    t0 = time.perf_counter()
    if quiet:
        ops.logFile(os.devnull, "-noEcho")
    end, _ = _build_model(
        ops, E=E, nu=nu, L=L, a=a, b=b, elements_per_link=elements_per_link,
        imperfection=imperfection, lateral_load_ratio=lateral_load_ratio, n_elements=n_el,
    )
    _static_analysis(ops, "BandSPD", tol, 50)
    du_nominal = max_deflection / steps
    ops.integrator("DisplacementControl", end, 1, -du_nominal)
    ops.analysis("Static")

    nodes = ops.getNodeTags()

    def record() -> tuple[float, float, float, float]:
        defl = -ops.nodeDisp(end, 1)
        force = ops.getLoadFactor(_PATTERN)
        uy = max(abs(ops.nodeDisp(n, 2)) for n in nodes)
        uz = max(abs(ops.nodeDisp(n, 3)) for n in nodes)
        return defl, force, uy, uz

    def try_step(du: float) -> bool:
        for algorithm in (("Newton",), ("NewtonLineSearch", "-type", "Bisection")):
            ops.algorithm(*algorithm)
            ops.integrator("DisplacementControl", end, 1, -du)
            # a failed static step reverts the domain to the last commit itself
            if ops.analyze(1) == 0:
                if algorithm[0] != "Newton":
                    ops.algorithm("Newton")
                return True
        ops.algorithm("Newton")
        return False

    history = [(0.0, 0.0, 0.0, 0.0)]
    du = du_nominal
    shortening = 0.0
    n_cuts = 0
    cuts_in_a_row = 0
    completed = True
    while shortening < max_deflection * (1.0 - 1e-9):
        step = min(du, max_deflection - shortening)
        if try_step(step):
            history.append(record())
            shortening = history[-1][0]
            cuts_in_a_row = 0
            du = min(2.0 * du, du_nominal)
        else:
            n_cuts += 1
            cuts_in_a_row += 1
            if cuts_in_a_row > max_cuts:
                completed = False
                break
            du = 0.5 * step
    ops.reactions()
    base_reaction = float(ops.nodeReaction(1, 1))
    wall_time = time.perf_counter() - t0
    ops.wipe()

    arr = np.asarray(history, dtype=float)
    deflection, force, lat_y, lat_z = arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3]
    secant = np.diff(force) / np.maximum(np.diff(deflection), np.finfo(float).tiny)
    k0 = float(secant[0]) if secant.size else float("nan")
    knee = np.flatnonzero(secant < knee_fraction * k0) if secant.size else np.array([], int)
    if knee.size:
        knee_index = int(knee[0]) + 1
        p_cr = float(force[knee_index])
        d_cr = p_cr / k0
    else:
        knee_index, p_cr, d_cr = -1, float("nan"), float("nan")

    result: dict[str, Any] = {
        "critical_force": p_cr,
        "critical_deflection": d_cr,
        "buckled": knee_index >= 0,
        "euler_load": p_euler,
        "relative_error": p_cr / p_euler - 1.0,
        "deflection": deflection,
        "force": force,
        "lateral_z": lat_z,
        "lateral_y": lat_y,
        "initial_stiffness": k0,
        "knee_index": knee_index,
        "completed": completed,
        "n_steps": len(history) - 1,
        "n_cuts": n_cuts,
        "wall_time": wall_time,
        "n_elements": n_el,
        "n_nodes": n_el + 1,
        "elements_per_link": n_el // 3 if n_el % 3 == 0 else None,
        "base_reaction_x": base_reaction,
        "E": E, "nu": nu, "L": L, "a": a, "b": b,
        "max_deflection": max_deflection,
        "imperfection": imperfection,
        "lateral_load_ratio": lateral_load_ratio,
        "knee_fraction": knee_fraction,
    }
    if linearized:
        lin = linear_buckling_force(E=E, nu=nu, L=L, a=a, b=b, elements_per_link=elements_per_link,
                                    quiet=quiet, n_elements=n_el)
        result["linear_buckling_force"] = lin["linear_buckling_force"]
        result["linear_relative_error"] = lin["relative_error"]
        result["linear_wall_time"] = lin["wall_time"]
    return result


# --------------------------------------------------------------------------- #
# Linearized buckling                                                         #
# --------------------------------------------------------------------------- #
def linear_buckling_force(
    E: float = 2.1e11,
    nu: float = 0.3,
    L: float = 1.0,
    a: float = 0.02,
    b: float = 0.05,
    elements_per_link: int = 8,
    reference_load: float | None = None,
    quiet: bool = True,
    n_elements: int | None = None,
) -> dict[str, Any]:
    """Linearized (eigenvalue) buckling load of the perfect column.

    OpenSees has no buckling eigen solver, so the tangent stiffness is read
    with ``printA`` (``FullGeneral`` system) at zero load, ``K0``, and after a
    load-controlled step to the compressive end load ``P_ref``, ``K_T``.  With
    the corotational transformation ``K_T = K0 + P_ref · K_G`` (the straight
    column stays straight), and the critical load is the smallest positive
    ``P`` with ``det(K0 + P K_G) = 0``, i.e. ``1 / max eig(-K0⁻¹ K_G)``.

    Parameters
    ----------
    E, nu, L, a, b, elements_per_link, n_elements
        As in :func:`critical_force` (Pa, -, m, m, m, -, -).
    reference_load : float, optional
        ``P_ref`` (N).  Default ``E I_y / (3L)²`` (about 10 % of the Euler load).
    quiet : bool
        Send OpenSees messages to the null device.

    Returns
    -------
    dict
        ``linear_buckling_force`` (N), ``euler_load`` (N), ``relative_error``
        (-), ``wall_time`` (s, OpenSees part only), ``n_elements``.
    """
    ops = load_opensees()
    sec = section_properties(a, b)
    if reference_load is None:
        reference_load = E * sec["Iy"] / (3.0 * L) ** 2
    t0 = time.perf_counter()
    if quiet:
        ops.logFile(os.devnull, "-noEcho")
    n_el = 3 * elements_per_link if n_elements is None else int(n_elements)
    if n_el < 1:
        raise ValueError("need at least one element")
    _build_model(ops, E=E, nu=nu, L=L, a=a, b=b, elements_per_link=elements_per_link,
                 imperfection=0.0, lateral_load_ratio=0.0, n_elements=n_el)
    _static_analysis(ops, "FullGeneral", 1e-12 * L, 20)
    ops.integrator("LoadControl", 0.0)
    ops.analysis("Static")

    def tangent() -> np.ndarray:
        # a zero-increment step forms the tangent at the committed state
        ops.integrator("LoadControl", 0.0)
        if ops.analyze(1) != 0:
            raise RuntimeError("OpenSees: zero-load step failed")
        k = np.asarray(ops.printA("-ret"), dtype=float)
        n = math.isqrt(k.size)
        return k.reshape(n, n)

    k0 = tangent()
    ops.integrator("LoadControl", reference_load)
    if ops.analyze(1) != 0:
        raise RuntimeError("OpenSees: reference load step failed")
    kt = tangent()
    wall_time = time.perf_counter() - t0
    ops.wipe()

    kg = (kt - k0) / reference_load
    mu = np.linalg.eigvals(np.linalg.solve(k0, -kg))
    mu = mu[np.abs(mu.imag) <= 1e-9 * np.max(np.abs(mu))].real
    mu_max = float(np.max(mu)) if mu.size else 0.0
    p_lin = 1.0 / mu_max if mu_max > 0.0 else float("inf")
    p_euler = euler_load(E, L, a, b)
    return {
        "linear_buckling_force": p_lin,
        "euler_load": p_euler,
        "relative_error": p_lin / p_euler - 1.0,
        "wall_time": wall_time,
        "n_elements": n_el,
    }


# --------------------------------------------------------------------------- #
# Mesh study and command line                                                 #
# --------------------------------------------------------------------------- #
def convergence_study(
    elements_per_link: Sequence[int] = (1, 2, 4, 8, 16),
    n_elements: Sequence[int] | None = None,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """Run :func:`critical_force` for several meshes.

    Parameters
    ----------
    elements_per_link : sequence of int
        Meshes to run (elements per link).
    n_elements : sequence of int, optional
        Meshes to run as total element counts along the column (any count);
        replaces ``elements_per_link`` when given.
    **kwargs
        Passed to :func:`critical_force`.

    Returns
    -------
    list of dict
        One result per mesh, in the given order.
    """
    if n_elements is not None:
        return [critical_force(n_elements=int(n), **kwargs) for n in n_elements]
    return [critical_force(elements_per_link=int(n), **kwargs) for n in elements_per_link]


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: critical force vs mesh, as a table or JSON."""
    p = argparse.ArgumentParser(
        description="OpenSeesPy peer: buckling of Model C (S posture) of "
        "Pashkevich, Klimchik & Chablat (2011) -- three rigidly connected links "
        "between a universal joint and a spherical joint, compressed along x."
    )
    p.add_argument("--elements-per-link", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    p.add_argument("--elements", type=int, nargs="+", default=None,
                   help="total element counts along the column (any count; replaces "
                        "--elements-per-link)")
    p.add_argument("--E", type=float, default=2.1e11, help="Young's modulus (Pa)")
    p.add_argument("--nu", type=float, default=0.3, help="Poisson ratio")
    p.add_argument("--L", type=float, default=1.0, help="link length (m)")
    p.add_argument("--a", type=float, default=None, help="section side along z (m); default 0.02 L")
    p.add_argument("--b", type=float, default=None, help="section side along y (m); default 0.05 L")
    p.add_argument("--max-deflection", type=float, default=None, help="final end shortening (m)")
    p.add_argument("--steps", type=int, default=200, help="displacement increments")
    p.add_argument("--imperfection", type=float, default=1e-7,
                   help="initial bow amplitude / (3L)")
    p.add_argument("--lateral-load-ratio", type=float, default=0.0,
                   help="mid-span z load / axial load")
    p.add_argument("--knee-fraction", type=float, default=0.01,
                   help="tangent/initial stiffness ratio marking the knee")
    p.add_argument("--linearized", action="store_true",
                   help="also compute the linearized (eigenvalue) buckling load")
    p.add_argument("--curves", action="store_true", help="include the traced curves in --json")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = p.parse_args(argv)

    a = 0.02 * args.L if args.a is None else args.a
    b = 0.05 * args.L if args.b is None else args.b
    try:
        results = convergence_study(
            args.elements_per_link, n_elements=args.elements, E=args.E, nu=args.nu, L=args.L, a=a, b=b,
            max_deflection=args.max_deflection, steps=args.steps,
            imperfection=args.imperfection, lateral_load_ratio=args.lateral_load_ratio,
            knee_fraction=args.knee_fraction, linearized=args.linearized,
        )
    except (RuntimeError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    if args.json:
        curve_keys = {"deflection", "force", "lateral_z", "lateral_y"}
        out = [
            {k: v for k, v in r.items() if args.curves or k not in curve_keys} for r in results
        ]
        print(json.dumps(_jsonable(out), indent=2))
        return 0

    r0 = results[0]
    print(f"Model C, S posture: 3 links of L = {r0['L']:g} m, a x b = {a:g} x {b:g} m, "
          f"E = {r0['E']:.4g} Pa, nu = {r0['nu']:g}")
    print(f"Euler load pi^2 E Iy / (3L)^2 = {r0['euler_load']:.6g} N; "
          f"imperfection = {r0['imperfection']:g} x 3L; "
          f"max deflection = {r0['max_deflection']:.4g} m; steps = {args.steps}")
    head = (f"{'el/link':>7} {'n_el':>5} {'P_cr (N)':>12} {'err':>9} {'d_cr (m)':>11} "
            f"{'steps':>6} {'cuts':>5} {'time (s)':>9}")
    if args.linearized:
        head += f" {'P_lin (N)':>12} {'err_lin':>9}"
    print(head)
    for r in results:
        epl = r["elements_per_link"]
        line = (f"{'-' if epl is None else epl:>7} {r['n_elements']:>5d} {r['critical_force']:>12.6g} "
                f"{100 * r['relative_error']:>8.3f}% {r['critical_deflection']:>11.4e} "
                f"{r['n_steps']:>6d} {r['n_cuts']:>5d} {r['wall_time']:>9.3f}")
        if args.linearized:
            line += (f" {r['linear_buckling_force']:>12.6g}"
                     f" {100 * r['linear_relative_error']:>8.3f}%")
        if not r["buckled"]:
            line += "  (no knee traced)"
        elif not r["completed"]:
            line += "  (trace stopped early)"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
