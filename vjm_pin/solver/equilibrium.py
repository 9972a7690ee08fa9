"""Loaded static equilibrium (paper §4.1, eq. 5–11).

For a prescribed end location ``t`` the unknowns are the wrench ``F`` and the
configuration ``(q, θ)`` that satisfy eq. (5)::

    J_θᵀ F = K_θ (θ − θ₀),    J_qᵀ F = 0,    t = g(q, θ).

This is the stationarity (KKT) system of "minimise the spring energy
E = ½(θ−θ₀)ᵀK_θ(θ−θ₀) subject to g(q, θ) = t", with ``F`` the Lagrange multiplier; a
stable equilibrium is a constrained energy minimum (eq. 23).

Two iterations are offered:

``"fixed-point"`` — the paper's scheme (eq. 9–10), written in increments so that
    orientation errors use ``log3``: ``[[J_θ K_θ⁻¹ J_θᵀ, J_q], [J_qᵀ, 0]] [F; Δq] =
    [e + J_θ(θ − θ₀); 0]``, ``θ⁺ = θ₀ + K_θ⁻¹ J_θᵀ F``. It ignores the Hessians, converges
    linearly far from buckling, stalls next to a bifurcation and is singular for a straight
    chain of rigid links.
``"newton"`` (default) — Newton's method on eq. (5); its Jacobian is the matrix of
    eq. (28). When a stable branch is followed the reduced Hessian is shifted to be
    positive definite (so the step descends the energy) and a step is only accepted if it
    decreases the ℓ₁ merit ``E + ρ‖t − g‖₁`` or, when it is an unmodified Newton step,
    the residual of eq. (5); an energy-increasing step is never taken.

    Every Newton attempt first tries the plain local iteration (:meth:`EquilibriumSolver._fast_newton`):
    unmodified Newton steps of eq. (28) from the start, without restoration, taken only
    while the reduced Hessian is positive definite (stable branch followed) and the step
    is within the step limit, and kept only if the residual of eq. (5) at least halves at
    every step and the converged equilibrium is stable. These are exactly the steps the
    safeguarded iteration accepts by its residual test; when any condition fails the
    attempt restarts from the same start on the safeguarded path. A warm start from a
    neighbouring equilibrium (curve tracing) usually converges in one or two such steps.

Both are wrapped in continuation (``t_i = α_i t + (1−α_i) t₀``, eq. after 10) and
perturbed restarts (small seeded random noise on ``(q, θ)``, §4.1) when an iteration
stalls; an unstable equilibrium is left along its unstable eigenvectors first
(:meth:`EquilibriumSolver._escape`). The result says which path was used. Inside an escape
attempt the safeguarded iteration hands over to at most :data:`HANDOFF_STEPS` unmodified Newton
steps from each accepted iterate (:meth:`EquilibriumSolver._relaxed_local`: positive definite
reduced Hessian, step limit, no residual-halving test, which a soft mode next to a bifurcation
fails), kept when they reach a stable equilibrium of no higher energy; the same equilibrium, in
fewer safeguarded iterations and restorations.

A warm start from the equilibrium the solver found last (a curve's next point, ``x0`` = that
result's ``x``) takes a lean path (:meth:`EquilibriumSolver._solve_lean`): the same checks,
iterations and results bit for bit, without the general set-up (the kernel context is kept
between solves, the compiled kernel is called directly with its buffers, the result is built
once); for models of order ≤ :data:`~vjm_pin.solver.stability.SCIPY_LAPACK_MAX_N` it also runs
without the BLAS thread limit, as OpenBLAS uses one thread at these orders. With the compiled
kernel on a chain of 1-DoF joints the plain local iteration runs as one compiled call, its end
placement, frame Jacobian and ``log3`` by :mod:`vjm_pin.kinematics.compiled_chain` (Pinocchio's to
rounding), and so does each least-energy restoration (:meth:`EquilibriumSolver._restore`); the numpy
twin keeps Pinocchio.

Every iterate's coordinates smaller than :data:`~vjm_pin.kinematics.chain.FLUSH_BELOW` (1e-150) are
set to exactly zero (:func:`~vjm_pin.kinematics.chain.flush_tiny`): on a straight column they would
otherwise converge to subnormal floats, which slow Pinocchio, without changing any result. The
public calls run with one BLAS thread (:mod:`vjm_pin.solver.threads`; the lean warm-start path of
a small model excepted, see below).

Mixed control (:meth:`EquilibriumSolver.solve_mixed`): each task component is *held*
(deflection prescribed) or *loaded* (dead force/moment prescribed). The equilibrium is a
stationary point of the total potential ``½(θ−θ₀)ᵀK_θ(θ−θ₀) − w_Lᵀ t_L`` subject to the held
components, the multipliers being the reactions; Newton's method with the matrix
``[[K − H(w), −J_Hᵀ], [J_H, 0]]`` (``w`` the total end wrench). Every component held is the
problem above; every component loaded (:meth:`EquilibriumSolver.solve_wrench`) replaces the
outer loop of eq. (11), which needed a regular K_C. Results carry two verdicts: ``stable``
for the control as run, ``stable_end_held`` for eq. (23); :meth:`EquilibriumSolver.verify`
checks a result (eq. 5 residual per unit, both verdicts, K_C against re-solved equilibria).

Public API (stable; names as in the docstrings below)::

    solver = EquilibriumSolver(vm, tol=1e-10, max_iter=60, restarts=8, seed=0)
    solver.solve(deflection, *, target=None, x0=None, wrench0=None, raise_on_failure=True,
                 fast_fail=False)                                  # all held
    solver.solve_wrench(wrench, *, x0=None, raise_on_failure=True, fast_fail=False)  # all loaded
    solver.solve_mixed(deflection=None, wrench=None, *, held, x0=None, wrench0=None,
                       raise_on_failure=True, fast_fail=False)     # held: names or 0..5
    solver.verify(result, *, method="eq30", rtol=1e-3)            # checked result or error
    solver.components(spec) -> tuple of task component indices
    EquilibriumResult: x, q, theta, wrench (6,), deflection (6,), position, rotation,
        converged, iterations, residuals, energy, path, stability, held, stability_end_held,
        warnings, checks; properties stable, stable_end_held.
"""

from __future__ import annotations

import copy
import functools
import inspect
import math
from dataclasses import MISSING as _MISSING
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import (
    EquilibriumCheckError,
    InputError,
    ModelError,
    NoEquilibrium,
    SingularStiffness,
)
from vjm_pin.kinematics import chain as _chain
from vjm_pin.kinematics.chain import (
    Kinematics,
    KinematicState,
    contract_hessian,
    deflection,
    displace,
    flush_tiny,
    pose_error,
)
from vjm_pin.kinematics.screw import psi_hessian_screw
from vjm_pin.model.format import VjmModel
from vjm_pin.model.task import task_vector
from vjm_pin.solver import kernel as _kernel  # numpy only at import; numba when first needed
from vjm_pin.solver.blocks import (
    Blocks,
    LazyBlocks,
    evaluate_blocks,
    full_wrench,
    remember_blocks,
    remember_lazy,
)
from vjm_pin.solver.lapack import lapack as _lapack
from vjm_pin.solver.lapack import solve_triangular as _solve_triangular
from vjm_pin.solver.stability import (
    RANK_TOL,
    SCIPY_LAPACK_MAX_N,
    STABILITY_TOL,
    DeferredStability,
    SpectrumLater,
    StabilityResult,
    check_stability,
    check_stability_held,
    null_space,
    reduced_matrix,
    spectral_norm,
)
from vjm_pin.solver.stiffness import stiffness_from_blocks
from vjm_pin.solver.threads import one_blas_thread, single_blas_thread

METHODS = ("newton", "fixed-point")
#: A converged iterate is polished by up to this many further Newton steps while the step
#: (the error estimate, relative: rad, or m/L_c) exceeds :data:`POLISH_STEP`.
POLISH_ITERATIONS = 3
POLISH_STEP = 1e-12
#: Margin (relative to max|K_θ|) below which the reduced Hessian of a Newton step is
#: shifted to be positive definite when a stable branch is followed; of the order of the
#: stability threshold (:data:`~vjm_pin.solver.stability.STABILITY_TOL`) so that a stable
#: equilibrium next to a bifurcation (small positive eigenvalue) keeps quadratic Newton steps.
SHIFT_TOL = 1e-10
#: Warning of a deflection-driven result when only an unstable equilibrium was found.
UNSTABLE_HELD_NOTE = (
    "only an unstable equilibrium was found for this deflection (eq. 23 fails): restarts and "
    "escapes along its unstable modes found no stable one"
)
#: Rotation-target iterations of a partial-rotation task (see ``EquilibriumSolver.solve``) and
#: their tolerance on the held rotation-vector components (rad).
ROTATION_TARGET_ITER = 200
ROTATION_TARGET_TOL = 1e-12
#: A held rotation component missed by more than this (rad) after the corrections is a failure.
ROTATION_TARGET_FAIL = 1e-10
#: Unstable modes pushed along, and the push amplitudes, when a deflection-driven solve
#: converged to an unstable equilibrium (:meth:`EquilibriumSolver._escape`).
ESCAPE_MODES = 2
ESCAPE_AMPLITUDES = (1e-3, 1e-2, 1e-1)
#: Steps of the escape's hand-off to the local iteration (:meth:`EquilibriumSolver._relaxed_local`):
#: a short budget, so that it takes over only next to the equilibrium.
HANDOFF_STEPS = 4
#: Iterations of the plain local Newton attempt of a load-controlled solve, and the budget of
#: its energy-descent attempt in units of ``max_iter``.
LOCAL_MAX_ITER = 12
DESCENT_ITER_FACTOR = 8
#: Tolerances of :meth:`EquilibriumSolver.verify`: K_C against re-solved equilibria
#: (relative), and the static residual of eq. (5) per unit (relative to each row's scale).
VERIFY_RTOL = 1e-3
VERIFY_STATICS = 1e-8
#: Names of the six task components, in order.
COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
#: Private switch (False: the safeguarded line search halves the step, as before issue 14's third
#: round, instead of interpolating (:func:`_backtrack`); for the tests and the benchmark).
_safeguard_shortcuts = True
#: Private switch of the fused Newton kernel (:mod:`vjm_pin.solver.kernel`): False runs the
#: unfused local iteration (``_fast_factor`` / ``_fast_step``; for the tests and the benchmark).
_fused_enabled = True
#: Private switch of the curve corrector (:meth:`EquilibriumSolver._corrector_context`): True lets its
#: compiled kernel certify a stable verdict without the eigenvalues of eq. (23), computed when first
#: read (:class:`~vjm_pin.solver.stability.SpectrumLater`); False computes them at every point (the
#: same numbers; for the tests and the benchmark).
_corrector_defer = True
#: Private switch of the compiled kinematics of the compiled kernel (:mod:`vjm_pin.kinematics.compiled_chain`,
#: :meth:`EquilibriumSolver._compiled_chain`): False keeps Pinocchio's (for the tests and the benchmark).
_compiled_kinematics = True
#: Placeholder factorisation arrays of a fused-kernel call that computes its own (one array type
#: for the compiled kernel), then an empty Jacobian for a call that reuses a cached one.
_KERNEL_DUMMY = (np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros(0), np.zeros(0), np.zeros(0),
                 np.zeros((0, 0)), np.zeros(0), np.zeros((6, 0)))
_NO_KEY = np.frombuffer(b"")  # no kept equilibrium (a read-only empty configuration; _fused_looped)
_new_object = object.__new__
#: ``EquilibriumSolver._corrector``'s ``flushed`` for a flushed and fresh start (see there).
FRESH = 2
_deferred_result = None  # vjm_pin.solver.deferred_result.DeferredResult once imported (_load_deferred)


def _load_deferred():
    """:class:`vjm_pin.solver.deferred_result.DeferredResult` (that module imports this one: bound
    when first needed, not at every result)."""
    global _deferred_result
    from vjm_pin.solver.deferred_result import DeferredResult

    _deferred_result = DeferredResult
    return DeferredResult


class _Placement:
    """The end rotation of a compiled kinematics evaluation where :meth:`_fused_iterations` reads
    ``data.oMf[fid].rotation``."""

    __slots__ = ("rotation",)

    def __init__(self, rotation):
        self.rotation = rotation


@dataclass(frozen=True)
class EquilibriumResult:
    """A loaded equilibrium (eq. 5 under the control of :meth:`EquilibriumSolver.solve_mixed`).

    Attributes:
        x: (nq,) full configuration (m, rad), Pinocchio order.
        q: (n_q,) perfect passive coordinates.
        theta: (n_θ,) spring coordinates.
        wrench: (6,) total external wrench applied to the end frame at equilibrium: force (N)
            at the frame origin and moment (N·m), world axes. On held task components it is
            the reaction (the Lagrange multiplier), on loaded ones the prescribed dead load;
            zero for components outside the task.
        deflection: (6,) end location minus the unloaded one: (m, world rotation vector rad,
            ``log3(R R0ᵀ)``). Equal to the prescribed value in the held components.
        position: (3,) end frame position (m). rotation: (3, 3) end frame orientation.
        converged: Whether eq. (5) holds to the tolerance.
        iterations: Total iterations over all attempts.
        residuals: ``position`` (m), ``orientation`` (rad), ``statics`` (max |eq. 5 static
            residual|, N·m or N) at the returned configuration.
        energy: Spring energy ½(θ−θ₀)ᵀK_θ(θ−θ₀) (J).
        path: How it was found, e.g. ``"newton"``, ``"newton+continuation(4)"``,
            ``"newton+restart(2)"``, ``"newton+escape(1)"``, ``"total-potential"``.
        stability: :class:`StabilityResult` for the control as run: the Hessian of the total
            potential restricted to the displacements that keep the *held* components fixed
            (:func:`~vjm_pin.solver.stability.check_stability_held`); with every task
            component held this is eq. (23). None if not evaluated.
        held: Task component indices (0..5 = x y z rx ry rz) that were held (deflection
            prescribed); the other task components were loaded (dead wrench prescribed).
            None means every task component (the deflection-driven problem).
        stability_end_held: :class:`StabilityResult` of eq. (23) alone (every task component
            held at the equilibrium reached); the same object as ``stability`` when every
            component was held.
        warnings: Plain-language notes, e.g. that only an unstable equilibrium was found.
        checks: Filled by :meth:`EquilibriumSolver.verify`: the measured residuals per unit,
            the recomputed verdicts and the K_C-against-branch error; empty when not checked.
    """

    x: np.ndarray
    q: np.ndarray
    theta: np.ndarray
    wrench: np.ndarray
    deflection: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    converged: bool
    iterations: int
    residuals: dict = field(default_factory=dict)
    energy: float = 0.0
    path: str = ""
    stability: StabilityResult | None = None
    held: tuple[int, ...] | None = None
    stability_end_held: StabilityResult | None = None
    warnings: tuple[str, ...] = ()
    checks: dict = field(default_factory=dict)

    @property
    def stable(self) -> bool | None:
        """Verdict for the control as run (see ``stability``); None if not evaluated."""
        return None if self.stability is None else self.stability.stable

    @property
    def stable_end_held(self) -> bool | None:
        """Eq. (23) alone: stable with the end held in every task component at this
        configuration; None if not evaluated."""
        st = self.stability_end_held if self.stability_end_held is not None else (
            self.stability if self.held is None else None
        )
        return None if st is None else st.stable

    def residual(self) -> float:
        """Largest of the three residual norms (mixed units; 0 at an exact equilibrium)."""
        return float(max(self.residuals.values())) if self.residuals else float("nan")


_ZERO3 = np.zeros(3).tobytes()  # +0.0 exactly (not -0.0)
_F64 = np.dtype(np.float64)  # (``a.dtype is _F64``: the cheap test first, equality when it fails)
_FROZEN_SPECS: dict = {}


def _frozen(cls, **fields):
    """``cls(**fields)`` for a frozen dataclass (no ``__post_init__``, no slots) without its
    ``__init__``, which sets each field through ``object.__setattr__`` (~4× the cost; several
    such objects per solve: the result, its stability verdict, the kept Blocks). Fields not
    given take their defaults; the same object otherwise (``replace``, equality, pickling)."""
    spec = _FROZEN_SPECS.get(cls)
    if spec is None:
        import dataclasses

        ok = (dataclasses.is_dataclass(cls) and not hasattr(cls, "__post_init__")
              and "__slots__" not in cls.__dict__)
        spec = _FROZEN_SPECS[cls] = tuple(
            (f.name, f.default, f.default_factory) for f in dataclasses.fields(cls) if f.init
        ) if ok else False
    if spec is False or len(fields) > len(spec):
        return cls(**fields)
    d = {}
    for name, default, factory in spec:
        if name in fields:
            d[name] = fields[name]
        elif default is not _MISSING:
            d[name] = default
        elif factory is not _MISSING:
            d[name] = factory()
        else:
            return cls(**fields)  # a required field missing: the constructor's error
    if any(k not in d for k in fields):
        return cls(**fields)  # an unknown keyword: the constructor's error
    obj = object.__new__(cls)
    obj.__dict__.update(d)
    return obj


def _built(cls, d: dict):
    """The frozen dataclass ``cls`` (no ``__post_init__``, no slots) whose fields are exactly the
    dict ``d`` (every init field, in field order), without ``__init__`` and without the checks of
    :func:`_frozen`: for the solver's own objects built at every solve, whose callers name every
    field (``tests/test_solve_overhead.py`` compares them with the constructors)."""
    obj = object.__new__(cls)
    obj.__dict__.update(d)
    return obj


def _new_result(**fields) -> EquilibriumResult:
    """``EquilibriumResult(**fields)`` (see :func:`_frozen`)."""
    return _frozen(EquilibriumResult, **fields)


def _blocks_builder(jac, hz, nt, kt, st):
    """A function returning the :class:`Blocks` of a fast-path equilibrium (J task rows / free
    columns, Hessian of Ψ in (θ, q) order) as :func:`evaluate_blocks` lays them out."""

    def build():
        return Blocks(jac[:, :nt], jac[:, nt:], hz[:nt, :nt], hz[:nt, nt:], hz[nt:, :nt], hz[nt:, nt:], kt, st)

    return build


