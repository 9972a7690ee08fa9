"""One solver for a mechanism: loop closures, held/loaded task components, dead loads anywhere
(issue 13; paper §4–5 generalised).

A mechanism is one Pinocchio tree (:class:`~vjm_pin.model.format.VjmModel`) with springs ``K_θ``,
passive joints, loop closures ``c(x) = 0`` (:mod:`vjm_pin.kinematics.closures`, held at the assembled
reference), one task frame whose components are *held* (deflection prescribed) or *loaded*
(dead wrench prescribed), and dead loads at any frames plus link weights
(:mod:`vjm_pin.kinematics.dead_loads`). Only the spring and passive coordinates ``z = (θ, q)`` move;
rigid actuated joints stay at their reference value.

Equilibrium = stationary point of the total potential

    Π(z) = ½(θ−θ₀)ᵀK_θ(θ−θ₀) − (work of the dead loads and of the loaded task wrench)

subject to ``c(z) = 0`` and ``g_H(z) = t_H`` (held task rows of the pose error, as
:meth:`~vjm_pin.solver.EquilibriumSolver.solve_mixed`). With ``A = [C; J_H]`` the stacked
constraint Jacobian (closure rows first) and ``ν = (μ, λ)`` its multipliers (closure reaction
multipliers, task reactions)::

    r = [K_θ(θ−θ₀); 0] − Q_loads − J_Lᵀ w_L − Aᵀν = 0,     c = 0,    t_H − g_H = 0    (eq. 5 form)

One Newton iteration over all coordinates with the matrix ``[[W, −A_Iᵀ], [A_I, 0]]``,

    W = K − ∂Q_loads/∂z − H(w) − Σ_k μ_k ∂²c_k/∂z²                             (eq. 16 forms)

(``H(w)`` the eq. 16 contraction of the total end wrench ``w``: dead load on loaded rows,
reaction on held rows; the closure term is :meth:`~vjm_pin.kinematics.closures.ClosureState.hessian`),
solved in null-space form on the *independent* rows ``A_I`` (:func:`~vjm_pin.kinematics.closures.constraint_rank`,
closure rows preferred; redundant rows are dropped for the step: at an assembled configuration
they are implied). Globalisation as the serial solver: a plain local Newton attempt first, then
steps with the reduced Hessian shifted to be positive definite (descent towards a stable
equilibrium), an Armijo line search on the merit ``Π + Σ ρ_i |b_i|`` (ℓ₁ penalty of the
constraint residuals ``b``), an escape along negative curvature from a saddle, continuation in
the load factor and the held deflection (4, then 16 steps), perturbed restarts. The line search's
trial points need placements only; the curve tracer's branch-switch descents add the
second-order correction to rejected trial points (:meth:`MechanismSolver._newton`, ``soc``).

Multipliers. On the independent rows the multipliers are unique (least squares on the
stationarity residual). With redundant rows (an over-constrained mechanism) the reactions are
statically indeterminate; the reported multipliers are the **minimum-norm** set (Euclidean norm
of the raw multipliers, N for translation rows and N·m for rotation rows) that carries the same
generalised force — the choice of :func:`~vjm_pin.kinematics.closures.min_norm_multipliers`; zero on rows
that are identically zero (a planar loop closed in six components). The stability verdicts and
K_C do not depend on this choice (the Lagrangian Hessian on the constraint null space does not).

Stability (eq. 23 generalised): the symmetric part of ``−Zᵀ W Z`` must be negative definite,
``Z`` an orthonormal basis of the null space of the stacked Jacobian: of (closure + held rows) for
``stable`` (the control as run), of (closure + every task row) for ``stable_end_held``.

Loaded stiffness (eq. 28 bordered with the closure rows)::

    [[0, 0, J], [0, 0, C_I], [Jᵀ, C_Iᵀ, −W]] [δw; δμ; δz] = [δt; 0; 0],   K_C = ∂w/∂t

(``J`` every task row), see :meth:`MechanismSolver.stiffness`.

Public API::

    solver = MechanismSolver(vm, loads=(), gravity=None, tol=1e-10, max_iter=60, restarts=2, seed=0)
    res = solver.solve(deflection=None, wrench=None, held=None, x0=None)   # MechanismResult
    solver.stiffness(res) -> StiffnessResult (method "eq28-closures")
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import InputError, NoEquilibrium, SingularStiffness
from vjm_pin.kinematics.chain import contract_hessian, deflection, displace, pose_error
from vjm_pin.kinematics.closures import RANK_RTOL, ClosureSet, constraint_rank, row_rank
from vjm_pin.kinematics.dead_loads import DeadLoads, Load
from vjm_pin.kinematics.frames import FrameKinematics
from vjm_pin.kinematics.screw import psi_hessian_screw, screw_applicable, support_mask
from vjm_pin.kinematics.shared import data_for
from vjm_pin.model.format import VjmModel
from vjm_pin.solver.stability import STABILITY_TOL, StabilityResult, spectral_norm
from vjm_pin.solver.stiffness import StiffnessResult
from vjm_pin.solver.threads import one_blas_thread

#: Names of the six task components, in order.
COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
#: Margin (relative to max|K_θ|) below which the reduced Hessian is shifted when a stable
#: equilibrium is sought (as :data:`vjm_pin.solver.equilibrium.SHIFT_TOL`).
SHIFT_TOL = 1e-10
#: Further Newton steps at convergence while the step exceeds :data:`POLISH_STEP` (relative).
POLISH_ITERATIONS = 3
POLISH_STEP = 1e-12
#: Iterations of the plain local attempt; the descent budget in units of ``max_iter``.
LOCAL_MAX_ITER = 12
DESCENT_ITER_FACTOR = 8
#: A descent with a stall window (``_newton(stall=...)``, the branch switch's candidates) gives up
#: when, over that many iterations, the accepted steps lowered the merit by less than
#: :data:`STALL_REL` × (|merit| + spring energy) in total and the KKT residual did not halve: it
#: creeps along a flat saddle and would exhaust its budget without converging.
STALL_WINDOW = 40
STALL_REL = 1e-9
#: Largest step (rad, or ×L_c for prismatic coordinates) of one Newton iteration.
MAX_STEP = 0.3
#: A dead-loaded solve whose descent moves a coordinate further than this (rad, or × the length
#: scale) from the start is checked against the loading path (:meth:`MechanismSolver._on_loading_path`).
FAR_JUMP = 1.0
#: Rotation-target iterations of a task holding some but not all rotations, and their tolerance (rad).
ROTATION_TARGET_ITER = 30
ROTATION_TARGET_TOL = 1e-12
#: Evaluated Newton states (:meth:`MechanismSolver._state`) a solver keeps, per thread, keyed on the
#: exact bytes of their inputs: a Newton attempt that starts where the previous one started (the
#: curve tracer's short-step fall-back after the plain local attempt, a result formed at the
#: converged point) reuses them instead of evaluating again (the same numbers: the evaluation is
#: deterministic).
STATE_CACHE_SIZE = 16
#: Bound on the rounding error of a computed singular value of a row-normalised constraint
#: Jacobian (rows of unit norm, so ‖S‖₂ ≤ √rows; LAPACK's error is ~n·ε·‖S‖₂ ≈ 1e-13 here) used by
#: :meth:`MechanismSolver._full_row_rank`.
SV_ERROR = 1e-10
#: Note attached to a result whose multipliers are not unique.
MULTIPLIERS_NOTE = (
    "{n} redundant constraint row(s) ({labels}): the reactions are statically indeterminate; "
    "the reported multipliers are the minimum-norm set (N, N·m) that carries the same generalised force"
)


@dataclass(frozen=True)
class MechanismResult:
    """An equilibrium of a mechanism (:meth:`MechanismSolver.solve`).

    Attributes:
        x: (nq,) configuration (m, rad), Pinocchio order.
        q: (n_q,) passive coordinates. theta: (n_θ,) spring coordinates.
        wrench: (6,) total wrench on the task frame (N at its origin, N·m; world axes):
            reaction on held components, the dead load on loaded ones, zero off the task.
        closure_multipliers: (m_c,) closure multipliers ``μ`` (N for translation rows, N·m for
            rotation rows; rows in ``closure_labels`` order); minimum-norm when redundant.
        closure_labels: Row names ``"<closure>.<component>"``.
        reaction_wrenches: Closure name → (W_a, W_b), the reaction wrenches (6,) on frame_a and
            frame_b (N, N·m; world axes, at the frame origins).
        deflection: (6,) task-frame deflection ``(p − p0, log3(R R0ᵀ))`` (m, rad).
        position: (3,) task-frame position (m). rotation: (3, 3).
        converged: Eq. (5) form holds to the tolerance.
        iterations: Newton iterations over all attempts.
        residuals: Per unit: ``position`` (m) and ``orientation`` (rad) of the held task rows,
            ``closure_position`` (m) and ``closure_orientation`` (rad), ``statics`` (N·m, rows
            of revolute coordinates) and ``statics_prismatic`` (N).
        energy: Spring energy (J).
        path: How it was found (``"newton"``, ``"+descent"``, ``"+continuation(4)"``, ...).
        held: Held task components (0..5); the other task components were loaded.
        stability: Verdict for the control as run (null space of closure + held rows).
        stability_end_held: Eq. (23) (null space of closure + every task row).
        redundant: Labels of the redundant constraint rows (closure rows ``"<closure>.<c>"``,
            task rows ``"task.<c>"``) of the stacked (closure + held) Jacobian at ``x``.
        multipliers_note: Why the multipliers are a choice (None when they are unique).
        warnings: Plain-language notes.
        held_axes: (k, 6) the held task axes (world components) when the solver holds task
            directions other than the components (:meth:`MechanismSolver.with_task_axes`;
            ``held`` is then empty); None otherwise.
    """

    x: np.ndarray
    q: np.ndarray
    theta: np.ndarray
    wrench: np.ndarray
    closure_multipliers: np.ndarray
    closure_labels: tuple[str, ...]
    reaction_wrenches: dict
    deflection: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    converged: bool
    iterations: int
    residuals: dict = field(default_factory=dict)
    energy: float = 0.0
    path: str = ""
    held: tuple[int, ...] = ()
    stability: StabilityResult | None = None
    stability_end_held: StabilityResult | None = None
    redundant: tuple[str, ...] = ()
    multipliers_note: str | None = None
    warnings: tuple[str, ...] = ()
    held_axes: np.ndarray | None = None

    @property
    def stable(self) -> bool | None:
        """Verdict for the control as run (None if not evaluated)."""
        return None if self.stability is None else self.stability.stable

    @property
    def stable_end_held(self) -> bool | None:
        """Eq. (23): stable with the task frame held in every task component (None if not evaluated)."""
        return None if self.stability_end_held is None else self.stability_end_held.stable

    def residual(self) -> float:
        """Largest residual (mixed units; 0 at an exact equilibrium)."""
        return float(max(self.residuals.values())) if self.residuals else float("nan")


@dataclass(frozen=True)
class Linearization:
    """The mechanism linearised at one configuration (:meth:`MechanismSolver.linearize`).

    Attributes:
        x: (nq,) configuration (m, rad).
        hessian: (n, n) ``W = K − ∂Q/∂z − H(w) − Σ μ_k ∂²c_k/∂z²`` on ``z = (θ, q)`` (N·m/rad,
            N/m, N/rad), the multipliers solved by least squares from the stationarity at ``x``
            (exact at an equilibrium).
        closure_jacobian: (m_c, n) ``C`` on ``z``; ``closure_independent``: its independent rows
            (indices, :func:`~vjm_pin.kinematics.closures.constraint_rank`).
        task_jacobian: (6, n) task-frame Jacobian on ``z`` (world axes, every component).
        wrench: (6,) total task wrench (N, N·m): dead on loaded rows, reaction on held rows.
        closure_multipliers: (m_c,) ``μ`` (minimum-norm when redundant).
        held_rows: (k, 6) the held task axes (world components).
        independent_multipliers: The multipliers of the independent closure rows
            (``closure_independent`` order) that carry the generalised force with them alone.
    """

    x: np.ndarray
    hessian: np.ndarray
    closure_jacobian: np.ndarray
    closure_independent: np.ndarray
    task_jacobian: np.ndarray
    wrench: np.ndarray
    closure_multipliers: np.ndarray
    held_rows: np.ndarray
    independent_multipliers: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class _State:
    """Everything one Newton iteration needs at one configuration (internal)."""

    end: object
    cstate: object
    grad: np.ndarray  # ∇Π (free order)
    tau: np.ndarray
    load_force: np.ndarray  # generalised force of every dead load incl. the loaded task wrench
    a: np.ndarray  # stacked constraint Jacobian (closure rows, held rows), free columns
    b: np.ndarray  # its right-hand side (A δz = b)
    bscale: np.ndarray  # per row: L_c for metres, 1 for radians
    indep: np.ndarray
    redundant: tuple[int, ...]
    y: np.ndarray
    z: np.ndarray
    rr: np.ndarray
    nu: np.ndarray  # min-norm multipliers, all rows
    nu_i: np.ndarray  # multipliers on the independent rows
    r: np.ndarray  # stationarity residual
    w6: np.ndarray
    dload: np.ndarray | None  # ∂Q/∂z (free block), hessian=True only
    hess: np.ndarray | None = None  # W, once :meth:`MechanismSolver._hessian` formed it (read-only)


@dataclass(frozen=True)
class _Placement:
    """A frame's placement at a trial point (world): ``position`` (3,) m, ``rotation`` (3, 3)."""

    position: np.ndarray
    rotation: np.ndarray


