"""Force–deflection curves and critical points (paper §6.1, Fig. 4–6), for every model kind.

One tracer and one critical-point rule for serial chains, parallel robots and closed-loop
mechanisms (``<vjm:closure>``), with dead loads anywhere: serial chains without dead loads
run on :class:`~vjm_pin.solver.EquilibriumSolver` (the blocks of eq. 30), everything else on
:class:`~vjm_pin.solver.mechanism.MechanismSolver` (:mod:`vjm_pin.analysis.mechanism_curve`:
eq. 23, the margin ``μ`` and the tangent of eq. 28 with the closure rows added). Below, "the
end held" means the control as run: every task component held, or with ``free=True`` only the
component along ``d`` (the other task components then carry zero wrench).

The curve
---------
The end is moved along a fixed unit direction ``d`` (deflection ``s·d``, ``s`` in m for a
translation, rad for a rotation) with every task component held: the loaded equilibrium
of eq. (5) is deflection-driven. The *followed branch* is traced by predictor–corrector
continuation: the tangent predictor of eq. (29) (``δq = K_q δt``, ``δθ = K_θ δt``,
``δF = K_C δt`` with ``δt = δs·d``; optionally, ``_second_order``, along the followed branch
plus the term ``½δs²·(t_a − t_prev)/(s_a − s_prev)`` from the tangents of the last two points,
error O(δs³)), a plain Newton corrector, and adaptive sub-steps inside every requested step.
The common sub-step (a warm start from the prediction that the solver's plain local iteration
settles) runs as one lean pass, :meth:`_Tracer._fused_step`: the solver's fused Newton kernel
(``EquilibriumSolver._corrector``) and the point kernel on the converged iteration's own ``J`` and
``H(F)``, the per-solve set-up done once per curve; anything else takes the general solve and point
path, and both give the same numbers (``tests/test_curve_corrector.py``).
A sub-step is accepted only when the corrected configuration stays
close to the prediction (``‖x − x_pred‖ ≤`` :data:`CORRECTOR_RATIO` ``·‖x_pred − x_a‖``,
scaled by rad and the chain length, the prediction itself at most :data:`MAX_MOVE`), and
a sub-step over which a stability verdict changes only when it is short
(:data:`FINE_STEP`): the continuation does not jump to another branch, however large the
requested step. Every reported point of the followed branch is stable
under the control as run (eq. 23 with the end held, ``stable_end_held``). When the
continued branch loses that stability (a bifurcation) the followed branch switches to
the stable branch that leaves it: the configuration is perturbed along the critical
eigenvector of eq. (23), both signs, re-solved just past the critical deflection, and the
lower-energy stable equilibrium is kept (the first sign on a tie).

Critical points
---------------
A critical point is where the followed equilibrium stops being stable under **force
control along d**: the components of the end orthogonal to ``d`` (within the task) held,
a dead force along ``d``. Its measure is ``μ(s)``, the largest eigenvalue of the matrix
``Vᵀ(H − K)V`` of :func:`~vjm_pin.solver.stability.check_stability_held` on the null
space ``V`` of ``P·[J_θ J_q]`` (``P``: orthonormal rows spanning the complement of ``d``
within the task rows): stable iff ``μ < 0``; a point reports ``force_control_margin =
−μ``. Because ``V`` contains the null space of eq. (23), ``μ ≥`` the largest eigenvalue
of eq. (23) (so ``μ ≥ 0`` wherever the end-held equilibrium is unstable or bifurcates),
and where eq. (23) is regular ``μ = 0`` exactly where the force along ``d`` is stationary
(``dF/ds = dᵀK_C d = 0``, the Schur complement of the bordered matrix). So one
continuous function gives every kind of critical point (``CriticalPoint.kind``):

``"bifurcation"``
    ``μ`` crosses zero from below and the continued branch then loses the stability of
    eq. (23) (buckling of the straight column, Models A/B/C in the S posture); the
    followed branch switches to the stable bent branch.
``"limit"``
    ``μ`` crosses zero from below and the branch stays stable with the end held (a
    force maximum, ``dF/ds`` changes sign): it is followed on.
``"imperfect"``
    An imperfect bifurcation: the branch stays stable under force control but nearly
    loses it. A local minimum ``m*`` of the margin ``m(s) = −μ(s) > 0`` at which the margin
    has fallen below :data:`IMPERFECT_RATIO` times its largest value on the same continuous
    stretch of the followed branch (since the start, the last critical point or the last
    branch switch). Model B in the Z posture (paper: 1.07 Kθ/L) is of this kind: its force
    keeps rising, with a sharp knee.

``μ`` crossing zero from above (stability regained, e.g. a force minimum) is not a
critical point. Roots are found by Illinois regula falsi on ``μ(s)`` and the margin
minimum by the same on ``dμ/ds``, both on the continued branch, every trial equilibrium
reached by continuation (with the continuity check) from the nearer end of the bracket;
the force is located to ``1e-3·refine_tol`` relative. Two crossings within one step
cannot hide: over every sub-step a cubic Hermite model of ``μ`` from its values and its
derivatives along the branch (``dμ/ds`` analytically by first-order perturbation of the
eigenvalue, :mod:`vjm_pin.analysis.point_kernel`, or by a finite difference along the tangent of
eq. 29 where the kernel declines) is checked, and the sub-step is sampled at the model's extremum whenever the
model comes within its own curvature of zero. A start that is rigid along ``d`` (a
straight chain of rigid links, Model A S: the force at ``s = 0`` is indeterminate) is
searched along the force at the unloaded configuration: the critical point is then at
deflection 0. ``stiffness_before`` and ``stiffness_after`` are ``dᵀK_C d`` on the followed
branch at ``s_c ∓ ε``, ``ε = max(`` :data:`OFFSET_REL` ``·|s_c|,`` :data:`OFFSET_ABS`
``· max_deflection)``; one critical point per event.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from vjm_pin.analysis import point_kernel as _pk
from vjm_pin.analysis.point_kernel import FAST_RANK, PointKernel, _jit_mode, compiled, use_compiled
from vjm_pin.exceptions import InputError, NoEquilibrium, SingularStiffness
from vjm_pin.kinematics import chain as _chain
from vjm_pin.kinematics.chain import displace as _displace
from vjm_pin.kinematics.chain import flush_tiny
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.format import VjmModel
from vjm_pin.model.task import task_vector
from vjm_pin.solver.equilibrium import FRESH as _FRESH
from vjm_pin.solver.equilibrium import EquilibriumResult, EquilibriumSolver
from vjm_pin.solver.mechanism import MechanismSolver
from vjm_pin.solver.stability import (
    RANK_TOL,
    STABILITY_TOL,
    check_stability_held,
    null_space,
    reduced_matrix,
    spectral_norm,
)
from vjm_pin.solver.stiffness import SINGULAR_RCOND, stiffness_from_blocks
from vjm_pin.solver.threads import one_blas_thread

#: Maximum iterations of a root or extremum search (Illinois).
MAX_BISECTIONS = 60
#: An interior minimum of the force-control margin below this fraction of its largest
#: value on the same stretch of the followed branch is an imperfect bifurcation.
IMPERFECT_RATIO = 0.1
#: ``stiffness_before``/``_after`` are evaluated at ``s_c ∓ ε``, ``ε = max(OFFSET_REL·|s_c|,
#: OFFSET_ABS·max_deflection)``; also the offset of a branch switch.
OFFSET_REL = 1e-4
OFFSET_ABS = 1e-6
#: Continuity test of a continuation sub-step: corrector displacement ≤ this × predictor step.
CORRECTOR_RATIO = 0.25
#: A sub-step over which μ or eq. (23) changes sign is only accepted when it is at most
#: this × max_deflection (a long step could land on the other, unstable branch of an
#: imperfect bifurcation, close to the prediction); longer ones are halved.
FINE_STEP = 1e-3
#: Largest predicted move of one sub-step (rad; prismatic coordinates per chain length).
MAX_MOVE = 0.1
#: Smallest continuation sub-step, × max_deflection.
MIN_STEP = 1e-10
#: Largest recursion depth of the check for two crossings within one sub-step.
DIP_DEPTH = 12
#: :meth:`_Tracer._fused_step`'s answer "the local iteration gave way: go on as the general path".
_GENERAL = object()
#: :meth:`_Tracer._merged_step`'s answer "not merged: the step as before".
_UNMERGED = object()
_new_object = object.__new__
#: The fused step's point kernel's "no (Qᵀ W Q)ᵀ given: compute it" (a (0, 0) array: one compiled signature).
_NO_WT = np.zeros((0, 0))
#: Private switch (False: the fused step's point kernel computes ``(Qᵀ W Q)ᵀ`` itself instead of reading
#: the converged corrector's: the same bits; for the tests and the benchmark).
_reuse_wt = True
#: Private switch (False: a curve's common sub-step as three compiled calls with Python between them
#: instead of one, :meth:`_Tracer._merged_step`; the same numbers bit for bit; for the tests and the benchmark).
_merged = True

#: Private switch (False: every point by the generic eq. 30 inverse and the SVD null space of
#: check_stability_held, as released; for the side-by-side benchmark and the tests).
_fast_points = True
#: Private switch (False: dμ/ds by the forward difference of :meth:`_Tracer.dmu` everywhere).
_analytic_rate = True
#: Private switch (False: the point kernel's top eigenvalue from the Gershgorin bracket every time;
#: True: from a bracket predicted by the previous point's μ and dμ/ds where the Sturm counts confirm it).
_mu_hint = True
#: Private switch (True: the second-order predictor along the followed branch, used only with
#: ``_fast_points``). On by default since it is compiled with the first-order one (the fused step's
#: ``_predict2_loops``): on the Model C curve ~1 Newton iteration fewer on ~40 % of the points
#: (~3 µs per point); the equilibria move within the solver's tolerance, not beyond.
_second_order = True
#: Private switch (False: every continuation sub-step by the general solve and point path,
#: ``EquilibriumSolver._solve_local`` then :meth:`_Tracer.point`; True: the fused warm corrector of
#: :meth:`_Tracer._fused_step`, the same numbers; for the tests and the benchmark).
_fused_corrector = True
#: Private switch (False: the fused step's compiled point kernel factors ``J`` again instead of reusing
#: the converged Newton iteration's QR; the same numbers to rounding; for the tests and the benchmark).
_reuse_qr = True
#: The second-order predictor term of a sub-step ``ds`` uses the tangent of the point continued
#: from when that point lies at least this × ``|ds|`` behind (a shorter difference quotient of
#: the tangent is dominated by rounding).
SECOND_ORDER_BACK = 0.25


@dataclass(frozen=True)
class CurvePoint:
    """One point of a force–deflection curve.

    Attributes:
        deflection: Scalar deflection ``s`` along the direction (m, or rad for a rotation).
        force: External force (N, or N·m) along the direction that holds the end there,
            ``dᵀ F``: positive when it pushes the end along the direction.
        wrench: (6,) full external wrench at equilibrium (N, N·m), world axes.
        stable: Verdict for the control as run: the end held in every task component
            (deflection-driven), i.e. eq. (23); with ``free=True`` only along the direction.
        stiffness: Tangent stiffness ``dᵀ K_C d`` (N/m) with K_C of eq. (30); ``inf`` when
            the end cannot move along ``d`` to first order (straight chain of rigid
            links), ``nan`` when K_C is singular for another reason.
        equilibrium: The :class:`EquilibriumResult` (serial path) or
            :class:`~vjm_pin.solver.mechanism.MechanismResult` (mechanism path).
        stable_end_held: Eq. (23) alone (the end held in every task component).
        force_control_margin: ``−μ``: minus the largest eigenvalue of the Hessian of the
            total potential on the displacements that keep the components orthogonal to
            the direction fixed (N·m/rad for spring coordinates); positive iff the point
            is stable under a dead force along the direction (see the module docstring).
    """

    deflection: float
    force: float
    wrench: np.ndarray
    stable: bool
    stiffness: float
    equilibrium: EquilibriumResult = field(repr=False)
    stable_end_held: bool = True
    force_control_margin: float = float("nan")


@dataclass(frozen=True)
class CriticalPoint:
    """A critical point (module docstring), located to ``1e-3·refine_tol`` in force.

    Attributes:
        force: Critical force (N) along the direction.
        deflection: Critical deflection (m or rad) along the direction.
        stiffness_before: Tangent stiffness ``dᵀK_C d`` (N/m) on the followed branch at
            ``deflection − ε`` (see the module docstring for ε).
        stiffness_after: The same at ``deflection + ε`` on the branch followed next.
        index: Index in ``Curve.points`` of the first point after it.
        force_after: Force (N) of the followed branch at ``deflection + ε``.
        bisections: Iterations of the root (or extremum) search.
        kind: ``"bifurcation"``, ``"limit"`` or ``"imperfect"``.
    """

    force: float
    deflection: float
    stiffness_before: float
    stiffness_after: float
    index: int
    force_after: float = float("nan")
    bisections: int = 0
    kind: str = "bifurcation"


@dataclass(frozen=True)
class Curve:
    """A traced force–deflection curve.

    Attributes:
        direction: (6,) unit direction of the deflection, world axes (translation, rotation).
        points: The followed (stable when one exists) branch, ``s = 0 … max_deflection``.
        critical: Critical points found on it (see the module docstring for the rule).
        branches: Unstable (or other) branches traced with ``all_branches=True``; else ``()``.
        free: The task frame was held only along the direction (``trace_curve(free=True)``).
        loads: The dead loads (:class:`~vjm_pin.kinematics.dead_loads.Load`) it was traced under.
    """

    direction: np.ndarray
    points: tuple[CurvePoint, ...]
    critical: tuple[CriticalPoint, ...]
    branches: tuple[tuple[CurvePoint, ...], ...] = ()
    free: bool = False
    loads: tuple = ()

    @property
    def deflections(self) -> np.ndarray:
        return np.array([p.deflection for p in self.points])

    @property
    def forces(self) -> np.ndarray:
        return np.array([p.force for p in self.points])


def _direction(vm: VjmModel, direction) -> np.ndarray:
    """The unit (6,) direction of a curve: 3 or 6 finite numbers in the task
    (:func:`~vjm_pin.model.task.task_vector`), not zero, a pure translation or rotation."""
    d = task_vector(direction, vm.task, "direction", "translation or rotation; normalised")
    n = np.linalg.norm(d)
    if n == 0:
        raise InputError("direction must not be zero")
    d = d / n
    if np.any(d[:3]) and np.any(d[3:]):
        raise InputError(
            "direction must be a pure translation or a pure rotation (the force would mix N and N·m)"
        )
    return d


def tangent_stiffness(
    vm: VjmModel, eq: EquilibriumResult, direction: np.ndarray, kin=None
) -> float:
    """``dᵀ K_C d`` (N/m or N·m/rad) at the equilibrium ``eq`` (K_C of eq. 30).

    ``inf`` when the end cannot move along ``d`` to first order ([J_θ J_q] does not reach
    ``d``: a straight chain of rigid links), ``nan`` when K_C is singular otherwise.
    """
    from vjm_pin.solver import blocks_at

    return _stiffness_along(vm, blocks_at(vm, eq.x, eq.wrench, kin), direction)[0]


def _stiffness_along(vm, b, direction: np.ndarray):
    """(:func:`tangent_stiffness`, the :class:`StiffnessResult` of eq. 30 or None when
    singular) from the blocks ``b`` at the equilibrium."""
    try:
        st = stiffness_from_blocks(b, vm.task, "eq30")
    except SingularStiffness:
        task = list(vm.task)
        jall = np.hstack([b.J_theta, b.J_q])
        dt = direction[task]
        u, s, _ = np.linalg.svd(jall, full_matrices=True)
        rank = int(np.sum(s > RANK_TOL * max(s.max() if s.size else 0.0, 1e-300)))
        if np.linalg.norm(u[:, rank:].T @ dt) > 1e-6:
            return float("inf"), None
        return float("nan"), None
    return float(direction @ st.stiffness @ direction), st


def _max_eig(res) -> float:
    """The largest eigenvalue of eq. (23) (−inf without any): ``−margin``, so a long chain's
    :class:`~vjm_pin.solver.stability.DeferredStability` is not asked for its whole spectrum."""
    return -res.margin


def _complement_rows(vm, d: np.ndarray) -> np.ndarray:
    """(m−1, m) orthonormal rows spanning the complement of ``d`` within the m task rows."""
    dt = d[list(vm.task)].reshape(-1, 1)
    u = np.linalg.svd(dt, full_matrices=True)[0]
    return u[:, 1:].T.copy()


#: :func:`_complement_rows` by the task rows of ``d`` (bytes): a function of them only (the SVD of
#: one column); bounded, a copy handed out.
_ROWS: dict = {}


def _complement_rows_kept(vm, d: np.ndarray) -> np.ndarray:
    """:func:`_complement_rows`, remembered per task and direction (the same numbers: one SVD of
    the same column); a copy of its own for the caller."""
    dt = np.ascontiguousarray(d[list(vm.task)], dtype=float)
    key = (dt.shape, dt.tobytes())
    hit = _ROWS.get(key)
    if hit is None:
        hit = _complement_rows(vm, d)
        if len(_ROWS) >= 32:
            _ROWS.clear()  # (directions of a map's sweep: rebuilt on demand)
        _ROWS[key] = hit
    return hit.copy()


def _point(vm, eq: EquilibriumResult, s: float, d: np.ndarray, kin) -> CurvePoint:
    """A :class:`CurvePoint` at the equilibrium ``eq`` (other branches, not followed)."""
    from vjm_pin.solver import blocks_at

    b = blocks_at(vm, eq.x, eq.wrench, kin)
    k = _stiffness_along(vm, b, d)[0]
    held = bool(check_stability_held(b, None).stable)
    mu = _max_eig(check_stability_held(b, _complement_rows(vm, d)))
    return CurvePoint(
        deflection=float(s),
        force=float(d @ eq.wrench),
        wrench=np.asarray(eq.wrench, float).copy(),
        stable=held,
        stiffness=k,
        equilibrium=eq,
        stable_end_held=held,
        force_control_margin=-mu,
    )


def illinois(evaluate, lo, flo, hi, fhi, coord, done, max_iter: int):
    """Illinois regula falsi for the root of a scalar ``f`` with ``f(lo) < 0 ≤ f(hi)``.

    ``evaluate(s, lo, hi)`` returns ``(state, f)`` at the coordinate ``s`` of the current
    bracket (or None when it cannot be evaluated), ``coord(state)`` the coordinate of a state, ``done(lo, hi, m, s)`` whether
    the bracket is tight enough. Returns ``(lo, flo, hi, fhi, iterations, ok)``; ``ok`` is
    False when an evaluation failed (the bracket so far is returned)."""
    side = 0
    n = 0
    for n in range(1, max_iter + 1):
        s = (coord(lo) * fhi - coord(hi) * flo) / (fhi - flo)
        res = evaluate(s, lo, hi)
        if res is None:
            return lo, flo, hi, fhi, n, False
        m, fm = res
        if fm < 0:
            lo, flo = m, fm
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = m, fm
            if side == 1:
                flo *= 0.5
            side = 1
        if done(lo, hi, m, s):
            break
    return lo, flo, hi, fhi, n, True


def _hermite_extremum(s0, f0, g0, s1, f1, g1, maximum: bool):
    """Interior extremum of the cubic Hermite interpolant of ``f`` (values ``f0, f1``,
    derivatives ``g0, g1`` at ``s0 < s1``): ``(t, value, deviation)`` with ``t ∈ (0, 1)``
    the relative position, ``deviation`` the distance there to the chord; None if the
    cubic has no interior maximum (``maximum``) or minimum."""
    h = s1 - s0
    a0, a1 = h * g0, h * g1
    # p(t) = f0 + a0 t + c t² + e t³
    c = 3 * (f1 - f0) - 2 * a0 - a1
    e = 2 * (f0 - f1) + a0 + a1
    # p'(t) = a0 + 2c t + 3e t² = 0
    if abs(e) > 1e-14 * (abs(c) + abs(a0) + abs(a1)):
        disc = c * c - 3 * e * a0
        if disc < 0:
            return None
        r = disc**0.5
        roots = ((-c + r) / (3 * e), (-c - r) / (3 * e))
    elif c != 0:
        roots = (-a0 / (2 * c),)
    else:
        return None
    best = None
    for t in roots:
        if not 0.0 < t < 1.0:
            continue
        curv = 2 * c + 6 * e * t
        if (curv < 0) != maximum:
            continue
        v = f0 + a0 * t + c * t * t + e * t**3
        if best is None or (v > best[1]) == maximum:
            best = (t, v, abs(v - (f0 + (f1 - f0) * t)))
    return best


class _BP:
    """A point of a continued branch (internal): equilibrium, force, tangent stiffness,
    eq. (30) result, ``μ`` (force control) and ``λ`` (largest eigenvalue of eq. 23)."""

    __slots__ = ("dmu", "eq", "force", "hist", "k", "lam", "mu", "s", "st", "tan")

    def __init__(self, s, eq, force, k, st, mu, lam):
        self.s, self.eq, self.force, self.k, self.st = float(s), eq, float(force), k, st
        self.mu, self.lam, self.dmu, self.tan = mu, lam, None, False
        self.hist = None  # (s, tangent) of the point it was continued from (the second-order predictor)

    def below(self, thr: float) -> bool:
        """``λ < −thr`` (eq. 23 holds with the tracer's threshold ``thr``)."""
        return self.lam < -thr

    def above(self, thr: float) -> bool:
        """``λ ≥ −thr`` (eq. 23 lost)."""
        return self.lam >= -thr


class _LateBP(_BP):
    """A :class:`_BP` of the fused corrector whose eq. (23) verdict "stable" was certified without
    the eigenvalues (:class:`~vjm_pin.solver.stability.SpectrumLater`, a Cholesky factorisation past
    the solver's threshold): ``λ`` is computed from that verdict's spectrum when first read (the
    expression of :meth:`_Tracer._fused_step`: the same number); :meth:`below` and :meth:`above`
    answer from the certificate while the tracer's threshold is not above the solver's."""

    __slots__ = ("_lv", "_stab")

    def __init__(self, s, eq, force, k, mu, stab):
        # (the slots of _BP.__init__ set here: λ = None, computed when first read)
        self._stab, self._lv = stab, None
        self.s, self.eq, self.force, self.k, self.st = float(s), eq, float(force), k, None
        self.mu, self.dmu, self.tan, self.hist = mu, None, False, None

    @classmethod
    def with_tangent(cls, s, eq, force, k, mu, stab, dmu, tan) -> _LateBP:
        """``_LateBP(s, eq, force, k, mu, stab)`` with its ``dμ/ds`` and tangent set, built slot by slot
        (the fused curve step makes one per point: no ``__init__`` call)."""
        p = _new_object(cls)
        p._stab, p._lv = stab, None
        p.s, p.eq, p.force, p.k, p.st, p.mu = float(s), eq, float(force), k, None, mu
        p.dmu, p.tan, p.hist = dmu, tan, None
        return p

    def _get_lam(self) -> float:
        v = self._lv
        if v is None:
            ev = self._stab.eigenvalues
            v = self._lv = float(ev[-1]) if ev.size else -np.inf  # (ascending: _max_eig)
        return v

    def _set_lam(self, value) -> None:
        self._lv = value  # (None: computed when first read)

    lam = property(_get_lam, _set_lam)

    def _certified(self, thr: float) -> bool:
        st = self._stab
        return self._lv is None and st.stable and st.tolerance >= thr  # every eigenvalue < −tolerance ≤ −thr

    def below(self, thr: float) -> bool:
        st = self._stab  # (_certified(thr), inline)
        if self._lv is None and st.stable and st.tolerance >= thr:
            return True
        return self.lam < -thr

    def above(self, thr: float) -> bool:
        st = self._stab  # (_certified(thr), inline)
        if self._lv is None and st.stable and st.tolerance >= thr:
            return False
        return self.lam >= -thr


class _StateBlocks:
    """:func:`~vjm_pin.solver.blocks.evaluate_blocks` at ``(x, w)`` split in two (a point of a
    tracer whose Hessian of Ψ is in screw form): the kinematic state (``.state``, as
    ``evaluate_blocks`` evaluates it) now, the Blocks when first read — any other attribute, or
    the call ``b()`` — by ``evaluate_blocks`` from that state (the same numbers). Kept Blocks at
    that ``(x, w)`` (``evaluate_blocks``'s cache) are taken at once. The compiled chain point
    kernel reads ``state.jacobian`` only: where it decides, no dense Hessian is formed."""

    __slots__ = ("_args", "_b", "state")

    def __init__(self, vm, kin, x, w):
        from vjm_pin.solver.blocks import evaluate_blocks

        x = np.asarray(x, dtype=float)
        w = np.asarray(w, dtype=float)
        last = getattr(kin, "_blocks_last", None)
        if last is not None and last[0] is vm and last[1] == x.tobytes() + w.tobytes():
            self._b = evaluate_blocks(vm, kin, x, w)  # kept: returned (or built) as they are
            self.state = self._b.state
        else:
            self._b = None
            self.state = kin.evaluate(x, hessian=False)  # as evaluate_blocks (screw form)
        self._args = (vm, kin, x, w)

    def __call__(self):
        b = self._b
        if b is None:
            from vjm_pin.solver.blocks import evaluate_blocks

            vm, kin, x, w = self._args
            b = self._b = evaluate_blocks(vm, kin, x, w, self.state)
        return b

    @property
    def blocks(self):
        """The Blocks if built by now, else this object (call it for them)."""
        return self if self._b is None else self._b

    def __getattr__(self, name):
        return getattr(self(), name)


class _Tracer:
    """The followed branch of one curve and its critical points (module docstring)."""

    #: The second-order predictor between grid points (set per instance; off for subclasses
    #: with their own :meth:`step`).
    second_order = False
    #: The fused step's compiled helpers (set per instance by :meth:`_point_fn`).
    _fz = None
    #: The merged step's compiled call and target constants (set per instance by :meth:`_merged_step`).
    _ms = _p0d = None

    def __init__(self, vm, d, max_deflection, solver: EquilibriumSolver, refine_tol):
        self.vm, self.d, self.solver = vm, d, solver
        self.kin = solver.kin
        # plain Newton on whichever branch it starts on (shares the solver's pin.Data)
        self.cont = solver._sibling(follow_stable=False, restarts=0, tol=solver.tol)
        self.range = float(max_deflection)
        self.P = _complement_rows_kept(vm, d)
        self.free = solver.free
        self.task = np.asarray(vm.task, dtype=int)
        self.var_scale = solver.var_scale
        self.hmin = MIN_STEP * self.range
        self.eps_abs = OFFSET_ABS * self.range
        self.refine_tol = refine_tol
        self.k_norm = spectral_norm(vm.K_theta) if vm.K_theta.size else 1.0  # ‖K_θ‖₂ (1 without springs)
        self.thr = STABILITY_TOL * self.k_norm
        self.h = self.range
        self.seg_margin = 0.0  # largest −μ on the current stretch of the followed branch
        # the per-point algebra in one pass where it is far from singular (point_kernel)
        kz = getattr(solver, "_kz", None)  # (K_θ ⊕ 0 of solver.free: shared, read only)
        self.kernel = PointKernel(vm.K_theta, self.free, d[self.task], self.task, kz=kz) if _fast_points else None
        # dμ/ds analytically where the Hessian of Ψ is in screw form (else by a difference)
        self.mask = self.kin.support_mask(self.free) if _fast_points and getattr(self.kin, "uses_screw", False) else None
        self._fn = None  # the compiled point kernel once wanted (point_kernel.use_compiled)
        self._npts = 0
        self._zero_x = np.zeros(vm.model.nq)  # templates of the tangent (δx, δF) of a point
        self._zero_w = np.zeros(6)
        self.second_order = _fast_points and _second_order  # the predictor (step)
        # the fused warm corrector (_fused_step): the solver's per-curve bundle, VJM_PIN_JIT read once
        self._corr = self.cont._corrector_context() if _fast_points and _fused_corrector else None
        self._jit = _jit_mode() if self._corr is not None else None
        self._pargs = None  # the compiled point kernel's constant arguments (_fused_step)
        self._reuse = None  # the fused step's point on the corrector's QR (_reuse_setup; None: not decided yet)
        self._rargs = self._hh_shape = None  # its constant arguments, the reflectors' shape (_reuse_setup)
        self._rt = None  # (rotation part of the last target or None for a translation, its target rotation, both
        # target arrays float64 and C-contiguous) (_fused_step)
        self._p0l = None  # (p0, p0's and d[:3]'s entries as floats) (_fused_step)
        self._p0d = None  # (p0, [p0, d[:3]] as a float64 array) (_merged_step)
        self._ms = None  # the merged step's compiled call (_merged_step; None: not decided yet, False: not used)
        self._hz_shape = (self.kernel.n, self.kernel.n) if self.kernel is not None else None  # H(F)'s shape, (n, n)
        self._d_lin, self._d_rot = d[:3].copy(), d[3:].copy()  # (s·d[:3] is (s·d)[:3], element by element)
        self._d_translation = not self._d_rot.any()
        self._dense_point = False  # the compiled dense point kernel applies (PointKernel.point's dispatch)
        self._fz = None  # the fused step's compiled helpers once the compiled point kernel is used (_point_fn)
        self._nq = vm.model.nq
        if self._corr is not None:
            from vjm_pin.solver import chain_kernel

            self._dense_point = len(self.free) < getattr(chain_kernel, "POINT_MIN_N", 0)
        # the compiled point kernel's chain algebra applies (PointKernel.point's dispatch): point()
        # evaluates the kinematic state first and the Blocks only if asked for (_StateBlocks)
        self._chain_point = False
        if self.kernel is not None and self.mask is not None:
            from vjm_pin.solver import chain_kernel

            self._chain_point = self.kernel.n >= getattr(chain_kernel, "POINT_MIN_N", 1 << 62)

    # ------------------------------------------------------------------ evaluation
    def blocks(self, x, w):
        from vjm_pin.solver import blocks_at

        return blocks_at(self.vm, x, w, self.kin)

    def point(self, eq: EquilibriumResult, s: float) -> _BP:
        fast = None
        if self.kernel is not None:
            if self._fn is None and use_compiled(self._npts):
                self._fn = compiled()
            self._npts += 1
            if self._fn is not None and self._chain_point:
                # the compiled chain kernel reads the frame Jacobian alone: the Blocks (the dense
                # Hessian of Ψ) are built only if another path asks for them (_StateBlocks)
                b = _StateBlocks(self.vm, self.kin, eq.x, eq.wrench)
                fast = self.kernel.point(b, self.mask, eq.wrench, self._fn)
                b = b.blocks
            else:
                b = self.blocks(eq.x, eq.wrench)
                fast = self.kernel.point(b, self.mask, eq.wrench, self._fn)
        else:
            b = self.blocks(eq.x, eq.wrench)
        held = getattr(eq, "stability_end_held", None)  # eq. (23) as the solver found it
        if held is None and getattr(eq, "held", None) is None:
            held = eq.stability  # every task component held: the verdict of eq. (23)
        if (held is None or fast is None) and type(b) is _StateBlocks:
            b = b()  # the Blocks themselves (built now)
        lam = _max_eig(held if held is not None else check_stability_held(b, None))
        if fast is not None:
            # k, the tangent of eq. (29) along d and μ in one pass (point_kernel)
            k, xd, fd, mu, rate = fast
            return self._kernel_point(eq, s, k, mu, lam, xd, fd, rate)
        k, st = _stiffness_along(self.vm, b, self.d)
        mu = _max_eig(check_stability_held(b, self.P))
        return _BP(s, eq, self.d @ eq.wrench, k, st, mu, lam)

    def _kernel_point(self, eq: EquilibriumResult, s: float, k, mu, lam, xd, fd, rate) -> _BP:
        """The point at ``eq`` from the point kernel's numbers: ``k``, ``μ``, its rate ``dμ/ds``
        (None: not given) and the tangent of eq. (29) (``xd``: free coordinates, ``fd``: task rows)."""
        p = _BP(s, eq, self.d @ eq.wrench, k, None, mu, lam)
        if rate is not None and _analytic_rate:
            p.dmu = rate
        x_dot = self._zero_x.copy()
        x_dot[self.free] = xd
        w_dot = self._zero_w.copy()
        w_dot[self.task] = fd
        p.tan = (x_dot, w_dot)
        return p

    def tangent(self, p: _BP):
        """(dx/ds (nq,), dF/ds (6,)) along the branch at ``p`` (eq. 29), or None."""
        if p.tan is False:
            p.tan = self._tangent(p)
        return p.tan

    def _tangent(self, p: _BP):
        if p.st is None:
            return None
        xd = np.zeros_like(p.eq.x)
        xd[self.vm.theta_idx] = p.st.dtheta_dt @ self.d
        xd[self.vm.q_idx] = p.st.dq_dt @ self.d
        wd = p.st.stiffness @ self.d
        if not (np.all(np.isfinite(xd)) and np.all(np.isfinite(wd))):
            return None
        return xd, wd

    def dmu(self, p: _BP) -> float:
        """``dμ/ds`` at ``p``: set by :meth:`point` from the point kernel (analytic) where it
        applies; else the forward difference of ``μ`` along the tangent (eq. 29) over a step that
        moves the configuration by 1e-6 (rad, scaled): error O(1e-6·μ'')."""
        if p.dmu is None:
            t = self.tangent(p)
            if t is None:
                p.dmu = float("nan")
            else:
                xd, wd = t
                sc = float(np.abs(xd[self.free] / self.var_scale).max())
                h = 1e-6 * self.range
                if sc * h > 1e-6:
                    h = 1e-6 / sc
                b = self.blocks(p.eq.x + h * xd, p.eq.wrench + h * wd)
                mu = self.kernel.margin(b) if self.kernel is not None else None
                if mu is None:
                    mu = _max_eig(check_stability_held(b, self.P))
                p.dmu = (mu - p.mu) / h
        return p.dmu

    def scaled(self, dx) -> float:
        return float(np.abs(dx[self.free] / self.var_scale).max()) if dx.size else 0.0

    # ------------------------------------------------------------------ continuation
    def step(self, a: _BP, s: float, second_order: bool = False) -> _BP | None:
        """``a``'s branch continued to ``s``: predictor (eq. 29; with ``second_order`` plus
        the term from the change of the tangent since the point ``a`` was continued from, error
        O(δs³): the followed branch between grid points), plain Newton corrector, continuity
        check; None when the corrector strays (or does not converge)."""
        s = float(s)
        t = a.tan
        if t is False:
            t = self.tangent(a)
        ds = s - a.s
        gave = False  # the merged step's corrector gave way (the general path goes on from its prediction)
        if t is not None:
            dw = None  # ds·t[1] (+ the second-order term), when the general solve needs it
            h = a.hist if second_order else None
            c = None
            if h is not None:
                # second order: the tangent's change since the point ``a`` was continued from
                # (a difference quotient of eq. 29's tangent over a step not much shorter than ds)
                back = a.s - h[0]
                if abs(back) >= SECOND_ORDER_BACK * abs(ds) and abs(back) >= 1e-6 * self.range:
                    c = 0.5 * ds * ds / back
            fz = self._fz
            fresh = fz is not None
            if fresh and self._ms is not False:
                got = self._merged_step(a, s, t, h, c, ds)
                if got is not _UNMERGED:
                    if type(got) is not tuple:
                        return got
                    x_pred, move = got
                    gave = True
            if gave:
                pass
            elif fresh:  # x_pred and its scaled move in one compiled call (x_pred: a fresh float64 (nq,) array)
                x_pred = np.empty(self._nq)
                if c is None:
                    move = fz[0](a.eq.x, t[0], ds, self.free, self.var_scale, _chain._flush_enabled, x_pred)
                else:  # (the same numbers as the expressions below; dw when the general solve needs it)
                    move = fz[3](a.eq.x, t[0], h[1], ds, c, self.free, self.var_scale, _chain._flush_enabled,
                                 x_pred)
            else:
                dx, dw = ds * t[0], ds * t[1]
                if c is not None:
                    dx = dx + c * (t[0] - h[1])
                    dw = dw + c * (t[1] - h[2])
                x_pred = flush_tiny(a.eq.x + dx)  # no subnormal coordinates (FLUSH_BELOW)
                move = self.scaled(x_pred - a.eq.x)
            w_pred = None  # a.eq.wrench + dw, when the general solve needs it
            if move > MAX_MOVE:  # checked before the corrector: a rejected prediction costs no solve
                return None
        else:
            x_pred, w_pred = a.eq.x.copy(), a.eq.wrench.copy()
            move = 0.0
        if gave:
            eq = None  # the merged step's local iteration gave way: as _solve_local returning None
            target = s * self.d
        elif t is not None and self._corr is not None:
            got = self._fused_step(a, s, x_pred, move, t, fresh)
            if got is not _GENERAL:
                return got
            eq = None  # the local iteration gave way: as _solve_local returning None
            target = s * self.d
        else:
            target = s * self.d
            eq = self.cont._solve_local(target, x_pred)
        if eq is None:
            if abs(ds) > 1e-4 * self.range and len(self.vm.task) < len(self.free):
                return None  # a shorter step first: the safeguarded path is costly
            if w_pred is None:
                if dw is None:
                    dw = ds * t[1] if c is None else ds * t[1] + c * (t[1] - h[2])
                w_pred = a.eq.wrench + dw
            try:
                eq = self.cont.solve(
                    target, x0=x_pred, wrench0=w_pred, raise_on_failure=False, fast_fail=True
                )
            except NoEquilibrium:  # pragma: no cover - raise_on_failure=False
                return None
            if not eq.converged:
                return None
        corr = self.scaled(eq.x - x_pred)
        if t is not None:
            ok = corr <= CORRECTOR_RATIO * move + 1e-9
        else:
            ok = corr <= 1e-2
        if not ok:
            return None
        p = self.point(eq, s)
        if t is not None:
            p.hist = (a.s, t[0], t[1])
        return p

    def _merged_step(self, a: _BP, s: float, t, h, c, ds: float):
        """:meth:`step`'s common case (the compiled prediction, :meth:`_fused_step` on the corrector's own
        QR) in one compiled call (:func:`~vjm_pin.analysis.point_kernel._step_loops` through
        ``EquilibriumSolver._corrector_step``): the same calls on the same arrays, so the same point bit
        for bit. Returns the point or None (rejected: the move, the continuity check) as :meth:`step`,
        ``(x_pred, move)`` when the corrector gave way (the general path goes on from that prediction), or
        :data:`_UNMERGED` where the merged call does not apply (yet): the steps before the fused step set
        its pieces up, a direction with a rotation, ``_merged`` off, or a ``LinAlgError`` of the point
        kernel (the unmerged step then runs the same calls again and declines that point)."""
        ms = self._ms
        if ms is None:
            if self._reuse is not True or self._rt is None:
                return _UNMERGED  # (decided once the fused step has run)
            ws = self._corr[6][1] if len(self._corr) > 6 and self._corr[6] is not None else None
            ok = (_merged and self._d_translation and ws is not None and len(ws) > 11
                  and ws[1].shape == self._hh_shape and ws[6].shape == self._hz_shape)
            ms = self._ms = (_pk.step() if ok else None) or False
            if not ms:
                return _UNMERGED
        rt = self._rt
        if rt[0] is not None or not rt[2]:
            return _UNMERGED
        solver = self.cont
        pl = self._p0d
        if pl is None or pl[0] is not solver.p0:
            pl = self._p0d = (solver.p0, np.array(solver.p0.tolist() + self._d_lin.tolist()))
        pa = self._rargs
        nq = self._nq
        x_pred = np.empty(nq)
        pt = np.empty(3)
        out = np.empty(nq + 6)
        mu0, rate0 = a.mu, a.dmu
        hint = _mu_hint and rate0 is not None and rate0 == rate0 and mu0 == mu0
        second = c is not None
        pre = (a.eq.x, t[0], h[1] if second else t[0], ds, c if second else 0.0, second, MAX_MOVE, pl[1], s,
               x_pred, pt)
        post = (CORRECTOR_RATIO, hint, mu0 if hint else 0.0, rate0 if hint else 0.0, pa[1], pa[2], pa[3], pa[4], out)
        try:
            got = solver._corrector_step(self._corr, ms, pre, post, pt, rt[1])
        except np.linalg.LinAlgError:  # (numba's np.linalg raises on an exactly singular matrix)
            return _UNMERGED
        if got is None:
            return _UNMERGED
        res, raw = got
        if res[0] == 0:  # the predicted move is too large: no solve
            return None
        if raw is None:  # the local iteration gave way
            return x_pred, res[9]
        st = res[10]
        if st < 0:  # the corrector strayed
            return None
        return self._step_point(a, s, t, raw, pt, rt[1], st, res[11], res[12], res[13], res[14], out)

    def _step_point(self, a: _BP, s: float, t, raw, p_t, r_t, st, k, mu, rate, force, out) -> _BP:
        """The point of a converged fused step (:meth:`_fused_step`, :meth:`_merged_step`) from the
        corrector's raw equilibrium and the point kernel's answer: the generic :meth:`point` where the
        kernel declined (``st``), else ``k``, ``μ``, ``dμ/ds``, ``dᵀF`` (``force``; None: from the wrench)
        and the tangent (``out``: ``(δx, δF)`` laid out (nq + 6,), or the pair itself); a :class:`_LateBP`
        where the corrector certified "stable" without the eigenvalues."""
        self._npts += 1
        eq = self.cont._corrector_result(raw, p_t, r_t)
        if st:  # the point kernel declines: the generic path (Blocks kept by the corrector)
            p = self.point(eq, s)
        else:
            tan = out if type(out) is tuple else (out[:self._nq], out[self._nq:])
            ev = raw[5]
            if force is None:
                force = self.d @ eq.wrench
            if ev is None:  # "stable" certified, the eigenvalues when first read (_LateBP)
                p = _LateBP.with_tangent(s, eq, force, k, mu, raw[7],
                                         rate if self.mask is not None and _analytic_rate else None, tan)
            else:
                lam = float(ev[-1]) if ev.size else -np.inf  # (ascending: _max_eig)
                p = _BP(s, eq, force, k, None, mu, lam)
                if self.mask is not None and _analytic_rate:
                    p.dmu = rate
                p.tan = tan
        if self.second_order:
            p.hist = (a.s, t[0], t[1])
        return p

    def _point_fn(self):
        """The compiled point kernel when wanted (:meth:`point`'s rule, ``VJM_PIN_JIT`` as read at
        the start of the curve), else None; with it the fused step's compiled helpers (``_fz``:
        :func:`~vjm_pin.analysis.point_kernel.fused`)."""
        if self._fn is None:
            md = self._jit
            wanted = md == "1" or (md == "auto" and ("numba" in sys.modules or _pk._compiled))
            if wanted and use_compiled(self._npts):
                self._fn = compiled()
        fn = self._fn or None
        if fn is not None and self._fz is None and self._dense_point:
            self._fz = _pk.fused()
        return fn

    def _fused_step(self, a: _BP, s: float, x_pred, move: float, t, fresh: bool = False):
        """:meth:`step`'s corrector and point in one lean pass (the common step of a curve): the
        solver's fused local iteration from the prediction (``EquilibriumSolver._corrector``, the
        iterations of ``_solve_local``), the continuity check, then the point kernel on the
        converged iteration's own ``J`` and ``H(F)`` (no Blocks, no re-validation). Returns the
        point, None (the corrector strayed: the step is rejected, as :meth:`step`), or
        :data:`_GENERAL` when the local iteration gave way (the caller goes on as after
        ``_solve_local`` returned None). Every number is that of the general path; a point the
        compiled point kernel declines goes through :meth:`point` (its generic path). With the
        compiled kernels the continuity check, the point kernel, the force ``dᵀF`` and the tangent's
        layout are one call on the corrector's own QR of ``J``
        (:func:`~vjm_pin.analysis.point_kernel._reuse_point_loops`; where the corrector's kernel hands out
        an explicit ``Q`` instead, :func:`~vjm_pin.analysis.point_kernel._fused_point_loops` factors ``J``
        again: the same numbers to rounding). Where the compiled corrector
        certified "stable" without the eigenvalues of eq. (23) the point is a :class:`_LateBP`: ``λ``
        computed when first read (the tracer's verdicts ask the certificate first). ``fresh``:
        ``x_pred`` is a fresh float64 (nq,) array (the compiled prediction's): with a target whose
        arrays are float64 and C-contiguous the corrector goes straight to its one-call loop, which
        reads them as they are (``EquilibriumSolver._corrector`` with ``flushed`` ``FRESH``)."""
        solver = self.cont
        rt = self._rt
        if rt is not None and (rt[0] is None or rt[0] == (s * self._d_rot).tobytes()):
            # displace(p0, r0, s·d) with its rotation kept (fixed when d is a translation): the same numbers
            # (p0 + s·d[:3] element by element in Python floats: IEEE products and sums, as numpy's)
            pl = self._p0l
            if pl is None or pl[0] is not solver.p0:
                pl = self._p0l = (solver.p0,) + tuple(solver.p0.tolist()) + tuple(self._d_lin.tolist())
            p_t, r_t = np.array((pl[1] + s * pl[4], pl[2] + s * pl[5], pl[3] + s * pl[6])), rt[1]
            fresh = fresh and rt[2]
        else:
            target = s * self.d
            p_t, r_t = _displace(solver.p0, solver.r0, target)
            ok = (type(r_t) is np.ndarray and r_t.dtype == np.float64 and r_t.shape == (3, 3)
                  and r_t.flags.c_contiguous and type(p_t) is np.ndarray and p_t.dtype == np.float64
                  and p_t.shape == (3,))
            self._rt = (None if self._d_translation else target[3:].tobytes(), r_t, ok)
            fresh = fresh and ok
        # (step flushed x_pred; fresh: the straight route to the compiled loop)
        raw = solver._corrector(self._corr, p_t, r_t, x_pred, flushed=_FRESH if fresh else True)
        if raw is None:
            return _GENERAL
        fz = self._fz
        if fz is None:
            self._point_fn()  # (the compiled point kernel when wanted: also for point() below)
            fz = self._fz
        kf = raw[4]
        if fz is None or kf[6].shape != self._hz_shape:
            corr = self.scaled(raw[0] - x_pred)
            if not corr <= CORRECTOR_RATIO * move + 1e-9:
                return None
            eq = solver._corrector_result(raw, p_t, r_t)
            p = self.point(eq, s)
            p.hist = (a.s, t[0], t[1])
            return p
        if self._reuse is None:
            self._reuse_setup()
        if self._reuse and kf[1].shape == self._hh_shape:  # the point on the corrector's own QR
            pa = self._rargs
            nq = self._nq
            out = np.empty(nq + 6)
            cfl = pa[2]
            mu0, rate0 = a.mu, a.dmu
            if _mu_hint and rate0 is not None and rate0 == rate0 and mu0 == mu0:
                # μ's bracket predicted from the point continued from (μ + δs·dμ/ds, ± twice the move
                # and 1e-6 of |μ|): the kernel keeps what the Sturm counts confirm
                ds = s - a.s
                half = 2.0 * abs(ds * rate0) + 1e-6 * abs(mu0) + 1e-300
                cfl[-2], cfl[-1] = mu0 + ds * rate0 - half, mu0 + ds * rate0 + half
            else:
                cfl[-2] = cfl[-1] = math.nan
            k = mu = rate = force = tan = None  # (st = 1 below: the generic point)
            try:
                wt = raw[8]  # the corrector's (Qᵀ W Q)ᵀ at the convergence (None: computed by the kernel)
                wt = _NO_WT if wt is None or not _reuse_wt else wt
                st, k, mu, rate, force = pa[0](raw[0], x_pred, CORRECTOR_RATIO * move + 1e-9, raw[3].jacobian, kf[1],
                                               kf[6], kf[7], wt, pa[1], pa[2], pa[3], pa[4], out)
            except np.linalg.LinAlgError:  # an exactly singular matrix (numba's np.linalg raises): after the check
                st = 1
            if not st:
                tan = (out[:nq], out[nq:])
        else:
            pa = self._pargs
            if pa is None:
                pk = self.kernel
                mask = self.mask if self.mask is not None else pk._nomask
                pa = self._pargs = (pk.kz, pk.task, pk.dt, mask, pk.nt, self.mask is not None, FAST_RANK,
                                    SINGULAR_RCOND, np.zeros(6))
            x_dot = np.empty(self._nq)
            w_dot = np.empty(6)
            k = mu = rate = None  # (st = 1 below: the generic point)
            try:
                st, k, mu, rate = fz[1](raw[0], x_pred, CORRECTOR_RATIO * move + 1e-9, self.free, self.var_scale,
                                        raw[3].jacobian, kf[6], pa[0], pa[1], pa[2], pa[3], kf[7] if pa[5] else pa[8],
                                        pa[4], pa[5], pa[6], pa[7], x_dot, w_dot)
            except np.linalg.LinAlgError:  # an exactly singular matrix (numba's np.linalg raises): after the check
                st = 1
            tan = (x_dot, w_dot)
            force = None
        if st < 0:  # the corrector strayed
            return None
        return self._step_point(a, s, t, raw, p_t, r_t, st, k, mu, rate, force, tan)

    def _reuse_setup(self) -> None:
        """Whether the fused step's point may run on the corrector's own factorisation
        (:func:`~vjm_pin.analysis.point_kernel._reuse_point_loops`, where the corrector's kernel
        hands out the Householder reflectors of ``Jᵀ``, ``(m + 1, n)``: the compiled one), and its
        packed constants (``_rargs``)."""
        pk = self.kernel
        fn = _pk.reuse() if _reuse_qr else None
        self._reuse = ok = fn is not None
        self._hh_shape = (pk.m + 1, pk.n)
        if ok:
            rate = self.mask is not None
            ci = np.concatenate([[pk.n, pk.nt, pk.m, int(rate)], self.free, pk.task]).astype(np.int64)
            cfl = np.concatenate([[FAST_RANK, SINGULAR_RCOND], self.d, pk.dt, self.var_scale, [np.nan, np.nan]])
            self._rargs = (fn, ci, cfl, pk.kz, self.mask if rate else pk._nomask)

    def reach(self, a: _BP, s: float) -> _BP | None:
        """``a``'s branch continued to ``s`` in adaptive sub-steps; None if it cannot be."""
        cur, h = a, s - a.s
        if abs(h) <= 1e-14 * self.range:
            return a
        while cur.s != s:
            rem = s - cur.s
            if abs(h) >= abs(rem) or abs(rem - h) <= 1e-14 * self.range:
                h = rem
            nxt = self.step(cur, s if h == rem else cur.s + h)
            if nxt is None:
                h *= 0.5
                if abs(h) < self.hmin:
                    return None
                continue
            cur = nxt
            h *= 2.0
        return cur

    def reach_or_predict(self, a: _BP, s: float) -> _BP | None:
        """:meth:`reach`, or, when the corrector cannot converge within a fine step of
        ``a`` (next to a bifurcation the deflection-driven Newton matrix is singular), the
        tangent prediction of eq. (29) itself (error O(δs²))."""
        m = self.reach(a, s)
        if m is not None or abs(s - a.s) > FINE_STEP * self.range:
            return m
        t = self.tangent(a)
        if t is None:
            return None
        ds = s - a.s
        eq = replace(
            a.eq, x=flush_tiny(a.eq.x + ds * t[0]), wrench=a.eq.wrench + ds * t[1], path="tangent-prediction"
        )
        return self.point(eq, s)

    def _nearest(self, s, pts):
        return min(pts, key=lambda p: abs(p.s - s))

    def eps(self, s_c: float) -> float:
        return max(OFFSET_REL * abs(s_c), self.eps_abs)

    # ------------------------------------------------------------------ branch switch
    def switch(self, u: _BP, s: float) -> _BP | None:
        """The stable branch leaving the bifurcation at ``u`` (continued branch, on the
        verge of losing eq. 23), solved at ``s``: ``u`` perturbed along ± the critical
        eigenvector of eq. (23), the stable solver, the lower energy (first sign on a tie)."""
        b = self.blocks(u.eq.x, u.eq.wrench)
        z = null_space(b.J_theta, b.J_q)
        cands = []
        if z.shape[1]:
            v = np.linalg.eigh(reduced_matrix(b, z))[1]
            vec = np.zeros_like(u.eq.x)
            vec[self.free] = z @ v[:, -1]
            vec /= max(self.scaled(vec), 1e-300)
            for amp in (1e-3, 1e-2, 1e-1):
                for sign in (1.0, -1.0):
                    eq = self.solver.solve(
                        s * self.d,
                        x0=u.eq.x + sign * amp * vec,
                        wrench0=u.eq.wrench,
                        raise_on_failure=False,
                    )
                    if eq.converged:
                        p = self.point(eq, s)
                        if p.lam < -self.thr:
                            cands.append(p)
                if cands:
                    break
        if not cands:
            eq = self.solver.solve(
                s * self.d, x0=u.eq.x, wrench0=u.eq.wrench, raise_on_failure=False
            )
            if not eq.converged:
                return None
            return self.point(eq, s)
        best = cands[0]
        for p in cands[1:]:
            if p.eq.energy < best.eq.energy - 1e-9 * max(abs(best.eq.energy), 1e-300):
                best = p
        return best

    def jump(self, a: _BP, s: float) -> _BP:
        """The stable solver at ``s`` from ``a`` (the branch cannot be continued)."""
        eq = self.solver.solve(s * self.d, x0=a.eq.x, wrench0=a.eq.wrench)
        return self.point(eq, s)

    # ------------------------------------------------------------------ events
    def first_event(self, p: _BP, q: _BP, depth: int = 0):
        """The first candidate event on the continued branch over ``[p, q]``:
        ``("cross", lo, hi)`` (μ crosses zero from below in it), ``("max", lo, hi)`` (an
        interior maximum of μ < 0), or None."""
        f0, f1 = p.mu, q.mu
        if f0 < 0 <= f1:
            return ("cross", p, q)
        h = q.s - p.s
        if depth >= DIP_DEPTH or h <= 4 * self.hmin:
            return None
        g0, g1 = p.dmu, q.dmu
        if g0 is None:
            g0 = self.dmu(p)
        if g1 is None:
            g1 = self.dmu(q)
        if not (math.isfinite(g0) and math.isfinite(g1)):
            return None
        both_neg = f0 < 0 and f1 < 0
        if not both_neg and not (f0 >= 0 and f1 >= 0):
            return None  # μ falls through zero: stability regained (not an event)
        # The cubic is the chord plus t(1−t)[(a₀−Δ)(1−t) − (a₁−Δ)t] (a = h·g, Δ = f₁ − f₀): at an
        # interior extremum |value − chord| ≤ M/4, M = max|a − Δ|. So with two negative ends and no
        # imperfect-bifurcation shape (g₀ > 0 ≥ g₁) it cannot come "near" zero when
        # max(f₀, f₁) + M/2 < −2·tiny (M/8 and tiny to spare for the rounding of the extremum's value,
        # ~1e-14·(|f| + M); the same for two non-negative ends): the answer of the extremum below (None)
        # without computing it.
        # (the builtins max and min written out, their rule: max(a, b) is b if b > a else a)
        a0, a1, thr = abs(f0), abs(f1), self.thr
        tiny = a1 if a1 > a0 else a0
        tiny = 1e-12 * (thr if thr > tiny else tiny)
        dl = f1 - f0
        a0, a1 = abs(h * g0 - dl), abs(h * g1 - dl)
        bound = 0.5 * (a1 if a1 > a0 else a0)
        if both_neg:
            if (f1 if f1 > f0 else f0) + bound < -2.0 * tiny and not g0 > 0 >= g1:
                return None
        elif (f1 if f1 < f0 else f0) - bound > 2.0 * tiny:
            return None
        ext = _hermite_extremum(p.s, f0, g0, q.s, f1, g1, maximum=both_neg)
        if ext is None:
            return None
        t, v, dev = ext
        near = v >= -0.5 * dev - tiny if both_neg else v <= 0.5 * dev + tiny
        if near:
            m = self.reach(p, p.s + t * (q.s - p.s))
            if m is None:
                return None
            return self.first_event(p, m, depth + 1) or self.first_event(m, q, depth + 1)
        if both_neg and g0 > 0 >= g1 and -v <= 1.5 * IMPERFECT_RATIO * self.seg_margin:
            return ("max", p, q)
        return None

    def locate_cross(self, lo: _BP, hi: _BP):
        """Root of μ in ``[lo, hi]`` on their branch: (point at s_c, iterations)."""
        pts = [lo, hi]
        tol = 1e-3 * self.refine_tol

        def evaluate(s, lo_, hi_):
            m = self.reach_or_predict(lo_ if s - lo_.s <= hi_.s - s else hi_, s)
            if m is None:
                return None
            pts.append(m)
            return m, m.mu

        def done(lo_, hi_, m, s):
            k = max(abs(lo_.k), abs(hi_.k)) if np.isfinite(lo_.k) and np.isfinite(hi_.k) else 0.0
            w = hi_.s - lo_.s
            return w * k <= tol * max(abs(m.force), 1e-300) or w <= 1e-13 * self.range

        lo2, flo, hi2, fhi, n, _ = illinois(
            evaluate, lo, lo.mu, hi, hi.mu, lambda p: p.s, done, MAX_BISECTIONS
        )
        w = flo / (flo - fhi) if fhi != flo else 0.5
        s_c = lo2.s + w * (hi2.s - lo2.s)
        c = self.reach_or_predict(lo2 if s_c - lo2.s <= hi2.s - s_c else hi2, s_c) or lo2
        return c, lo, hi, n

    def locate_max(self, lo: _BP, hi: _BP):
        """Maximum of μ in ``[lo, hi]`` on their branch (``dμ/ds(lo) > 0 ≥ dμ/ds(hi)``):
        Illinois on ``dμ/ds``; (point, iterations)."""
        pts = [lo, hi]

        def evaluate(s, lo_, hi_):
            m = self.reach_or_predict(lo_ if s - lo_.s <= hi_.s - s else hi_, s)
            if m is None:
                return None
            pts.append(m)
            return m, -self.dmu(m)

        def done(lo_, hi_, m, s):
            return hi_.s - lo_.s <= 1e-10 * self.range

        illinois(
            evaluate, lo, -self.dmu(lo), hi, -self.dmu(hi), lambda p: p.s, done, MAX_BISECTIONS
        )
        best = max(pts, key=lambda p: p.mu)
        return best, len(pts) - 2

    def finish(self, c: _BP, lo: _BP, hi: _BP, kind: str, index: int, n: int, critical: list):
        """Record the critical point at ``c`` (``lo``, ``hi``: points of the same branch
        before and after it, reached from away from the singular point). Returns
        ``(switched, plus)``: the point of the branch switched to (or None when the
        branch is followed on) and the continued branch at ``s_c + ε``."""
        e = self.eps(c.s)
        before = self.reach_or_predict(lo, c.s - e) if lo.s < c.s - e else None
        before = before or self.reach_or_predict(c, c.s - e)
        k_before = before.k if before is not None else c.k
        plus = self.reach_or_predict(hi, c.s + e) if hi.s > c.s + e else None
        plus = plus or self.reach_or_predict(c, c.s + e)
        switched = None
        if kind != "imperfect" and (plus is None or plus.lam >= -self.thr or self._loses_eq23(c, e)):
            kind = "bifurcation"
            switched = self.switch(c, c.s + e)
            after = switched
        else:
            if kind != "imperfect":
                kind = "limit"
            after = plus
        cp = CriticalPoint(
            force=float(c.force),
            deflection=float(c.s),
            stiffness_before=float(k_before),
            stiffness_after=float(after.k) if after is not None else float("nan"),
            index=index,
            force_after=float(after.force) if after is not None else float("nan"),
            bisections=int(n),
            kind=kind,
        )
        if not critical or abs(cp.deflection - critical[-1].deflection) > 1e-6 * self.range:
            critical.append(cp)
        self.seg_margin = 0.0
        return switched, plus

    def _loses_eq23(self, c: _BP, e: float) -> bool:
        """Whether the continued branch loses eq. (23) at the critical point ``c``, to first order:
        ``λ(s_c + ε) ≈ λ(s_c) + ε·|dμ/ds| ≥ −thr`` (where it does, eq. 23's critical eigenvector is
        μ's and λ moves with μ). :meth:`finish` asks it besides the point ``plus`` it reached at
        ``s_c + ε``: next to a pitchfork that point can lie on the bent branch, which is stable, and
        a bifurcation would be called a limit depending on where the grid put the bracket
        (:func:`vjm_pin.analysis.critical._kind` uses the same rule)."""
        g = self.dmu(c)
        if not math.isfinite(g):
            return False
        return c.lam >= -max(self.thr, e * abs(g))

    def process(self, p: _BP, q: _BP, index: int, critical: list) -> _BP:
        """Events over the accepted sub-step ``[p, q]``; returns the followed point that
        ends it (``q``, or the point of the branch switched to)."""
        ev = self.first_event(p, q)
        if ev is None:  # (the common answer, before the loop)
            return q
        a = p
        for i in range(64):  # events within one sub-step: a handful at most
            if i:
                ev = self.first_event(a, q)
                if ev is None:
                    return q
            kind, lo, hi = ev
            if kind == "cross":
                c, lo0, hi0, n = self.locate_cross(lo, hi)
                switched, plus = self.finish(c, lo0, hi0, "limit", index, n, critical)
                if switched is not None:
                    return switched
            else:
                c, n = self.locate_max(lo, hi)
                if not (0 < -c.mu <= IMPERFECT_RATIO * max(self.seg_margin, -lo.mu)):
                    return q
                _, plus = self.finish(c, lo, hi, "imperfect", index, n, critical)
            if plus is None or plus.s >= q.s:
                return q
            a = plus
        return q

    def advance(self, cur: _BP, s_end: float, index: int, critical: list) -> _BP:
        """The followed branch from ``cur`` to ``s_end``: the point there."""
        h = min(self.h, s_end - cur.s)
        while cur.s < s_end:
            rem = s_end - cur.s
            h = min(h, rem)
            s_try = s_end if rem - h <= 1e-14 * self.range else cur.s + h
            nxt = self.step(cur, s_try, True) if self.second_order else self.step(cur, s_try)
            lost = None  # eq. (23) lost over the sub-step (cur.below and nxt.above), once asked
            if (nxt is not None and s_try - cur.s > FINE_STEP * self.range
                    and (cur.mu < 0 <= nxt.mu or (lost := cur.below(self.thr) and nxt.above(self.thr)))):
                nxt = None  # a stability change is only accepted over a fine step (no jump across a knee)
            if nxt is None:
                h *= 0.5
                if h < self.hmin:  # the branch ends (fold): the stable solver jumps
                    cur = self.jump(cur, s_try)
                    self.seg_margin = 0.0
                    h = self.range
                continue
            m = -cur.mu
            if m > self.seg_margin:  # (max(self.seg_margin, -cur.mu))
                self.seg_margin = m
            new = self.process(cur, nxt, index, critical)
            if new is not nxt:  # switched branch at a bifurcation
                cur = new if new is not None else nxt
                self.seg_margin = 0.0
                h = max(self.eps(cur.s), h / 4)
                continue
            if lost is None:
                lost = nxt.above(self.thr) and cur.below(self.thr)
            if lost:
                # eq. (23) lost without a new force-control event (μ ≥ 0 already): switch
                u, _, _ = self.locate_lam(cur, nxt)
                sw = self.switch(
                    u, min(u.s + self.eps(u.s), s_end) if s_end > u.s else u.s + self.eps(u.s)
                )
                cur = sw if sw is not None else nxt
                self.seg_margin = 0.0
                h = max(self.eps(cur.s), h / 4)
                continue
            cur = nxt
            h *= 2.0
            if s_try != s_end:  # a step not shortened to reach the grid point: remember it
                self.h = h
        if cur.s > s_end + 1e-14 * self.range:  # a switch landed past the grid point
            back = self.reach(cur, s_end)
            cur = back if back is not None and back.lam < -self.thr else self.jump(cur, s_end)
        return cur

    def locate_lam(self, lo: _BP, hi: _BP):
        """Where the largest eigenvalue of eq. (23) crosses zero in ``[lo, hi]``: the last
        point on the stable side."""

        def evaluate(s, lo_, hi_):
            m = self.reach(lo_ if s - lo_.s <= hi_.s - s else hi_, s)
            return None if m is None else (m, m.lam)

        def done(lo_, hi_, m, s):
            return hi_.s - lo_.s <= 1e-12 * self.range

        lo2, _, hi2, _, n, _ = illinois(
            evaluate, lo, lo.lam, hi, hi.lam, lambda p: p.s, done, MAX_BISECTIONS
        )
        return lo2, hi2, n

    # ------------------------------------------------------------------ rigid start
    def rigid_start(self, p0: _BP):
        """A start rigid along ``d``: the force at the unloaded configuration grows until
        μ crosses zero. Returns ``(force, u)`` (``u`` the loaded reference point) or None."""
        x = p0.eq.x

        def mu(f):
            return _max_eig(check_stability_held(self.blocks(x, f * self.d), self.P))

        f = rigid_start_force(mu, max(self.solver.kscale / self.solver.length_scale, 1e-300))
        if f is None:
            return None
        eq = replace(p0.eq, wrench=f * self.d)
        return f, self.point(eq, 0.0)


def rigid_start_force(mu, scale: float) -> float | None:
    """The force (N) along a rigid start direction at which the force-control margin ``mu(f)``
    crosses zero: doubling from ``1e-6·scale`` to bracket it, then :func:`illinois` and a final
    secant; None when no crossing below ``1e9·scale`` (``scale`` a stiffness per length, N/m).
    Shared by the serial and the mechanism tracers."""
    lo, hi = 0.0, 1e-6 * scale
    flo, fhi = mu(lo), mu(hi)
    while fhi < 0:
        lo, flo, hi = hi, fhi, 2 * hi
        fhi = mu(hi)
        if hi > 1e9 * scale:
            return None
    lo, flo, hi, fhi, _, _ = illinois(
        lambda f, a, b: (f, mu(f)),
        lo,
        flo,
        hi,
        fhi,
        float,
        lambda a, b, m, f: b - a <= 1e-14 * b,
        MAX_BISECTIONS,
    )
    return lo + flo / (flo - fhi) * (hi - lo) if fhi != flo else hi


def _curve_point(p: _BP, thr: float) -> CurvePoint:
    held = bool(p.below(thr))
    w = p.eq.wrench
    # CurvePoint(...) without its field-by-field frozen __init__ (one per point): every field, in order
    # (_built(CurvePoint, ...), inline)
    obj = _new_object(CurvePoint)
    obj.__dict__.update({
        "deflection": float(p.s),
        "force": float(p.force),
        "wrench": w.copy() if type(w) is np.ndarray and w.dtype == np.float64 else np.asarray(w, float).copy(),
        "stable": held,
        "stiffness": p.k,
        "equilibrium": p.eq,
        "stable_end_held": held,
        "force_control_margin": float(-p.mu),
    })
    return obj


def _trace_branch(vm, d, start_eq: EquilibriumResult, s_values, kin, solver) -> list[CurvePoint]:
    pts = []
    prev = start_eq
    for s in s_values:
        try:
            eq = solver.solve(s * d, x0=prev.x, wrench0=prev.wrench)
        except NoEquilibrium:
            break
        if not eq.converged:
            break
        pts.append(_point(vm, eq, s, d, kin))
        prev = eq
    return pts


def _distinct(eq: EquilibriumResult, others, tol=1e-6) -> bool:
    return all(np.linalg.norm(eq.x - o.x) > tol * max(1.0, np.linalg.norm(o.x)) for o in others)


def _other_branches(
    vm, d, points, critical, s_grid, kin, solver
) -> tuple[tuple[CurvePoint, ...], ...]:
    """Branches that leave the critical points: seeds at the first step after each
    critical point, from the pre-critical state itself (the trivial branch continued) and
    from it displaced along ± each eigenvector of the reduced matrix of eq. (23), solved
    with ``follow_stable=False`` and continued by warm starts."""
    from vjm_pin.solver import blocks_at

    unstable = solver._sibling(follow_stable=False)  # shares the Kinematics (pin.Data)
    branches = []
    seen = [p.equilibrium for p in points]
    for c in critical:
        i0 = max(c.index - 1, 0)
        base = points[i0].equilibrium
        rest = [s for s in s_grid if s > points[i0].deflection]
        if not rest:
            continue
        b = blocks_at(vm, base.x, base.wrench, kin)
        z = null_space(b.J_theta, b.J_q)
        free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
        amp = np.sqrt(abs(rest[0] - points[i0].deflection))
        seeds = [base.x.copy()]
        for j in range(z.shape[1]):
            for sign in (1.0, -1.0):
                x = base.x.copy()
                x[free] += sign * amp * z[:, j]
                seeds.append(x)
        for x0 in seeds:
            try:
                eq = unstable.solve(rest[0] * d, x0=x0, wrench0=base.wrench)
            except NoEquilibrium:
                continue
            if not eq.converged or eq.stable or not _distinct(eq, seen):
                continue
            first = _point(vm, eq, rest[0], d, kin)
            pts = [first] + _trace_branch(vm, d, eq, rest[1:], kin, unstable)
            seen.extend(p.equilibrium for p in pts[:1])
            branches.append(tuple(pts))
    return tuple(branches)


def _reference_equilibrium(vm, solver, kin) -> EquilibriumResult | None:
    """The unloaded reference configuration as a converged equilibrium under zero wrench
    (path ``"reference"``, 0 iterations, its eq. (23) verdict), or None when a spring is
    preloaded there (``K_θ(θ − θ₀) ≠ 0``: not an equilibrium without load)."""
    from vjm_pin.solver import blocks_at
    from vjm_pin.solver.stability import check_stability

    x = _reference_x(vm)
    if x is None:
        return None
    return _reference_result(vm, solver, x, check_stability(blocks_at(vm, x, np.zeros(6), kin)))


def _reference_x(vm) -> np.ndarray | None:
    """A copy of the reference configuration, or None when a spring is preloaded there (not an
    equilibrium without load): the solver's rule (``equilibrium.reference_if_unloaded``, also behind
    ``EquilibriumSolver.solve`` at a zero deflection)."""
    from vjm_pin.solver.equilibrium import reference_if_unloaded

    return reference_if_unloaded(vm)


def _reference_result(vm, solver, x: np.ndarray, stability) -> EquilibriumResult:
    """The result of the unloaded reference ``x`` (:func:`_reference_x`) with its eq. (23) verdict
    ``stability`` (path ``"reference"``, zero wrench and deflection, 0 iterations)."""
    return EquilibriumResult(
        x=x,
        q=x[vm.q_idx].copy(),
        theta=x[vm.theta_idx].copy(),
        wrench=np.zeros(6),
        deflection=np.zeros(6),
        position=solver.p0.copy(),
        rotation=solver.r0.copy(),
        converged=True,
        iterations=0,
        residuals={"position": 0.0, "orientation": 0.0, "statics": 0.0},
        energy=0.0,
        path="reference",
        stability=stability,
    )


def _unloaded(vm, solver, d, kin) -> EquilibriumResult | None:
    """The unloaded reference as the first point when the chain is rigid along ``d``
    there (straight chain of rigid links, Model A S): the force at zero deflection is then
    indeterminate and the solver's perturbed start would pick an arbitrary one; the
    unloaded state (zero wrench) is the natural start of the curve."""
    probe = _reference_equilibrium(vm, solver, kin)
    if probe is None or not np.isinf(tangent_stiffness(vm, probe, d, kin)):
        return None
    return probe


def _follow(tr: _Tracer, first: _BP, rigid: bool, s_grid, progress, make_point):
    """The followed branch from ``first`` over ``s_grid`` and its critical points (module
    docstring): ``(points, critical)``; ``make_point(bp, thr)`` builds a :class:`CurvePoint`."""
    steps = len(s_grid) - 1
    critical: list[CriticalPoint] = []
    points = [make_point(first, tr.thr)]
    cur = first
    if rigid:
        # rigid along d at the start: search along the force at the unloaded configuration
        found = tr.rigid_start(first) if first.mu < 0 else None
        s1 = s_grid[1]
        if found is not None:
            f, u = found
            e = tr.eps(0.0)
            after = tr.switch(u, e)
            if after is not None:
                critical.append(
                    CriticalPoint(
                        force=float(f),
                        deflection=0.0,
                        stiffness_before=float(first.k),
                        stiffness_after=float(after.k),
                        index=1,
                        force_after=float(after.force),
                        bisections=0,
                        kind="bifurcation",
                    )
                )
                cur = after
        if cur is first:
            cur = tr.jump(first, s1)
    tr.seg_margin = max(0.0, -cur.mu)
    if progress is not None:
        progress(1, steps + 1)
    for i, s in enumerate(s_grid[1:], start=1):
        cur = tr.advance(cur, s, i, critical)
        points.append(make_point(cur, tr.thr))
        if progress is not None:
            progress(i + 1, steps + 1)
    return tuple(points), critical


def _mechanism_solver(vm, solver, loads, gravity, what: str) -> MechanismSolver:
    """``solver`` for a run on the mechanism solver of ``vm`` (``what``: the run's name in the
    message), or a new :class:`~vjm_pin.solver.mechanism.MechanismSolver` with the dead loads and
    gravity when None.

    Raises:
        InputError: a solver of another kind or of another model, or dead loads given both to
            the passed solver and here.
    """
    if solver is None:
        return MechanismSolver(vm, loads=loads, gravity=gravity)
    if not isinstance(solver, MechanismSolver):
        raise InputError(
            f"this {what} needs the mechanism solver (loop closures, dead loads or a free task frame): "
            "pass a MechanismSolver as solver, or none"
        )
    if loads or gravity is not None:
        raise InputError("give the dead loads and gravity to the MechanismSolver passed as solver, not twice")
    if solver.vm is not vm:
        raise InputError("the solver was built for another model")
    return solver


def check_free_start(vm, tr, p0) -> None:
    """``free=True``: refuse a start that is a mechanism with only ``d`` held.

    ``p0`` is the first point of the mechanism tracer (:meth:`MechanismTracer.start`). Its
    verdict for the control as run (eq. 23 on the null space ``Z`` of ``[C; dᵀJ]``) and its
    force-control margin ``μ`` (on the null space of ``C``: nothing held with ``free``) are the
    start's own quantities. When an eigenvalue of the former, or ``μ``, lies within the
    stability tolerance of zero the model has a motion of zero stiffness there (passive joints
    with no load on them: the Model C column pinned at its base swings across ``d``, Model B
    along it): the tangent of eq. (28) is undefined or the force stays zero to rounding, and
    the "critical points" found along the path are rounding noise. The eigenvectors of those
    eigenvalues name the task components the motion moves the end in (rotations scaled by the
    chain length).

    Raises:
        FreeMechanism: such a start (a one-line message naming the model and components).
    """
    from vjm_pin.exceptions import FreeMechanism
    from vjm_pin.model.format import COMPONENTS
    from vjm_pin.solver.mechanism import _null_basis

    tol, lin = float(p0.run.tolerance), p0.lin
    if np.any(np.abs(p0.run.eigenvalues) <= tol):
        z = p0.z_run  # across d
    elif abs(p0.mu) <= tol:  # along d: nothing held but the closures
        z = _null_basis(np.vstack([lin.closure_jacobian, tr.p_rows @ lin.task_jacobian]), tr.run.rank_rtol)[0]
    else:
        return
    red = -(z.T @ lin.hessian @ z)
    w, v = np.linalg.eigh(0.5 * (red + red.T))
    zero = np.abs(w) <= tol
    modes = z @ v[:, zero]
    task = list(tr.solver.task)
    move = np.abs(lin.task_jacobian[task] @ modes).max(axis=1, initial=0.0)
    move = move * np.where(np.array(task) >= 3, tr.solver.length_scale, 1.0)
    comps = [COMPONENTS[c] for c, m in zip(task, move) if m > 1e-6 * max(move.max(initial=0.0), 1e-300)]
    along = np.abs(tr.d @ lin.task_jacobian @ modes).max(initial=0.0) > 1e-6 * max(move.max(initial=0.0), 1e-300)
    where = (f"it moves the end in {', '.join(comps)}{' (along the direction)' if along else ''} with zero "
             "stiffness" if comps else "an internal motion has zero stiffness (the end stays in place)")
    raise FreeMechanism(
        f"with the end held only along the direction (free=True, --free) model '{vm.name}' is a "
        f"mechanism at the start: {where} ({int(zero.sum())} zero eigenvalue(s) of its loaded "
        "stiffness matrix, which is singular there); hold the end in every task component (no free) "
        "or add springs or loads that stiffen it",
        model=vm.name, components=comps, eigenvalues=w[zero],
    )


def _trace_mechanism(vm, d, max_deflection, steps, solver, refine_tol, all_branches, progress, loads, gravity, free):
    """:func:`trace_curve` on :class:`~vjm_pin.solver.mechanism.MechanismSolver`
    (:mod:`vjm_pin.analysis.mechanism_curve`)."""
    from vjm_pin.analysis.mechanism_curve import MechanismTracer, check_free_direction, curve_point

    if all_branches:
        raise InputError(
            "all_branches (the unstable branches) is only traced for serial chains without dead loads"
        )
    solver = _mechanism_solver(vm, solver, loads, gravity, "curve")
    if free:
        check_free_direction(d)
    tr = MechanismTracer(vm, d, max_deflection, solver, refine_tol, bool(free))
    s_grid = [max_deflection * i / steps for i in range(steps + 1)]
    first, rigid = tr.start()
    if free:
        check_free_start(vm, tr, first)
    points, critical = _follow(tr, first, rigid or not np.isfinite(first.k), s_grid, progress, curve_point)
    return Curve(direction=d, points=points, critical=tuple(critical), free=bool(free),
                 loads=tuple(solver.loads.loads))


@one_blas_thread
def trace_curve(
    vm: VjmModel,
    direction,
    max_deflection: float,
    steps: int = 100,
    *,
    solver: EquilibriumSolver | MechanismSolver | None = None,
    refine_tol: float = 1e-4,
    all_branches: bool = False,
    progress: Callable[[int, int], None] | None = None,
    loads: Sequence[Load] = (),
    gravity=None,
    free: bool = False,
) -> Curve:
    """Trace the force–deflection curve of ``vm`` along ``direction`` (paper §6.1, Fig. 4–5).

    The followed branch and its critical points are defined in the module docstring;
    they do not depend on ``steps``, which only sets where the curve is reported.

    Args:
        vm: The model.
        direction: (3,) or (6,) direction of the end deflection, world axes; normalised;
            must lie in the task components and be a pure translation or rotation.
        max_deflection: Final deflection along the direction (m or rad), > 0.
        steps: Number of equal steps (the curve has ``steps + 1`` points, from 0).
        solver: Equilibrium solver (default ``EquilibriumSolver(vm)`` for a serial chain,
            ``MechanismSolver(vm, loads, gravity)`` otherwise; follows the stable branch);
            used for the start and for branch switches.
        refine_tol: Relative force tolerance of the critical points (they are located
            to ``1e-3·refine_tol``).
        all_branches: Also trace the branches that leave each critical point
            (unstable ones, as in Fig. 4) into ``Curve.branches``.
        progress: Optional ``callable(done, total)`` called after every step.
        loads: Dead loads anywhere (:class:`~vjm_pin.kinematics.dead_loads.Load`, world axes).
        gravity: (3,) gravity (m/s²) for the link weights, or None.
        free: Hold the task frame only along ``d`` (a translation); the other task
            components carry zero wrench (the free-platform curve of a parallel robot).
            ``stable`` is then the verdict with only ``d`` held, and the force-control margin
            ``μ`` is judged with nothing held but the closures.

    Models with loop closures, dead loads, gravity or ``free`` are traced on
    :class:`~vjm_pin.solver.mechanism.MechanismSolver` (:mod:`vjm_pin.analysis.mechanism_curve`:
    the same continuation, critical-point rule and branch switch, with the closure rows in
    eq. 23, in the margin μ and in the bordered tangent of eq. 28); serial chains without them
    on :class:`EquilibriumSolver` as before.

    Returns:
        The :class:`Curve`.

    Raises:
        InputError: bad direction, range, steps or tolerance; ``all_branches`` or a serial
            solver with closures, dead loads or ``free``.
        FreeMechanism: with ``free`` the start is a mechanism (a motion of zero stiffness with
            only ``d`` held, :func:`check_free_start`), before any tracing.
        NoEquilibrium: no equilibrium at some point of the range.
    """
    d = _direction(vm, direction)
    if not np.isfinite(max_deflection) or max_deflection <= 0:
        raise InputError(
            f"max_deflection must be a positive number (m or rad), got {max_deflection}"
        )
    if int(steps) != steps or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps}")
    steps = int(steps)
    if not refine_tol > 0:
        raise InputError(f"refine_tol must be positive, got {refine_tol}")
    if free or loads or gravity is not None or getattr(vm, "closures", ()) or isinstance(solver, MechanismSolver):
        return _trace_mechanism(
            vm, d, max_deflection, steps, solver, refine_tol, all_branches, progress, loads, gravity, free
        )
    solver = solver or EquilibriumSolver(vm)
    kin = solver.kin
    s_grid = [max_deflection * i / steps for i in range(steps + 1)]
    tr = _Tracer(vm, d, max_deflection, solver, refine_tol)
    probe = _unloaded(vm, solver, d, kin)
    first = tr.point(probe if probe is not None else solver.solve(0.0 * d), 0.0)
    rigid = probe is not None or not np.isfinite(first.k)
    points, critical = _follow(tr, first, rigid, s_grid, progress, _curve_point)
    branches = _other_branches(vm, d, points, critical, s_grid, kin, solver) if all_branches else ()
    return Curve(direction=d, points=points, critical=tuple(critical), branches=branches)