def _backtrack(alpha: float, e0: float, slope: float, en: float | None) -> float:
    """The next trial step of the safeguarded line search after ``alpha`` was rejected: the
    minimiser of the quadratic through the energy ``e0`` and ``slope`` at 0 and ``en`` at ``alpha``,
    kept in [0.1, 0.5]·alpha (Nocedal & Wright §3.5); halving when ``en`` is unknown (restoration
    failed) or the model has no minimum."""
    if en is None or not slope < 0.0:
        return 0.5 * alpha
    c = en - e0 - slope * alpha  # curvature term × alpha²
    if not c > 0.0:
        return 0.5 * alpha
    return min(max(-slope * alpha * alpha / (2.0 * c), 0.1 * alpha), 0.5 * alpha)


def _chain_kernel_min_n() -> int:
    """Free coordinates from which the compiled kernel hands an iteration to the O(n) chain algebra
    (:data:`vjm_pin.solver.chain_kernel.ITERATE_MIN_N`; the direct call of :meth:`EquilibriumSolver._corrector`
    is for shorter chains only)."""
    from vjm_pin.solver import chain_kernel

    return int(getattr(chain_kernel, "ITERATE_MIN_N", 0))


def _all_finite(a: np.ndarray) -> bool:
    """``np.isfinite(a).all()`` for a float array, without its temporary boolean array: the largest
    and smallest entries are finite (NaN propagates through both; no arithmetic, so no overflow
    warning for huge finite entries)."""
    return not a.size or (math.isfinite(a.max()) and math.isfinite(a.min()))


def _singular_values(a: np.ndarray) -> np.ndarray:
    """Singular values of a small matrix (LAPACK ``gesdd`` directly; numpy's wrapper costs more)."""
    if a.size:
        _, sv, _, info = _lapack.dgesdd(a, compute_uv=0)
        if not info:
            return sv
    return np.linalg.svd(a, compute_uv=False)


def _as_target(vm, kin, p0, r0, deflection_=None, target=None):
    if (deflection_ is None) == (target is None):
        raise InputError("give exactly one of a deflection or a target pose")
    if deflection_ is not None:
        return displace(p0, r0, task_vector(deflection_, vm.task, "deflection", "m, rad"))
    p, r = target
    p = np.asarray(p, float)
    r = np.asarray(r, float)
    if p.shape != (3,) or r.shape != (3, 3) or not (np.all(np.isfinite(p)) and np.all(np.isfinite(r))):
        raise InputError("target must be a finite position (3,) and rotation (3, 3)")
    return p, r


#: Allowed range of the relative tolerance ``tol`` of :class:`EquilibriumSolver`: above
#: 1e-4 a "converged" end could be 0.01 % of the chain size off its target and the static
#: residual 0.01 % of the spring torques (a zero deflection would pass for any load);
#: below 1e-15 rounding alone exceeds it.
TOL_RANGE = (1e-15, 1e-4)
#: Iteration / restart / perturbation limits accepted by :class:`EquilibriumSolver`.
MAX_ITER_RANGE = (1, 100_000)
RESTARTS_RANGE = (0, 1000)
PERTURBATION_RANGE = (1e-12, 1.0)


def _check_options(*, method, tol, max_iter, restarts, perturbation, seed, follow_stable, **_):
    """:class:`InputError` naming the first out-of-range solver option and its allowed range."""
    if not isinstance(method, str) or method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}; got {method!r}")

    def number(name, v, lo, hi, integer=False):
        kind = "an integer" if integer else "a number"
        ok = isinstance(v, (int, np.integer)) if integer else isinstance(v, (int, float, np.integer, np.floating))
        if isinstance(v, bool) or not ok or not math.isfinite(float(v)) or not lo <= v <= hi:
            raise InputError(f"{name} must be {kind} in [{lo:g}, {hi:g}]; got {v!r}")

    number("tol", tol, *TOL_RANGE)
    number("max_iter", max_iter, *MAX_ITER_RANGE, integer=True)
    number("restarts", restarts, *RESTARTS_RANGE, integer=True)
    number("perturbation", perturbation, *PERTURBATION_RANGE)
    number("seed", seed, 0, 2**63 - 1, integer=True)
    if not isinstance(follow_stable, (bool, np.bool_)):
        raise InputError(f"follow_stable must be True or False; got {follow_stable!r}")


@functools.lru_cache(maxsize=1)
def _init_defaults() -> tuple:
    """The public keyword options of :class:`EquilibriumSolver` and their defaults (read once)."""
    params = inspect.signature(EquilibriumSolver.__init__).parameters
    return tuple((k, p.default) for k, p in params.items() if k not in ("self", "vm") and not k.startswith("_"))


#: :func:`_prismatic_columns` by model (the model kept with its answer, as
#: :func:`~vjm_pin.kinematics.screw.screw_applicable`: an id is never reused while its entry lives).
_PRISMATIC: dict[int, tuple[pin.Model, int, np.ndarray]] = {}


def _prismatic_columns(model: pin.Model) -> np.ndarray:
    """``(nv,)`` bool, read only: the velocity columns of prismatic joints, remembered per model
    object (reading the joint types copies every joint model: ~0.2 ms at 148 joints)."""
    hit = _PRISMATIC.get(id(model))
    if hit is not None and hit[0] is model and hit[1] == model.njoints:  # a joint added since: asked again
        return hit[2]
    prism = np.array([model.joints[i + 1].shortname().startswith("JointModelP") for i in range(model.nv)], bool)
    prism.flags.writeable = False
    if len(_PRISMATIC) >= 16:
        _PRISMATIC.pop(next(iter(_PRISMATIC)))
    _PRISMATIC[id(model)] = (model, model.njoints, prism)
    return prism


#: ``np.triu(np.ones((m, m)))`` for the task sizes m = 0…6 (:func:`_triu_ones`).
_TRIU = tuple(np.triu(np.ones((m, m))) for m in range(7))


def _triu_ones(m: int) -> np.ndarray:
    """A new ``np.triu(np.ones((m, m)))`` (a copy of a kept one: ~20 µs less per solver)."""
    return _TRIU[m].copy() if m < len(_TRIU) else np.triu(np.ones((m, m)))