def _null_basis(a: np.ndarray, rtol: float) -> tuple[np.ndarray, int]:
    """Orthonormal basis of the null space of ``a`` (rows normalised first, rank as
    :func:`~vjm_pin.kinematics.closures.constraint_rank`) and the rank."""
    n = a.shape[1]
    if a.shape[0] == 0:
        return np.eye(n), 0
    norms = np.linalg.norm(a, axis=1)
    keep = norms > 0
    s = np.zeros_like(a)
    s[keep] = a[keep] / norms[keep, None]
    big = float(norms.max())
    if not np.all(np.isfinite(a)) or np.any(keep & (norms <= rtol * big)):
        # rows that constraint_rank counts as zero but are not: its rank, this SVD's basis
        rank = constraint_rank(a, rtol=rtol).rank
        _, _, vt = np.linalg.svd(s, full_matrices=True)
        return vt[rank:].T.copy(), rank
    # the same row-normalised matrix as constraint_rank: its rank from this one SVD
    _, sv, vt = np.linalg.svd(s, full_matrices=True)
    rank = int(np.sum(sv > rtol * float(sv[0]))) if sv.size and big > 0 else 0
    return vt[rank:].T.copy(), rank


def _verdict(w: np.ndarray, z: np.ndarray, thr: float) -> StabilityResult:
    """Eq. (23) form: eigenvalues of the symmetric part of ``−ZᵀWZ``; stable iff all < −thr."""
    red = -(z.T @ w @ z)
    ev = np.linalg.eigvalsh(0.5 * (red + red.T)) if red.size else np.zeros(0)
    return StabilityResult(bool(ev.size == 0 or ev.max() < -thr), ev, z.shape[1], float(thr))