class EquilibriumSolver:
    """Solves eq. (5) for one model; keeps a Pinocchio ``Data`` and the reference pose.

    Args:
        vm: The model.
        method: ``"newton"`` (default) or ``"fixed-point"`` (eq. 10).
        tol: Relative tolerance in :data:`TOL_RANGE` (1e-15…1e-4): position error ≤ tol·L_c
            (L_c = size of the chain), orientation error ≤ tol rad, static residual ≤
            tol·max(|K_θ(θ−θ₀)|, 1e-6·|K_θ|).
        max_iter: Iterations per attempt (1…100000).
        restarts: Perturbed restarts after a stall or an unstable result (0…1000).
        perturbation: Size of the restart noise (rad; ×L_c·1e-3 for prismatic coordinates),
            1e-12…1.
        seed: Seed of the restart noise, a non-negative integer (results are reproducible).

    Raises:
        InputError: an option out of its range (the message names it and the range).
        follow_stable: Prefer stable equilibria: inertia-corrected Newton steps and restarts
            when the converged equilibrium is unstable (eq. 23).
    """

    @one_blas_thread  # its setup inverts K_θ and the metric: order 6n at k-subdivided links
    def __init__(
        self,
        vm: VjmModel,
        *,
        method: str = "newton",
        tol: float = 1e-10,
        max_iter: int = 60,
        restarts: int = 8,
        perturbation: float = 1e-3,
        seed: int = 0,
        follow_stable: bool = True,
        _kin: Kinematics | None = None,
    ):
        _check_options(method=method, tol=tol, max_iter=max_iter, restarts=restarts,
                       perturbation=perturbation, seed=seed, follow_stable=follow_stable)
        if getattr(vm, "closures", ()):  # this solver would ignore them: MechanismSolver solves them
            raise ModelError(
                f"model '{vm.name}' has loop closures ({', '.join(c.name for c in vm.closures)}): the serial "
                "EquilibriumSolver would ignore them; solve it with MechanismSolver"
            )
        self.vm = vm
        # ``_kin`` (private): a Kinematics of this model and frame to share (one pin.Data per
        # map worker instead of one per pose); same results, it only holds Pinocchio's workspace
        if _kin is not None and (_kin.model is not vm.model or _kin.frame_id != vm.frame_id):
            raise InputError("_kin must be a Kinematics of the same pin.Model and end frame")
        self.kin = _kin if _kin is not None else Kinematics(vm.model, vm.frame_id)
        self.method = method
        self.tol = tol
        self.max_iter = max_iter
        self.restarts = restarts
        self.perturbation = perturbation
        self.seed = seed
        self.follow_stable = follow_stable
        self.max_step = 0.3
        self.p0, self.r0 = self.kin.placement(vm.reference)
        self.task = list(vm.task)
        self.free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
        self.nt = vm.n_theta
        # the joint placements at the reference: placement() has just run the forward kinematics
        # there; tolist() reads them without one binding call per index (~2× faster at 148 joints)
        pts = np.concatenate([m.translation for m in self.kin.data.oMi.tolist()[1:]] + [self.p0]).reshape(-1, 3)
        self.length_scale = max(float(np.sqrt(((pts - self.p0) ** 2).sum(axis=1)).max()), 1e-3)
        prism = _prismatic_columns(vm.model)
        self.var_scale = np.where(prism[self.free], self.length_scale, 1.0)
        self.kscale = float(max(vm.K_theta.max(), -vm.K_theta.min()))  # max|K_θ| without a temporary
        # per-task-row scale of pose errors (m rows by L_c, rad rows by 1), and the row groups
        self._err_scale = np.where(np.array(self.task) < 3, self.length_scale, 1.0)
        self._rows_p = [i for i, t in enumerate(self.task) if t < 3]
        self._rows_r = [i for i, t in enumerate(self.task) if t >= 3]
        # the fast local Newton path: K_θ ⊕ 0 in (θ, q) order (the gathers of H: _hidx)
        self._kz = np.zeros((len(self.free),) * 2)
        self._kz[: self.nt, : self.nt] = vm.K_theta
        self._smask = self.kin.support_mask(self.free) if hasattr(self.kin, "support_mask") else None
        self._all_task = self.task == [0, 1, 2, 3, 4, 5]
        self._off_task = np.array([i for i in range(6) if i not in self.task], int)
        self._off_task_list = self._off_task.tolist()
        self._r_unrotated = displace(self.p0, self.r0, np.zeros(6))[1]  # target rotation of a zero rotation part
        self._ip = np.array(self._rows_p, int)
        self._zero3 = np.zeros(3)  # erot of a task without rotations (the kernels only read it)
        self._task_idx = np.array(self.task, int)
        self._partial_task_rotation = bool(self._partial_rotation(self.task))  # see _rotation_targets
        self._ir = np.array(self._rows_r, int)
        self._triu = _triu_ones(len(self.task))
        t = self.task
        contiguous = bool(t) and t == list(range(t[0], t[-1] + 1))
        self._task_rows = slice(t[0], t[-1] + 1) if contiguous else np.array(t, int)
        self._fast_max_iter = 8
        self._fast_cache: tuple[bytes, dict, StabilityResult | None] | None = None
        self._fast_fact: tuple | None = None  # factorisation at the last fast-path equilibrium
        self._kpack: tuple | None = None  # constants of the fused kernel (_kernel_consts)
        self._lean_ctx: tuple | None = None  # the warm-start solve's kernel context (_lean_context)
        # (key of _fast_fact, ‖R‖_F‖R⁻¹‖_F ≥ cond(J) there) from the compiled kernel (kernel._iterate_into)
        self._fast_cond: tuple | None = None
        self._handoff = False  # inside _escape: the safeguarded iteration hands off (_relaxed_local)

    def _sibling(self, **options) -> EquilibriumSolver:
        """A solver of the same model with the given options (the defaults of ``__init__``
        for the others) that shares this one's :class:`Kinematics`: creating a ``pin.Data``
        costs seconds for finely subdivided models. Use in the same thread only."""
        opts = dict(_init_defaults())
        opts.update(options)
        _check_options(**opts)
        new = copy.copy(self)
        for k, v in opts.items():
            setattr(new, k, v)
        new.max_step = 0.3
        new._fast_cache = None
        new._fast_fact = None
        new._lean_ctx = None  # (its buffers are this solver's)
        new._fast_cond = None
        return new

    @functools.cached_property
    def _hidx(self) -> np.ndarray:
        """(n², ) flat indices of the (θ, q)-ordered block of a (nv, nv) matrix (the dense
        Newton path's gather of the contracted Hessian), built on first use (order n²)."""
        return (self.free[:, None] * self.vm.model.nv + self.free[None, :]).ravel()

    # ----------------------------------------------------------------- helpers
    def energy(self, x: np.ndarray) -> float:
        d = x[self.vm.theta_idx] - self.vm.theta0
        return 0.5 * float(d @ self.vm.K_theta @ d)

    def _residuals(self, x, f, state, p_t, r_t):
        vm = self.vm
        e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
        jz = state.jacobian[self.task][:, self.free]
        tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        grad = np.concatenate([tau, np.zeros(vm.n_q)])
        r = grad - jz.T @ f
        tp, tr = self._rows_p, self._rows_r
        res = {
            "position": float(np.abs(e[tp]).max()) if tp else 0.0,
            "orientation": float(np.abs(e[tr]).max()) if tr else 0.0,
            "statics": float(np.abs(r).max()) if r.size else 0.0,
        }
        stat_scale = max(float(np.abs(tau).max()) if tau.size else 0.0, 1e-6 * self.kscale)
        ok = (
            res["position"] <= self.tol * self.length_scale
            and res["orientation"] <= self.tol
            and res["statics"] <= self.tol * stat_scale
        )
        return e, jz, grad, r, res, ok

    def _psi_hessian(self, x, state, w6):
        """The (θ, q) block of the Hessian of Ψ (eq. 16) at ``x`` (kinematic ``state``) for the 6-D
        wrench ``w6``: screw form from J when the model allows it, else Pinocchio's tensor
        (evaluated here if ``state`` lacks it: restoration evaluates J only)."""
        kin = self.kin
        if getattr(kin, "uses_screw", False):
            return kin.psi_hessian(state, w6, self.free)
        if state.hessian is None:
            state = kin.evaluate(x)
        return state.psi_hessian(w6)[np.ix_(self.free, self.free)]

    def _kkt_norm(self, e, r):
        return float(np.linalg.norm(e / self._err_scale) + np.linalg.norm(r) / max(self.kscale, 1e-300))

    # ----------------------------------------------------------------- iterations
    def _iterate(self, x, f, p_t, r_t, max_iter):
        """One attempt from (x, f); returns (x, f, iterations, converged, state)."""
        if self.method == "fixed-point":
            return self._fixed_point(x, f, p_t, r_t, max_iter)
        return self._newton(x, f, p_t, r_t, max_iter)

    def _moved(self, x, dx) -> np.ndarray:
        """A copy of ``x`` with ``dx`` added to its free coordinates (tiny values flushed)."""
        x = x.copy()
        x[self.free] += dx
        flush_tiny(x)
        return x

    def _fast_newton(self, x, p_t, r_t):
        """Plain local Newton on eq. (5) from ``x``; None when it must give way to the
        safeguarded iteration (see the module docstring).

        Each iteration: ``J`` and the Hessian at ``x`` (one Pinocchio evaluation), the
        complete QR ``Jᵀ = [Y Z] [R; 0]`` (``Z``: null space of eq. 20–21; the singular
        values of ``R`` are those of ``J``, checked against :data:`RANK_TOL`), the
        least-squares multiplier ``F = R⁻¹ Yᵀ ∇E`` (as the safeguarded path), the
        residual test of :meth:`_residuals`, then the Newton step of eq. (28),
        ``[[W, −Jᵀ], [J, 0]] [δx; δF] = [−r; e]`` with ``W = K − H(F)``, solved in the
        null-space form ``Rᵀ p_Y = e``, ``(ZᵀWZ) p_Z = −Zᵀ(r + W Y p_Y)``. The positive
        definiteness of ``ZᵀWZ`` (symmetric part, margin ``1e-8·max|K_θ|``) is the
        condition of the safeguarded path for an unmodified step; at convergence its
        negative is the matrix of eq. (23), so the stability verdict comes for free.

        Returns (x, f, iterations, state) with the verdict cached for :meth:`_result`.
        """
        m, n = len(self.task), len(self.free)
        if m == 0 or m >= n:
            return None
        if _fused_enabled and self._smask is not None and getattr(self.kin, "uses_screw", False):
            return self._fast_newton_fused(x, p_t, r_t)
        tol = self.tol
        tol_p = tol * self.length_scale
        kscale = max(self.kscale, 1e-300)
        stat_floor = 1e-6 * self.kscale
        escale = self._err_scale
        pt = np.asarray(p_t, float)
        rt = np.asarray(r_t, float)
        kkt_prev = np.inf
        x = flush_tiny(np.array(x, dtype=float))
        f6 = np.zeros(6)
        qfull = np.zeros((n, n), order="F")
        # LAPACK directly for small models: numpy.linalg's wrappers cost more than these small
        # factorisations; numpy.linalg for large ones (see SCIPY_LAPACK_MAX_N)
        big = n > SCIPY_LAPACK_MAX_N
        polish = 0
        for it in range(self._fast_max_iter + 1 + POLISH_ITERATIONS):
            key = x.tobytes()
            fact = self._fast_fact
            if fact is not None and fact[0] == key and fact[1] is self.kin and len(fact) == 10:
                # a warm start from the equilibrium this solver just found: its J, QR,
                # multiplier and Hessian depend on x only (the target does not enter them)
                st, jac, qf, rr, f, r, tau, hz = fact[2:]
                f6[self._task_rows] = f
            else:
                got = self._fast_factor(x, f6, qfull, big)
                if got is None:
                    return None
                st, jac, qf, rr, f, r, tau, hz = got
            y, z = qf[:, :m], qf[:, m:]
            e, ep, er = self._fast_error(st, pt, rt)
            rs = np.abs(r).max()
            es = e / escale
            kkt = math.sqrt(es @ es) + math.sqrt(r @ r) / kscale
            # the test of _residuals, with the end placed as accurately as the safeguarded
            # path's restoration places it (0.01·tol): wrench-driven loops (eq. 11) rely on it
            converged = ep <= 0.01 * tol_p and er <= 0.01 * tol and rs <= tol * max(np.abs(tau).max(), stat_floor)
            red_step = None  # Zᵀ(K − H)Z of the polish step, reused (negated) for eq. (23)
            if converged and polish < POLISH_ITERATIONS:
                # the residual test alone misses the error along a soft mode next to a
                # bifurcation (error = residual / small eigenvalue): the Newton step is the
                # error estimate; polish while it is not negligible
                step, red_step = self._fast_step(self._kz, hz, z, y, rr, e, r, big)
                if step is not None and np.abs(step / self.var_scale).max() > POLISH_STEP:
                    polish += 1
                    x = self._moved(x, step)
                    kkt_prev = np.inf
                    continue
            if converged:
                res = {"position": float(ep), "orientation": float(er), "statics": float(rs)}
                fact = (key, self.kin, st, jac, qf, rr, f, r, tau, hz)
                if not self._fast_accept(x, it, fact, f6, pt, rt, res, red_step, big):
                    return None
                return x, f, it, st
            self._fast_its = it
            if it and not kkt < 0.5 * kkt_prev or it - polish >= self._fast_max_iter:
                return None
            dx = self._fast_descent_step(hz, y, z, rr, e, r, big)
            if dx is None:
                return None
            x = self._moved(x, dx)
            kkt_prev = kkt
        return None

    def _kernel_consts(self):
        """The constant arrays of the fused kernel (:func:`vjm_pin.solver.kernel.pack`) and the
        stability threshold, rebuilt when an option they hold changed (``_sibling``)."""
        sig = (self.tol, self.follow_stable, self.max_step, self.kscale, id(self.kin))
        kp = self._kpack
        if kp is not None and kp[0] == sig:
            return kp[1], kp[2]
        from vjm_pin.solver import kernel

        vm, n = self.vm, len(self.free)
        kt = vm.K_theta
        consts = kernel.pack(
            free=self.free, theta_idx=vm.theta_idx, theta0=vm.theta0, task=self.task, kz=self._kz,
            mask=self._smask, var_scale=self.var_scale, err_scale=self._err_scale, nq=vm.model.nq,
            tol=self.tol, tol_p=self.tol * self.length_scale, kscale=max(self.kscale, 1e-300),
            stat_floor=1e-6 * self.kscale, shift=SHIFT_TOL * self.kscale, max_step=self.max_step,
            follow_stable=self.follow_stable, polish_step=POLISH_STEP, rank_tol=RANK_TOL,
            big=n > SCIPY_LAPACK_MAX_N,
        )
        thr = float(STABILITY_TOL * (spectral_norm(kt) if kt.size else 1.0))
        self._kpack = (sig, consts, thr)
        return consts, thr

    def _fast_newton_fused(self, x, p_t, r_t):
        """:meth:`_fast_newton` for chains of 1-DoF joints (screw-form Hessian): per iteration one
        Pinocchio call (frame Jacobian and end placement) and one call of the fused kernel
        (:mod:`vjm_pin.solver.kernel`), with the same iterates, tests, caches and results
        (:meth:`_fused_iterations`, with ``VJM_PIN_JIT`` read now and the kernel's own call)."""
        ctx = self._lean_context()
        if ctx is not None and ctx[5] is not None and _compiled_kinematics:
            # the compiled kernel's direct call: the whole iteration in one compiled call with the
            # compiled kinematics where the chain allows (_fused_iterations), its context kept
            raw = self._fused_iterations(ctx, p_t, r_t, x, eager=True)  # (eigenvalues now, as below)
            return None if raw is None else raw[:4]
        consts, thr = self._kernel_consts()
        consts = _kernel.with_target(consts, np.asarray(p_t, float))
        raw = self._fused_iterations([None, consts, consts[1], thr, _kernel.get(), None, None], p_t, r_t, x)
        return None if raw is None else raw[:4]

    @functools.cached_property
    def Kinv(self) -> np.ndarray:
        """``K_θ⁻¹`` (rad/(N·m) or m/N): the compliant start of the restoration and the fixed-point
        start (built when first needed: an order-6n inversion a curve of fast solves never uses)."""
        with single_blas_thread():
            return np.linalg.inv(self.vm.K_theta)

    @functools.cached_property
    def Minv(self) -> np.ndarray:
        """Inverse of the restoration's metric ``K_θ ⊕ 0 + 1e-6·max|K_θ| / s²`` (``s`` the variable
        scale: ``L_c`` for prismatic coordinates, 1 otherwise); built when first needed."""
        metric = np.diag(1e-6 * self.kscale / self.var_scale**2)
        metric[: self.nt, : self.nt] += self.vm.K_theta
        with single_blas_thread():
            return np.linalg.inv(metric)

    def _kernel_stability(self, stable, ev, d, thr, jac, hz, st) -> StabilityResult:
        """The eq. (23) verdict of a fused-kernel convergence: all ``d`` eigenvalues from the dense
        kernel; from the O(n) chain kernel (:mod:`vjm_pin.solver.chain_kernel`) only the largest,
        and the rest computed from the equilibrium's Blocks when first read
        (:class:`~vjm_pin.solver.stability.DeferredStability`)."""
        if ev.size == d:
            return _built(StabilityResult, {"stable": stable, "eigenvalues": ev, "null_dim": d, "tolerance": thr})
        return DeferredStability(stable, float(ev[-1]), d, thr, _blocks_builder(jac, hz, self.nt, self.vm.K_theta, st))

    def _corrector_context(self):
        """The per-curve bundle of :meth:`_corrector` (None when the fused local iteration does not
        apply: another method, a task of 0 or ≥ n rows, no screw-form Hessian, the fused kernel
        switched off): ``VJM_PIN_JIT`` read once, the kernel's constants (:meth:`_kernel_consts`)
        and a target slot of its own (``cf``), unpacked for the compiled kernel's direct call."""
        m, n = len(self.task), len(self.free)
        if (self.method != "newton" or m == 0 or m >= n or not _fused_enabled or self._smask is None
                or not getattr(self.kin, "uses_screw", False)):
            return None
        consts, thr = self._kernel_consts()
        cf = consts[1].copy()
        consts = (consts[0], cf) + tuple(consts[2:])
        # [mode, consts, cf, thr, the step function last used, its direct compiled call (kernel.lean) with
        # the constants or None, that call's buffers (kernel.workspace), stable verdicts certified without
        # the eigenvalues (_fused_iterations; the tracer reads them when it needs them)]
        return [_kernel.mode(), consts, cf, thr, None, None, None, _corrector_defer]

    def _corrector(self, ctx, p_t, r_t, x, flushed: bool | int = False):
        """:meth:`_fast_newton_fused` from ``x`` (a predicted point of a curve) towards the target
        ``(p_t, r_t)`` for :meth:`~vjm_pin.analysis.curve._Tracer.step`: the same iterations, tests,
        caches and numbers (:meth:`_fused_iterations`), with the per-solve set-up done once per curve
        (``ctx`` from :meth:`_corrector_context`: the environment read, the constants, the compiled
        kernel called directly with them unpacked).

        Returns None when the plain local iteration gives way (``_fast_its`` set, as
        :meth:`_fast_newton`), else the raw equilibrium of :meth:`_fused_iterations` (build the
        result with :meth:`_corrector_result`). ``flushed``: ``x`` has no entry below 1e-150
        already (:func:`flush_tiny` would not change it). ``flushed`` :data:`FRESH` (2): flushed,
        and fresh: ``x`` is a C-contiguous writable float64 (nq,) array of the caller's, ``p_t`` a
        float64 (3,) array and ``r_t`` a C-contiguous float64 (3, 3) array (what
        :meth:`_fused_iterations` would make of them): once the context's one-call compiled loop is
        set up (:meth:`_fused_looped`, the common case) the iteration goes straight to it
        (:meth:`_corrector_looped`), its per-call checks made once per context (``_corrector_route``)."""
        kernel = _kernel
        c = kernel._compiled
        # kernel.get(mode): the loaded compiled kernel in modes "1" and "auto" (get's own answer, without its calls)
        fn = c if c and ctx[0] != "0" else kernel.get(ctx[0])
        if flushed is FRESH:
            route = self._route_now(ctx, fn)
            if route is not None:
                self._fast_its = 0
                return self._corrector_looped(ctx, route, p_t, r_t, x)
        consts, step_fn = ctx[1], ctx[4]
        if fn is not step_fn:  # first call, or auto mode switched to the compiled kernel
            small = getattr(fn, "dispatcher", None) is not None and int(consts[0][0]) < _chain_kernel_min_n()
            lean = kernel.lean() if small else None
            ctx[4], ctx[5] = fn, ((lean,) + consts[2:] if lean is not None else None)
            ctx[6] = kernel.workspace(consts[0], self.kin.model.nq) if lean is not None else None
        self._fast_its = 0
        return self._fused_iterations(ctx, p_t, r_t, x, bool(flushed))

    def _route_now(self, ctx, fn):
        """The route kept in ``ctx`` (:meth:`_corrector_route`) while it is valid for the step function
        ``fn``, the plan, the kinematics and ``_fast_max_iter``; else made anew (None: not set up)."""
        route = ctx[11] if len(ctx) > 11 else None
        if (route is None or route[0] is not fn or ctx[4] is not fn or ctx[10] is not route[1]
                or route[2] is not self.kin or route[3] != self._fast_max_iter):
            route = self._corrector_route(ctx, fn)
        return route

    def _corrector_route(self, ctx, fn):
        """The per-context constants of :meth:`_corrector_looped` (kept as ``ctx``'s twelfth item), or
        None while :meth:`_fused_iterations` would not take the one-call compiled loop with the plan
        kept in ``ctx`` (:meth:`_fused_looped`; not set up yet, or another path): ``(step function,
        plan, kinematics, max_iter, loop limits, whole-iteration call, rot, defer, kept verdict's
        fields, its eigenvalue function)``. Valid while the step function, the plan, the kinematics
        and ``_fast_max_iter`` stay the same (:meth:`_corrector` checks them)."""
        if (len(ctx) < 11 or ctx[4] is not fn or getattr(fn, "dispatcher", None) is None or ctx[5] is None
                or not ctx[8] or ctx[8][0] is None):
            return None
        plan = ctx[10]
        if plan is None or plan[0] is not self.kin or plan[1] is not fn:
            return None
        lim = np.array([self._fast_max_iter, POLISH_ITERATIONS, 0], np.int64)  # (_loop_limits(0))
        spectrum = _kernel.spectrum
        route = (fn, plan, self.kin, self._fast_max_iter, lim, ctx[8], self._ir.size > 0, bool(ctx[7]),
                 plan[15], spectrum)
        if len(ctx) > 11:
            ctx[11] = route
        else:
            ctx.append(route)
        return route

    def _corrector_looped(self, ctx, route, p_t, r_t, x):
        """:meth:`_fused_iterations` then :meth:`_fused_looped` for :meth:`_corrector` with :data:`FRESH`
        inputs and the ``route`` of :meth:`_corrector_route` (``relaxed`` 0, not ``eager``): the plain
        local Newton iteration of eq. (5) in the same compiled call with the same arguments, the same
        caches (``_fast_fact``, ``_fast_cache``, ``_fast_cond``, ``kin._last``, the kept Blocks of eq.
        16) and the same raw result with its eq. (23) verdict, their objects built without the general
        path's per-call checks (the kept Blocks as :class:`~vjm_pin.solver.blocks.LazyBlocks`, a
        certified verdict from the template of :meth:`SpectrumLater.stable_fields`)."""
        step_fn, plan, kin, _, lim, ck, rot, defer, later, spectrum = route
        _, _, kbuf, ci, cf, kz, mask, theta0, vscale, escale, thr = plan[:11]
        cf[9:12] = p_t  # kernel.with_target
        xout, ws = ctx[6]
        fact = self._fast_fact
        if fact is not None and fact[1] is kin and fact[-1] is step_fn:
            kst = fact[2]
            out = ck[0](
                x, np.frombuffer(fact[0]), True, fact[3:11], kst.position, kst.rotation, ck[3], ck[4], r_t, rot,
                bool(_chain._flush_enabled), ci, cf, kz, mask, theta0, vscale, escale, xout, ws, kbuf, thr, defer,
                lim)
        else:  # (kx read only, as np.frombuffer's: one compiled signature)
            dummy = _KERNEL_DUMMY
            out = ck[0](
                x, _NO_KEY, False, dummy[:8], dummy[3], dummy[0], ck[3], ck[4], r_t, rot,
                bool(_chain._flush_enabled), ci, cf, kz, mask, theta0, vscale, escale, xout, ws, kbuf, thr, defer,
                lim)
        return self._looped_finish(ctx, plan, later, fact, out, p_t, r_t, p_t, r_t)

    def _corrector_step(self, ctx, fn, pre, post, pt, r_t):
        """:meth:`_corrector` with :data:`FRESH` inputs, the prediction before it and the curve's point after
        it in one compiled call ``fn`` (:func:`vjm_pin.analysis.point_kernel._step_loops`, called with
        ``pre``, this context's loop arguments as :meth:`_corrector_looped` passes them (the kept state's
        Jacobian after its rotation), then ``post``): the same calls on the same arrays, the same
        caches. ``pt`` is the fresh (3,) array ``fn`` writes the target position into, ``r_t`` the
        kept target rotation (C-contiguous float64). Returns ``(out, raw)``: ``fn``'s tuple and the raw
        equilibrium of :meth:`_looped_finish` (None unless converged: ``_fast_its`` set as there), or
        None when the one-call loop is not set up for ``ctx`` (call :meth:`_corrector`)."""
        c = _kernel._compiled
        route = self._route_now(ctx, c if c and ctx[0] != "0" else _kernel.get(ctx[0]))
        if route is None:
            return None
        step_fn, plan, kin, _, lim, ck, rot, defer, later, spectrum = route
        _, _, kbuf, ci, cf, kz, mask, theta0, vscale, escale, thr = plan[:11]
        xout, ws = ctx[6]
        fact = self._fast_fact
        if fact is not None and fact[1] is kin and fact[-1] is step_fn:
            kst = fact[2]
            out = fn(*pre, np.frombuffer(fact[0]), True, fact[3:11], kst.position, kst.rotation, kst.jacobian, ck[3],
                     ck[4], r_t, rot, bool(_chain._flush_enabled), ci, cf, kz, mask, theta0, vscale, escale, xout, ws,
                     kbuf, thr, defer, lim, *post)
        else:
            dummy = _KERNEL_DUMMY
            out = fn(*pre, _NO_KEY, False, dummy[:8], dummy[3], dummy[0], dummy[0], ck[3], ck[4], r_t, rot,
                     bool(_chain._flush_enabled), ci, cf, kz, mask, theta0, vscale, escale, xout, ws, kbuf, thr,
                     defer, lim, *post)
        if out[0] == 0:  # rejected by the prediction's move: the corrector did not run
            return out, None
        self._fast_its = 0
        return out, self._looped_finish(ctx, plan, later, fact, out[1:9], pt, r_t, pt, r_t)

    def _looped_finish(self, ctx, plan, later, fact, out, pt, rt, p_t, r_t):
        """After the one-call compiled loop (:func:`vjm_pin.solver.kernel._iterations_into`, its
        returned tuple ``out``) of :meth:`_fused_looped` and :meth:`_corrector_looped`: None where it
        gave way (``_fast_its`` set), else the raw equilibrium of :meth:`_fused_iterations` and the
        same caches (``_fast_fact``, ``_fast_cache``, ``_fast_cond``, ``kin._last``, the kept Blocks
        of eq. 16 as :class:`~vjm_pin.solver.blocks.LazyBlocks`); a certified stable verdict of eq. (23)
        from ``later``, the fields of :meth:`SpectrumLater.stable_fields`. ``fact`` is the
        ``_fast_fact`` the loop was called with, ``(pt, rt)`` the target as arrays (their bytes key
        ``_fast_cache``), ``(p_t, r_t)`` as the caller gave it (kept: :meth:`_result` tests identity).
        The raw equilibrium's last item is the loop's ``(Qᵀ W Q)ᵀ`` at the convergence (``ws[11]``, kept in
        the fresh buffers: valid until the context's next call)."""
        code, it, counted, _, ep, er, rs, reused = out
        if counted >= 0:
            self._fast_its = counted
        if code != _kernel.DONE:
            return None
        kin, kbuf, d, pool = plan[0], plan[2], plan[11], plan[14]
        xout, ws = ctx[6]
        x = xout.copy()
        key = x.tobytes()
        kf = ws[:8]
        info = ws[10]
        jac, qf, rr, f, r, tau, hz, f6 = kf
        # the buffers now belong to the caches: fresh ones (xout, info and an unused eigenvalue buffer
        # are read here and kept, as kernel.workspace lays them out)
        if info[0] != 0.0:  # stable, certified: the eigenvalues when first read
            ctx[6] = (xout, _kernel.workspace_after(ws, True, pool))
            ev = None
            stab = _new_object(SpectrumLater)  # SpectrumLater.stable_now(d, thr, ws[9], spectrum)
            sd = stab.__dict__
            sd.update(later)
            sd["_matrix"] = ws[9]
        else:
            ctx[6] = (xout, _kernel.workspace_after(ws, False, pool))
            ev = ws[8]
            stab = None
        if reused:
            st = fact[2]
        else:
            st = _new_object(KinematicState)  # _built(KinematicState, ...)
            st.__dict__.update({"position": kbuf[1].copy(), "rotation": kbuf[2].copy(),
                                "jacobian": kbuf[0].copy(), "hessian": None})
            kin._last = (key, st)  # kin.evaluate(x, hessian=False) at this point: no Pinocchio call
        if stab is None:
            thr = plan[10]
            stable = bool(ev.size == 0 or ev[-1] < -thr)  # (ascending)
            stab = self._kernel_stability(stable, ev, d, thr, jac, hz, st)
        res = {"position": float(ep), "orientation": float(er), "statics": float(rs)}
        wkey = key + f6.tobytes()
        self._fast_cache = (wkey + pt.tobytes() + rt.tobytes(), res, stab, x, f, f6, p_t, r_t)
        self._fast_fact = (key, kin, st, jac, qf, rr, f, r, tau, hz, f6, plan[1])
        self._fast_cond = (key, info[1])
        try:  # remember_lazy(self.vm, kin, wkey, _blocks_builder(jac, hz, nt, kt, st))
            kin._blocks_last = (self.vm, wkey, LazyBlocks((jac, hz, plan[12], plan[13], st)))
        except AttributeError:  # a kinematics object with __slots__: no cache
            pass
        return x, f, it, st, kf, ev, res, stab, ws[11]

    def _fused_iterations(self, ctx, p_t, r_t, x, flushed: bool = False, relaxed: int = 0, eager: bool = False):
        """The fused local iteration of :meth:`_fast_newton_fused` and :meth:`_corrector` from ``x``
        towards the target ``(p_t, r_t)``: per iteration one Pinocchio call (frame Jacobian and end
        placement, none on a warm start from the equilibrium this solver just found) and one call
        of the fused kernel; at convergence the eq. (23) verdict and the caches (``_fast_fact``,
        ``_fast_cache``, the kept Blocks).

        ``ctx``: ``[mode, consts, cf, thr, step function, direct call or None, its buffers]``
        (:meth:`_corrector_context`; ``cf`` is ``consts``' float array, its target slots written
        here); the direct call (:func:`vjm_pin.solver.kernel.lean` with the constants unpacked)
        writes into the buffers, replaced by fresh ones at convergence. Returns None when the plain
        local iteration gives way (``_fast_its`` set where it counts iterations), else
        ``(x, f, iterations, state, fact, ev, residuals, stability, wt)`` (``fact`` = (J, Q or
        reflectors, R, F, r, ∇E, H(F), F (6,)) of the kernel; ``wt`` the converged iteration's
        ``(Qᵀ(K − H)Q)ᵀ`` from the one-call loop (:meth:`_looped_finish`; valid until this context's next
        call, for the curve point's tangent), else None). A context with an eighth item True
        (:meth:`_lean_context`; :meth:`_corrector_context` while ``_corrector_defer`` holds) lets the
        direct call certify a stable verdict without the eigenvalues
        (:func:`vjm_pin.solver.kernel._iterate_into`): ``ev`` is then None and the verdict's
        eigenvalues are computed when first read (:class:`~vjm_pin.solver.stability.SpectrumLater`).

        ``relaxed`` (a number of steps, 0: off): steps are not required to halve the residual (still
        a positive definite reduced matrix, within the step limit), at most ``relaxed`` of them; for
        :meth:`_relaxed_local` only. ``eager``: the eigenvalues of a verdict computed now whatever
        ``ctx`` lets the direct call certify (:meth:`_fast_newton_fused` in the lean context).

        With the compiled kernel on a chain of 1-DoF joints the kinematics are compiled too
        (:meth:`_compiled_chain`, :mod:`vjm_pin.kinematics.compiled_chain`: no Pinocchio or ``log3``
        binding call), and with the direct call the whole loop is one compiled call
        (:meth:`_fused_looped`): the same iterates, tests, caches and result layout."""
        chain, kernel = _chain, _kernel
        kin, m, n = self.kin, len(self.task), len(self.free)
        _, consts, cf, thr, step_fn, direct = ctx[:6]
        pt = np.asarray(p_t, float)
        rt = np.asarray(r_t, float)
        cf[9:12] = pt  # kernel.with_target
        rot = self._ir.size > 0
        flush = bool(chain._flush_enabled)
        # the compiled kernel's kinematics: compiled too (kinematics/compiled_chain.py) where the chain
        # applies; the whole iteration in one compiled call with the direct call (_fused_looped)
        ck = self._compiled_chain(ctx) if getattr(step_fn, "dispatcher", None) is not None else None
        looped = ck is not None and direct is not None and ck[0] is not None
        # (x used as it is on the looped path: _iterations_into copies its start, never writes it)
        if not (looped and flushed and type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1
                and x.flags.c_contiguous and x.flags.writeable):
            x = np.array(x, dtype=float)
            if not flushed:
                fact = self._fast_fact
                if fact is None or fact[0] != x.tobytes():  # (the last equilibrium is flushed already)
                    flush_tiny(x)
        if looped:
            return self._fused_looped(ctx, ck, x, p_t, r_t, pt, rt, rot, flush, relaxed, eager)
        model, fid, data = kin.model, kin.frame_id, None  # data: kin.data when first needed
        lwa = pin.LOCAL_WORLD_ALIGNED
        zero3 = self._zero3  # (read only)
        dummy = _KERNEL_DUMMY
        ci = consts[0]
        if direct is not None:
            lean, kz, mask, theta0, vscale, escale = direct
            defer = len(ctx) > 7 and ctx[7] and not eager
        cond = None
        cont_, polish_, conv_ = kernel.CONTINUE, kernel.POLISH, kernel.CONVERGED
        kkt_prev = np.inf
        polish = 0
        mo = None
        for it in range(self._fast_max_iter + 1 + POLISH_ITERATIONS):
            key = x.tobytes()
            fact = self._fast_fact
            if fact is not None and fact[0] == key and fact[1] is kin and fact[-1] is step_fn:
                # a warm start from the equilibrium this solver just found (the target does not
                # enter the factorisation; a factorisation by the other implementation is redone)
                st = fact[2]
                kf = fact[3:11]  # (jac, qf, rr, f, r, tau, hz, f6), read only
                j6, pos, rotm, refactor = dummy[8], st.position, st.rotation, False
            elif ck is not None:  # the compiled forward kinematics (as _fused_looped)
                j6, pos, rotm = np.empty((6, model.nv)), np.empty(3), np.empty((3, 3))
                ck[1](x, ck[3], ck[4], j6, pos, rotm)
                mo = _Placement(rotm)
                st, kf, refactor = None, dummy[:8], True
            else:
                if data is None:
                    data = kin.data
                j6 = pin.computeFrameJacobian(model, data, x, fid, lwa)
                if j6.ndim != 2 or not j6.flags.c_contiguous:
                    j6 = np.ascontiguousarray(j6).reshape(6, model.nv)
                mo = data.oMf[fid]
                pos, rotm = mo.translation, (mo.rotation if rot else None)
                st, kf, refactor = None, dummy[:8], True
            if ck is not None:
                erot = zero3
                if rot:
                    erot = np.empty(3)
                    ck[2](rt if rt.flags.c_contiguous else np.ascontiguousarray(rt), rotm, erot)
            else:
                erot = pin.log3(rt @ rotm.T) if rot else zero3
            if direct is not None:  # the compiled kernel, its arrays into the buffers (kernel.lean)
                xout, ws = ctx[6]
                status, kkt, ep, er, rs = lean(
                    j6, pos, erot, x, refactor, polish < POLISH_ITERATIONS, flush, kf, ci, cf, kz, mask, theta0,
                    vscale, escale, xout, ws, thr, defer
                )
                if status == cont_ or status == polish_:
                    xn = xout.copy()
                elif status == conv_:  # the buffers now belong to the caches: fresh ones
                    kf, ev, sym, info = ws[:8], ws[8], ws[9], ws[10]
                    if info[0]:  # stable, certified: the eigenvalues when first read
                        ev = None
                    cond = (key, info[1])
                    ctx[6] = kernel.workspace(ci, model.nq)
            else:
                status, kkt, ep, er, rs, kf, _, xn, ev = step_fn(
                    j6, pos, erot, x, refactor, polish < POLISH_ITERATIONS, flush, False, kf, consts
                )
            if status == kernel.FACTOR_FAIL:
                return None
            if status == kernel.POLISH:
                polish += 1
                x = xn
                kkt_prev = np.inf
                continue
            if status == kernel.RANK_FAIL:
                return None
            if status == kernel.CONVERGED:
                stable = ev is None or bool(ev.size == 0 or ev[-1] < -thr)  # (ascending)
                if self.follow_stable and not stable:
                    self._fast_its = it
                    return None
                jac, qf, rr, f, r, tau, hz, f6 = kf
                if st is None:
                    st = _built(KinematicState, {"position": pos.copy(), "rotation": mo.rotation.copy(), "jacobian": j6,
                                                 "hessian": None})
                    kin._last = (key, st)  # kin.evaluate(x, hessian=False) at this point: no Pinocchio call
                if ev is None:
                    stab = SpectrumLater(True, n - m, thr, sym, kernel.spectrum)
                else:
                    stab = self._kernel_stability(stable, ev, n - m, thr, jac, hz, st)
                res = {"position": float(ep), "orientation": float(er), "statics": float(rs)}
                wkey = key + f6.tobytes()
                self._fast_cache = (wkey + pt.tobytes() + rt.tobytes(), res, stab, x, f, f6, p_t, r_t)
                self._fast_fact = (key, kin, st, jac, qf, rr, f, r, tau, hz, f6, step_fn)
                self._fast_cond = cond
                # the Blocks at this equilibrium (as evaluate_blocks builds them), built when first
                # asked for (a curve point's stiffness): kept lazily
                remember_lazy(self.vm, kin, wkey, _blocks_builder(jac, hz, self.nt, self.vm.K_theta, st))
                return x, f, it, st, kf, ev, res, stab, None
            self._fast_its = it
            if (it and not relaxed and not kkt < 0.5 * kkt_prev) or it - polish >= (relaxed or self._fast_max_iter):
                return None
            if status != kernel.CONTINUE:
                return None
            x = xn
            kkt_prev = kkt
        return None
    def _compiled_chain(self, ctx):
        """``(whole-iteration call or None, forward, rotation_error, geo, jinfo)``: the compiled kinematics
        of :mod:`vjm_pin.kinematics.compiled_chain` for this solver's chain and the compiled local
        iteration (:func:`vjm_pin.solver.kernel.looped`), kept in ``ctx`` (its ninth item); None when the
        model is not a chain of 1-DoF joints or numba is missing (Pinocchio then)."""
        if len(ctx) > 8:
            return ctx[8]
        if not _compiled_kinematics:
            return None
        while len(ctx) < 8:  # (a context without the eighth item: _fast_newton_fused)
            ctx.append(False)
        kin = self.kin
        got = self.__dict__.get("_ckin")
        if got is None or got[0] is not kin:
            from vjm_pin.kinematics import compiled_chain

            # (a Kinematics whose evaluation is its own, e.g. a finite-difference baseline, keeps it)
            own = type(kin).evaluate is not Kinematics.evaluate
            table = None if own else compiled_chain.chain_table(kin.model, kin.frame_id)
            fns = compiled_chain.compiled() if table is not None else None
            got = self._ckin = (kin, None if fns is None else (fns[0], fns[2], table.geo, table.jinfo))
        ck = None
        if got[1] is not None:
            ck = (_kernel.looped(),) + got[1]
        ctx.append(ck)
        return ck

    def _fused_looped(self, ctx, ck, x, p_t, r_t, pt, rt, rot, flush, relaxed, eager=False):
        """:meth:`_fused_iterations` with the direct call and the compiled kinematics: the whole local
        iteration in one compiled call (:func:`vjm_pin.solver.kernel._iterations_into`: the same
        iterates, tests and verdicts as the loop of :meth:`_fused_iterations`), then the same caches
        and result."""
        kin = self.kin
        plan = ctx[10] if len(ctx) > 10 else None
        if plan is None or plan[0] is not kin or plan[1] is not ctx[4]:
            plan = self._looped_plan(ctx)
        _, step_fn, kbuf, ci, cf, kz, mask, theta0, vscale, escale, thr = plan[:11]
        defer = bool(ctx[7]) and not eager
        xout, ws = ctx[6]
        fact = self._fast_fact
        if fact is not None and fact[1] is kin and fact[-1] is step_fn:
            kx, have, kf, kst = np.frombuffer(fact[0]), True, fact[3:11], fact[2]
            kpos, krot = kst.position, kst.rotation
        else:  # (kx read only, as np.frombuffer's: one compiled signature)
            dummy = _KERNEL_DUMMY
            kx, have, kf, kpos, krot = _NO_KEY, False, dummy[:8], dummy[3], dummy[0]
        lim = self.__dict__.get("_lim")  # (_loop_limits)
        if lim is None or lim[0][0] != self._fast_max_iter or lim[0][1] != relaxed:
            lim = (None, self._loop_limits(relaxed))
        if not rt.flags.c_contiguous:
            rt = np.ascontiguousarray(rt)
        out = ck[0](
            x, kx, have, kf, kpos, krot, ck[3], ck[4], rt, rot, flush, ci, cf, kz, mask, theta0, vscale,
            escale, xout, ws, kbuf, thr, defer, lim[1])
        return self._looped_finish(ctx, plan, plan[15], fact, out, pt, rt, p_t, r_t)

    def _looped_plan(self, ctx):
        """The per-context constants of :meth:`_fused_looped`, kept as ``ctx``'s eleventh item (with
        the kinematics' buffers ``(j6, pos, rot)`` as its tenth): ``(kinematics, step function,
        buffers, ci, cf, kz, mask, θ₀, variable scales, error scales, threshold, d = n − m, nθ, K_θ, the
        pool of fresh kernel buffers of :func:`vjm_pin.solver.kernel.workspace_after`, the fields of a
        certified stable verdict (:meth:`SpectrumLater.stable_fields`))``."""
        kin = self.kin
        _, consts, cf, thr, step_fn, direct = ctx[:6]
        _, kz, mask, theta0, vscale, escale = direct
        while len(ctx) < 10:
            ctx.append(None)
        kbuf = ctx[9]
        if kbuf is None:
            kbuf = ctx[9] = (np.empty((6, kin.model.nv)), np.empty(3), np.empty((3, 3)))
        d = len(self.free) - len(self.task)
        plan = (kin, step_fn, kbuf, consts[0], cf, kz, mask, theta0, vscale, escale, thr, d, self.nt,
                self.vm.K_theta, [], SpectrumLater.stable_fields(d, thr, _kernel.spectrum))
        if len(ctx) > 10:
            ctx[10] = plan
        else:
            ctx.append(plan)
        return plan

    def _loop_limits(self, relaxed):
        """``(max_iter, polish steps, relaxed steps)`` of :func:`vjm_pin.solver.kernel._iterations_into`."""
        lim = self.__dict__.get("_lim")
        key = (self._fast_max_iter, relaxed)
        if lim is None or lim[0] != key:
            lim = self._lim = (key, np.array([self._fast_max_iter, POLISH_ITERATIONS, relaxed], np.int64))
        return lim[1]

    def _corrector_result(self, raw, p_t, r_t, path: str = "newton+tangent-predictor") -> EquilibriumResult:
        """The :class:`EquilibriumResult` of a converged :meth:`_corrector` (what :meth:`_result`
        builds from the fused iteration's convergence): the fields of :meth:`_pack`, the ones derived
        from the configuration and the end placement (``q``, ``theta``, ``deflection``, ``position``,
        ``rotation``, ``energy``) computed when first read
        (:class:`~vjm_pin.solver.deferred_result.DeferredResult`: most results of a curve's steps are
        never read), by the same expressions: the same numbers."""
        x, _, it, st, kf, _, res, stab, _ = raw
        src = self.__dict__.get("_deferred_src")
        if src is None or src[0] is not self.vm or src[1] is not self.task:
            vm = self.vm
            src = self._deferred_src = (vm, self.task, tuple(self.task), (self.p0, self.r0, vm.theta_idx, vm.theta0,
                                                                          vm.q_idx, vm.K_theta))
        # deferred_result(fields, sources) without its call: the fields, then the sources (the
        # iteration's own x, which no one writes, the field a copy of its own; the kept state)
        obj = _new_object(_deferred_result or _load_deferred())
        obj.__dict__.update({
            "x": x.copy(),
            "wrench": kf[7].copy(),
            "converged": True,
            "iterations": int(it),
            "residuals": dict(res),
            "path": path,
            "stability": stab,
            "held": src[2],
            "stability_end_held": stab,
            "warnings": () if stab.stable else (UNSTABLE_HELD_NOTE,),
            "checks": {},
            "_src": (x, st, src[3]),
        })
        return obj

    def _fast_factor(self, x, f6, qfull, big):
        """The quantities of one :meth:`_fast_newton` iteration at ``x``: (state, J (task
        rows, free columns), Q = [Y Z], R, multiplier F, static residual r, ∇E, Hessian
        H(F) of Ψ); None when a factorisation fails. Writes F into ``f6`` (task rows)."""
        kin, free, nt = self.kin, self.free, self.nt
        m, n = len(self.task), len(free)
        rows = None if self._all_task else self._task_rows
        # the Hessian of Ψ in screw form from J (no kinematic Hessian tensor) when the
        # model allows it (Kinematics.uses_screw), else Pinocchio's tensor contracted
        screw = self._smask is not None and getattr(kin, "uses_screw", False)
        st = kin.evaluate(x, hessian=not screw)
        if not screw and st.hessian is None:
            return None
        jfree = st.jacobian.take(free, axis=1)  # (6, n), (θ, q) order
        jac = jfree if rows is None else jfree[rows]
        tau = np.zeros(n)
        tau[:nt] = self.vm.K_theta @ (x.take(self.vm.theta_idx) - self.vm.theta0)  # ∇E: K_θ(θ − θ₀), 0 for q
        # complete QR of Jᵀ (n × m): Q = [Y Z], R = upper triangle of qr[:m]
        if big:
            qf, rf = np.linalg.qr(jac.T, mode="complete")
            rr, info, info2 = rf[:m], 0, 0
        else:
            qr, tq, _, info = _lapack.dgeqrf(jac.T)
            qfull[:, :m] = qr
            qf, _, info2 = _lapack.dorgqr(qfull, tq)
            rr = qr[:m]  # R is its upper triangle (dtrtrs reads only that)
        if info or info2:
            return None
        # the rank test (RANK_TOL, as null_space) is made where the result is used: at
        # convergence; before it a rank-deficient J gives a non-finite or clipped step
        f, info = _lapack.dtrtrs(rr, qf[:, :m].T @ tau)  # least-squares multiplier
        if info:
            return None
        r = tau - jac.T @ f
        f6[self._task_rows] = f
        if screw:
            hz = psi_hessian_screw(jfree, f6, self._smask)
        else:
            hz = contract_hessian(st.hessian, f6).take(self._hidx).reshape(n, n)
        return st, jac, qf, rr, f, r, tau, hz

    def _fast_error(self, st, pt, rt):
        """Task error ``e`` (task rows) at the state ``st`` and its largest position and
        orientation components (log3 only when orientation rows are constrained)."""
        ip, ir = self._ip, self._ir
        rows = None if self._all_task else self._task_rows
        if ir.size > 0:
            e = np.concatenate([pt - st.position, pin.log3(rt @ st.rotation.T)])
            if rows is not None:
                e = e[rows]
            ae = np.abs(e)
            ep = ae[ip].max() if ip.size else 0.0
            er = ae[ir].max()
        else:
            e = (pt - st.position)[rows]
            ep, er = np.abs(e).max(), 0.0
        return e, ep, er

    def _fast_accept(self, x, it, fact, f6, pt, rt, res, red_step, big) -> bool:
        """At a converged :meth:`_fast_newton` point: the rank test of ``J``, the stability
        verdict of eq. (23) and the caches for :meth:`_result` and :func:`evaluate_blocks`;
        False when the point must go to the safeguarded path instead."""
        key, kin, st, jac, qf, rr, _, _, _, hz = fact
        vm, kt, nt = self.vm, self.vm.K_theta, self.nt
        m, n = len(self.task), len(self.free)
        _, sv, _, info = _lapack.dgesdd(rr * self._triu, compute_uv=0)
        if info or not sv[-1] > RANK_TOL * sv[0]:  # descending
            return False
        # eq. (23) in the basis Z (its eigenvalues do not depend on the basis); the
        # polish step's Zᵀ(K − H)Z negated is this matrix bit for bit
        z = qf[:, m:]
        red = -red_step if red_step is not None else z.T @ (hz - self._kz) @ z
        if big:
            ev = np.linalg.eigvalsh(0.5 * (red + red.T))
        else:
            ev, _, info = _lapack.dsyevd(0.5 * (red + red.T), compute_v=0)
            if info:
                return False
        thr = STABILITY_TOL * (spectral_norm(kt) if kt.size else 1.0)
        stab = StabilityResult(bool(ev.size == 0 or ev.max() < -thr), ev, n - m, float(thr))
        if self.follow_stable and not stab.stable:
            self._fast_its = it
            return False
        self._fast_cache = (key + f6.tobytes() + pt.tobytes() + rt.tobytes(), res, stab)
        self._fast_fact = fact
        # the Blocks at this equilibrium, as evaluate_blocks would build them (the
        # stiffness of a curve point is evaluated here next)
        blocks = Blocks(jac[:, :nt], jac[:, nt:], hz[:nt, :nt], hz[:nt, nt:], hz[nt:, :nt], hz[nt:, nt:], kt, st)
        remember_blocks(vm, kin, x, f6, blocks)
        return True

    def _fast_descent_step(self, hz, y, z, rr, e, r, big):
        """The Newton step of :meth:`_fast_newton` away from convergence; None when the reduced
        matrix is not positive definite (``follow_stable``), a solve fails, or the step is
        longer than ``max_step``."""
        n, m = len(self.free), len(self.task)
        w = self._kz - hz
        red = z.T @ w @ z
        if self.follow_stable:  # ½(red + redᵀ) − shift·I ≻ 0
            sym = red + red.T
            sym.flat[np.arange(n - m) * (n - m + 1)] -= 2.0 * (SHIFT_TOL * self.kscale)
            if big:
                try:
                    np.linalg.cholesky(sym)
                except np.linalg.LinAlgError:
                    return None
            elif _lapack.dpotrf(sym, overwrite_a=1)[1]:
                return None  # not positive definite: the safeguarded path shifts it
        py, info = _lapack.dtrtrs(rr, e, trans=1)  # Rᵀ p_Y = e
        dy = y @ py
        if big:
            try:
                pz, info2 = np.linalg.solve(red, z.T @ (r + w @ dy)), 0
            except np.linalg.LinAlgError:
                return None
        else:
            _, _, pz, info2 = _lapack.dgesv(red, z.T @ (r + w @ dy), overwrite_b=1)
        if info or info2:
            return None
        dx = dy - z @ pz
        smax = np.abs(dx / self.var_scale).max()
        if not smax <= self.max_step:  # also catches NaN
            return None
        return dx

    def _fast_step(self, kz, hz, z, y, rr, e, r, big):
        """The unmodified Newton step of :meth:`_fast_newton` (None if singular) and the reduced
        matrix ``Zᵀ(K − H)Z`` it solved with (None if not formed)."""
        w = kz - hz
        red = z.T @ w @ z
        py, info = _lapack.dtrtrs(rr, e, trans=1)
        if info:
            return None, None
        dy = y @ py
        rhs = z.T @ (r + w @ dy)
        if big:
            try:
                pz = np.linalg.solve(red, rhs)
            except np.linalg.LinAlgError:
                return None, red
        else:  # LAPACK directly (numpy's wrapper costs more at this size)
            _, _, pz, info = _lapack.dgesv(red, rhs)
            if info:
                return None, red
        dx = dy - z @ pz
        return (dx if np.all(np.isfinite(dx)) else None), red

    def _newton(self, x, f, p_t, r_t, max_iter):
        """Newton on eq. (5) (matrix of eq. 28), kept on the constraint ``g = t``.

        Every iterate is first made geometrically feasible by least-energy restoration
        steps (:meth:`_restore`); then the spring energy itself is the merit function. When a
        stable branch is followed the reduced Hessian is shifted to be positive definite, so
        the step descends the energy, and a step is accepted only if the energy does not
        increase (Armijo), or, for an unmodified Newton step, if the residual of eq. (5)
        falls; a rejected step is shortened to the minimiser of the quadratic through the energy
        and its slope at the iterate and the energy at the rejected trial, kept in [0.1, 0.5] of
        it (:func:`_backtrack`; each trial costs a restoration). With ``follow_stable=False``
        full Newton steps are taken (unstable branches).
        The plain local iteration (:meth:`_fast_newton`) is tried first.
        """
        self._fast_its = 0
        fast = self._fast_newton(x, p_t, r_t)
        if fast is not None:
            xf, ff, itf, stf = fast
            return xf, ff, itf, True, stf
        return self._newton_rest(x, f, p_t, r_t, max_iter, self._fast_its)

    def _newton_rest(self, x, f, p_t, r_t, max_iter, spent):
        """:meth:`_newton` once its plain local iteration from ``x`` gave way after ``spent``
        iterations: the safeguarded iteration, then the local one from its equilibrium."""
        x, f, it, ok, state = self._newton_safeguarded(x, f, p_t, r_t, max_iter)
        if ok:  # polish (and cache the verdict) by the local iteration from the converged point
            fast = self._fast_newton(x, p_t, r_t)
            if fast is not None:
                x, f, itp, state = fast
                it += itp
        return x, f, it + spent, ok, state

    def _relaxed_local(self, x, p_t, r_t):
        """The fused local iteration from ``x`` (a feasible iterate of the safeguarded path that
        descended from a push off an unstable equilibrium, :meth:`_escape`) with the relaxed progress
        test of :meth:`_fused_iterations`: unmodified Newton steps of eq. (28) while the reduced
        Hessian is positive definite and the step within the step limit (at most :data:`HANDOFF_STEPS`),
        kept only if they converge to a stable equilibrium whose energy does not exceed that at ``x``
        (the safeguarded path only descends from ``x``). Next to a bifurcation the residual of a
        full Newton step rises before it falls (a soft mode), so the plain local iteration gives way
        where these steps converge. Returns (x, f, iterations, state) or None (the safeguarded
        iteration goes on from ``x``)."""
        if self.method != "newton" or not self.follow_stable:
            return None
        ctx = self._lean_context()
        if ctx is None:
            return None
        e0 = self.energy(x)
        raw = self._fused_iterations(ctx, p_t, r_t, x, relaxed=HANDOFF_STEPS)
        if raw is None or not self.energy(raw[0]) <= e0 + 1e-14 * max(abs(e0), 1e-300):
            return None
        return raw[:4]

    def _newton_safeguarded(self, x, f, p_t, r_t, max_iter):
        vm = self.vm
        kz = self._kz  # (K_θ ⊕ 0, read only)
        m = len(self.task)
        n = len(self.free)
        x, state, ok = self._restore(x.copy(), None, p_t, r_t, max_iter=40)
        if not ok:
            return x, f, 0, False, state
        for it in range(max_iter + 1):
            jz = state.jacobian[self.task][:, self.free]
            tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
            grad = np.concatenate([tau, np.zeros(vm.n_q)])
            f = np.linalg.lstsq(jz.T, grad, rcond=None)[0]  # least-squares multiplier
            e, jz, grad, r, res, ok = self._residuals(x, f, state, p_t, r_t)
            if ok:
                return x, f, it, True, state
            if it == max_iter:
                break
            if it and self._handoff:  # an escape attempt: the local iteration from the accepted iterate
                got = self._relaxed_local(x, p_t, r_t)
                if got is not None:
                    xr, fr, itr, sr = got
                    return xr, fr, it + itr, True, sr
            h = self._psi_hessian(x, state, full_wrench(vm, f))
            w = kz - h
            modified = False
            if self.follow_stable:
                z = null_space(jz[:, : self.nt], jz[:, self.nt :])
                if z.shape[1]:
                    red = z.T @ w @ z
                    lam = np.linalg.eigvalsh(0.5 * (red + red.T)).min()
                    delta = SHIFT_TOL * self.kscale
                    if lam < delta:
                        w = w + (delta - lam + 1e-3 * abs(lam)) * np.eye(n)
                        modified = True
            a = np.zeros((n + m, n + m))
            a[:n, :n] = w
            a[:n, n:] = -jz.T
            a[n:, :n] = jz
            rhs = np.concatenate([-r, e])
            try:
                sol = np.linalg.solve(a, rhs)
                if not np.all(np.isfinite(sol)):
                    raise np.linalg.LinAlgError
            except np.linalg.LinAlgError:
                sol = np.linalg.lstsq(a, rhs, rcond=None)[0]
            dz = sol[:n]
            smax = np.abs(dz / self.var_scale).max() if n else 0.0
            if smax > self.max_step:
                dz = dz * (self.max_step / smax)
                modified = True
            e0 = self.energy(x)
            slope = float(grad @ dz)
            kkt0 = self._kkt_norm(e, r)
            alpha = 1.0
            accepted = False
            for _ in range(30):
                xn = x.copy()
                xn[self.free] += alpha * dz
                flush_tiny(xn)
                xn, sn, feas = self._restore(xn, None, p_t, r_t)
                en_ = None
                if feas:
                    en_ = self.energy(xn)
                    if not self.follow_stable:
                        accepted = True
                    elif en_ <= e0 + 1e-4 * alpha * min(slope, 0.0) + 1e-14 * max(abs(e0), 1e-300):
                        accepted = True
                    elif alpha == 1.0 and not modified:
                        tau_n = vm.K_theta @ (xn[vm.theta_idx] - vm.theta0)
                        jn = sn.jacobian[self.task][:, self.free]
                        gn = np.concatenate([tau_n, np.zeros(vm.n_q)])
                        fn = np.linalg.lstsq(jn.T, gn, rcond=None)[0]
                        e_n, _, _, r_n, _, _ = self._residuals(xn, fn, sn, p_t, r_t)
                        accepted = self._kkt_norm(e_n, r_n) < 0.5 * kkt0
                if accepted:
                    break
                alpha = _backtrack(alpha, e0, slope, en_) if _safeguard_shortcuts else 0.5 * alpha
            if not accepted:
                return x, f, it + 1, False, state
            x, state = xn, sn
        return x, f, max_iter, False, state

    def _restore(self, x, state, p_t, r_t, max_iter: int = 12):
        """Least-energy restoration of ``g(x) = t``: repeated steps ``δ = M⁻¹Jᵀ(J M⁻¹ Jᵀ)⁻¹ e``
        with the metric ``M = diag(K_θ, 0) + ε·I`` (passive joints move first, as in the
        fixed-point scheme of eq. 10). Returns (x, state, converged); ``state`` carries no
        Hessian (callers evaluate it when they need it)."""
        tol_p = self.tol * self.length_scale
        kin, task, free, minv, escale = self.kin, self._task_idx, self.free, self.Minv, self._err_scale
        lim, max_step, vscale = 0.01 * self.tol, self.max_step, self.var_scale
        p_t = np.asarray(p_t)
        # the pose error's task rows (pose_error(...)[task]); log3 only when rotations are held
        rot, rows = self._ir.size > 0, self._task_rows
        solve, isfinite = np.linalg.solve, np.isfinite
        step = _kernel.restorer() if getattr(_kernel.get(), "dispatcher", None) is not None else None
        if step is not None:  # the compiled step (kernel._restore_step): the same iteration
            pt = np.asarray(p_t, float)
            flush, zero3, nq = bool(_chain._flush_enabled), self._zero3, x.shape[0]
            ck = self._compiled_chain([]) if state is None else None
            loop = _kernel.restore_looped() if ck is not None else None
            if loop is not None:  # the whole restoration with the compiled kinematics: one call
                kbuf = (np.empty((6, kin.model.nv)), np.empty(3), np.empty((3, 3)))
                xo = np.empty(nq)
                rt = np.ascontiguousarray(r_t, dtype=float)
                status, _ = loop(np.ascontiguousarray(x, dtype=float), ck[3], ck[4], rt, rot, task, free, minv, escale,
                                 vscale, pt, lim, max_step, flush, max_iter, xo, kbuf)
                state = _built(KinematicState, {"position": kbuf[1], "rotation": kbuf[2], "jacobian": kbuf[0],
                                                "hessian": None})
                kin._last = (xo.tobytes(), state)  # kin.evaluate(xo, hessian=False): no Pinocchio call
                if status != 0:
                    return xo, state, status == 1
                e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
                return xo, state, bool(np.abs(e).max() <= max(tol_p, self.tol))
            for _ in range(max_iter + 1):
                if state is None:
                    state = kin.evaluate(x, hessian=False)
                erot = pin.log3(np.asarray(r_t) @ state.rotation.T) if rot else zero3
                xn = np.empty(nq)
                status = step(state.position, erot, state.jacobian, x, task, free, minv, escale, vscale, pt, lim,
                              max_step, flush, xn)
                if status == 1:
                    return x, state, True
                if status < 0:
                    return x, state, False
                x, state = xn, None
            state = kin.evaluate(x, hessian=False)
            e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
            return x, state, bool(np.abs(e).max() <= max(tol_p, self.tol))
        for _ in range(max_iter + 1):
            if state is None:
                state = kin.evaluate(x, hessian=False)
            if rot:
                e = np.concatenate([p_t - state.position, pin.log3(np.asarray(r_t) @ state.rotation.T)])[task]
            else:
                e = (p_t - state.position)[rows]
            scaled = np.abs(e / escale).max() if e.size else 0.0
            if scaled <= lim:
                return x, state, True
            jz = state.jacobian[task][:, free]
            a = jz @ minv @ jz.T
            try:
                delta = minv @ jz.T @ solve(a, e)
            except np.linalg.LinAlgError:
                return x, state, False
            if not isfinite(delta).all():
                return x, state, False
            big = np.abs(delta / vscale).max()
            if big > max_step:  # damped (far from the constraint, e.g. a straight chain)
                delta *= max_step / big
            x = x.copy()
            x[free] += delta
            flush_tiny(x)
            state = None
        state = kin.evaluate(x, hessian=False)
        e = pose_error(p_t, r_t, state.position, state.rotation)[self.task]
        return x, state, bool(np.abs(e).max() <= max(tol_p, self.tol))

    def _fixed_point(self, x, f, p_t, r_t, max_iter):
        vm = self.vm
        x = x.copy()
        state = self.kin.evaluate(x, hessian=False)
        for it in range(max_iter + 1):
            e, jz, _, _, res, ok = self._residuals(x, f, state, p_t, r_t)
            if ok and it > 0:
                return x, f, it, True, self.kin.evaluate(x)
            if it == max_iter:
                break
            jt, jq = jz[:, : self.nt], jz[:, self.nt :]
            m, nq = jt.shape[0], jq.shape[1]
            a = np.zeros((m + nq, m + nq))
            a[:m, :m] = jt @ self.Kinv @ jt.T
            a[:m, m:] = jq
            a[m:, :m] = jq.T
            theta = x[vm.theta_idx]
            rhs = np.concatenate([e + jt @ (theta - vm.theta0), np.zeros(nq)])
            try:
                sol = np.linalg.solve(a, rhs)
            except np.linalg.LinAlgError:
                return x, f, it, False, self.kin.evaluate(x)
            f = sol[:m]
            x[vm.q_idx] += sol[m:]
            x[vm.theta_idx] = vm.theta0 + self.Kinv @ jt.T @ f
            flush_tiny(x)
            if not np.all(np.isfinite(x)):
                return x, f, it, False, self.kin.evaluate(np.nan_to_num(x))
            state = self.kin.evaluate(x, hessian=False)
        return x, f, max_iter, False, self.kin.evaluate(x)

    # ----------------------------------------------------------------- public
    def _result(self, x, f, iters, ok, state, p_t, r_t, path, with_stability=True) -> EquilibriumResult:
        vm = self.vm
        fc = self._fast_cache
        if fc is not None and len(fc) > 3 and fc[3] is x and fc[4] is f and fc[6] is p_t and fc[7] is r_t:
            # straight from the fused iteration's convergence (its own arrays): its wrench (6,)
            w6 = fc[5].copy()  # full_wrench(vm, f)
            res, stab = dict(fc[1]), fc[2]
        else:
            w6 = np.zeros(6)
            w6[self._task_rows] = f  # full_wrench(vm, f)
            if fc is not None and fc[0] == x.tobytes() + w6.tobytes() + p_t.tobytes() + r_t.tobytes():  # by _fast_newton
                res, stab = dict(fc[1]), fc[2]
            else:
                _, _, _, _, res, _ = self._residuals(x, f, state, p_t, r_t)
                stab = None
        if not (with_stability and ok):
            stab = None
        elif stab is None:
            stab = check_stability(evaluate_blocks(vm, self.kin, x, w6, state))
        return self._pack(
            x, w6, state, ok, iters, res, path, stab, stab, tuple(self.task),
            () if stab is None or stab.stable else (UNSTABLE_HELD_NOTE,),
        )

    def _pack(self, x, w6, state, ok, iters, res, path, stab, end, held, warnings) -> EquilibriumResult:
        """The :class:`EquilibriumResult` at configuration ``x`` (kinematic ``state``) under the
        total end wrench ``w6``, shared by the all-held and the mixed-control solves."""
        vm = self.vm
        pos, rot = state.position, state.rotation
        theta = x[vm.theta_idx]  # (index arrays: already copies)
        d = theta - vm.theta0  # energy(x)
        dfl = np.empty(6)  # kinematics.chain.deflection, written in place
        np.subtract(pos, self.p0, out=dfl[:3])
        dfl[3:] = pin.log3(rot @ self.r0.T)
        return _built(EquilibriumResult, {
            "x": x.copy(),
            "q": x[vm.q_idx],
            "theta": theta,
            "wrench": w6,
            "deflection": dfl,
            "position": pos.copy(),
            "rotation": rot.copy(),
            "converged": bool(ok),
            "iterations": int(iters),
            "residuals": res,
            "energy": 0.5 * float(d @ vm.K_theta @ d),
            "path": path,
            "stability": stab,
            "held": held,
            "stability_end_held": end,
            "warnings": warnings,
            "checks": {},
        })

    def _solve_local(self, deflection, x0: np.ndarray) -> EquilibriumResult | None:
        """The plain local Newton iteration alone (:meth:`_fast_newton`) from ``x0``: its
        equilibrium when it converges to an acceptable one (stable when ``follow_stable``),
        else None and the caller solves as usual. No safeguards, restarts or continuation:
        for a predicted start (tangent predictor of :func:`~vjm_pin.analysis.curve.trace_curve`).
        ``self._fast_its`` holds the iterations spent when it returns None."""
        self._fast_its = 0
        if self.method != "newton":
            return None
        p_t, r_t = _as_target(self.vm, self.kin, self.p0, self.r0, deflection, None)
        out = self._fast_newton(np.asarray(x0, float), p_t, r_t)
        if out is None:
            return None
        x, f, it, st = out
        return self._result(x, f, it, True, st, p_t, r_t, "newton+tangent-predictor")

    def _perturb(self, x, rng):
        if not isinstance(rng, np.random.Generator):  # a one-element box: created when first needed
            if not rng:
                rng.append(np.random.default_rng(self.seed))
            rng = rng[0]
        xn = x.copy()
        noise = rng.standard_normal(len(self.free)) * self.perturbation
        noise = np.where(self.var_scale > 1.0, noise * 1e-3 * self.length_scale, noise)
        xn[self.free] += noise
        return xn

    # ----------------------------------------------------------------- inputs
    def _task_wrench(self, wrench0) -> np.ndarray:
        """A starting wrench as task-row values: ``wrench0`` is (6,) (all components) or
        (m,) (the task rows, in task order); None gives zeros."""
        m = len(self.task)
        if wrench0 is None:
            return np.zeros(m)
        if type(wrench0) is np.ndarray and wrench0.shape == (6,) and wrench0.dtype == np.float64:
            w = wrench0.take(self._task_idx)  # (a copy) the common case: a result's wrench
            if _all_finite(w):
                return w
        w = np.asarray(wrench0, dtype=float).ravel()
        if w.size == 6:
            w = w[self.task]
        elif w.size != m:
            raise InputError(f"wrench0 must have 6 or {m} (task) components (N, N·m), got {w.size}")
        if not np.isfinite(w).all():
            raise InputError("wrench0 contains NaN or infinite values")
        return w.copy()

    def _start(self, x0) -> np.ndarray:
        vm = self.vm
        x = vm.reference.copy() if x0 is None else np.asarray(x0, float).ravel().copy()
        if x.shape != (vm.model.nq,) or not _all_finite(x):
            raise InputError(f"x0 must be a finite configuration of size {vm.model.nq}")
        return x

    def _vector6(self, v, name: str, unit: str) -> np.ndarray:
        """(6,) from 6 numbers, 3 numbers (x y z: the rest zero) or ``len(task)`` numbers (the
        task rows, in task order); :class:`InputError` on a wrong size or a NaN/inf."""
        if type(v) is np.ndarray and v.shape == (6,) and v.dtype == np.float64:
            # the common case (a curve's solves), as task_vector reads it: a copy, finite
            a = v.copy()
            if _all_finite(a):
                return a
        return task_vector(v, self.task, name, unit, task_sized=True, outside_task="keep")

    def components(self, spec) -> tuple[int, ...]:
        """Task component indices (task order) from names (``"x"``, ``"rz"``; a string of
        space-separated names) or indices 0..5; :class:`InputError` for a name that is not
        a component or not in the task."""
        if spec is None:
            return ()
        items = spec.split() if isinstance(spec, str) else list(spec)
        out = set()
        for c in items:
            if isinstance(c, str):
                if c not in COMPONENTS:
                    raise InputError(f"unknown task component {c!r}; components are {' '.join(COMPONENTS)}")
                c = COMPONENTS.index(c)
            elif isinstance(c, (int, np.integer)) and not isinstance(c, bool) and 0 <= c < 6:
                c = int(c)
            else:
                raise InputError(f"task components are names ({' '.join(COMPONENTS)}) or indices 0..5; got {c!r}")
            if c not in self.task:
                raise InputError(
                    f"component {COMPONENTS[c]} is not in the task of this model ({' '.join(self.vm.task_names)})"
                )
            out.add(c)
        return tuple(c for c in self.task if c in out)

    def _partial_rotation(self, held) -> list[int]:
        """The held rotation components when some but not all of rx ry rz are held (else [])."""
        hrot = [c for c in held if c >= 3]
        return hrot if 0 < len(hrot) < 3 else []

    def _target_pose(self, d):
        """The end pose ``displace(p0, r0, d)`` of the (6,) deflection ``d`` (without ``exp3`` for a
        zero rotation part: the same numbers)."""
        if d.tobytes()[24:] == _ZERO3:  # (d[3:]'s bytes)
            return self.p0 + d[:3], self._r_unrotated.copy()
        return displace(self.p0, self.r0, d)

    def _rotation_targets(self, d, held, run, x0, f0, raise_on_failure: bool = True) -> EquilibriumResult:
        """Meet the held rotation components of the deflection ``d`` in the reported
        coordinates ``log3(R R0ᵀ)`` when only some rotations are held.

        Every inner solve (``run(p_t, r_t, x0, f0)``) holds the rows of the pose error
        ``log3(R_t Rᵀ)`` with ``R_t = exp3(d̂) R0``, a twist-type constraint whose multiplier
        is the physical moment about the world axes of the held rows. The target ``d̂`` is
        corrected: ``d̂[held] += d[held] − φ[held]`` and ``d̂[other] = φ[other]`` with ``φ =
        log3(R R0ᵀ)`` of the last equilibrium, until ``|φ[held] − d[held]| ≤``
        :data:`ROTATION_TARGET_TOL`; at the fixed point ``R_t = R``, so the held components
        of the reported deflection equal the request and the wrench is the physical one.
        Far from the reference the fixed point converges slowly (the free rotation-vector
        components move with the held ones; a secant step diverged there). A held component missed by more than :data:`ROTATION_TARGET_FAIL` is a failure
        (:class:`NoEquilibrium`, or ``converged=False`` without ``raise_on_failure``), never a
        result with a warning only."""
        hrot = self._partial_rotation(held)
        p, r = self._target_pose(d)
        res = run(p, r, x0, f0)
        if not hrot:
            return res
        other = [c for c in (3, 4, 5) if c not in hrot]
        dh = np.array(d, float)
        total = res.iterations
        k = 0
        prev = np.inf
        for k in range(1, ROTATION_TARGET_ITER + 1):
            if not res.converged:
                break
            err = d[hrot] - res.deflection[hrot]
            size = np.abs(err).max()
            if size <= 0.1 * ROTATION_TARGET_TOL or (size <= ROTATION_TARGET_TOL and size > 0.5 * prev):
                break  # met (or met and no longer improving: the inner solve's own accuracy)
            prev = size
            dh[hrot] += err
            dh[other] = res.deflection[other]
            p, r = displace(self.p0, self.r0, dh)
            res = run(p, r, res.x, res.wrench)
            total += res.iterations
        warn = res.warnings
        miss = float(np.abs(d[hrot] - res.deflection[hrot]).max())
        if res.converged and miss > ROTATION_TARGET_TOL:
            warn = warn + (f"held rotation components met to {miss:.2g} rad only",)
        res = replace(res, iterations=total, path=res.path + f"+rotation-target({k})", warnings=warn)
        if res.converged and miss > ROTATION_TARGET_FAIL:
            msg = (
                f"held rotation components {[COMPONENTS[c] for c in hrot]} missed by {miss:.3g} rad "
                f"after {k} target corrections (tolerance {ROTATION_TARGET_FAIL:g} rad)"
            )
            res = replace(res, converged=False)
            if raise_on_failure:
                raise NoEquilibrium(msg, res, miss)
        return res

    # ----------------------------------------------------------------- deflection-driven
    def solve(
        self,
        deflection=None,
        *,
        target=None,
        x0: np.ndarray | None = None,
        wrench0: np.ndarray | None = None,
        raise_on_failure: bool = True,
        fast_fail: bool = False,
    ) -> EquilibriumResult:
        """Equilibrium for a prescribed end location: every task component held (eq. 5–10).

        A stable equilibrium is returned whenever one is found: when the iteration converges
        to an unstable one (eq. 23 fails) the configuration is pushed along each unstable
        eigenvector of the matrix of eq. (23), both signs, and re-solved; the stable one of
        lowest energy is kept (path ``+escape(k)``; energies within 10·tol of each other, e.g. the
        two mirror images of a symmetric buckled column, are a tie won by the first found, so the
        branch does not depend on rounding); then seeded random restarts. When only
        unstable equilibria are found, the one of lowest energy is returned with
        ``stable=False`` and a note in ``warnings``.

        Args:
            deflection: Deflection from the unloaded end location: 6 numbers (position m,
                world rotation vector rad), 3 (position only) or ``len(task)`` (the task
                rows, in task order). Components outside the task must be zero. The held
                components of the returned ``deflection`` equal these (to 1e-12 rad for a
                task with some but not all rotations, see :meth:`_rotation_targets`).
                Or give ``target``.
            target: (position (3,), rotation (3, 3)) of the end frame; the task rows of the
                pose error ``(p* − p, log3(R* Rᵀ))`` are driven to zero.
            x0: Starting configuration (nq,); default the unloaded reference (warm start
                from a neighbouring equilibrium when tracing a curve).
            wrench0: Starting wrench, (6,) or (m,) task rows (N, N·m); default zero.
            raise_on_failure: Raise :class:`NoEquilibrium` (carrying the last iterate) when
                no attempt converges; otherwise return it with ``converged=False``.
            fast_fail: One Newton attempt from ``x0``, without continuation, escapes or
                perturbed restarts: for trial points of a line search, where a failure only
                shortens the step and the full recovery is wasted.

        A zero ``deflection`` from the default start where the end frame cannot move along some
        task direction (a straight chain of rigid links, Model A S: every force along it
        balances there) gives the unloaded reference with zero wrench, the minimum-norm one
        (path ``"reference"``, 0 iterations; :meth:`_unloaded_reference`).
        """
        if x0 is None and wrench0 is None and target is None:
            ref = self._unloaded_reference(deflection)
            if ref is not None:
                return ref
        if target is None and x0 is not None and len(self.free) <= SCIPY_LAPACK_MAX_N:
            # a warm start (curve tracing) of a small model: the lean path when it applies, without
            # the BLAS thread limit (OpenBLAS runs one thread at these orders anyway; its fallback
            # takes the limit)
            res = self._solve_lean(deflection, x0, wrench0, raise_on_failure, fast_fail)
            if res is not None:
                return res
        return self._solve_limited(deflection, target, x0, wrench0, raise_on_failure, fast_fail)

    def _unloaded_reference(self, deflection) -> EquilibriumResult | None:
        """The unloaded reference as the equilibrium of a zero ``deflection`` where the end frame
        cannot move along some task direction there (``J`` rank deficient at the start: the test
        that would perturb it, :meth:`_start_regular`). Every wrench along such a direction
        balances at the reference (``Jᵀw = 0``), so the held problem leaves it indeterminate; the
        minimum-norm one, zero, is the unloaded state (as the curve tracer starts:
        :func:`vjm_pin.analysis.curve._unloaded`), where a perturbed start would pick an arbitrary
        force and a bend. Returned with its eq. (23) verdict (path ``"reference"``, 0 iterations),
        or None: a non-zero or malformed deflection (the usual path answers), a spring preloaded at
        the reference (not an equilibrium without load), or a regular start (the iteration
        returns the reference itself)."""
        try:
            d = np.asarray(deflection, dtype=float)
        except (TypeError, ValueError):
            return None
        if d.ndim != 1 or d.size not in (3, 6, len(self.task)) or not (_all_finite(d) and not d.any()):
            return None
        x = reference_if_unloaded(self.vm)
        if x is None or self._start_regular(x):
            return None
        state = self.kin.evaluate(x, hessian=False)
        return self._result(x, np.zeros(len(self.task)), 0, True, state, self.p0, self.r0, "reference")

    @one_blas_thread
    def _solve_limited(self, deflection, target, x0, wrench0, raise_on_failure, fast_fail) -> EquilibriumResult:
        """:meth:`solve` under one BLAS thread (:mod:`vjm_pin.solver.threads`)."""
        if target is None and x0 is not None and len(self.free) > SCIPY_LAPACK_MAX_N:
            res = self._solve_lean(deflection, x0, wrench0, raise_on_failure, fast_fail)
            if res is not None:
                return res
        x_start = self._start(x0)
        f_start = self._task_wrench(wrench0)

        def run(p, r, x, f):
            # f_start is task rows already (a later target correction passes a result's (6,) wrench)
            return self._solve_target(p, r, x, f if f is f_start else self._task_wrench(f), raise_on_failure, fast_fail)

        if target is not None or deflection is None:
            p_t, r_t = _as_target(self.vm, self.kin, self.p0, self.r0, deflection, target)
            return run(p_t, r_t, x_start, f_start)
        d = self._vector6(deflection, "deflection", "m, rad")
        if self._off_task.size and d.take(self._off_task).any():
            task_vector(d, self.vm.task, "deflection", "m, rad")  # its error: components outside the task (as _as_target)
        if not self._partial_task_rotation:  # one target pose (what _rotation_targets does then)
            p_t, r_t = self._target_pose(d)
            return self._solve_target(p_t, r_t, x_start, f_start, raise_on_failure, fast_fail)
        return self._rotation_targets(d, self.task, run, x_start, f_start, raise_on_failure)

    def _escape(self, res, p_t, r_t, attempt_once) -> list[EquilibriumResult]:
        """Stable equilibria reached from the unstable equilibrium ``res`` by pushing its
        configuration along each unstable eigenvector of the matrix of eq. (23) (at most
        :data:`ESCAPE_MODES`), both signs, amplitudes :data:`ESCAPE_AMPLITUDES` (rad, or
        ×L_c for prescribed coordinates) and re-solving with energy descent."""
        vm = self.vm
        b = evaluate_blocks(vm, self.kin, res.x, res.wrench)
        basis = null_space(b.J_theta, b.J_q)
        if not basis.shape[1]:
            return []
        ev, vecs = np.linalg.eigh(reduced_matrix(b, basis))
        thr = res.stability.tolerance if res.stability is not None else 0.0
        found = []
        self._handoff = True
        try:
            for j in np.argsort(-ev)[:ESCAPE_MODES]:
                if ev[j] < -thr:
                    break
                v = basis @ vecs[:, j]
                v = v / max(np.abs(v / self.var_scale).max(), 1e-300)
                for sign in (1.0, -1.0):
                    for amp in ESCAPE_AMPLITUDES:
                        x = res.x.copy()
                        x[self.free] += sign * amp * v
                        r2 = attempt_once(x)
                        if r2.converged and r2.stable:
                            found.append(r2)
                            break
        finally:
            self._handoff = False
        return found

    def _start_regular(self, x_start, jz0=None) -> bool:
        """False when ``J`` (task rows, free columns) at the start is rank deficient (smallest
        singular value ≤ 1e-9 × the largest): the start is then perturbed (§4.1). A warm start from
        the last fast-path equilibrium reads its kept ``J`` (or ``jz0``: that ``J``, given)."""
        fact = self._fast_fact
        if jz0 is not None:
            pass
        elif fact is not None and fact[1] is self.kin and fact[0] == x_start.tobytes():
            jz0 = fact[3]  # a warm start from the last fast-path equilibrium: its J (task rows, free columns)
        else:
            jz0 = self.kin.evaluate(x_start, hessian=False).jacobian[self._task_rows].take(self.free, axis=1)
        sv = _singular_values(jz0)  # descending
        return not (sv.size < len(self.task) or sv[-1] <= 1e-9 * max(sv[0], 1e-300))

    def _lean_context(self):
        """The kernel context of :meth:`_solve_lean` (the layout of :meth:`_corrector_context`), kept
        while the kernel's constants and implementation stay the same; None when the fused local
        iteration does not apply (another method, a task of 0 or ≥ n rows, no screw-form Hessian,
        the fused kernel switched off). ``VJM_PIN_JIT`` is read at every call, as
        :meth:`_fast_newton_fused` reads it."""
        kernel = _kernel
        kept = self._lean_ctx
        if kept is not None and _fused_enabled:  # (the kept context's own test, cut to what can change)
            kp = self._kpack
            if (kp is not None and kp[1] is kept[0]
                    and kp[0] == (self.tol, self.follow_stable, self.max_step, self.kscale, id(self.kin))
                    and kept[1][4] is kernel.get(kernel.mode())):
                return kept[1]
        m, n = len(self.task), len(self.free)
        if (m == 0 or m >= n or not _fused_enabled or self._smask is None
                or not getattr(self.kin, "uses_screw", False)):
            return None
        consts, thr = self._kernel_consts()
        md = kernel.mode()
        fn = kernel.get(md)
        if kept is not None and kept[0] is consts and kept[1][4] is fn:
            return kept[1]
        cf = consts[1].copy()  # its own target slots
        own = (consts[0], cf) + tuple(consts[2:])
        # the compiled kernel called directly, its arrays into buffers (kernel.lean), below the chain
        # kernel's order (as _corrector)
        small = getattr(fn, "dispatcher", None) is not None and n < _chain_kernel_min_n()
        lean = kernel.lean() if small else None
        direct = (lean,) + own[2:] if lean is not None else None
        ws = kernel.workspace(own[0], self.kin.model.nq) if lean is not None else None
        # [mode, consts, cf, thr, step function, direct call, its buffers, stable verdicts certified without
        # the eigenvalues (see _fused_iterations)], kept with the constants it was built from
        ctx = [md, own, cf, thr, fn, direct, ws, True]
        self._lean_ctx = (consts, ctx)
        return ctx

    def _solve_lean(self, deflection, x0, wrench0, raise_on_failure, fast_fail) -> EquilibriumResult | None:
        """:meth:`solve` of a warm start from the equilibrium this solver found last (a curve's next
        point): the same checks, iterations and result as the general path, with its set-up cut to
        what this case needs; None (nothing done) when the case does not apply: another method, a
        task with some but not all rotations, the fused kernel not applicable, inputs other than
        float64 arrays of their final shapes, a non-finite or out-of-task input (the general path
        raises its error), or ``x0`` not bit for bit the last fast-path equilibrium.

        The deflection is read as :meth:`_vector6` reads a (6,) array, the start as :meth:`_start`
        (finite, as that equilibrium is), ``wrench0`` validated as :meth:`_task_wrench` (the
        local iteration does not read it; a later attempt does); the perturbed-start test of
        :meth:`_solve_target` reads the kept ``J``; the plain local iteration is
        :meth:`_fused_iterations` with the kernel context kept between solves
        (:meth:`_lean_context`). When it gives way the solve goes on in :meth:`_solve_target`
        (``spent``), as the general path does.

        With the compiled kernel the start test reads the kernel's bound of ``cond(J)`` at that
        equilibrium when it is conclusive (``_fast_cond``; the SVD otherwise) and a stable verdict's
        eigenvalues are computed when first read (:class:`~vjm_pin.solver.stability.SpectrumLater`).
        The result is a :class:`~vjm_pin.solver.deferred_result.DeferredResult` (:meth:`_corrector_result`):
        the fields derived from ``x`` and the end placement computed when first read, the same numbers
        as :meth:`_pack`'s."""
        if self.method != "newton" or self._partial_task_rotation:
            return None
        fact = self._fast_fact
        if (fact is None or fact[1] is not self.kin or type(x0) is not np.ndarray or x0.ndim != 1
                or (x0.dtype is not _F64 and x0.dtype != _F64) or fact[0] != x0.tobytes()):
            return None  # (x0 float64, 1-D, its bytes those of the (nq,) equilibrium: of shape (nq,))
        d = deflection
        if type(d) is not np.ndarray or (d.dtype is not _F64 and d.dtype != _F64) or d.shape != (6,):
            return None
        # finite (a sum of Python floats: no overflow warning; a huge finite input overflows it to
        # inf and takes the general path, which accepts it) and zero outside the task
        dl = d.tolist()
        if not math.isfinite(sum(dl)) or any(dl[i] for i in self._off_task_list):
            return None
        if wrench0 is not None:
            w = wrench0
            if type(w) is not np.ndarray or (w.dtype is not _F64 and w.dtype != _F64) or w.shape != (6,):
                return None
            wl = w.tolist()
            if not math.isfinite(sum([wl[i] for i in self.task])):  # (task rows, as _task_wrench reads them)
                return None
        ctx = self._lean_context()
        if ctx is None:
            return None
        fc = self._fast_cond
        if not (fc is not None and fc[0] is fact[0] and 1e-9 * fc[1] < 0.5) and not self._start_regular(x0, fact[3]):
            # (σ_min/σ_max ≥ 1/cond(J)-bound > 2e-9 passes _start_regular's test without its SVD)
            return None  # (perturbed: the general path)
        p_t, r_t = self._target_pose(d)
        self._fast_its = 0
        raw = self._fused_iterations(ctx, p_t, r_t, x0)
        if raw is None:  # the plain local iteration gave way: the general path from there
            x_start = x0.copy()
            f_start = self._task_wrench(wrench0)
            with single_blas_thread():
                return self._solve_target(p_t, r_t, x_start, f_start, raise_on_failure, fast_fail, spent=self._fast_its)
        # the fields derived from x and the end placement computed when first read (the same numbers
        # as _pack: DeferredResult)
        return self._corrector_result(raw, p_t, r_t, "newton")

    def _lowest(self, found: list[EquilibriumResult]) -> EquilibriumResult:
        """The equilibrium of lowest energy in ``found``; energies within ``10·tol`` (relative) of
        the lowest are a tie, won by the first found. Mirror-image branches (a symmetric chain
        buckling either way) have equal energies up to the convergence tolerance: without the tie
        the branch would be chosen by rounding (and could differ between the compiled kernel and
        its numpy twin)."""
        low = min(r.energy for r in found)
        tie = 10.0 * self.tol * max(abs(low), 1e-300)
        return next(r for r in found if r.energy <= low + tie)

    def _solve_target(self, p_t, r_t, x_start, f_start, raise_on_failure, fast_fail, spent=None) -> EquilibriumResult:
        """:meth:`solve` for the target pose ``(p_t, r_t)`` (every task row held). ``spent``: the start
        passed the perturbed-start test and the plain local iteration from it already gave way after
        ``spent`` iterations (:meth:`_solve_lean`); the attempt goes on from there."""
        rng = []  # the restart noise generator, seeded with ``seed`` when first used
        total = 0
        name = self.method

        def attempt(x_init, f_init, label, continuation=True, spent=None):
            nonlocal total
            if spent is None:
                x, f, it, ok, st = self._iterate(x_init, f_init, p_t, r_t, self.max_iter)
            else:  # Newton whose plain local iteration from x_init already gave way (spent iterations)
                x, f, it, ok, st = self._newton_rest(x_init, f_init, p_t, r_t, self.max_iter, spent)
            total += it
            if not ok and (fast_fail or not continuation):
                return self._result(x, f, total, False, st, p_t, r_t, label, with_stability=False)
            if not ok:
                # continuation from the attempt's start towards the target
                ps, rs = self.kin.placement(x_init)
                for nsteps in (4, 16):
                    xc, fc, okc = x_init.copy(), f_init.copy(), True
                    dlog = pin.log3(r_t @ rs.T)
                    for k in range(1, nsteps + 1):
                        a = k / nsteps
                        pk = (1 - a) * ps + a * p_t
                        rk = pin.exp3(a * dlog) @ rs
                        xc, fc, itc, okc, st = self._iterate(xc, fc, pk, rk, self.max_iter)
                        total += itc
                        if not okc:
                            break
                    if okc:
                        return self._result(xc, fc, total, True, st, p_t, r_t, f"{label}+continuation({nsteps})")
                return self._result(x, f, total, False, st, p_t, r_t, label, with_stability=False)
            return self._result(x, f, total, True, st, p_t, r_t, label)

        def done(r):
            return r if r.iterations == total else replace(r, iterations=total)

        if spent is not None:  # (the start passed its test in _solve_lean)
            res = attempt(x_start, f_start, name, spent=spent)
        else:
            # A start where the end cannot move in some constrained direction (e.g. a straight
            # chain of rigid links) gives a singular eq. (28)/(10) matrix: perturb it first (§4.1).
            if not self._start_regular(x_start):
                x_start = self._perturb(x_start, rng)
                name += "+perturbed-start"
            if name == "newton":  # the common case first, without the attempt machinery
                self._fast_its = 0
                fast = self._fast_newton(x_start, p_t, r_t)
                if fast is not None:  # stable, or any equilibrium when not follow_stable: done
                    x, f, it, st = fast
                    return self._result(x, f, it, True, st, p_t, r_t, name)
                res = attempt(x_start, f_start, name, spent=self._fast_its)
            else:
                res = attempt(x_start, f_start, name)
        if res.converged and (res.stable or not self.follow_stable):
            return done(res)
        best = res
        if res.converged and not fast_fail and self.restarts > 0:
            esc = self._escape(res, p_t, r_t, lambda x: attempt(x, res.wrench[self.task], f"{name}+escape", False))
            if esc:
                return done(replace(self._lowest(esc), path=f"{name}+escape({len(esc)})"))
        for k in range(1, 0 if fast_fail else self.restarts + 1):
            xr = self._perturb(x_start if not res.converged else res.x, rng)
            r2 = attempt(xr, f_start if not res.converged else res.wrench[self.task], f"{name}+restart({k})")
            if r2.converged and (r2.stable or not self.follow_stable):
                return done(r2)
            if r2.converged and (not best.converged or r2.energy < best.energy):
                best = r2
        best = done(best)
        if not best.converged and raise_on_failure:
            # the requested deflection (the target against the unloaded end), then where the last
            # iterate ended (not an equilibrium)
            asked = np.concatenate([np.asarray(p_t, float) - self.p0, pin.log3(np.asarray(r_t, float) @ self.r0.T)])
            raise NoEquilibrium(
                f"no equilibrium found for deflection {(np.round(asked, 9) + 0.0).tolist()} after "
                f"{total} iterations and {self.restarts} restarts (the last iterate ended at deflection "
                f"{np.round(best.deflection, 9).tolist()}; residuals {best.residuals})",
                best,
                best.residual(),
            )
        return best

    # ----------------------------------------------------------------- mixed control
    @one_blas_thread
    def solve_mixed(
        self,
        deflection=None,
        wrench=None,
        *,
        held,
        x0: np.ndarray | None = None,
        wrench0: np.ndarray | None = None,
        raise_on_failure: bool = True,
        fast_fail: bool = False,
    ) -> EquilibriumResult:
        """Equilibrium under mixed control: each task component is *held* (its deflection
        prescribed) or *loaded* (a dead force/moment prescribed).

        The equilibrium is a stationary point of the total potential
        ``Π = ½(θ−θ₀)ᵀK_θ(θ−θ₀) − w_Lᵀ t_L`` subject to ``t_H = d_H`` (the held rows of the
        pose error, as :meth:`solve`); the multipliers are the reactions on the held rows.
        With ``J`` the task Jacobian (``LOCAL_WORLD_ALIGNED``, (θ, q) columns) and ``w`` the
        total end wrench (dead load on loaded rows, reaction on held rows)::

            r = [K_θ(θ−θ₀); 0] − Jᵀ w = 0,    g_H(x) − t_H = 0,

        solved by Newton's method with the matrix ``[[K − H(w), −J_Hᵀ], [J_H, 0]]``
        (``H`` the eq. 16 contraction) in null-space form; the reduced Hessian is shifted to
        be positive definite when a stable equilibrium is sought, and steps are accepted by an
        Armijo test on ``Π + Σ ρ_i |e_i|`` (ℓ₁ penalty of the held rows) or, for full
        unmodified steps, by halving the residual (a dead moment has no exact potential).
        When the direct iteration fails, continuation in the load factor and the held
        deflection (4, then 16 steps). No stiffness matrix is inverted: a chain whose end is
        free along a passive direction (singular K_C) has a well-posed problem here.

        All held: the same as :meth:`solve` (eq. 5–10). None held: :meth:`solve_wrench`.
        The iteration starts at ``x0`` (default: the reference) and reports the equilibrium it
        reaches, stable or not (``stable`` says which; no search for remote stable states
        under load control).

        Args:
            deflection: Prescribed deflection (m, rad; 6, 3 or ``len(task)`` numbers, see
                :meth:`solve`); non-zero only on held components.
            wrench: Dead load (N at the end frame origin, N·m; world axes; 6, 3 or
                ``len(task)`` numbers); non-zero only on loaded components.
            held: Held task components: names (``("x", "y")`` or ``"x y"``) or indices
                0..5; the other task components are loaded.
            x0: Starting configuration (nq,).
            wrench0: Starting wrench (6,) or (m,) (used when every component is held).
            raise_on_failure: Raise :class:`NoEquilibrium` when nothing converges.
            fast_fail: One attempt, no continuation.

        Returns:
            :class:`EquilibriumResult` with ``held``, the total ``wrench``, ``stable`` (the
            control as run) and ``stable_end_held`` (eq. 23).
        """
        hcomp = self.components(held)
        d = np.zeros(6) if deflection is None else self._vector6(deflection, "deflection", "m, rad")
        w = np.zeros(6) if wrench is None else self._vector6(wrench, "wrench", "N, N·m")
        outside = [COMPONENTS[i] for i in range(6) if i not in self.task and (d[i] or w[i])]
        if outside:
            raise InputError(
                f"components {outside} are not constrained by this model (task is "
                f"{' '.join(self.vm.task_names)}): no deflection or wrench can be prescribed there"
            )
        bad = [COMPONENTS[c] for c in self.task if c not in hcomp and d[c]]
        if bad:
            raise InputError(f"deflection prescribed on loaded components {bad}: hold them, or prescribe their wrench")
        bad = [COMPONENTS[c] for c in hcomp if w[c]]
        if bad:
            raise InputError(f"wrench prescribed on held components {bad}: their wrench is the reaction")
        if len(hcomp) == len(self.task):
            return self.solve(d, x0=x0, wrench0=wrench0, raise_on_failure=raise_on_failure, fast_fail=fast_fail)
        x_start = self._start(x0)
        hrows = [self.task.index(c) for c in hcomp]

        def run(p, r, x, f):
            return self._mixed_solve_target(p, r, x, hrows, w, raise_on_failure, fast_fail)

        return self._rotation_targets(d, hcomp, run, x_start, None, raise_on_failure)

    @one_blas_thread
    def solve_wrench(
        self,
        wrench,
        *,
        x0: np.ndarray | None = None,
        raise_on_failure: bool = True,
        fast_fail: bool = False,
    ) -> EquilibriumResult:
        """Equilibrium for a prescribed dead end wrench: every task component loaded.

        Newton's method on the total potential (:meth:`solve_mixed` with nothing held),
        with line search and continuation in the load factor; it replaces the outer loop of
        eq. (11), which needed a regular K_C. ``stable`` is the verdict under this load
        control (``K − H`` positive definite: the end free under the dead load), and
        ``stable_end_held`` that of eq. (23).

        Args:
            wrench: Force (N) at the end frame origin and moment (N·m), world axes: 6, 3
                (force) or ``len(task)`` (task rows) numbers; zero outside the task.
            x0: Starting configuration (nq,); default the unloaded reference.
        """
        return self.solve_mixed(wrench=wrench, held=(), x0=x0, raise_on_failure=raise_on_failure, fast_fail=fast_fail)

    def _mixed_solve_target(self, p_t, r_t, x_start, hrows, w_dead, raise_on_failure, fast_fail):
        """:meth:`solve_mixed` for the held rows ``hrows`` (positions in the task) of the target
        pose ``(p_t, r_t)`` and the dead load ``w_dead`` (6,): a direct attempt, continuation
        in the load factor and the held target, then perturbed restarts."""
        total = 0
        rng = []
        label = "total-potential"
        # the equilibrium next to the start first (plain Newton, stable or not: a load applied
        # at the start configuration), then energy descent towards a stable one
        x, lam, it, ok, st = self._mixed_newton(x_start, hrows, w_dead, p_t, r_t, LOCAL_MAX_ITER, local=True)
        total += it
        if not ok:
            # descent crosses the whole energy landscape (a pinned chain swinging round under a
            # dead load) in steps of at most max_step: a longer budget than a local attempt
            x, lam, it, ok, st = self._mixed_newton(x_start, hrows, w_dead, p_t, r_t, DESCENT_ITER_FACTOR * self.max_iter)
            total += it
            label += "+descent"
        if not ok and not fast_fail:
            ps, rs = self.kin.placement(x_start)
            dlog = pin.log3(r_t @ rs.T)
            starts = [x_start] + [self._perturb(x_start, rng) for _ in range(min(self.restarts, 2))]
            for si, xs in enumerate(starts):
                for nsteps in (1, 4, 16) if si else (4, 16):
                    xc, okc = xs.copy(), True
                    for k in range(1, nsteps + 1):
                        a = k / nsteps
                        pk = (1 - a) * ps + a * p_t
                        rk = pin.exp3(a * dlog) @ rs
                        xc, lamc, itc, okc, stc = self._mixed_newton(xc, hrows, a * w_dead, pk, rk, self.max_iter)
                        total += itc
                        if not okc:
                            break
                    if okc:
                        x, lam, ok, st = xc, lamc, True, stc
                        label += (f"+restart({si})" if si else "") + (f"+continuation({nsteps})" if nsteps > 1 else "")
                        break
                if ok:
                    break
        res = self._mixed_result(x, lam, total, ok, st, hrows, w_dead, p_t, r_t, label)
        if not ok and raise_on_failure:
            held = " ".join(COMPONENTS[self.task[i]] for i in hrows) or "none"
            raise NoEquilibrium(
                f"no equilibrium found under load control (held: {held}; dead wrench "
                f"{np.round(w_dead, 9).tolist()}) after {total} iterations (residuals {res.residuals})",
                res,
                res.residual(),
            )
        return res

    def _mixed_state(self, x, hrows, lrows, w_dead, p_t, r_t, hessian):
        """Quantities of the mixed Newton iteration at ``x``: (state, J, τ, ∇Π, Y, Z, R, λ, r, e)."""
        vm, free, nt = self.vm, self.free, self.nt
        tarr = np.asarray(self.task)
        st = self.kin.evaluate(x, hessian=hessian and not getattr(self.kin, "uses_screw", False))
        jac = st.jacobian[tarr][:, free]
        n = len(free)
        tau = np.zeros(n)
        tau[:nt] = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        gl = tau - jac[lrows].T @ w_dead[tarr[lrows]]
        k = len(hrows)
        if k:
            q, rm = np.linalg.qr(jac[hrows].T, mode="complete")
            y, z, rr = q[:, :k], q[:, k:], rm[:k]
            try:
                with np.errstate(all="ignore"):
                    lam = _solve_triangular(rr, y.T @ gl)
            except np.linalg.LinAlgError:  # held rows not independent here: least squares
                lam = np.linalg.lstsq(jac[hrows].T, gl, rcond=None)[0]
        else:
            y, z, rr, lam = np.zeros((n, 0)), np.eye(n), np.zeros((0, 0)), np.zeros(0)
        r = gl - jac[hrows].T @ lam
        e = pose_error(p_t, r_t, st.position, st.rotation)[tarr[hrows]]
        return st, jac, tau, gl, y, z, rr, lam, r, e

    def _potential(self, x, st, lrows, w_dead) -> float:
        """Total potential ``E − w_Lᵀ t_L`` (J); the moment's work through ``log3(R R0ᵀ)``
        (exact for a force; a dead moment has no exact potential in 3-D)."""
        tl = np.asarray(self.task)[lrows]
        d = deflection(self.p0, self.r0, st.position, st.rotation)
        return self.energy(x) - float(w_dead[tl] @ d[tl])

    def _mixed_newton(self, x, hrows, w_dead, p_t, r_t, max_iter, local=False):
        """Newton on the stationarity of the total potential (see :meth:`solve_mixed`) from
        ``x``; returns (x, λ (held rows), iterations, converged, state).

        ``local``: plain Newton steps only, each kept only if it halves the residual and is
        within the step limit (converges to the equilibrium next to ``x``, stable or not);
        otherwise shifted (descent) steps when ``follow_stable`` and a line search."""
        m = len(self.task)
        hrows = np.asarray(hrows, int)
        lrows = np.array([i for i in range(m) if i not in set(hrows.tolist())], int)
        tarr = np.asarray(self.task)
        hcomp = tarr[hrows]
        escale = self._err_scale[hrows]
        hp, hr = hcomp < 3, hcomp >= 3
        kscale = max(self.kscale, 1e-300)
        tol = self.tol
        x = np.array(x, float)
        polish = escapes = 0
        kkt_prev = np.inf
        lam, st = np.zeros(len(hrows)), None
        for it in range(max_iter + 1 + POLISH_ITERATIONS):
            st, jac, tau, gl, y, z, rr, lam, r, e = self._mixed_state(x, hrows, lrows, w_dead, p_t, r_t, True)
            if not (np.all(np.isfinite(lam)) and np.all(np.isfinite(r))):
                return x, np.nan_to_num(lam), it, False, st
            w6 = w_dead.copy()
            w6[hcomp] = lam
            ae = np.abs(e)
            ep = ae[hp].max() if hp.any() else 0.0
            er = ae[hr].max() if hr.any() else 0.0
            rs = np.abs(r).max() if r.size else 0.0
            load = np.abs(jac.T @ w6[tarr]).max() if jac.size else 0.0
            stat_scale = max(np.abs(tau).max() if tau.size else 0.0, load, 1e-6 * self.kscale)
            conv = ep <= 0.01 * tol * self.length_scale and er <= 0.01 * tol and rs <= tol * stat_scale
            dx, wm, lmin, modified = self._mixed_step(x, st, w6, y, z, rr, e, r, len(hrows), local)
            if not np.all(np.isfinite(dx)):
                return x, lam, it, conv, st
            if not conv and not modified and np.abs(dx / self.var_scale).max() <= POLISH_STEP:
                # at the rounding floor: the Newton correction is negligible
                conv = ep <= 0.01 * tol * self.length_scale and er <= 0.01 * tol and rs <= 1e3 * tol * stat_scale
            if conv and polish == 0 and not local:
                kkt_prev = np.inf
            if conv and modified and not local and escapes < ESCAPE_MODES and lmin < -STABILITY_TOL * kscale:
                # descent crept onto a saddle: leave it along its most negative curvature
                escapes += 1
                x = self._mixed_escape(x, z, wm)
                continue
            if conv:
                if modified or polish >= POLISH_ITERATIONS or np.abs(dx / self.var_scale).max() <= POLISH_STEP:
                    return x, lam, it, True, st
                polish += 1
                x = self._moved(x, dx)
                continue
            if it - polish >= max_iter:
                break
            smax = np.abs(dx / self.var_scale).max()
            kkt0 = float(np.linalg.norm(e / escale) + np.linalg.norm(r) / kscale)
            if local:
                if not (smax <= self.max_step and kkt0 < 0.5 * kkt_prev):
                    return x, lam, it, False, st
                kkt_prev = kkt0
                x = self._moved(x, dx)
                continue
            if smax > self.max_step:
                dx = dx * (self.max_step / smax)
                modified = True
            rho = 2.0 * np.abs(lam) + 1e-9 * stat_scale * np.where(hp, 1.0 / self.length_scale, 1.0)
            xn = self._mixed_line_search(
                x, st, dx, gl, rho, ae, modified, kkt0, (hrows, lrows, w_dead, p_t, r_t)
            )
            if xn is None:
                return x, lam, it + 1, False, st
            x = xn
        return x, lam, max_iter, False, st

    def _mixed_step(self, x, st, w6, y, z, rr, e, r, nheld, local):
        """The Newton step of :meth:`_mixed_newton` in the null-space form (eq. 28): returns
        (dx, K − H, smallest eigenvalue of the reduced matrix, whether it was shifted to a
        descent step (``follow_stable`` and not ``local``))."""
        kz = self._kz
        shift = SHIFT_TOL * max(self.kscale, 1e-300)
        hz = self._psi_hessian(x, st, w6)
        wm = kz - hz
        red = z.T @ wm @ z
        lmin = np.linalg.eigvalsh(0.5 * (red + red.T)).min() if red.size else np.inf
        modified = False
        if self.follow_stable and not local and lmin < shift:
            red = red + (shift - lmin + 1e-3 * abs(lmin)) * np.eye(red.shape[0])
            modified = True
        with np.errstate(all="ignore"):
            try:
                py = _solve_triangular(rr, e, trans="T") if nheld else np.zeros(0)
            except np.linalg.LinAlgError:
                py = np.full(nheld, np.nan)
            dy = y @ py
            try:
                pz = np.linalg.solve(red, z.T @ (r + wm @ dy))
            except np.linalg.LinAlgError:
                pz = np.linalg.lstsq(red, z.T @ (r + wm @ dy), rcond=None)[0]
            dx = dy - z @ pz
        return dx, wm, lmin, modified

    def _mixed_escape(self, x, z, wm):
        """``x`` moved off a saddle along the reduced matrix's most negative curvature, by the
        step limit."""
        sym = z.T @ wm @ z
        _, vec = np.linalg.eigh(0.5 * (sym + sym.T))
        v = z @ vec[:, 0]
        x = x.copy()
        x[self.free] += v * (self.max_step / max(np.abs(v / self.var_scale).max(), 1e-300))
        flush_tiny(x)
        return x

    def _mixed_line_search(self, x, st, dx, gl, rho, ae, modified, kkt0, problem):
        """Backtracking along ``dx`` on the merit ``E − w_Lᵀ t_L + ρ·|e|`` (``follow_stable``;
        otherwise the full step); the new configuration, or None when no step is accepted.
        ``problem``: (held rows, loaded rows, dead wrench, target position, rotation)."""
        hrows, lrows, w_dead, p_t, r_t = problem
        free = self.free
        escale = self._err_scale[hrows]
        kscale = max(self.kscale, 1e-300)
        phi0 = self._potential(x, st, lrows, w_dead) + float(rho @ ae)
        slope = min(float(gl @ dx) - float(rho @ ae), 0.0)
        noise = 1e-13 * (abs(phi0) + self.energy(x) + 1e-300)
        alpha, accepted = 1.0, False
        for _ in range(40):
            xn = x.copy()
            xn[free] += alpha * dx
            flush_tiny(xn)
            stn, _, _, _, _, _, _, lamn, rn, en = self._mixed_state(xn, hrows, lrows, w_dead, p_t, r_t, False)
            if np.all(np.isfinite(rn)) and np.all(np.isfinite(lamn)):
                if not self.follow_stable:
                    accepted = True
                elif self._potential(xn, stn, lrows, w_dead) + float(rho @ np.abs(en)) <= (
                    phi0 + 1e-4 * alpha * slope + noise
                ):
                    accepted = True
                elif alpha == 1.0 and not modified:
                    accepted = float(np.linalg.norm(en / escale) + np.linalg.norm(rn) / kscale) < 0.5 * kkt0
            if accepted:
                return xn
            alpha *= 0.5
        return None

    def _mixed_result(self, x, lam, iters, ok, st, hrows, w_dead, p_t, r_t, path) -> EquilibriumResult:
        vm, m = self.vm, len(self.task)
        tarr = np.asarray(self.task)
        hrows = np.asarray(hrows, int)
        lrows = np.array([i for i in range(m) if i not in set(hrows.tolist())], int)
        st, jac, tau, gl, y, z, rr, lam2, r, e = self._mixed_state(x, hrows, lrows, w_dead, p_t, r_t, False)
        if np.all(np.isfinite(lam2)):
            lam = lam2
        w6 = w_dead.copy()
        w6[tarr[hrows]] = lam
        hcomp = tarr[hrows]
        ae = np.abs(e)
        res = {
            "position": float(ae[hcomp < 3].max()) if np.any(hcomp < 3) else 0.0,
            "orientation": float(ae[hcomp >= 3].max()) if np.any(hcomp >= 3) else 0.0,
            "statics": float(np.abs(r).max()) if r.size else 0.0,
        }
        stab = end = None
        warnings = ()
        if ok:
            b = evaluate_blocks(vm, self.kin, x, w6)
            stab = check_stability_held(b, np.eye(m)[hrows])
            end = check_stability(b)
            if not stab.stable:
                loaded = " ".join(COMPONENTS[c] for c in tarr[lrows])
                warnings = (
                    f"unstable under the prescribed load (loaded components {loaded}): the end would move "
                    "away from this equilibrium under the dead load"
                    + ("; stable with the end held (eq. 23)" if end.stable else ""),
                )
        return self._pack(x, w6, st, ok, iters, res, path, stab, end, tuple(int(c) for c in hcomp), warnings)

    # ----------------------------------------------------------------- checks
    @one_blas_thread
    def verify(self, res: EquilibriumResult, *, method: str = "eq30", rtol: float = VERIFY_RTOL) -> EquilibriumResult:
        """Check an equilibrium of this solver; retry once (tighter tolerance, warm start) on
        failure; return it with ``checks`` filled, or raise :class:`EquilibriumCheckError`.

        1. Eq. (5) recomputed with Pinocchio over all coordinates, ``K_θ(θ−θ₀) − J_θᵀw`` and
           ``−J_qᵀw`` with the full 6-D wrench, each row against its own scale: revolute rows
           (N·m) against ``max(|τ|, |f|·L_c + |m|)``, prismatic rows (N) against
           ``max(|τ|, |f| + |m|/L_c)``; pass below :data:`VERIFY_STATICS`.
        2. Both verdicts recomputed from fresh blocks (:func:`check_stability_held` for the
           control as run, :func:`check_stability` for eq. 23); a verdict whose deciding
           eigenvalue is within 10× the threshold of zero is not contested.
        3. K_C (``method``) along its softest task direction ``u`` (smallest |eigenvalue| of
           the symmetric part, rotations scaled by L_c) against central differences of the
           wrench of re-solved equilibria at ``t ± h u`` (every component held, plain Newton
           from ``res``), ``h`` = 1e-6, 1e-8, 1e-10 ×L_c: relative error ≤ ``rtol``. Skipped
           when K_C is singular (the caller reports that).

        Raises:
            NoEquilibrium: ``res`` did not converge. EquilibriumCheckError: a check failed twice.
        """
        if not res.converged:
            raise NoEquilibrium("the equilibrium did not converge: nothing to check", res, res.residual())
        checks = self._checks(res, method, rtol)
        if checks["ok"]:
            return replace(res, checks=checks)
        # retry: the same control, tighter tolerance, from the equilibrium itself
        retry = self._resolve_like(res, tol=max(self.tol * 1e-2, TOL_RANGE[0]), restarts=1)
        if retry is not None and (retry.stable or not res.stable):
            checks2 = self._checks(retry, method, rtol)
            if checks2["ok"]:
                checks2["retried"] = True
                return replace(retry, checks=checks2, path=retry.path + "+verified-retry")
        failed = ", ".join(k for k in ("statics_ok", "stability_ok", "stiffness_ok") if not checks.get(k, True))
        raise EquilibriumCheckError(
            f"the equilibrium failed its check ({failed}): statics residual {checks['statics_relative']:.2g} "
            f"(relative), K_C along the softest direction off by {checks.get('stiffness_relative_error', float('nan')):.2g} "
            "against re-solved equilibria; not reported"
            + (
                " (the equilibrium is at or next to a critical point, where K_C jumps between branches)"
                if not checks["stiffness_ok"] and checks["statics_ok"]
                else ""
            ),
            res,
            checks,
        )

    def _resolve_like(self, res, **options):
        """``res`` re-solved under the same control from its own configuration (None on failure)."""
        held = tuple(self.task) if res.held is None else tuple(res.held)
        d = np.zeros(6)
        d[list(held)] = res.deflection[list(held)]
        loaded = [c for c in self.task if c not in held]
        w = np.zeros(6)
        w[loaded] = res.wrench[loaded]
        try:
            return self._sibling(**options).solve_mixed(d, w, held=held, x0=res.x, wrench0=res.wrench)
        except NoEquilibrium:
            return None

    def _checks(self, res, method, rtol) -> dict:
        vm = self.vm
        lc = self.length_scale
        x = np.asarray(res.x, float)
        w6 = np.asarray(res.wrench, float)
        st = self.kin.evaluate(x, hessian=False)
        tau = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        gen = st.jacobian.T @ w6
        r = np.concatenate([tau - gen[vm.theta_idx], -gen[vm.q_idx]])
        tq = np.concatenate([tau, np.zeros(vm.n_q)])
        fn, mn = float(np.abs(w6[:3]).max()), float(np.abs(w6[3:]).max())
        # the rules shared with check_mechanism
        from vjm_pin.solver.checks import statics_relative, verdict_agrees

        rel = statics_relative(r, tq, self.var_scale > 1.0, fn, mn, lc)
        off_task = [i for i in range(6) if i not in self.task]
        checks = {
            "statics_relative": rel,
            "statics_ok": bool(rel <= VERIFY_STATICS and not np.any(w6[off_task])),
            "position_m": res.residuals.get("position", 0.0),
            "orientation_rad": res.residuals.get("orientation", 0.0),
        }
        checks["statics_ok"] = bool(
            checks["statics_ok"]
            and checks["position_m"] <= max(self.tol, 1e-12) * lc * 10
            and checks["orientation_rad"] <= max(self.tol, 1e-12) * 10
        )
        b = evaluate_blocks(vm, self.kin, x, w6)
        held = tuple(self.task) if res.held is None else tuple(res.held)
        hm = np.eye(len(self.task))[[self.task.index(c) for c in held]]
        ctl, end = check_stability_held(b, hm), check_stability(b)

        def agrees(given, fresh):
            return verdict_agrees(given, fresh.stable, fresh.eigenvalues, fresh.tolerance)

        checks["stable"] = ctl.stable
        checks["stable_end_held"] = end.stable
        checks["stability_ok"] = agrees(res.stability, ctl) and agrees(res.stability_end_held, end)
        checks["stiffness_ok"] = True
        try:
            k = stiffness_from_blocks(b, vm.task, method).task_stiffness
        except SingularStiffness:
            k = None
            checks["stiffness_checked"] = False
        if k is not None:
            checks.update(self._check_stiffness(res, k, rtol))
        checks["ok"] = bool(checks["statics_ok"] and checks["stability_ok"] and checks["stiffness_ok"])
        return checks

    def _check_stiffness(self, res, k, rtol) -> dict:
        # the rules shared with check_mechanism
        from vjm_pin.solver.checks import softest_direction, stiffness_fd_error

        task = self.task
        u = softest_direction(k, task, self.length_scale)
        plain = self._sibling(tol=self.tol, max_iter=self.max_iter, follow_stable=False, restarts=0)

        def task_wrench(dt):
            try:
                rr = plain.solve(target=displace(res.position, res.rotation, dt), x0=res.x, wrench0=res.wrench, fast_fail=True)
            except NoEquilibrium:
                return None
            return rr.wrench[task] if rr.converged else None

        best = stiffness_fd_error(k, u, task, self.length_scale, task_wrench, rtol)
        return {
            "stiffness_checked": True,
            "stiffness_direction": u,
            "stiffness_relative_error": best,
            "stiffness_ok": bool(best <= rtol),
        }


def reference_if_unloaded(vm: VjmModel) -> np.ndarray | None:
    """A copy of the reference configuration when it is an equilibrium without load (no spring
    preloaded there: ``K_θ(θ − θ₀) = 0``), else None."""
    x = np.asarray(vm.reference, float).copy()
    stat = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    if stat.size and np.abs(stat).max() > 0:
        return None
    return x


def solve_equilibrium(vm: VjmModel, deflection=None, *, target=None, **kwargs) -> EquilibriumResult:
    """Convenience: :meth:`EquilibriumSolver.solve` with a fresh solver.

    Solver options (``method``, ``tol``, ``max_iter``, ``restarts``, ``seed``, ...) and
    ``x0``/``wrench0``/``raise_on_failure`` may be passed as keywords."""
    call = {k: kwargs.pop(k) for k in ("x0", "wrench0", "raise_on_failure") if k in kwargs}
    return EquilibriumSolver(vm, **kwargs).solve(deflection, target=target, **call)


def solve_for_wrench(vm: VjmModel, wrench, **kwargs) -> EquilibriumResult:
    """Convenience: :meth:`EquilibriumSolver.solve_wrench` with a fresh solver."""
    call = {k: kwargs.pop(k) for k in ("x0", "raise_on_failure") if k in kwargs}
    return EquilibriumSolver(vm, **kwargs).solve_wrench(wrench, **call)