class MechanismSolver:
    """Equilibrium, stability and loaded stiffness of a mechanism (module docstring).

    Args:
        vm: The model (its ``closures``, springs, roles and task).
        loads: Dead loads anywhere (:class:`~vjm_pin.kinematics.dead_loads.Load`, world axes).
        gravity: (3,) gravity (m/s²) for the link weights, or None.
        tol: Relative tolerance (1e-15…1e-4): constraint residuals ≤ 0.01·tol·L_c (m) and
            0.01·tol (rad), statics ≤ tol × max(|K_θ(θ−θ₀)|, |loads|, 1e-6·|K_θ|).
        max_iter: Iterations per attempt. restarts: perturbed restarts after failure.
        perturbation: Restart noise (rad; ×1e-3·L_c for prismatic coordinates). seed: its seed.
        follow_stable: Prefer stable equilibria (shifted descent steps, saddle escape).
        rank_rtol: Relative tolerance of the constraint rank (:func:`constraint_rank`).
    """

    def __init__(
        self,
        vm: VjmModel,
        loads: Sequence[Load] = (),
        gravity=None,
        *,
        tol: float = 1e-10,
        max_iter: int = 60,
        restarts: int = 2,
        perturbation: float = 1e-3,
        seed: int = 0,
        follow_stable: bool = True,
        rank_rtol: float = RANK_RTOL,
    ):
        if not isinstance(vm, VjmModel):
            raise InputError(f"vm must be a VjmModel, got {type(vm).__name__}")
        for name, v, lo, hi in (("tol", tol, 1e-15, 1e-4), ("perturbation", perturbation, 1e-12, 1.0),
                                ("rank_rtol", rank_rtol, 1e-16, 1e-2)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise InputError(f"{name} must be a number in [{lo:g}, {hi:g}]; got {v!r}")
        for name, v, lo, hi in (("max_iter", max_iter, 1, 100_000), ("restarts", restarts, 0, 1000),
                                ("seed", seed, 0, 2**63 - 1)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise InputError(f"{name} must be an integer in [{lo}, {hi}]; got {v!r}")
        self.vm = vm
        self.tol, self.max_iter, self.restarts = float(tol), int(max_iter), int(restarts)
        self.perturbation, self.seed, self.follow_stable = float(perturbation), int(seed), bool(follow_stable)
        self.rank_rtol = float(rank_rtol)
        model = vm.model
        if isinstance(loads, Load):
            loads = (loads,)
        loads = tuple(loads)
        probe_c = ClosureSet(vm)
        probe_l = DeadLoads(vm, loads, None)
        ids = [vm.frame_id, *probe_c.frame_ids, *probe_l.frame_ids]
        self.frames = FrameKinematics(model, ids)
        # eq. (16) contractions in screw form from the Jacobians (no 6 × nv × nv kinematic
        # Hessians; the same matrices to round-off) for chains of 1-DoF joints without link weights
        self._screw = screw_applicable(model) and gravity is None
        self.closures = ClosureSet(vm, frames=self.frames, screw=self._screw)
        self.loads = DeadLoads(vm, loads, gravity, frames=self.frames)
        self._gravity_only = DeadLoads(vm, (), gravity) if self.loads.gravity is not None else None
        self.task = list(vm.task)
        self.free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
        self.nt = vm.n_theta
        self._mask_free = support_mask(model.nv, self.free) if self._screw else None
        # screw form: the free coordinates (free order) whose joints support the task frame (the
        # nonzero columns of its Jacobian at every configuration: a 1-DoF joint's column holds its
        # unit axis) and their support mask (_hessian)
        self._end_support = None
        if self._screw:
            sup = {model.joints[j].idx_v for j in model.supports[model.frames[vm.frame_id].parentJoint] if j > 0}
            nz = np.flatnonzero(np.isin(self.free, sorted(sup)))
            self._end_support = (nz, support_mask(model.nv, self.free[nz]))
        n = len(self.free)
        ref = self.frames.evaluate(vm.reference, hessian=False)
        end0 = ref[vm.frame_id]
        self.p0, self.r0 = end0.position.copy(), end0.rotation.copy()
        self._load_ref = [(ref[f].position.copy(), ref[f].rotation.copy()) for f in self.loads.load_frame_ids]
        data = data_for(model)  # the thread's shared Data (kinematics/shared.py)
        pin.forwardKinematics(model, data, vm.reference)
        pts = [m.translation for m in data.oMi[1:]] + [self.p0]
        self.length_scale = max(max(np.linalg.norm(p - self.p0) for p in pts), 1e-3)
        prism = np.array([model.joints[i + 1].shortname().startswith("JointModelP") for i in range(model.nv)])
        self.var_scale = np.where(prism[self.free], self.length_scale, 1.0) if n else np.zeros(0)
        self._prism = prism[self.free] if n else np.zeros(0, bool)
        self.kscale = float(np.abs(vm.K_theta).max()) if vm.K_theta.size else 1.0
        self.kz = np.zeros((n, n))
        self.kz[: self.nt, : self.nt] = vm.K_theta
        self.threshold = STABILITY_TOL * (spectral_norm(vm.K_theta) if vm.K_theta.size else 1.0)
        self.closure_labels = self.closures.labels
        self._cscale = np.array(
            [self.length_scale if c in ("x", "y", "z") else 1.0 for cl in self.closures.closures for c in cl.components]
        )
        self._closure_position = np.array(
            [c in ("x", "y", "z") for cl in self.closures.closures for c in cl.components], bool
        )
        # task axes: rows (world components) of the task coordinates that held/loaded rows index
        self._axes = np.eye(6)[self.task]
        self._axis_labels = tuple(f"task.{COMPONENTS[c]}" for c in self.task)
        self._axis_translation = np.array([c < 3 for c in self.task], bool)
        self._custom_axes = False
        self._states = threading.local()  # per thread: an OrderedDict of STATE_CACHE_SIZE states
        self._split_memo: dict = {}  # _split_axes

    def with_task_axes(self, axes) -> MechanismSolver:
        """A solver sharing this one's kinematics whose task coordinates are the rows of ``axes``
        instead of the task components: the held rows ``hrows`` of the internal Newton
        (``_solve_target``, :meth:`linearize`) index these rows, the loaded ones carry the dead
        wrench projected on them (the free-platform curve of
        :func:`~vjm_pin.analysis.curve.trace_curve` holds one direction ``d`` and loads the rest
        with zero). Results of such a solver report ``held_axes`` instead of ``held``.

        Args:
            axes: (m, 6) orthonormal rows (world components) spanning the task components, each
                a pure translation or a pure rotation.
        """
        import copy

        t = np.asarray(axes, float)
        m = len(self.task)
        off = [i for i in range(6) if i not in self.task]
        pure = all(not (np.any(r[:3]) and np.any(r[3:])) for r in t) if t.ndim == 2 else False
        if (t.shape != (m, 6) or not np.all(np.isfinite(t)) or not pure
                or np.abs(t[:, off]).max(initial=0.0) > 0 or not np.allclose(t @ t.T, np.eye(m), atol=1e-12)):
            raise InputError(
                f"task axes must be {m} orthonormal rows of 6 (translation or rotation) spanning the task components"
            )
        new = copy.copy(self)
        new._axes = t.copy()
        new._axis_labels = tuple(f"task.axis{i}" for i in range(m))
        new._axis_translation = np.array([bool(np.any(r[:3])) for r in t], bool)
        new._custom_axes = True
        new._states = threading.local()  # other task rows: other states
        new._split_memo = {}
        return new

    def sibling(self, **options) -> MechanismSolver:
        """A copy sharing the kinematics (one ``pin.Data``) with some of ``follow_stable``,
        ``restarts``, ``tol``, ``max_iter`` changed (and the evaluated states: these options do
        not enter them)."""
        import copy

        new = copy.copy(self)
        for k, v in options.items():
            if k not in ("follow_stable", "restarts", "tol", "max_iter"):
                raise InputError(f"sibling options are follow_stable, restarts, tol, max_iter; got {k!r}")
            setattr(new, k, type(getattr(self, k))(v))
        return new

    def at_reference(self, vm: VjmModel) -> MechanismSolver:
        """A copy sharing the kinematics (one ``pin.Data``) for ``vm``: the same Pinocchio model,
        task, springs, roles and closures with another reference configuration and rest values
        (actuators moved and the mechanism re-assembled: the poses of a map, issue 14). What
        depends on the reference is recomputed as in ``__init__`` (``p0``, ``r0``, the load
        frames' reference placements, ``L_c``), so the numbers equal a new solver's.

        Raises:
            InputError: ``vm`` differs in more than its reference and rest values.
        """
        import copy

        old = self.vm
        same = (
            isinstance(vm, VjmModel) and vm.model is old.model and vm.frame_id == old.frame_id
            and tuple(vm.task) == tuple(old.task) and vm.closures == old.closures
            and np.array_equal(vm.theta_idx, old.theta_idx) and np.array_equal(vm.q_idx, old.q_idx)
            and np.array_equal(vm.K_theta, old.K_theta)
        )
        if not same:
            raise InputError("at_reference takes the solver's model with another reference configuration only")
        new = copy.copy(self)
        new.vm = vm
        ref = self.frames.evaluate(vm.reference, hessian=False)
        end0 = ref[vm.frame_id]
        new.p0, new.r0 = end0.position.copy(), end0.rotation.copy()
        new._load_ref = [(ref[f].position.copy(), ref[f].rotation.copy()) for f in self.loads.load_frame_ids]
        data = data_for(vm.model)  # the thread's shared Data (kinematics/shared.py)
        pin.forwardKinematics(vm.model, data, vm.reference)
        pts = [m.translation for m in data.oMi[1:]] + [new.p0]
        new.length_scale = max(max(np.linalg.norm(p - new.p0) for p in pts), 1e-3)
        new.var_scale = np.where(new._prism, new.length_scale, 1.0) if len(self.free) else np.zeros(0)
        new._cscale = np.array(
            [new.length_scale if c in ("x", "y", "z") else 1.0 for cl in self.closures.closures for c in cl.components]
        )
        new._states = threading.local()  # another model: other states
        return new

    def linearize(self, x, hrows, wrench=None, state=None) -> Linearization:
        """The :class:`Linearization` at ``x`` with the task axes ``hrows`` held and the dead
        task ``wrench`` (6,) on the others (default zero); ``state``: the internal state there
        when already evaluated with the Hessian (``_newton``'s last)."""
        w = np.zeros(6) if wrench is None else np.asarray(wrench, float)
        s = state if state is not None else self._state(
            np.asarray(x, float), hrows, w, self.p0, self.r0, 1.0, True
        )
        nc = s.cstate.residual.size
        c = s.cstate.jacobian[:, self.free]
        ind = np.array([i for i in s.indep if i < nc], int) if nc else np.zeros(0, int)
        return Linearization(
            x=np.asarray(x, float).copy(),
            hessian=self._hessian(s),
            closure_jacobian=c,
            closure_independent=ind,
            task_jacobian=s.end.jacobian[:, self.free],
            wrench=s.w6.copy(),
            closure_multipliers=s.nu[:nc].copy(),
            held_rows=self._split_axes(hrows)[0],
            independent_multipliers=np.asarray(s.nu_i[: len(ind)], float).copy(),
        )

    def kkt_residual(self, x, hrows, w_dead, p_t, r_t, closure_rows, mu, nu):
        """The equilibrium residuals at ``x`` without Hessians (a chord corrector's): the
        stationarity ``r = ∇Π − C_Iᵀμ − (H J)ᵀν`` (free order), the held rows' ``b_h`` (target
        minus current, ``H J δz = b_h``), the closure residual ``c`` (every row) and the
        convergence test of the Newton iteration (:meth:`_newton`'s, with these multipliers).
        ``closure_rows``: the independent closure rows ``μ`` belongs to."""
        vm, free = self.vm, self.free
        th, tl = self._split_axes(hrows)
        states = self.frames.evaluate(x, hessian=False)
        end = states[vm.frame_id]
        cst = self.closures.evaluate(x, hessian=False)
        lst = self.loads.evaluate(x, hessian=False)
        tau = np.zeros(len(free))
        tau[: self.nt] = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        jz = end.jacobian[:, free]
        qload = lst.force[free] + jz.T @ (tl.T @ (tl @ w_dead))
        ci = cst.jacobian[closure_rows][:, free]
        react = ci.T @ mu + (th @ jz).T @ nu
        r = tau - qload - react
        bh = th @ pose_error(p_t, r_t, end.position, end.rotation)
        c = cst.residual
        pos = self._is_position_row(hrows)
        ab = np.abs(np.concatenate([c, bh]))
        ep = ab[pos].max(initial=0.0)
        er = ab[~pos].max(initial=0.0)
        stat_scale = max(np.abs(tau).max(initial=0.0), np.abs(qload).max(initial=0.0),
                         np.abs(react).max(initial=0.0), 1e-6 * self.kscale)
        conv = (ep <= 0.01 * self.tol * self.length_scale and er <= 0.01 * self.tol
                and np.abs(r).max(initial=0.0) <= self.tol * stat_scale)
        return r, bh, c, bool(conv)

    def _split_axes(self, hrows) -> tuple[np.ndarray, np.ndarray]:
        """(held rows, loaded rows) of the task axes, world components (read-only arrays, kept per
        set of held rows)."""
        key = tuple(int(i) for i in hrows)
        hit = self._split_memo.get(key)
        if hit is None:
            h = np.asarray(key, int)
            mask = np.ones(len(self._axes), bool)
            mask[h] = False
            hit = (self._axes[h], self._axes[mask])
            for arr in hit:
                arr.flags.writeable = False
            self._split_memo[key] = hit
        return hit

    # ----------------------------------------------------------------- inputs
    def components(self, spec) -> tuple[int, ...]:
        """Task component indices (task order) from names or indices 0..5."""
        if spec is None:
            return ()
        items = spec.split() if isinstance(spec, str) else list(spec)
        out = set()
        for c in items:
            if isinstance(c, str) and c in COMPONENTS:
                c = COMPONENTS.index(c)
            elif not (isinstance(c, (int, np.integer)) and not isinstance(c, bool) and 0 <= c < 6):
                raise InputError(f"task components are names ({' '.join(COMPONENTS)}) or indices 0..5; got {c!r}")
            if int(c) not in self.task:
                raise InputError(
                    f"component {COMPONENTS[int(c)]} is not in the task of this model ({' '.join(self.vm.task_names)})"
                )
            out.add(int(c))
        return tuple(c for c in self.task if c in out)

    def _vector6(self, v, name: str, unit: str) -> np.ndarray:
        """6 numbers, one per task component (in task order) or 3 (the translation):
        :func:`~vjm_pin.model.task.task_vector`; components outside the task are checked by the
        caller, which names held and loaded ones."""
        from vjm_pin.model.task import task_vector

        return task_vector(v, self.task, name, unit, task_sized=True, outside_task="keep")

    # ----------------------------------------------------------------- evaluation
    def energy(self, x: np.ndarray) -> float:
        """Spring energy ½(θ−θ₀)ᵀK_θ(θ−θ₀) (J)."""
        d = x[self.vm.theta_idx] - self.vm.theta0
        return 0.5 * float(d @ self.vm.K_theta @ d)

    def _potential(self, x, end, lrows, w_dead, factor) -> float:
        """Total potential (J): springs minus the work of the loads (a moment's work through
        ``log3(R R0ᵀ)``, exact for forces; a dead moment has no exact potential in 3-D)."""
        pot = self.energy(x)
        tl = self._axes[np.asarray(lrows, int)]
        if tl.size:
            d = deflection(self.p0, self.r0, end.position, end.rotation)
            pot -= float((tl @ w_dead) @ (tl @ d))
        if factor and (self.loads.loads or self._gravity_only is not None):
            states = self.frames.evaluate(x, hessian=False)
            for ld, fid, (p0, r0) in zip(self.loads.loads, self.loads.load_frame_ids, self._load_ref):
                st = states[fid]
                pot -= factor * float(ld.wrench[:3] @ (st.position - p0))
                if np.any(ld.wrench[3:]):
                    pot -= factor * float(ld.wrench[3:] @ pin.log3(st.rotation @ r0.T))
            if self._gravity_only is not None:
                pot += factor * float(self._gravity_only.evaluate(x, hessian=False).potential)
        return pot

    def _state(self, x, hrows, w_dead, p_t, r_t, factor, hessian) -> _State:
        """The :class:`_State` at ``x`` (:meth:`_evaluate_state`), one of the last
        :data:`STATE_CACHE_SIZE` evaluated on this thread when its inputs are the same bytes."""
        key = (
            np.ascontiguousarray(x, dtype=float).tobytes(),
            tuple(int(i) for i in hrows),
            np.ascontiguousarray(w_dead, dtype=float).tobytes(),
            np.ascontiguousarray(p_t, dtype=float).tobytes(),
            np.ascontiguousarray(r_t, dtype=float).tobytes(),
            float(factor),
            bool(hessian),
            self.rank_rtol,
        )
        cache = getattr(self._states, "cache", None)
        if cache is None:
            cache = self._states.cache = OrderedDict()
        hit = cache.get(key)
        if hit is not None:
            cache.move_to_end(key)
            return hit
        st = self._evaluate_state(x, hrows, w_dead, p_t, r_t, factor, hessian)
        cache[key] = st
        if len(cache) > STATE_CACHE_SIZE:
            cache.popitem(last=False)
        return st

    def _evaluate_state(self, x, hrows, w_dead, p_t, r_t, factor, hessian) -> _State:
        vm, free = self.vm, self.free
        th, tl = self._split_axes(hrows)
        screw = hessian and self._screw
        states = self.frames.evaluate(x, hessian=hessian and not screw)
        end = states[vm.frame_id]
        cst = self.closures.evaluate(x, hessian=hessian)
        lst = self.loads.evaluate(x, hessian=hessian and not screw)
        n = len(free)
        tau = np.zeros(n)
        tau[: self.nt] = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
        jz = end.jacobian[:, free]
        wl = tl.T @ (tl @ w_dead)
        qload = factor * lst.force[free] + jz.T @ wl
        grad = tau - qload
        a = np.vstack([cst.jacobian[:, free], th @ jz])
        e = th @ pose_error(p_t, r_t, end.position, end.rotation)
        b = np.concatenate([-cst.residual, e])
        bscale = np.concatenate([self._cscale, np.where(self._axis_translation[np.asarray(hrows, int)], self.length_scale, 1.0)])
        k = a.shape[0]
        if k and self._full_row_rank(a):  # full row rank: every row independent
            indep, redundant = np.arange(k), ()
        elif k:
            info = constraint_rank(a, rtol=self.rank_rtol)
            indep = np.array(sorted(info.independent), int)
            redundant = info.redundant
        else:
            indep, redundant = np.zeros(0, int), ()
        ki = len(indep)
        if ki:
            q, rm = np.linalg.qr(a[indep].T, mode="complete")
            y, z, rr = q[:, :ki], q[:, ki:], rm[:ki]
            with np.errstate(all="ignore"):
                nu_i = np.linalg.solve(rr, y.T @ grad)
        else:
            y, z, rr, nu_i = np.zeros((n, 0)), np.eye(n), np.zeros((0, 0)), np.zeros(0)
        r = grad - a[indep].T @ nu_i if ki else grad.copy()
        nu = np.zeros(k)
        if ki:
            nu[indep] = nu_i
            if redundant:  # the minimum-norm set carrying the same generalised force
                u, s, vt = np.linalg.svd(a.T, full_matrices=False)
                g = a[indep].T @ nu_i
                nu = vt[:ki].T @ ((u[:, :ki].T @ g) / s[:ki])
        w6 = wl + th.T @ nu[cst.residual.size :]
        dload = None
        if screw:  # the dead loads' eq. (16) contractions (no link weights on this path)
            dload = np.zeros((n, n))
            for ld, fid in zip(self.loads.loads, self.loads.load_frame_ids):
                dload += psi_hessian_screw(states[fid].jacobian[:, free], ld.wrench, self._mask_free)
            dload *= factor
        elif hessian:
            dload = factor * lst.derivative[np.ix_(free, free)]
        return _State(end, cst, grad, tau, qload, a, b, bscale, indep, redundant, y, z, rr, nu, nu_i, r, w6, dload)

    def _full_row_rank(self, a: np.ndarray) -> bool:
        """``row_rank(a)[4] == len(a)`` (:func:`~vjm_pin.kinematics.closures.row_rank`: every
        singular value of the row-normalised ``S`` above ``rank_rtol`` × the largest), without its
        SVD when the last matrix of this shape found full rank on this thread, ``S₀``, is close:
        singular values move by at most ``‖S − S₀‖_F`` (Weyl), so ``σ_min(S₀) − δ > rtol·(σ_max(S₀) +
        δ)`` with ``δ = ‖S − S₀‖_F +`` :data:`SV_ERROR` decides it (the Newton iterates of one
        solve barely move the constraint rows; the same answer as the SVD)."""
        memo = getattr(self._states, "rank", None)
        if memo is not None and memo[0].shape == a.shape and np.all(np.isfinite(a)):
            norms = np.linalg.norm(a, axis=1)
            big = float(norms.max())
            if big > 0 and np.all(norms > self.rank_rtol * big):
                delta = float(np.linalg.norm(a / norms[:, None] - memo[0])) + SV_ERROR
                if memo[1] - delta > self.rank_rtol * (memo[2] + delta):
                    return True
        _, scaled, sv, _, rank = row_rank(a, self.rank_rtol)
        if rank == a.shape[0]:
            self._states.rank = (scaled, float(sv[-1]), float(sv[0]))
            return True
        return False

    def _hessian(self, s: _State) -> np.ndarray:
        """``W = K − ∂Q/∂z − H(w) − Σ μ_k ∂²c_k/∂z²`` (free block); formed once per state (the
        Newton iteration's, then the linearisation and the verdicts at its converged point)."""
        if s.hess is not None:
            return s.hess
        free = self.free
        nc = s.cstate.residual.size
        if s.end.hessian is None:  # screw form (self._screw), on the joints that move the task frame
            jf = s.end.jacobian[:, free]
            nz, mask = self._end_support
            hend = np.zeros((len(free), len(free)))
            hend[np.ix_(nz, nz)] = psi_hessian_screw(jf[:, nz], s.w6, mask)
        else:
            hend = contract_hessian(s.end.hessian, s.w6)[np.ix_(free, free)]
        w = self.kz - s.dload - hend
        if nc:
            w = w - s.cstate.hessian(s.nu[:nc])[np.ix_(free, free)]
        w.flags.writeable = False  # shared: the state (kept, _state) and every Linearization of it
        s.hess = w
        return w

    # ----------------------------------------------------------------- Newton
    def _newton(self, x, hrows, w_dead, p_t, r_t, factor, max_iter, local=False, stall=0, soc=False,
                radius=None):
        """Returns (x, iterations, converged, state). ``stall``: give up (not converged) when the
        last ``stall`` descent steps made no progress (:data:`STALL_WINDOW`); 0: never.
        ``radius``: give up (not converged; state None) at an iterate farther than that from the
        start (largest free coordinate change, rad, prismatic ones per ``var_scale``): for a
        caller that accepts only a solution near the start.
        ``soc``: a trial point of the line search that the merit rejects is tried again with the
        second-order correction ``−A_I⁺ b(x + αδx)`` (minimum-norm, the factorisation of the
        iteration: Nocedal & Wright §15.6), which removes the constraint curvature's
        O(|αδx|²) residual that otherwise makes the ℓ₁ merit cut the steps of a descent
        along a curved constraint manifold (Maratos effect) to a crawl."""
        tol, lc = self.tol, self.length_scale
        kscale = max(self.kscale, 1e-300)
        shift = SHIFT_TOL * kscale
        lrows = [i for i in range(len(self.task)) if i not in set(hrows)]
        x = np.array(x, float)
        polish = escapes = 0
        kkt_prev = np.inf
        s = rho_prev = None
        drops: list[float] = []  # merit decrease of each accepted descent step (stall test)
        kkts: list[float] = []
        x_start = x.copy() if radius is not None else None
        for it in range(max_iter + 1 + POLISH_ITERATIONS):
            if it and radius is not None and np.abs((x - x_start)[self.free] / self.var_scale).max() > radius:
                return x, it, False, None
            s = self._state(x, hrows, w_dead, p_t, r_t, factor, True)
            if not (np.all(np.isfinite(s.nu)) and np.all(np.isfinite(s.r))):
                return x, it, False, s
            ab = np.abs(s.b)
            pos = self._is_position_row(hrows)
            ep = ab[pos].max() if pos.any() else 0.0
            er = ab[~pos].max() if (~pos).any() else 0.0
            stat_scale = max(np.abs(s.tau).max() if s.tau.size else 0.0,
                             np.abs(s.load_force).max() if s.load_force.size else 0.0,
                             np.abs(s.a.T @ s.nu).max() if s.a.size else 0.0, 1e-6 * self.kscale)
            rs = np.abs(s.r).max() if s.r.size else 0.0
            conv = ep <= 0.01 * tol * lc and er <= 0.01 * tol and rs <= tol * stat_scale
            wm = self._hessian(s)
            red = s.z.T @ wm @ s.z
            if self.follow_stable and not local:
                lmin = np.linalg.eigvalsh(0.5 * (red + red.T)).min() if red.size else np.inf
            else:  # the plain Newton: no shift, no escape (the smallest eigenvalue is not used)
                lmin = np.inf
            modified = False
            if self.follow_stable and not local and lmin < shift:
                # mirror a negative curvature (min eigenvalue |λ_min| + shift): a near-singular
                # shifted matrix would send the step along the softest mode at full length
                red = red + (shift - lmin + max(-lmin, 0.0)) * np.eye(red.shape[0])
                modified = True
            bi = s.b[s.indep]
            with np.errstate(all="ignore"):
                try:
                    py = np.linalg.solve(s.rr.T, bi) if bi.size else np.zeros(0)
                    dy = s.y @ py
                    pz = np.linalg.solve(red, -s.z.T @ (s.r + wm @ dy)) if red.size else np.zeros(0)
                except np.linalg.LinAlgError:
                    return x, it, False, s
                dx = dy + s.z @ pz
            if not np.all(np.isfinite(dx)):
                return x, it, False, s
            smax = np.abs(dx / self.var_scale).max() if dx.size else 0.0
            if not conv and not modified and smax <= POLISH_STEP:  # the rounding floor
                conv = ep <= 0.01 * tol * lc and er <= 0.01 * tol and rs <= 1e3 * tol * stat_scale
            if conv and modified and not local and escapes < 2 and lmin < -self.threshold:
                escapes += 1  # a saddle reached by descent: leave along the most negative curvature
                sym = s.z.T @ wm @ s.z
                _, vec = np.linalg.eigh(0.5 * (sym + sym.T))
                v = s.z @ vec[:, 0]
                x = x.copy()
                x[self.free] += v * (MAX_STEP / max(np.abs(v / self.var_scale).max(), 1e-300))
                kkt_prev = np.inf
                drops.clear()
                kkts.clear()
                continue
            if conv:
                if modified or polish >= POLISH_ITERATIONS or smax <= POLISH_STEP:
                    return x, it, True, s
                polish += 1
                x = x.copy()
                x[self.free] += dx
                continue
            if it - polish >= max_iter:
                break
            kkt0 = float(np.linalg.norm(s.b / s.bscale) + np.linalg.norm(s.r) / kscale)
            if local:
                if not (smax <= MAX_STEP and kkt0 < 0.5 * kkt_prev):
                    return x, it, False, s
                kkt_prev = kkt0
                x = x.copy()
                x[self.free] += dx
                continue
            if smax > MAX_STEP:
                dx = dx * (MAX_STEP / smax)
                modified = True
            # ℓ₁ penalty weights above the current and the step's multipliers (exact penalty),
            # never decreasing along the attempt
            nu_all = np.zeros(len(s.b))
            nu_all[s.indep] = np.abs(s.nu_i)
            if s.indep.size:
                with np.errstate(all="ignore"):
                    nu_new = np.linalg.solve(s.rr, s.y.T @ (s.grad + wm @ dx))
                if np.all(np.isfinite(nu_new)):
                    nu_all[s.indep] = np.maximum(nu_all[s.indep], np.abs(nu_new))
            rho = 2.0 * nu_all + 1e-9 * stat_scale / s.bscale
            if rho_prev is not None and rho_prev.shape == rho.shape:
                rho = np.maximum(rho, rho_prev)
            rho_prev = rho
            phi0 = self._potential(x, s.end, lrows, w_dead, factor) + float(rho @ ab)
            slope = min(float(s.grad @ dx) - float(rho @ ab), 0.0)
            noise = 1e-13 * (abs(phi0) + self.energy(x) + 1e-300)
            alpha, accepted = 1.0, False
            phi_n = phi0
            for _ in range(40):
                xn = x.copy()
                xn[self.free] += alpha * dx
                end_n, bn = self._trial(xn, hrows, p_t, r_t)
                if np.all(np.isfinite(bn)):
                    if not self.follow_stable:
                        accepted = True
                    else:
                        phi_n = self._potential(xn, end_n, lrows, w_dead, factor) + float(rho @ np.abs(bn))
                        if phi_n <= (phi0 + 1e-4 * alpha * slope + noise):
                            accepted = True
                        elif alpha == 1.0 and not modified:
                            sn = self._state(xn, hrows, w_dead, p_t, r_t, factor, False)
                            kn = float(np.linalg.norm(sn.b / sn.bscale) + np.linalg.norm(sn.r) / kscale)
                            accepted = kn < 0.5 * kkt0
                        if not accepted and soc and s.indep.size:
                            with np.errstate(all="ignore"):
                                xc = xn.copy()
                                xc[self.free] += s.y @ np.linalg.solve(s.rr.T, bn[s.indep])
                            end_c, bc = self._trial(xc, hrows, p_t, r_t)
                            if np.all(np.isfinite(bc)):
                                phi_c = self._potential(xc, end_c, lrows, w_dead, factor) + float(rho @ np.abs(bc))
                                if phi_c <= (phi0 + 1e-4 * alpha * slope + noise):
                                    accepted, xn, phi_n = True, xc, phi_c
                if accepted:
                    break
                alpha *= 0.5
            if not accepted:
                return x, it + 1, False, s
            if stall:
                drops.append(phi0 - phi_n)
                kkts.append(kkt0)
                if len(kkts) > stall:
                    recent = sum(drops[-stall:])
                    if recent <= STALL_REL * (abs(phi0) + self.energy(x)) and min(kkts[-stall:]) > 0.5 * min(kkts[:-stall]):
                        return x, it + 1, False, s
            x = xn
        return x, max_iter, False, s

    def _trial(self, x, hrows, p_t, r_t):
        """The task-frame placement (``position``, ``rotation``) and the constraint right-hand
        side ``b`` at a trial point of the line search: placements only (one forward-kinematics
        pass, no Jacobians; the same numbers as the full evaluation's)."""
        pl = self._placements(x)
        end = _Placement(*pl[self.vm.frame_id])
        e = self._split_axes(hrows)[0] @ pose_error(p_t, r_t, end.position, end.rotation)
        return end, np.concatenate([-self.closures.residual_from(pl), e])

    def _placements(self, x) -> dict:
        """Frame id → (position, rotation) (world) of every frame this solver evaluates, at ``x``
        (the thread's shared ``pin.Data``; copies)."""
        model = self.vm.model
        data = data_for(model)
        pin.forwardKinematics(model, data, np.asarray(x, float))
        out = {}
        for fid in self.frames.frame_ids:
            m = pin.updateFramePlacement(model, data, fid)
            out[fid] = (m.translation.copy(), m.rotation.copy())
        return out

    def _is_position_row(self, hrows) -> np.ndarray:
        cp = self._closure_position
        return np.concatenate([cp, self._axis_translation[np.asarray(hrows, int)]])

    def _perturb(self, x, rng) -> np.ndarray:
        xn = x.copy()
        noise = rng.standard_normal(len(self.free)) * self.perturbation
        xn[self.free] += np.where(self._prism, noise * 1e-3 * self.length_scale, noise)
        return xn

    # ----------------------------------------------------------------- solve
    @one_blas_thread
    def solve(self, deflection=None, wrench=None, held=None, *, x0=None, raise_on_failure: bool = True) -> MechanismResult:
        """Equilibrium of the mechanism under mixed control.

        Args:
            deflection: Prescribed task deflection (m, world rotation vector rad): 6, 3 or
                ``len(task)`` numbers; non-zero only on held components.
            wrench: Dead task wrench (N at the task-frame origin, N·m; world axes): 6, 3 or
                ``len(task)`` numbers; non-zero only on loaded components.
            held: Held task components (names or 0..5); the others are loaded. Default:
                every component held when ``wrench`` is None, none when ``deflection`` is None
                and ``wrench`` given; required when both are given.
            x0: Starting configuration (nq,), assembled or near it; default the reference.
            raise_on_failure: Raise :class:`NoEquilibrium` when nothing converges.

        Returns:
            :class:`MechanismResult` (both verdicts; redundant rows; min-norm multipliers).
        """
        if held is None:
            if wrench is None:
                held = tuple(self.task)
            elif deflection is None:
                held = ()
            else:
                raise InputError("both a deflection and a wrench given: say which task components are held")
        hcomp = self.components(held)
        d = np.zeros(6) if deflection is None else self._vector6(deflection, "deflection", "m, rad")
        w = np.zeros(6) if wrench is None else self._vector6(wrench, "wrench", "N, N·m")
        outside = [COMPONENTS[i] for i in range(6) if i not in self.task and (d[i] or w[i])]
        if outside:
            raise InputError(
                f"components {outside} are not in the task of this model ({' '.join(self.vm.task_names)})"
            )
        bad = [COMPONENTS[c] for c in self.task if c not in hcomp and d[c]]
        if bad:
            raise InputError(f"deflection prescribed on loaded components {bad}: hold them, or prescribe their wrench")
        bad = [COMPONENTS[c] for c in hcomp if w[c]]
        if bad:
            raise InputError(f"wrench prescribed on held components {bad}: their wrench is the reaction")
        x = self.vm.reference.copy() if x0 is None else np.asarray(x0, float).ravel().copy()
        if x.shape != (self.vm.model.nq,) or not np.all(np.isfinite(x)):
            raise InputError(f"x0 must be a finite configuration of size {self.vm.model.nq}")
        hrows = [self.task.index(c) for c in hcomp]
        res = self._rotation_targets(d, hcomp, hrows, w, x, stall=STALL_WINDOW)
        if not res.converged and raise_on_failure and "+path-" in res.path:
            kind, rest = res.path.split("+path-")[1].split("(", 1)
            span, far = rest.rstrip(")").split(";far=")
            lo, hi = (float(v) for v in span.split("-"))
            what = "stops (a limit load)" if kind == "ends" else "loses its stability"
            raise NoEquilibrium(
                f"buckling: the loading path {what} between {lo:.3g} and {hi:.3g} × the load, so this load "
                f"exceeds a critical load; past it the mechanism jumps to a distant equilibrium "
                f"({float(far):.3g} m deflection), reported as no equilibrium of the load path",
                res,
                res.residual(),
            )
        if not res.converged and raise_on_failure:
            names = " ".join(COMPONENTS[c] for c in hcomp) or "none"
            raise NoEquilibrium(
                f"no equilibrium of the mechanism found (held: {names}; task wrench {np.round(w, 9).tolist()}; "
                f"{len(self.loads.loads)} dead load(s)) after {res.iterations} iterations (residuals {res.residuals})",
                res,
                res.residual(),
            )
        return res

    def _rotation_targets(self, d, hcomp, hrows, w, x0, stall: int = 0) -> MechanismResult:
        """Held rows of ``log3(R_t Rᵀ)`` with ``R_t = exp3(d̂) R0``; with some but not all
        rotations held, ``d̂`` is corrected until the reported ``log3(R R0ᵀ)`` meets ``d`` in the
        held components (as :meth:`EquilibriumSolver._rotation_targets`); ``stall`` as
        :meth:`_solve_target`."""
        p, r = displace(self.p0, self.r0, d)
        res = self._solve_target(p, r, hrows, w, x0, stall)
        hrot = [c for c in hcomp if c >= 3]
        if not (0 < len(hrot) < 3):
            return res
        other = [c for c in (3, 4, 5) if c not in hrot]
        dh = np.array(d, float)
        total, prev = res.iterations, np.inf
        for _ in range(ROTATION_TARGET_ITER):
            if not res.converged:
                break
            err = d[hrot] - res.deflection[hrot]
            size = np.abs(err).max()
            if size <= 0.1 * ROTATION_TARGET_TOL or (size <= ROTATION_TARGET_TOL and size > 0.5 * prev):
                break
            prev = size
            dh[hrot] += err
            dh[other] = res.deflection[other]
            p, r = displace(self.p0, self.r0, dh)
            res = self._solve_target(p, r, hrows, w, res.x, stall)
            total += res.iterations
        return replace(res, iterations=total)

    def _solve_target(self, p_t, r_t, hrows, w_dead, x_start, stall: int = 0) -> MechanismResult:
        """The equilibrium at the targets (local Newton, descent, continuation with restarts);
        ``stall``: the descents and continuation steps give up when they stall (:data:`STALL_WINDOW`;
        :meth:`solve`'s, so that an unreachable target fails sooner; the curve tracer keeps 0)."""
        total = 0
        label = "newton"
        x, it, ok, _ = self._newton(x_start, hrows, w_dead, p_t, r_t, 1.0, LOCAL_MAX_ITER, local=True)
        total += it
        if not ok:
            x, it, ok, _ = self._newton(x_start, hrows, w_dead, p_t, r_t, 1.0, DESCENT_ITER_FACTOR * self.max_iter,
                                        stall=stall)
            total += it
            label += "+descent"
            if ok and self._dead_loaded(w_dead) and self._jump(x, x_start) > FAR_JUMP:
                # The descent may land on a distant equilibrium that loading never reaches (past a
                # limit load the structure snaps through): accept what load continuation reaches.
                x, ok, it, label = self._on_loading_path(x, x_start, hrows, w_dead, p_t, r_t, label)
                total += it
                if not ok:
                    return self._result(x, total, ok, hrows, w_dead, p_t, r_t, label)
        if not ok:
            rng = np.random.default_rng(self.seed)
            ps = self.frames.evaluate(x_start, hessian=False)[self.vm.frame_id]
            dlog = pin.log3(r_t @ ps.rotation.T)
            starts = [x_start] + [self._perturb(x_start, rng) for _ in range(self.restarts)]
            for si, xs in enumerate(starts):
                for nsteps in (4, 16) if si == 0 else (1, 4, 16):
                    xc, okc = xs.copy(), True
                    for k in range(1, nsteps + 1):
                        a = k / nsteps
                        pk = (1 - a) * ps.position + a * p_t
                        rk = pin.exp3(a * dlog) @ ps.rotation
                        xc, itc, okc, _ = self._newton(xc, hrows, a * w_dead, pk, rk, a, self.max_iter, stall=stall)
                        total += itc
                        if not okc:
                            break
                    if okc:
                        x, ok = xc, True
                        label += (f"+restart({si})" if si else "") + f"+continuation({nsteps})"
                        break
                if ok:
                    break
        return self._result(x, total, ok, hrows, w_dead, p_t, r_t, label)

    def _jump(self, x, x0) -> float:
        """Largest change of a free coordinate from ``x0`` to ``x`` (rad; prismatic ones per
        the mechanism's length scale)."""
        dz = (np.asarray(x, float) - np.asarray(x0, float))[self.free]
        return float(np.abs(dz / self.var_scale).max()) if dz.size else 0.0

    def _dead_loaded(self, w_dead) -> bool:
        """A dead load acts: a task wrench, loads at frames or link weights."""
        return bool(np.any(w_dead)) or bool(self.loads.loads) or self.loads.gravity is not None

    def _on_loading_path(self, x_far, x_start, hrows, w_dead, p_t, r_t, label):
        """Is the descent's equilibrium ``x_far`` what loading reaches? Plain-Newton load
        continuation from ``x_start`` (4, then 16 steps), each step judged under the control
        as run. A path stable up to the full load gives its end (the equilibrium loading
        reaches); a path that turns unstable before the full load means the load exceeds a
        critical load: ``ok=False`` with a label naming the bracket (``path-unstable(a_lo-a_hi;
        far=…)``, fractions of the load, and the distance of the descent's equilibrium). When the
        plain Newton cannot follow the path at all (a singular start, e.g. a straight chain of
        passive joints under a lateral load) nothing is concluded and ``x_far`` stands.
        Returns ``(x, ok, iterations, label)``."""
        ps = self.frames.evaluate(x_start, hessian=False)[self.vm.frame_id]
        dlog = pin.log3(r_t @ ps.rotation.T)
        total, lo, step, kind = 0, 0.0, 1.0, "ends"
        for nsteps in (4, 16):
            xc, okc = x_start.copy(), True
            for k in range(1, nsteps + 1):
                a = k / nsteps
                pk = (1 - a) * ps.position + a * p_t
                rk = pin.exp3(a * dlog) @ ps.rotation
                xc, itc, okc, st = self._newton(xc, hrows, a * w_dead, pk, rk, a, self.max_iter, local=True)
                total += itc
                if okc and st is not None and self._result(xc, 0, True, hrows, a * w_dead, pk, rk, "", state=st).stable is False:
                    okc, kind = False, "unstable"
                if not okc:
                    if (k - 1) / nsteps >= lo:
                        lo, step = (k - 1) / nsteps, 1 / nsteps
                    break
            if okc:
                return xc, True, total, label + f"+continuation({nsteps})"
            if kind == "unstable":
                break
        if kind == "ends":  # plain Newton cannot follow (e.g. a singular start): nothing to conclude
            return x_far, True, total, label + "+path-unchecked"
        far = float(np.linalg.norm(self._result(x_far, 0, True, hrows, w_dead, p_t, r_t, "").deflection[:3]))
        hi = min(1.0, lo + step)
        return x_start, False, total, label + f"+path-{kind}({lo:.4g}-{hi:.4g};far={far:.4g})"

    def _result(self, x, iters, ok, hrows, w_dead, p_t, r_t, path, state=None, verdicts=True) -> MechanismResult:
        """The result at ``x`` (``state``: the :class:`_State` there when already evaluated with the
        Hessian; ``verdicts=False`` skips both stability verdicts: the caller judges)."""
        vm = self.vm
        s = state if state is not None else self._state(x, hrows, w_dead, p_t, r_t, 1.0, True)
        nc = s.cstate.residual.size
        tarr = np.asarray(self.task, int)
        hcomp = tarr[np.asarray(hrows, int)]
        pos = self._is_position_row(hrows)
        ab = np.abs(s.b)
        rabs = np.abs(s.r)

        def top(v, mask):
            return float(v[mask].max()) if np.any(mask) else 0.0

        cmask = np.arange(len(ab)) < nc
        res = {
            "position": top(ab, pos & ~cmask),
            "orientation": top(ab, ~pos & ~cmask),
            "closure_position": top(ab, pos & cmask),
            "closure_orientation": top(ab, ~pos & cmask),
            "statics": top(rabs, ~self._prism),
            "statics_prismatic": top(rabs, self._prism),
        }
        labels = tuple(self.closure_labels) + tuple(self._axis_labels[i] for i in hrows)
        redundant = tuple(labels[i] for i in s.redundant)
        note = (
            MULTIPLIERS_NOTE.format(n=len(redundant), labels=", ".join(redundant)) if redundant else None
        )
        stab = end = None
        warnings: tuple[str, ...] = ()
        if ok and verdicts:
            wm = self._hessian(s)
            z, _ = _null_basis(s.a, self.rank_rtol)
            stab = _verdict(wm, z, self.threshold)
            jall = s.end.jacobian[:, self.free][tarr]
            z_end, _ = _null_basis(np.vstack([s.cstate.jacobian[:, self.free], jall]), self.rank_rtol)
            end = _verdict(wm, z_end, self.threshold)
            if not stab.stable:
                warnings = (
                    "unstable under the prescribed control: the mechanism would move away from this equilibrium"
                    + ("; stable with the task frame held (eq. 23)" if end.stable else ""),
                )
        mu = s.nu[:nc].copy()
        return MechanismResult(
            x=x.copy(),
            q=x[vm.q_idx].copy(),
            theta=x[vm.theta_idx].copy(),
            wrench=s.w6.copy(),
            closure_multipliers=mu,
            closure_labels=tuple(self.closure_labels),
            reaction_wrenches=s.cstate.reaction_wrenches(mu) if nc else {},
            deflection=deflection(self.p0, self.r0, s.end.position, s.end.rotation),
            position=s.end.position.copy(),
            rotation=s.end.rotation.copy(),
            converged=bool(ok),
            iterations=int(iters),
            residuals=res,
            energy=self.energy(x),
            path=path,
            held=() if self._custom_axes else tuple(int(c) for c in hcomp),
            stability=stab,
            stability_end_held=end,
            redundant=redundant,
            multipliers_note=note,
            warnings=warnings,
            held_axes=self._axes[np.asarray(hrows, int)].copy() if self._custom_axes else None,
        )

    # ----------------------------------------------------------------- unstable modes
    def unstable_modes(self, res: MechanismResult) -> tuple[np.ndarray, np.ndarray]:
        """The directions in which the equilibrium ``res`` is unstable (the verdict ``stable``).

        Eigenvectors ``v`` of the symmetric part of ``−ZᵀWZ`` (``Z`` the null space of the
        closure + held rows, ``W`` as in the Newton iteration) whose eigenvalue is not below
        ``−threshold`` (eq. 23 form), as configuration directions ``δx = Z v`` (nq,), zero on
        the rigid actuated coordinates, unit Euclidean norm (m and rad mixed).

        Returns:
            (eigenvalues (k,), ascending order of −curvature; modes (nq, k)); k = 0 when stable.
        """
        hrows = [self.task.index(c) for c in res.held]
        s = self._state(np.asarray(res.x, float), hrows, np.asarray(res.wrench, float), self.p0, self.r0, 1.0, True)
        z, _ = _null_basis(s.a, self.rank_rtol)
        red = -(z.T @ self._hessian(s) @ z)
        if not red.size:
            return np.zeros(0), np.zeros((self.vm.model.nq, 0))
        ev, vec = np.linalg.eigh(0.5 * (red + red.T))
        bad = ev >= -self.threshold
        modes = np.zeros((self.vm.model.nq, int(bad.sum())))
        modes[self.free] = z @ vec[:, bad]
        return ev[bad], modes

    # ----------------------------------------------------------------- stiffness
    @one_blas_thread
    def stiffness(self, res: MechanismResult, method: str = "eq28") -> StiffnessResult:
        """Loaded Cartesian stiffness K_C of the task frame at the equilibrium ``res`` (paper
        eq. 28–33 with the independent closure rows ``C_I``; every task row is an output).

        ``method="eq28"`` solves the bordered system::

            [[0, 0, J], [0, 0, C_I], [Jᵀ, C_Iᵀ, −W]] [δw; δμ; δz] = [δt; 0; 0]

        ``"eq30"``, ``"eq32"``, ``"eq33"`` apply the paper's formulas with the closure rows
        bordered like passive-joint rows (:func:`~vjm_pin.solver.stiffness.border_closures`: the
        multipliers ``δμ`` are passive coordinates of zero stiffness); eq. (32)/(33) need
        ``K_θ − H_θθ`` (and for eq. 33 ``J_θ k_θ^F J_θᵀ``) invertible. ``W`` (equivalently
        the blocks ``H − K`` of eq. 28) as in the Newton iteration, with the total task wrench
        of ``res`` and its closure multipliers (minimum-norm when redundant: K_C does not depend
        on that choice). Returns a :class:`StiffnessResult` (``method="<method>-closures"``;
        ``dq_dt``/``dtheta_dt`` the passive/spring sensitivities).

        Raises:
            NoEquilibrium: ``res`` did not converge.
            SingularStiffness: a task row depends on the closure rows (the task frame cannot move
                that way: infinite stiffness), or the matrix is singular (a critical point).
            InputError: an unknown ``method``.
        """
        from vjm_pin.solver.blocks import Blocks
        from vjm_pin.solver.stiffness import CLOSURE_METHODS, stiffness_with_closures

        if method not in CLOSURE_METHODS:
            raise InputError(f"unknown stiffness method {method!r}; choose one of {', '.join(CLOSURE_METHODS)}")
        if not res.converged:
            raise NoEquilibrium("loaded stiffness of an equilibrium that did not converge", res, res.residual())
        vm, free, nt = self.vm, self.free, self.nt
        tarr = np.asarray(self.task, int)
        x = np.asarray(res.x, float)
        states = self.frames.evaluate(x, hessian=True)
        end = states[vm.frame_id]
        cst = self.closures.evaluate(x, hessian=True)
        lst = self.loads.evaluate(x, hessian=True)
        nc = cst.residual.size
        c = cst.jacobian[:, free]
        j = end.jacobian[tarr][:, free]
        info = constraint_rank(np.vstack([c, j]), rtol=self.rank_rtol)
        lost = [i - nc for i in info.redundant if i >= nc]
        if lost:
            raise SingularStiffness(
                "K_C is infinite along task component(s) "
                f"{' '.join(COMPONENTS[tarr[i]] for i in lost)}: the closures fix the task frame there to first order",
                info.singular_values,
            )
        ci = c[[i for i in info.independent if i < nc]] if nc else np.zeros((0, len(free)))
        # H of eq. (16) for the Lagrangian: dead loads, total task wrench, closure multipliers
        h = lst.derivative[np.ix_(free, free)] + contract_hessian(end.hessian, res.wrench)[np.ix_(free, free)]
        if nc:
            h = h + cst.hessian(res.closure_multipliers)[np.ix_(free, free)]
        b = Blocks(j[:, :nt], j[:, nt:], h[:nt, :nt], h[:nt, nt:], h[nt:, :nt], h[nt:, nt:], vm.K_theta, end)
        return stiffness_with_closures(b, ci[:, :nt], ci[:, nt:], tuple(self.task), method)

    # ----------------------------------------------------------------- checks
    @one_blas_thread
    def verify(self, res: MechanismResult, *, deflection=None, method: str = "eq28", rtol: float | None = None,
               stiffness: bool = True):
        """Re-check the equilibrium ``res`` independently (recomputed with Pinocchio from its
        configuration, not through this solver's evaluators; :mod:`vjm_pin.solver.mechanism_checks`):

        1. eq. (5) with the multipliers recomputed from scratch (minimum-norm least squares on
           the stacked closure + held-row Jacobian), each row against its own scale, and the
           fresh multipliers and their generalised forces against the result's;
        2. the closure residuals and the held task rows (against ``deflection`` when given:
           the deflection that was prescribed, 6, 3 or ``len(task)`` numbers, m and rad);
        3. both stability verdicts from a central-difference Hessian of the Lagrangian on the
           null space of the stacked constraint Jacobian, and their eigenvalues against the
           result's;
        4. with ``stiffness``, K_C (``method``) along its softest task direction against central
           differences of re-solved equilibria (relative error ≤ ``rtol``, default
           :data:`~vjm_pin.solver.mechanism_checks.VERIFY_RTOL`).

        Returns:
            :class:`~vjm_pin.solver.mechanism_checks.MechanismCheck` (frozen; ``ok`` when all pass).

        Raises:
            NoEquilibrium: ``res`` did not converge.
        """
        from vjm_pin.solver.mechanism_checks import VERIFY_RTOL, check_mechanism

        return check_mechanism(
            self, res, deflection=deflection, method=method, rtol=VERIFY_RTOL if rtol is None else float(rtol),
            stiffness=stiffness,
        )


__all__ = ["Linearization", "MechanismResult", "MechanismSolver"]
