"""The critical load along a direction, directly: "at what load does it buckle?".

:func:`critical_load` returns the first critical point of the loading path of a model along a
task direction ``d`` without tracing the whole curve: serial chains, and (see "Mechanisms" below)
closed loops, parallel robots, dead loads anywhere, gravity and a free end. It is the first critical point
that :func:`~vjm_pin.analysis.curve.trace_curve` reports on the same path: the same followed
branch (the end moved along ``d``, every task component held, eq. 5), the same measure and the
same rule, evaluated by the tracer's own code (:class:`~vjm_pin.analysis.curve._Tracer`):

- ``μ(s)``: the largest eigenvalue of ``Vᵀ sym(H − K) V`` on the null space ``V`` of ``P·[J_θ J_q]``
  (the components orthogonal to ``d`` held, a dead force along ``d``): the force-control margin
  is ``−μ``; a critical point is where ``μ`` crosses zero from below (or, ``"imperfect"``, a
  sharp interior maximum of ``μ < 0``; see :mod:`vjm_pin.analysis.curve`);
- its kind: ``"bifurcation"`` when just past it the continued branch loses the stability of
  eq. (23) with the end held (buckling of a straight column: the force is still rising),
  ``"limit"`` when the branch stays stable with the end held (a force maximum, ``dF/ds = 0``):
  the tracer's test of eq. (23) at ``s_c + ε`` (its offset), with the eigenvalue there to first
  order (:func:`_kind`);
- a rigid start along ``d`` (a straight chain of rigid links, Model A S) is searched along the
  force at the unloaded configuration (:func:`~vjm_pin.analysis.curve.rigid_start_force`).

Method
------
1. The unloaded point ``s₀`` (the reference, as the tracer starts), with ``μ₀ < 0``, the tangent
   stiffness ``k₀ = dᵀK_C d`` and the tangent ``(δx, δF)`` of eq. (29).
2. The linearised estimate (eq. 23 as a generalized eigenproblem at fixed geometry, the
   counterpart of classical linear buckling): with ``H(F) = H₀ + ΔF·H₁`` (``H`` of eq. 23 is
   linear in the wrench, ``H₁`` at the unit wrench ``δF/k₀``), the smallest ``ΔF > 0`` where
   ``Vᵀ(H₀ − K + ΔF H₁)V`` becomes singular is ``1/ν_max`` of ``Vᵀ H₁ V y = ν Vᵀ(K − H₀)V y``;
   the deflection estimate is ``s₀ + ΔF/k₀``.
3. Safeguarded Newton on ``μ(s) = 0`` with the analytic ``dμ/ds``
   (:mod:`vjm_pin.analysis.point_kernel`): every evaluation is a warm-started equilibrium
   reached by the tracer's continuation (tangent predictor, Newton corrector, continuity check)
   from the nearer end of the current bracket; a step that leaves the bracket is replaced by
   the secant point of the bracket; without a bracket yet the step at most quadruples the
   deflection. A loss of stability is trusted only over a fine step (the tracer's rule in
   :meth:`_Tracer.advance`: a long predictor step may jump across a knee onto a neighbouring
   branch); until then the bracket is approached from its stable end alone (half a fine step
   short of the root estimate, halving after an untrusted step or a stalled margin: an
   imperfect maximum ahead, :meth:`_Search.root`). Between the points of the
   followed branch the tracer's cubic model of ``μ`` (:meth:`_Tracer.first_event`) checks that
   no earlier crossing (or imperfect minimum of the margin) hides.
4. Converged when one more Newton step would move the force by less than ``rtol`` (relative),
   or the bracket is that narrow (the tracer's own stopping rule at ``refine_tol = 1e3·rtol``),
   and the deflection too (at a limit point the force is flat, ``dF/ds = 0``).

The buckling mode is the unit eigenvector of the critical matrix at the critical point: eq. (23)
(end held) at a bifurcation, the force-control matrix (``μ``'s) at a limit or imperfect point,
by inverse iteration (one Cholesky).

Where the tracer's points come from the compiled O(n) chain kernel (a long serial chain,
``VJM_PIN_JIT`` not 0: :func:`_chain`), the eigenproblems of steps 1–2 and of the mode use the
same chain algebra (:mod:`vjm_pin.solver.chain_eigen`, Sturm-certified) instead of dense ones:
the reference's eq. (23) (:func:`_reference_chain`), the estimate (:func:`_linearised_chain`:
the pencil's power iteration (Rayleigh–Ritz accelerated) bounded by a Sturm count, else Newton on
the smallest eigenvalue) and the mode (:func:`_mode_chain`: at a bifurcation the eigenvector of
eq. (23) that the corrector certified at the critical point's own equilibrium, when it is bit for
bit that problem); the dense routines decide wherever the chain algebra declines.
There the first evaluation may also start nearer the root (:func:`_refined_start`: the
frozen-geometry problem repeated at the estimate's tangent prediction, where the path is nearly
linear), so that one verified equilibrium can meet the tolerance of step 4.

Mechanisms
----------
Models with loop closures, dead loads, gravity, ``free=True`` or a
:class:`~vjm_pin.solver.mechanism.MechanismSolver` as ``solver`` take the same search on the
mechanism tracer of ``trace_curve`` (:class:`~vjm_pin.analysis.mechanism_curve.MechanismTracer`,
the same dispatch and critical-point rule): ``μ`` on the null space of the closure rows and the
held rows orthogonal to ``d`` with the Lagrangian Hessian ``W`` (dead loads, closure multipliers),
the bordered tangent of eq. (28), ``dμ/ds`` by the tracer's difference along it. Step 2 freezes
the start's geometry under an added dead force along ``d`` (the closures and held rows reacting by
least squares, :meth:`MechanismTracer.force_control_lin`): ``W`` is linear in it, the same
generalized eigenproblem (:func:`linearised_load_mechanism`); the estimate is the smaller of that
and one Newton step on ``μ`` from the start (``dμ/ds`` by the tracer's difference). A
start rigid along ``d`` is searched along the force at the start (:meth:`MechanismTracer.rigid_start`).
The mode at a bifurcation is the critical eigenvector of the control as run (every task row held;
only ``d`` with ``free``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from vjm_pin.analysis.curve import (
    DIP_DEPTH,
    FINE_STEP,
    IMPERFECT_RATIO,
    OFFSET_ABS,
    OFFSET_REL,
    _direction,
    _hermite_extremum,
    _max_eig,
    _mechanism_solver,
    _reference_equilibrium,
    _reference_result,
    _reference_x,
    _Tracer,
    _unloaded,
    check_free_start,
)
from vjm_pin.analysis.mechanism_curve import MechanismTracer, check_free_direction
from vjm_pin.analysis.point_kernel import use_compiled
from vjm_pin.exceptions import InputError, NoCriticalPoint
from vjm_pin.kinematics.dead_loads import Load
from vjm_pin.model.format import VjmModel
from vjm_pin.model.task import task_vector
from vjm_pin.solver import chain_kernel as _chain_kernel
from vjm_pin.solver.chain_eigen import held_eigen, remember, remembered
from vjm_pin.solver.equilibrium import EquilibriumResult, EquilibriumSolver
from vjm_pin.solver.lapack import lapack as _lapack
from vjm_pin.solver.lapack import solve_triangular
from vjm_pin.solver.mechanism import MechanismSolver, _null_basis
from vjm_pin.solver.stability import (
    DeferredStability,
    check_stability_held,
    STABILITY_TOL,
    null_space,
    spectral_norm,
)
from vjm_pin.solver.threads import one_blas_thread

#: Default relative force tolerance of the critical point (the tracer's ``1e-3·refine_tol`` at
#: its default ``refine_tol = 1e-4``).
RTOL = 1e-7
#: Default largest number of equilibrium evaluations of the search.
MAX_ITER = 40
#: Without ``max_deflection``: the search range is this × the linearised estimate of the
#: critical deflection, else (no estimate) this fraction of the chain length (m) or 1 rad.
RANGE_FACTOR = 4.0
RANGE_NO_ESTIMATE = 0.5
#: Without ``max_deflection``, a linearised estimate of the critical deflection beyond this ×
#: the chain length (m; or rad) is discarded as rounding (:func:`_search_from`).
ESTIMATE_MAX = 10.0
#: A bracket end whose force departs from the other end's by more than this × the tangent
#: stiffness × their distance lies on another branch (:meth:`_Search.continuous`).
JUMP_FACTOR = 8.0


@dataclass(frozen=True)
class CriticalLoad:
    """The first critical point of the loading path along a direction (module docstring).

    Attributes:
        force: Critical load (N; N·m along a rotational direction): ``dᵀF``, the external force
            along the direction that holds the end there (positive when it pushes the end
            along the direction); dead loads are not included.
        deflection: Critical deflection ``s`` along the direction (m, or rad).
        direction: (6,) unit direction, world axes (translation, rotation).
        wrench: (6,) external wrench at the critical point (N, N·m), world axes.
        x: (nq,) configuration at the critical point (Pinocchio coordinates: rad, m).
        kind: ``"bifurcation"``, ``"limit"`` or ``"imperfect"`` (as
            :class:`~vjm_pin.analysis.curve.CriticalPoint`).
        mode: (nq,) buckling mode: unit eigenvector (2-norm over the free coordinates, zero
            elsewhere; largest component positive) of the critical eigenvalue (eq. 23 at a
            bifurcation, the force-control matrix otherwise), rad and m per unit.
        margin: ``μ`` at the critical point (N·m/rad for spring coordinates), ≈ 0 (``−μ`` is
            ``CurvePoint.force_control_margin``); at a rigid start, ``μ`` at the critical force.
        margin_rate: ``dμ/ds`` there (per m, or per rad); nan when not available.
        stiffness: Tangent stiffness ``dᵀK_C d`` (N/m, N·m/rad) at the critical point (eq. 30).
        estimate: Linearised critical load (N, N·m): the start of the search (nan without one).
        converged: The search met its tolerance and the point is a converged equilibrium
            (when False, the other fields describe the point of the branch reached, and
            ``kind`` is the rule applied there).
        iterations: Equilibrium evaluations of the search (estimate and kind check excluded).
        residuals: ``location``: relative change of one more Newton step on ``μ`` (of the
            force, or of the deflection where larger: ``|μ/μ'|·max(|k|, |F/s|)/|F|``; the
            bracket width where ``μ'`` is not available; 0 for an imperfect point, an extremum
            located by the tracer's search), ``margin``: ``|μ|/‖K_θ‖₂``, and the equilibrium's
            own residuals ``position`` (m), ``orientation`` (rad), ``statics`` (N·m) (a
            mechanism's also ``closure_position``, ``closure_orientation``,
            ``statics_prismatic``: :class:`~vjm_pin.solver.mechanism.MechanismResult`).
        equilibrium: The :class:`~vjm_pin.solver.EquilibriumResult` at the critical point.
        message: Why it did not converge ("" when it did).
    """

    force: float
    deflection: float
    direction: np.ndarray
    wrench: np.ndarray
    x: np.ndarray
    kind: str
    mode: np.ndarray
    margin: float
    margin_rate: float
    stiffness: float
    estimate: float
    converged: bool
    iterations: int
    residuals: dict
    equilibrium: EquilibriumResult = field(repr=False)
    message: str = ""

    def check(self, rtol: float = 1e-6) -> bool:
        """True when the search converged, the located force is within ``rtol`` (relative) of
        the root of ``μ`` and the equilibrium converged."""
        r = self.residuals.get("location", float("nan"))
        return bool(self.converged and getattr(self.equilibrium, "converged", False) and r <= rtol)


# --------------------------------------------------------------------------- pieces
def _basis(tr: _Tracer, b):
    """(Z, V): orthonormal bases of the null space of ``[J_θ J_q]`` (eq. 21, end held) and of
    ``P·[J_θ J_q]`` (force control along d), in (θ, q) order: one QR of the point kernel
    (``V = [Z, y₀/‖y₀‖]``), else SVDs."""
    if tr.kernel is not None:
        jac, _ = tr.kernel.matrices(b)
        f = tr.kernel.factor(jac)
        if f is not None:
            q, _, y0 = f
            m = tr.kernel.m
            z = q[:, m:]
            return z, np.hstack([z, (y0 / np.sqrt(y0 @ y0))[:, None]])
    z = null_space(b.J_theta, b.J_q)
    v = null_space(tr.P @ b.J_theta, tr.P @ b.J_q)
    return z, v


def _a_matrix(b) -> np.ndarray:
    """``H − diag(K_θ, 0)`` in (θ, q) order (the matrix of eq. 23 before reduction)."""
    nt = b.H_tt.shape[0]
    n = nt + b.H_qq.shape[0]
    a = np.empty((n, n))
    a[:nt, :nt] = b.H_tt - b.K_theta
    a[:nt, nt:] = b.H_tq
    a[nt:, :nt] = b.H_qt
    a[nt:, nt:] = b.H_qq
    return a


def _sym(m):
    return 0.5 * (m + m.T)


def _largest_eigenpair(m: np.ndarray, above: float, scale: float):
    """(λ_max, unit eigenvector) of the symmetric ``m`` whose eigenvalues are all below
    ``above`` (+ rounding): inverse iteration with the shift ``above + 1e-9·scale`` (one Cholesky
    of the positive definite ``σI − m``, LAPACK), accepted when the eigen-residual is below
    ``1e-9·scale``; else the full ``eigh``."""
    n = m.shape[0]
    sigma = above + 1e-9 * scale
    ch, info = _lapack.dpotrf(sigma * np.eye(n) - m, lower=0)
    if info == 0:
        y = np.full((n, 1), 1.0 / np.sqrt(n))
        y[::2] *= -0.5  # not orthogonal to the wanted vector (a generic start)
        for _ in range(6):
            y, info = _lapack.dpotrs(ch, y, lower=0)
            if info:
                break
            y /= np.linalg.norm(y)
            v = y[:, 0]
            mv = m @ v
            lam = float(v @ mv)
            if np.linalg.norm(mv - lam * v) <= 1e-9 * scale:
                return lam, v
    ev, u = np.linalg.eigh(m)
    return float(ev[-1]), u[:, -1]


def linearised_load(tr: _Tracer, p0) -> float | None:
    """Step 2 of the module docstring: the load increment ``ΔF`` (N, N·m) above ``p0`` at which
    the force-control matrix of eq. (23) becomes singular with the geometry of ``p0`` frozen
    (``H`` linear in the wrench), or None (no positive root, or ``μ₀ ≥ 0``)."""
    t = tr.tangent(p0)
    if t is None or not (np.isfinite(p0.k) and p0.k > 0):
        return None
    if _chain(tr):
        df = _linearised_chain(tr, p0, t[1] / p0.k)
        if df is not None:
            return df
    x0, w0 = p0.eq.x, p0.eq.wrench
    b0 = tr.blocks(x0, w0)
    _, v = _basis(tr, b0)
    if v.shape[1] == 0:
        return None
    a = -_sym(v.T @ _a_matrix(b0) @ v)
    b1 = tr.blocks(x0, t[1] / p0.k)  # the wrench per unit force along d (eq. 29)
    h1 = _a_matrix(b1)
    nt = b1.H_tt.shape[0]
    h1[:nt, :nt] += b1.K_theta  # H₁ alone
    bm = _sym(v.T @ h1 @ v)
    lo, info = _lapack.dpotrf(a, lower=1)
    if info:
        return None
    try:
        y = solve_triangular(lo, bm, lower=True)  # L⁻¹ B
        c = solve_triangular(lo, y.T.copy(), lower=True)  # L⁻¹ (L⁻¹ B)ᵀ = L⁻¹ B L⁻ᵀ
    except (ValueError, np.linalg.LinAlgError):
        return None
    n = c.shape[0]
    w, _, _, _, info = _lapack.dsyevr(_sym(c), compute_v=0, range="I", il=n, iu=n)
    if info:
        return None
    nu = float(w[0])
    return 1.0 / nu if nu > 0 else None


def _mode(tr: _Tracer, c, held: bool) -> np.ndarray:
    """The buckling mode (nq,) at the point ``c``: the critical eigenvector of eq. (23)
    (``held``) or of the force-control matrix (its eigenvalue is ``c.mu``, the largest)."""
    if isinstance(tr, MechanismTracer):
        return _mode_mechanism(tr, c, held)
    if _chain(tr):
        out = _mode_chain(tr, c, held)
        if out is not None:
            return out
    b = tr.blocks(c.eq.x, c.eq.wrench)
    z, v = _basis(tr, b)
    basis = z if held and z.shape[1] else v
    out = np.zeros_like(c.eq.x)
    if basis.shape[1] == 0:
        return out
    scale = spectral_norm(tr.vm.K_theta) if tr.vm.K_theta.size else 1.0
    red = _sym(basis.T @ _a_matrix(b) @ basis)
    _, u = _largest_eigenpair(red, max(c.mu, 0.0), scale)  # eq. 23's eigenvalues are ≤ μ
    w = basis @ u
    w /= np.linalg.norm(w)
    i = int(np.argmax(np.abs(w)))
    out[tr.free] = w if w[i] >= 0 else -w
    return out


# --------------------------------------------------------------------------- long chains
#: Newton steps of :func:`_linearised_chain` before it gives way to the dense eigenproblem.
LIN_MAX_NEWTON = 12
#: :func:`_linearised_chain` stops when its last Newton step, or the error its quadratic
#: convergence predicts for the next (``δₖ³/δₖ₋₁²``), is below this × the increment (relative).
LIN_RTOL = 1e-10
#: The power iteration's root is accepted when a Sturm count this far (relative) short of it
#: finds no negative eigenvalue: it is then located to this.
LIN_CERT = 1e-10


def _chain(tr) -> bool:
    """Whether the tracer's points are those of the compiled O(n) chain kernel (a long serial
    chain, ``VJM_PIN_JIT`` not 0): then the eigenproblems of steps 1–2 and of the mode are solved
    by the same algebra (:mod:`vjm_pin.solver.chain_eigen`) instead of dense ones."""
    return (
        not isinstance(tr, MechanismTracer)
        and tr.kernel is not None
        and tr.mask is not None
        and tr.kernel.n >= _chain_kernel.POINT_MIN_N
        and use_compiled(0)
    )


def _jacobian(tr, x) -> np.ndarray:
    """(6, nv) frame Jacobian (world axes) at ``x`` (the tracer's kinematics, shared state)."""
    return tr.kin.evaluate(x, hessian=False).jacobian


def _reference_chain(vm, solver, tr) -> EquilibriumResult | None:
    """:func:`~vjm_pin.analysis.curve._reference_equilibrium` (the unloaded reference as a
    converged equilibrium, or None with a preloaded spring) with its eq. (23) verdict by the chain
    kernel (its largest eigenvalue, certified; the spectrum on demand:
    :class:`~vjm_pin.solver.stability.DeferredStability`); the dense one where the chain algebra
    declines. Its eigenvector starts the point kernel's ``μ`` at the start (a warm start only)."""
    x = _reference_x(vm)
    if x is None:
        return None
    w = np.zeros(6)
    he = held_eigen(tr.kernel, tr.mask, _jacobian(tr, x))
    got = None
    if he is not None:
        got = he.smallest_definite(w) or he.smallest(w)
    if got is None:
        return _reference_equilibrium(vm, solver, tr.kin)
    remember(tr.kernel, got[1])
    largest = -got[0]  # the largest eigenvalue of eq. (23)
    kin = tr.kin

    def blocks():
        from vjm_pin.solver import blocks_at

        return blocks_at(vm, x, w, kin)

    return _reference_result(vm, solver, x, DeferredStability(largest < -tr.thr, largest, he.n - he.m, tr.thr, blocks))


def _linearised_chain(tr, p0, w1) -> float | None:
    """:func:`linearised_load` by the chain algebra: the smallest ``ΔF > 0`` where ``λ₁(ΔF)``,
    the smallest eigenvalue of ``Vᵀ sym(A − ΔF·B) V`` (``A = K − H₀``, ``B = H(w₁)``, ``w₁`` the
    wrench per unit force along d, eq. 29), reaches zero. ``λ₁`` is concave in ``ΔF`` (the
    smallest eigenvalue of an affine family) and positive at 0 (``μ₀ < 0``): the root is unique and
    the generalized Rayleigh quotient ``yᵀAy / yᵀBy`` of any ``y`` of the null space with
    ``yᵀBy > 0`` bounds it from above (it is the quotient's minimum, ``1/ν_max`` of the dense
    routine).

    First the pencil's power iteration (:meth:`~vjm_pin.solver.chain_eigen.HeldEigen.pencil`,
    from ``μ``'s eigenvector at ``p0``, the point kernel's) to a quotient ``t``; accepted when a
    Sturm count finds ``λ₁ > 0`` at ``(1 − LIN_CERT)·t`` (the root then lies in that interval).
    Else Newton on ``λ₁`` from the quotient of the last vector: ``dλ₁/dΔF = −yᵀBy`` at its unit
    eigenvector, so each step is the quotient of the eigenvector at the last ``ΔF`` (``λ₁`` and
    ``y`` certified by the chain kernel's Sturm counts), decreasing to the root (Newton on a
    concave function from above), to :data:`LIN_RTOL`. None (the dense eigenproblem decides) where
    the chain algebra declines, a vector does not load the mode (``yᵀBy ≤ 0``) or the steps do not
    settle in :data:`LIN_MAX_NEWTON`. The last vector starts the next eigenproblems of the point
    kernel and of the corrector (a warm start only)."""
    w0 = p0.eq.wrench
    he = held_eigen(tr.kernel, tr.mask, _jacobian(tr, p0.eq.x), tr.P)
    if he is None:
        return None
    y = remembered(tr.kernel, he.n)
    if y is None:
        got = he.smallest(w0)
        if got is None:
            return None
        y = got[1]
    w0 = np.asarray(w0, float)
    w1 = np.asarray(w1, float)
    # power iteration on the pencil: its quotient bounds the root from above; no eigenvalue
    # below zero just short of it (a Sturm count) bounds it from below, to LIN_CERT (relative)
    pen = he.pencil(w0, w1, y, cert=LIN_CERT)
    if pen is not None:
        y = pen[1]
        if pen[2]:
            _warm(tr, y)
            return float(pen[0])
    t, step = 0.0, None
    for _ in range(LIN_MAX_NEWTON):
        r0 = he.rayleigh(w0, y)
        g = he.rayleigh(w0 + w1, y) - r0  # −yᵀH(w₁)y
        if not (g < 0 and r0 > 0 and np.isfinite(r0 / g)):
            return None
        tn = -r0 / g
        dt = abs(tn - t)
        if dt <= LIN_RTOL * tn or (
            step is not None and dt < 0.1 * step and dt**3 <= LIN_RTOL * tn * step**2
        ):
            _warm(tr, y)
            return float(tn)
        got = he.smallest(w0 + tn * w1, y)
        if got is None:
            return None
        y, t, step = got[1], tn, dt
    return None


#: :func:`_refined_start` applies when the second increment is at most this × the first (a
#: nearly linear path before the critical point) ...
REFINE_RATIO = 1e-3
#: ... and aims this × its error model ``(ΔF₂/ΔF₁)²·ΔF₁`` short of the refined estimate (the
#: stable side), when that stays within ``rtol/2`` of it.
REFINE_MARGIN = 2.0


def _refined_start(tr, p0, df, rtol, max_deflection) -> float | None:
    """A first deflection to evaluate nearer the critical point than the linearised estimate
    (chain path): the same frozen-geometry problem again at the tangent prediction of the estimate
    (``x₀ + s₁·δx``, ``F₀ + ΔF₁·w₁``, eq. 29), whose increment ``ΔF₂`` corrects the estimate for
    the geometry change along the path. Used where the path is nearly linear there
    (``0 ≤ ΔF₂ ≤ REFINE_RATIO·ΔF₁``, the pencil's root certified by a Sturm count): the error of
    ``ΔF₁ + ΔF₂`` is then of order ``(ΔF₂/ΔF₁)²·ΔF₁``; the start aims :data:`REFINE_MARGIN` × that
    short of it, on the stable side (a Sturm count: the refined problem still definite there), when
    the whole stays within ``rtol/2`` (so that one verified equilibrium there may already meet the
    tolerance); else None (the estimate's deflection).
    Only a start: the search verifies the point as always (μ, its rate, the stopping rule)."""
    t = tr.tangent(p0)
    if t is None or not (np.isfinite(p0.k) and p0.k > 0 and df > 0):
        return None
    w1 = t[1] / p0.k
    s1 = p0.s + df / p0.k
    x1 = p0.eq.x + (s1 - p0.s) * t[0]
    he = held_eigen(tr.kernel, tr.mask, _jacobian(tr, x1), tr.P)
    y = remembered(tr.kernel, he.n) if he is not None else None
    if he is None or y is None:
        return None
    w1x = p0.eq.wrench + df * w1
    pen = he.pencil(w1x, w1, y, atol=1e-10 * df)
    if pen is None:
        return None
    df2 = pen[0]
    r = df2 / df
    if not 0 <= r <= REFINE_RATIO:
        return None
    err = r * r * df
    f = abs(p0.force + df + df2)
    if (REFINE_MARGIN + 1.0) * err > 0.5 * rtol * f:
        return None
    # the root of the refined problem lies above the start (a Sturm count there: still definite)
    if he.count_below(w1x + (df2 - REFINE_MARGIN * err) * w1) != 0:
        return None
    return s1 + (df2 - REFINE_MARGIN * err) / p0.k


def _warm(tr, y) -> None:
    """Start the next eigenproblems of the point kernel (``μ``) and of the corrector (eq. 23)
    from ``y`` (chain order; a warm start only: their results are certified as before)."""
    remember(tr.kernel, y)
    try:  # the corrector's kernel constants (EquilibriumSolver._corrector_context): its eq. (23)
        key = tr._corr[1][0]
    except (AttributeError, TypeError, IndexError, KeyError):
        return
    if isinstance(key, np.ndarray):
        remember(key, y)


def _mode_chain(tr, c, held: bool) -> np.ndarray | None:
    """:func:`_mode` by the chain algebra (the eigenvector of ``λ₁``, certified, started from the
    point kernel's last eigenvector; at a bifurcation the corrector's certified one when it is
    bit for bit the same problem: :func:`_corrector_verdict`), or None where it declines."""
    he = held_eigen(tr.kernel, tr.mask, _jacobian(tr, c.eq.x), None if held else tr.P)
    if he is None:
        return None
    wrench = np.asarray(c.eq.wrench, float)
    got = _corrector_verdict(tr, he, wrench) if held else None
    if got is None:
        got = he.smallest(wrench, remembered(tr.kernel, he.n))
    if got is None:
        return None
    w = he.free_vector(got[1])
    w /= np.linalg.norm(w)
    i = int(np.argmax(np.abs(w)))
    out = np.zeros_like(c.eq.x)
    out[tr.free] = w if w[i] >= 0 else -w
    return out


def _corrector_verdict(tr, he, wrench):
    """The eigenpair of eq. (23) the corrector certified at its last converged equilibrium
    (:func:`~vjm_pin.solver.chain_kernel.last_verdict`: its smallest eigenvalue by a Sturm count,
    the unit eigenvector to ``VEC_TOL_VERDICT`` per inverse iteration) when that is bit for bit
    the problem of ``he`` (every task row held) under ``wrench``: the critical point's own
    equilibrium, so the mode needs no eigenproblem of its own; else None."""
    try:
        key = tr._corr[1][0]
    except (AttributeError, TypeError, IndexError, KeyError):
        return None
    if not isinstance(key, np.ndarray) or he.m != len(tr.task):
        return None
    got = _chain_kernel.last_verdict(key, he._lay, he._jz, tr.kernel.task, wrench)
    if got is None or got[1].shape != (he.n,) or not np.all(np.isfinite(got[1])):
        return None
    return got


def _mode_mechanism(tr, c, held: bool) -> np.ndarray:
    """:func:`_mode` on the mechanism tracer: the top eigenvector of ``−ZᵀWZ`` (``W`` the
    Lagrangian Hessian of :class:`~vjm_pin.solver.mechanism.Linearization`), ``Z`` the null space
    of the closure rows and the held task rows (``held``: eq. 23 generalised, the control as
    run, the tracer's ``λ``: only ``d`` with ``free``) or of the closure rows and the held rows
    orthogonal to ``d`` (``μ``'s)."""
    lin = getattr(c, "lin", None)
    if lin is None:
        lin = tr.run.linearize(c.eq.x, tr.hrows, tr.wdead)
    rows = tr.held6 if held else tr.p_rows
    z, _ = _null_basis(
        np.vstack([lin.closure_jacobian, rows @ lin.task_jacobian]), tr.run.rank_rtol
    )
    out = np.zeros_like(c.eq.x)
    if z.shape[1] == 0:
        return out
    red = -(z.T @ lin.hessian @ z)
    u = np.linalg.eigh(_sym(red))[1][:, -1]
    w = z @ u
    w /= np.linalg.norm(w)
    i = int(np.argmax(np.abs(w)))
    out[tr.free] = w if w[i] >= 0 else -w
    return out


def linearised_load_mechanism(tr, p0) -> float | None:
    """Step 2 on the mechanism tracer: the increment ``ΔF`` (N, N·m) of a dead force along ``d``
    (the held axes orthogonal to ``d`` and the closures reacting, their multipliers by least
    squares from the stationarity as :meth:`~vjm_pin.solver.mechanism.MechanismSolver.linearize`
    takes them) at which ``μ`` of the frozen geometry of ``p0`` reaches zero. ``W`` is linear in
    that force (``W = W₀ + ΔF·W₁``, ``W₁`` by the difference of two linearisations at the same
    ``x``), so the root is ``1/ν_max`` of ``−ZᵀW₁Z y = ν ZᵀW₀Z y`` on the null space ``Z`` of
    ``[C; P J]``; None without a positive root (or with ``free``: nothing held but ``d``'s force)."""
    x, f0 = p0.eq.x, float(p0.force)
    try:
        lin0 = tr.force_control_lin(x, f0)
        lin1 = tr.force_control_lin(x, f0 + 1.0)
    except (ValueError, np.linalg.LinAlgError):
        return None
    c, j = lin0.closure_jacobian, lin0.task_jacobian
    z, _ = _null_basis(np.vstack([c, tr.p_rows @ j]), tr.run.rank_rtol)
    if z.shape[1] == 0:
        return None
    a = _sym(z.T @ lin0.hessian @ z)
    bm = -_sym(z.T @ (lin1.hessian - lin0.hessian) @ z)
    lo, info = _lapack.dpotrf(a, lower=1)
    if info:
        return None
    try:
        y = solve_triangular(lo, bm, lower=True)
        cm = solve_triangular(lo, y.T.copy(), lower=True)
    except (ValueError, np.linalg.LinAlgError):
        return None
    nu = float(np.linalg.eigvalsh(_sym(cm))[-1])
    return 1.0 / nu if nu > 0 and np.isfinite(nu) else None


def _critical_mechanism(vm, d, solver, max_deflection, rtol, max_iter, loads, gravity, free):
    """:func:`critical_load` on :class:`~vjm_pin.solver.mechanism.MechanismSolver` and the
    mechanism tracer of :func:`~vjm_pin.analysis.curve.trace_curve`
    (:class:`~vjm_pin.analysis.mechanism_curve.MechanismTracer`): loop closures, dead loads
    anywhere, gravity, ``free``."""
    if free:
        check_free_direction(d)
    solver = _mechanism_solver(vm, solver, loads, gravity, "model")
    rotation = bool(np.any(d[3:]))
    r0 = max_deflection or (1.0 if rotation else solver.length_scale)
    tr = MechanismTracer(vm, d, r0, solver, 1e3 * rtol, free)
    p0, rigid = tr.start()
    if free:
        check_free_start(vm, tr, p0)  # a mechanism with only d held: no path to search
    if rigid or not np.isfinite(p0.k):
        return _rigid(vm, tr, p0, d)
    p0, pre = _stable_start(
        vm,
        tr,
        p0,
        max_deflection,
        r0,
        "the start (the loaded equilibrium at zero deflection)"
        if loads or gravity is not None
        else "the unloaded equilibrium",
    )
    # the smaller of the frozen-geometry estimate and one Newton step on μ from the start (the
    # least-squares reactions of the former overestimate where the load shares by compliance:
    # 1.8× on the two-column robot; the latter where μ curves: 2.6× on Model C S)
    est = [linearised_load_mechanism(tr, p0)]
    g = tr.dmu(p0)
    if np.isfinite(g) and g > 0 and p0.k > 0:
        est.append(-p0.mu / g * p0.k)
    est = [e for e in est if e is not None and np.isfinite(e) and e > 0]
    df = min(est) if est and p0.k > 0 else None  # a falling start: no estimate (as serial)
    return _search_from(vm, tr, p0, df, max_deflection, r0, rtol, max_iter, pre=pre)


def _scan(tr: _Tracer, lo, q, depth: int = 0):
    """The first event of the followed branch over ``[lo, q]`` (``lo.mu < 0``), by the tracer's
    rule: ``("cross", a, b)`` (μ crosses zero from below in ``[a, b]``), ``("max", a, b)`` (an
    interior maximum of μ < 0 to be checked for an imperfect bifurcation) or None. When
    ``q.mu ≥ 0`` the cubic model of μ on the bracket is sampled at its interior maximum if that
    comes near zero, so that an earlier crossing cannot hide (as
    :meth:`~vjm_pin.analysis.curve._Tracer.first_event` does for two negative ends)."""
    if q.mu < 0:
        return tr.first_event(lo, q)
    if depth >= DIP_DEPTH or q.s - lo.s <= 4 * tr.hmin:
        return ("cross", lo, q)
    g0, g1 = tr.dmu(lo), tr.dmu(q)
    if not (np.isfinite(g0) and np.isfinite(g1)):
        return ("cross", lo, q)
    ext = _hermite_extremum(lo.s, lo.mu, g0, q.s, q.mu, g1, maximum=True)
    if ext is None or ext[1] < -0.5 * ext[2]:
        return ("cross", lo, q)
    m = tr.reach(lo, lo.s + ext[0] * (q.s - lo.s))
    if m is None:
        return ("cross", lo, q)
    if m.mu >= 0:
        return _scan(tr, lo, m, depth + 1)
    return tr.first_event(lo, m) or _scan(tr, m, q, depth + 1)


def _predicted(p) -> bool:
    """Whether the point ``p`` is a tangent prediction (:meth:`_Tracer.reach_or_predict`), not a
    converged equilibrium."""
    return getattr(p.eq, "path", "") == "tangent-prediction"


def _newton_point(p, g, lo, hi, flo, fhi) -> float:
    """The next trial deflection: Newton on μ from ``p`` with the rate ``g`` (``dμ/ds``) when it
    stays inside the bracket ``[lo, hi]``, else the regula falsi point of the bracket with the
    (Illinois-weighted) end values ``flo < 0 ≤ fhi``; without a bracket (``hi`` None) the Newton
    point when it lies ahead of ``lo``, else nan (the caller steps on)."""
    s = p.s - p.mu / g if g is not None and np.isfinite(g) and g != 0 else float("nan")
    if hi is None:
        return s if np.isfinite(s) and s > lo.s and g > 0 else float("nan")
    if np.isfinite(s) and lo.s < s < hi.s:
        return s
    return lo.s + flo / (flo - fhi) * (hi.s - lo.s)


class _Search:
    """The bracketing Newton search of step 3 (module docstring) on one tracer."""

    def __init__(self, tr: _Tracer, rtol: float, max_iter: int, s_max: float):
        self.tr, self.rtol, self.max_iter, self.s_max = tr, rtol, max_iter, s_max
        self.n = 0
        self.message = ""
        self.location = float("nan")  # the relative force tolerance met (done)
        self.stable_to_end = False  # the branch stayed stable under force control up to s_max
        self.path_end = False  # the march met a deflection past which the path has no equilibrium
        self.best = None  # the point of the branch nearest to the critical point so far
        self.g_last = float("nan")  # the last available dμ/ds (the kernel may decline at a point)

    def rate(self, p) -> float:
        """``dμ/ds`` at ``p``, or the last one available (at the critical point itself the
        matrix of eq. 28 may be singular and the rate not defined there; it varies slowly)."""
        g = self.tr.dmu(p)
        if np.isfinite(g) and g != 0:
            self.g_last = g
            return g
        return self.g_last

    def evaluate(self, base, s):
        """The branch of ``base`` at ``s``: a converged equilibrium, or (within a fine step of a
        converged ``base`` only) the tangent prediction where the corrector fails; never a
        prediction from a prediction (past the end of the reach such chains are phantoms)."""
        self.n += 1
        return (
            self.tr.reach_or_predict(base, s)
            if abs(s - base.s) <= FINE_STEP * self.s_max and not _predicted(base)
            else self.tr.reach(base, s)
        )

    def consistent(self, lo, m) -> bool:
        """Whether ``m`` (``μ ≥ 0``, reached from ``lo`` with ``μ < 0``) is trusted to lie on
        ``lo``'s branch: the tracer accepts a loss of stability only over a fine step
        (:data:`~vjm_pin.analysis.curve.FINE_STEP` of the range; a longer step may have jumped
        across a knee onto a neighbouring branch, next to an imperfect bifurcation, where the
        straight branch the predictor follows crosses zero), so ``m`` is trusted when that close
        to ``lo``, and its force continues ``lo``'s (:meth:`continuous`)."""
        return m.s - lo.s <= FINE_STEP * self.s_max and self.continuous(lo, m)

    @staticmethod
    def continuous(lo, m) -> bool:
        """Whether the force at ``m`` continues ``lo``'s: within ``JUMP_FACTOR`` × the larger
        tangent stiffness times the distance (and rounding) of it. A point reached over a
        long step from the far side of a knee can lie on a neighbouring branch (the straight one,
        unstable, of an imperfect bifurcation; the Orthoglide's coupled legs pushed down): as the
        bracket narrows its force stays apart from ``lo``'s, so the bracket holds no crossing of
        ``lo``'s branch however narrow it gets."""
        ds = abs(m.s - lo.s)
        ks = [abs(k) for k in (lo.k, m.k) if np.isfinite(k)]
        k = max(ks) if ks else float("inf")
        tol = JUMP_FACTOR * k * ds + 1e-9 * max(abs(lo.force), abs(m.force))
        return bool(abs(m.force - lo.force) <= tol)

    def done(self, p, lo, hi, hi_ok: bool = True) -> bool:
        """The tracer's stopping rule (the bracket, or one more Newton step, moves the force by
        at most rtol relative), and the deflection to rtol relative as well (at a limit point
        the force is flat: ``k → 0``); a bracket end ``hi`` not trusted to lie on the branch
        (``hi_ok`` False, :meth:`consistent`) ends nothing."""
        if p is hi and not hi_ok:
            return False
        f = max(abs(p.force), 1e-300)
        k = max(abs(p.k) if np.isfinite(p.k) else 0.0, f / max(abs(p.s), 1e-300))
        g = self.rate(p)
        if np.isfinite(g) and abs(p.mu / g) * k <= self.rtol * f:
            self.location = abs(p.mu / g) * k / f
            return True
        if hi is not None and hi_ok:
            kk = max(abs(lo.k), abs(hi.k)) if np.isfinite(lo.k) and np.isfinite(hi.k) else 0.0
            kk = max(kk, f / max(abs(p.s), 1e-300))
            w = hi.s - lo.s
            if w * kk <= self.rtol * f or w <= 1e-13 * self.s_max:
                self.location = w * kk / f
                return True
        return False

    def bracket(self, lo, s):
        """March from ``lo`` (μ < 0): returns the first event ``(kind, a, b)`` or None."""
        tr = self.tr
        s_fail = float("inf")  # the nearest deflection ahead that could not be reached
        while self.n < self.max_iter:
            s = min(s, self.s_max)
            if s >= s_fail:  # no further than halfway to a deflection already out of reach
                s = lo.s + 0.5 * (s_fail - lo.s)
            if s_fail - lo.s <= max(tr.hmin, 1e-9 * abs(lo.s)):
                self.message = (
                    f"the loading path could not be continued past deflection {lo.s:.6g} "
                    "(no equilibrium beyond it: the end of the reach along the direction?)"
                )
                self.path_end = True
                self.best = lo if lo.s > 0 else self.best
                return None
            q = self.evaluate(lo, s)
            if q is None:
                s_fail = s
                s = lo.s + 0.5 * (s - lo.s)
                continue
            if np.isfinite(s_fail) and _predicted(q):
                # short of a deflection out of reach the corrector failed again and only the
                # tangent prediction is left (not an equilibrium; past the end of the reach it
                # is a phantom): the path is not marched along predictions
                s_fail = s
                s = lo.s + 0.5 * (s - lo.s)
                continue
            ev = _scan(tr, lo, q)
            if ev is not None:
                return ev
            if self.done(q, lo, None):  # the root within rtol just past q (μ(q) < 0, Newton)
                return ("near", lo, q)
            tr.seg_margin = max(tr.seg_margin, -lo.mu)
            self.best = q
            if q.s >= self.s_max:
                self.stable_to_end = True
                return None
            lo = q
            nxt = _newton_point(lo, self.rate(lo), lo, None, lo.mu, None)
            # Newton ahead, at most quadrupling the deflection (doubling without a Newton point)
            s = nxt if np.isfinite(nxt) else 2.0 * lo.s
            s = min(max(s, lo.s + tr.hmin), lo.s + 4.0 * max(lo.s, tr.hmin))
        self.message = f"the search stopped after {self.max_iter} equilibrium evaluations (no bracket of a critical point)"
        return None

    def root(self, lo, hi):
        """Safeguarded Newton on μ in the bracket ``[lo, hi]`` (``lo.mu < 0 ≤ hi.mu``): the point
        at the root (with a message when the budget ran out first), an earlier event
        ``(kind, a, b)`` found inside the bracket, or None (no equilibrium; message set)."""
        tr = self.tr
        hi_ok = self.consistent(lo, hi)
        p = hi if abs(hi.mu) < abs(lo.mu) and hi_ok else lo
        if self.done(p, lo, hi, hi_ok):
            return p
        flo, fhi, side, rejected, stalled, prev = lo.mu, hi.mu, 0, False, False, None
        while self.n < self.max_iter:
            if hi_ok:
                s = _newton_point(p, self.rate(p), lo, hi, flo, fhi)
                base = lo if s - lo.s <= hi.s - s else hi
            else:
                # hi may lie on another branch: approach the root from lo alone (the nearer of
                # Newton from lo and the secant point), aiming half a fine step short of it until
                # a fine step remains; halving the bracket after a step that was not trusted
                fine = FINE_STEP * self.s_max
                s = lo.s + lo.mu / (lo.mu - hi.mu) * (hi.s - lo.s)
                sn = _newton_point(lo, self.rate(lo), lo, None, lo.mu, None)
                if np.isfinite(sn):
                    s = min(s, sn)
                if rejected:
                    s = 0.5 * (lo.s + hi.s)
                elif stalled:
                    s = _past_peak(lo, self.rate(lo), prev, self.rate(prev), hi, self.tr.hmin)
                elif s - lo.s > fine:
                    s = max(0.5 * (lo.s + s), s - 0.5 * fine)
                base = lo
            m = self.evaluate(base, s)
            if m is None:
                self.message = (
                    f"no equilibrium on the branch at deflection {s:.6g} inside the bracket"
                )
                return None
            if m.mu < 0:
                ev = tr.first_event(lo, m) if m.s > lo.s else None
                if ev is not None:  # an earlier event between lo and m (a crossing or a maximum)
                    return ev
                # without a trusted hi, a margin that fell by less than half (μ flattening
                # below zero: an imperfect maximum ahead) steps just past the maximum next
                stalled, rejected = not hi_ok and m.mu < 0.5 * lo.mu, False
                prev, lo, flo = lo, m, m.mu
                fhi, side = (0.5 * fhi if side == -1 else fhi), -1  # Illinois: no stalled end
                hi_ok = hi_ok or self.consistent(lo, hi)
                if not hi_ok and hi.s - lo.s <= FINE_STEP * self.s_max:
                    # hi is a fine step away and its force does not continue lo's: it lies on
                    # another branch; the march goes on from lo past it
                    self.best = m
                    return ("resume", lo, hi)
            else:
                ok = hi_ok if base is hi else self.consistent(lo, m)
                hi, fhi, hi_ok, rejected, stalled = m, m.mu, ok, not ok, False
                flo, side = (0.5 * flo if side == 1 else flo), 1
            p = self.best = m
            if self.done(m, lo, hi, hi_ok):
                return m
        self.message = f"the critical point was not located to rtol={self.rtol:g} in {self.max_iter} evaluations"
        return p


def _past_peak(lo, g_lo, prev, g_prev, hi, hmin) -> float:
    """The next trial when ``μ`` stalls below zero between ``prev`` and ``lo`` (an imperfect
    maximum ahead): twice the distance from ``lo`` to the maximum of ``μ`` where its rate,
    linear between the two points, vanishes (so that the interval from ``lo`` holds the maximum
    and stays short); the bracket's midpoint without such an estimate, or past it."""
    mid = 0.5 * (lo.s + hi.s)
    if prev is None or not (np.isfinite(g_lo) and np.isfinite(g_prev)) or not g_prev > g_lo > 0:
        return mid
    peak = lo.s + g_lo * (lo.s - prev.s) / (g_prev - g_lo)
    return min(max(lo.s + 2.0 * (peak - lo.s), lo.s + hmin), mid)


def _start(vm, tr: _Tracer, solver: EquilibriumSolver, d: np.ndarray):
    """The first point of ``trace_curve``'s path: the unloaded reference when the chain is rigid
    along ``d`` there (:func:`~vjm_pin.analysis.curve._unloaded`), else ``solver.solve(0)``.
    Where the reference is a stable unloaded equilibrium (no spring preload; eq. 23 negative
    definite) ``solver.solve(0)`` returns it after 0 iterations, so it is taken directly (the
    rigidity test of ``_unloaded`` is then ``k = dᵀK_C d`` infinite at that point)."""
    if _chain(tr):
        probe = _reference_chain(vm, solver, tr)
    else:
        probe = _reference_equilibrium(vm, solver, tr.kin)
    if probe is not None:
        p0 = tr.point(probe, 0.0)
        if np.isinf(p0.k) or (np.isfinite(p0.k) and p0.lam < -tr.thr):
            return p0
    probe = _unloaded(vm, solver, d, solver.kin)
    return tr.point(probe if probe is not None else solver.solve(0.0 * d), 0.0)


# --------------------------------------------------------------------------- public
@one_blas_thread
def critical_load(
    vm: VjmModel,
    direction,
    *,
    solver: EquilibriumSolver | None = None,
    max_deflection: float | None = None,
    rtol: float = RTOL,
    max_iter: int = MAX_ITER,
    loads: Sequence[Load] = (),
    gravity=None,
    free: bool = False,
) -> CriticalLoad:
    """The first critical load of ``vm`` along ``direction`` (module docstring), directly.

    Args:
        vm: The model: a serial chain, or any model ``trace_curve`` takes (loop closures,
            parallel robots).
        direction: (3,) or (6,) direction of the end deflection, world axes
            (:func:`~vjm_pin.model.task.task_vector`); normalised; in the task components, a
            pure translation or rotation.
        solver: The :class:`~vjm_pin.solver.EquilibriumSolver` (serial chains) or
            :class:`~vjm_pin.solver.mechanism.MechanismSolver` (with its own dead loads and
            gravity) to use; default a new one, as ``trace_curve`` picks it.
        max_deflection: Search the path up to this deflection (m or rad); default
            :data:`RANGE_FACTOR` × the linearised estimate (or :data:`RANGE_NO_ESTIMATE` × the
            chain length, 1 rad along a rotation, without one).
        rtol: Relative force tolerance of the location (default 1e-7, as ``trace_curve``).
        max_iter: Largest number of equilibrium evaluations of the search.
        loads: Dead loads anywhere (:class:`~vjm_pin.kinematics.dead_loads.Load`, world axes),
            constant along the path, as ``trace_curve``'s.
        gravity: (3,) gravity (m/s²) for the link weights, or None.
        free: Hold the end only along ``d`` (a translation): the other task components carry no
            load (the free-platform path of a parallel robot), as ``trace_curve``'s.

    Returns:
        The :class:`CriticalLoad`; ``converged`` False (with ``message``) when the search did
        not meet its tolerance (a bracket not resolved, or the budget spent before a bracket):
        the best point found is returned, not hidden, and is not a located critical point.

    Raises:
        InputError: bad direction or options, a solver of the wrong kind or for another model,
            dead loads given both here and to the solver, ``free`` along a rotation.
        FreeMechanism: with ``free`` the start is a mechanism (a motion of zero stiffness with
            only ``d`` held, :func:`~vjm_pin.analysis.curve.check_free_start`).
        NoCriticalPoint: no critical point was bracketed: the followed branch stays stable
            under a force along the direction up to ``max_deflection``, or up to where the
            loading path cannot be continued (the end of the reach); the start is already
            unstable under that force (beyond the rounding band of :func:`margin_threshold`), or
            neutral (zero stiffness) and the branch does not become stable (:func:`_stable_start`).
        NoEquilibrium: no unloaded equilibrium to start from.
    """
    if not (isinstance(rtol, (int, float)) and 1e-13 <= rtol <= 0.1):
        raise InputError(f"rtol must be a number from 1e-13 to 0.1, got {rtol!r}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise InputError(f"max_iter must be a positive integer, got {max_iter!r}")
    if max_deflection is not None and not (np.isfinite(max_deflection) and max_deflection > 0):
        raise InputError(
            f"max_deflection must be a positive number (m or rad), got {max_deflection}"
        )
    d = _direction(vm, task_vector(direction, vm.task, "direction", "m or rad"))
    if (
        free
        or loads
        or gravity is not None
        or getattr(vm, "closures", ())
        or isinstance(solver, MechanismSolver)
    ):
        # the models trace_curve runs on the mechanism solver (the same dispatch)
        return _critical_mechanism(
            vm, d, solver, max_deflection, rtol, int(max_iter), loads, gravity, bool(free)
        )
    if solver is None:
        solver = EquilibriumSolver(vm)
    elif not isinstance(solver, EquilibriumSolver):
        raise InputError("critical_load needs an EquilibriumSolver or a MechanismSolver as solver")
    if solver.vm is not vm:
        raise InputError("the solver was built for another model")
    rotation = bool(np.any(d[3:]))
    # the tracer's range only sets its smallest sub-step (1e-10 of it); the search range
    # (s_max, below) sets the offsets of the kind test and the fine-step rule
    r0 = max_deflection or (1.0 if rotation else solver.length_scale)
    tr = _Tracer(vm, d, r0, solver, 1e3 * rtol)
    p0 = _start(vm, tr, solver, d)
    if not np.isfinite(p0.k):
        return _rigid(vm, tr, p0, d)
    p0, pre = _stable_start(vm, tr, p0, max_deflection, r0, "the unloaded equilibrium")
    df = linearised_load(tr, p0)
    start = (
        _refined_start(tr, p0, df, rtol, max_deflection) if df is not None and _chain(tr) else None
    )
    return _search_from(vm, tr, p0, df, max_deflection, r0, rtol, max_iter, start, pre=pre)


def margin_threshold(vm, tr) -> float:
    """The rounding band of the force-control margin ``μ``: ``STABILITY_TOL·‖K_θ‖₂`` (the serial
    tracer's ``thr``, the mechanism solver's ``threshold``); ``|μ|`` within it is zero (a neutral
    direction), not a verdict."""
    scale = getattr(tr, "k_norm", None)
    if scale is None:
        scale = spectral_norm(vm.K_theta) if vm.K_theta.size else 1.0
    return max(STABILITY_TOL * scale, float(getattr(tr, "verdict_thr", 0.0) or 0.0))


#: From a neutral start (``|μ| ≤`` :func:`margin_threshold`) the first step along the path is
#: this fraction of the search range, doubled until the margin leaves the rounding band.
NEUTRAL_FIRST = 1e-3
#: ... in at most this many equilibrium evaluations.
NEUTRAL_EVALS = 20


def _stable_start(vm, tr, p0, max_deflection, r0, what: str):
    """``(p, n)``: the point the search starts from and the equilibria evaluated to find it.

    ``p0`` itself when its force-control margin is clearly stable (``μ < −thr``,
    :func:`margin_threshold`). A margin within the rounding band of zero is a neutral start (zero
    stiffness along ``d`` there, e.g. a mechanism direction that stiffens with the deflection:
    Model B Π along y): the followed branch is stepped along from it (as ``trace_curve`` goes on
    from it) to its first point with a clearly stable margin, where the search starts (and its
    linearised estimate is taken). Raises :class:`~vjm_pin.exceptions.NoCriticalPoint` when the
    start is clearly unstable (``μ > thr``), or neutral and the branch does not become stable."""
    thr = margin_threshold(vm, tr)
    unit = "rad" if np.any(tr.d[3:]) else "m"
    if p0.mu < -thr:
        return p0, 0
    if p0.mu > thr:
        raise NoCriticalPoint(
            f"{what} is already unstable under a force along the direction (force-control "
            f"margin {-p0.mu:.3g}, beyond the rounding threshold {thr:.2g}): no critical point to "
            "approach",
            max_deflection=0.0,
        )
    neutral = (
        f"{what} is neutral along the direction (zero stiffness: force-control margin "
        f"{-p0.mu:.2g}, zero to within the rounding threshold {thr:.2g})"
    )
    s_range = float(max_deflection) if max_deflection else RANGE_NO_ESTIMATE * r0
    s, cur, n = NEUTRAL_FIRST * s_range, p0, 0
    while n < NEUTRAL_EVALS:
        s = min(s, s_range)
        q = tr.reach(cur, s)
        n += 1
        if q is None:
            s = cur.s + 0.5 * (s - cur.s)
            continue
        if q.mu < -thr:
            return q, n
        if q.mu > thr:
            raise NoCriticalPoint(
                f"no critical point: {neutral}, and the followed branch is unstable under a force "
                f"along it from there (force-control margin {-q.mu:.3g} at deflection "
                f"{q.s:.6g} {unit})",
                max_deflection=q.s,
            )
        cur = q
        if cur.s >= s_range:
            raise NoCriticalPoint(
                f"no critical point: {neutral}, and stays neutral up to deflection "
                f"{cur.s:.6g} {unit}",
                max_deflection=cur.s,
            )
        s = 2.0 * s
    raise NoCriticalPoint(
        f"no critical point located: {neutral}, and the loading path could not be continued "
        f"past deflection {cur.s:.6g} {unit}",
        max_deflection=cur.s,
    )


def _search_from(
    vm, tr, p0, df, max_deflection, r0, rtol, max_iter, start=None, pre: int = 0
) -> CriticalLoad:
    """Steps 3–4 of the module docstring from the start ``p0`` (``μ < 0``, finite stiffness)
    with the load increment ``df`` of the linearised estimate (or None): serial and mechanism
    tracers alike. ``start``: the first deflection to evaluate instead of the estimate's
    (:func:`_refined_start`); the search range is the estimate's either way. ``pre``: equilibria
    already evaluated to reach ``p0`` (:func:`_stable_start`), counted in ``iterations``.

    Without ``max_deflection`` an estimate beyond :data:`ESTIMATE_MAX` × the chain's length (or
    rad) is discarded: the frozen-geometry pencil's eigenvalue is then rounding (nothing along
    the path compresses the chain: a portal frame pushed sideways), not an estimate.

    No critical point is reported (:class:`~vjm_pin.exceptions.NoCriticalPoint`) unless one was
    bracketed: the branch stable up to the end of the range, or up to where the path could not
    be continued or the evaluations ran out (each message says which, and the deflection
    reached). A bracket whose root was not located to ``rtol`` returns the nearest point with
    ``converged`` False."""
    rotation = bool(np.any(tr.d[3:]))
    unit = "rad" if rotation else "m"
    s_est = p0.s + df / p0.k if df is not None else float("nan")
    if max_deflection is None and np.isfinite(s_est) and s_est > ESTIMATE_MAX * r0:
        df, s_est = None, float("nan")
    if max_deflection is not None:
        s_max = float(max_deflection)
    else:
        s_max = RANGE_FACTOR * s_est if np.isfinite(s_est) else RANGE_NO_ESTIMATE * r0
    search = _Search(tr, rtol, int(max_iter) + pre, s_max)
    search.n = pre
    tr.seg_margin = max(0.0, -p0.mu)
    tr.dmu(p0)
    lo, ev, c, bracketed = p0, None, None, False
    s = s_est if np.isfinite(s_est) and 0 < s_est else s_max / 16
    if start is not None and p0.s < start < s_max:
        s = start
    if s <= p0.s:  # a start stepped along the path (_stable_start): ahead of it
        s = min(max(2.0 * p0.s, p0.s + s_max / 16), s_max)
    while search.n < search.max_iter:
        ev = search.bracket(lo, s) if ev is None else ev
        if ev is None:
            break
        bracketed = True
        kind, a, b = ev
        if kind == "near":
            c = b
            break
        if kind == "max":
            c, _ = tr.locate_max(a, b)
            if 0 < -c.mu <= IMPERFECT_RATIO * max(tr.seg_margin, -a.mu):
                return _result(vm, tr, c, "imperfect", df, p0, search, True)
            tr.seg_margin = max(tr.seg_margin, -a.mu, -b.mu)
            lo, ev, c, s, bracketed = b, None, None, b.s + (b.s - a.s), False  # march on
            continue
        c = search.root(a, b)
        if isinstance(c, tuple) and c[0] == "resume":  # the bracket's end on another branch
            lo, ev, s, bracketed = c[1], None, c[2].s + (c[2].s - c[1].s), False
            c = None
            continue
        if isinstance(c, tuple):  # an earlier event found inside the bracket
            ev = c
            continue
        break
    if c is None:
        if search.stable_to_end:
            raise NoCriticalPoint(
                "no critical point: the followed branch stays stable under a force along the "
                f"direction up to deflection {s_max:.6g} {unit} (the end of the search range)",
                max_deflection=s_max,
            )
        far = search.best if search.best is not None else p0
        if not bracketed:
            stable = (
                "no critical point found: the followed branch stays stable under a force along "
                f"the direction up to deflection {far.s:.6g} {unit} (force {far.force:.6g} "
                f"{'N·m' if rotation else 'N'}), of the {s_max:.6g} {unit} searched"
            )
            if search.path_end or search.best is None:
                raise NoCriticalPoint(
                    f"{stable}: {search.message or 'the search stopped'}", max_deflection=far.s
                )
            # the budget ran out first: the last point reached, flagged (not a critical point)
            search.message = f"{stable}, where {search.message}"
        # the nearest point reached is reported with the reason (converged False)
        return _result(
            vm, tr, search.best, _kind(tr, search.best, s_max, search.g_last), df, p0, search, False
        )
    ok = not search.message
    return _result(vm, tr, c, _kind(tr, c, s_max, search.g_last), df, p0, search, ok)


def _kind(tr: _Tracer, c, s_max: float, g_last: float = float("nan")) -> str:
    """The tracer's rule (:meth:`_Tracer.finish`): ``"bifurcation"`` when the continued branch
    at ``s_c + ε`` has lost eq. (23) (its largest eigenvalue ``λ ≥ −thr``), else ``"limit"``.

    ``λ(s_c + ε)`` is taken to first order, ``λ(s_c) + ε·|dμ/ds|``: where the continued branch
    loses eq. (23) at the critical point, eq. (23)'s critical eigenvector is ``μ``'s (it keeps
    the end fixed) and ``λ`` moves with ``μ``. No equilibrium is solved: next to a pitchfork the
    corrector started at the singular point itself may land on the bent branch (which is stable),
    while the tracer reaches ``s_c + ε`` from the far end of its bracket. Where ``dμ/ds`` is not
    available at ``c`` the last rate of the search (``g_last``) is used, and without one the
    tracer's own continuation decides."""
    eps = max(OFFSET_REL * abs(c.s), OFFSET_ABS * s_max)  # the tracer's offset for a curve to s_max
    g = tr.dmu(c)
    if not np.isfinite(g):
        g = g_last
    if not np.isfinite(g):
        plus = tr.reach_or_predict(c, c.s + eps)
        return "bifurcation" if plus is None or plus.lam >= -tr.thr else "limit"
    return "bifurcation" if c.lam >= -max(tr.thr, eps * abs(g)) else "limit"


def _result(vm, tr, c, kind, df, p0, search, ok) -> CriticalLoad:
    eq = c.eq
    msg = search.message
    if getattr(eq, "path", "") == "tangent-prediction":  # re-solve the predicted point
        if isinstance(tr, MechanismTracer):
            sol = tr.solve(c.s, eq.x, tr.cont)
            sol = sol if sol.converged else None
        else:
            sol = tr.cont._solve_local(c.s * tr.d, eq.x)
        if sol is not None:
            c = tr.point(sol, c.s)
            eq = c.eq
        else:
            ok, msg = (
                False,
                msg or "the critical point is a tangent prediction (no converged equilibrium)",
            )
    g = tr.dmu(c)
    f = max(abs(c.force), 1e-300)
    k = max(abs(c.k) if np.isfinite(c.k) else 0.0, f / max(abs(c.s), 1e-300))
    g_loc = g if np.isfinite(g) and g != 0 else search.g_last
    loc = abs(c.mu / g_loc) * k / f if np.isfinite(g_loc) else search.location
    if kind == "imperfect":
        loc = 0.0  # an extremum of μ, located by the tracer's own search (locate_max)
    scale = getattr(tr, "k_norm", None)  # ‖K_θ‖₂ as the tracer took it
    if scale is None:
        scale = spectral_norm(vm.K_theta) if vm.K_theta.size else 1.0
    res = {
        "location": float(loc),
        "margin": float(abs(c.mu) / scale),
        **{k_: float(v) for k_, v in eq.residuals.items()},
    }
    return CriticalLoad(
        force=float(c.force),
        deflection=float(c.s),
        direction=tr.d.copy(),
        wrench=np.asarray(eq.wrench, float).copy(),
        x=np.asarray(eq.x, float).copy(),
        kind=kind,
        mode=_mode(tr, c, kind == "bifurcation"),
        margin=float(c.mu),
        margin_rate=float(g),
        stiffness=float(c.k),
        estimate=float(p0.force + df) if df is not None else float("nan"),
        converged=bool(ok and eq.converged),
        iterations=int(search.n),
        residuals=res,
        equilibrium=eq,
        message=""
        if ok and eq.converged
        else (msg or "the equilibrium at the critical point did not converge"),
    )


def _rigid(vm, tr, p0, d) -> CriticalLoad:
    """A start rigid along ``d``: the tracer's search along the force at the unloaded
    configuration (deflection 0; always a bifurcation, as in ``trace_curve``)."""
    found = tr.rigid_start(p0) if p0.mu < 0 else None
    if found is None:
        what = (
            "the stiffness along the direction is undefined at the start (its loaded stiffness "
            "matrix is singular there)"
            if np.isnan(p0.k)
            else "the chain is rigid along the direction at the unloaded configuration"
        )
        if np.isnan(p0.k):
            # no path at all when not even a short step along d has an equilibrium (Model A S
            # along y: x held, a straight chain of rigid links cannot move sideways)
            h = FINE_STEP * tr.range
            if tr.reach(p0, h) is None:
                raise NoCriticalPoint(
                    f"no critical point: {what}, and the end cannot be moved along the direction "
                    f"from it (no equilibrium at deflection {h:.3g} "
                    f"{'rad' if np.any(d[3:]) else 'm'}: out of reach with the other task "
                    "components held)",
                    max_deflection=0.0,
                )
        raise NoCriticalPoint(
            f"no critical point: {what} and no force along it makes it unstable", max_deflection=0.0
        )
    f, u = found
    eq = u.eq
    if isinstance(tr, MechanismTracer):
        mu = float(u.mu)  # μ of the loaded reference (force_control_lin at f)
    else:
        b = tr.blocks(eq.x, eq.wrench)
        mu = _max_eig(check_stability_held(b, tr.P))
    scale = spectral_norm(vm.K_theta) if vm.K_theta.size else 1.0

    res = {
        "location": 0.0,
        "margin": float(abs(mu) / scale),
        **{k: float(v) for k, v in eq.residuals.items()},
    }
    return CriticalLoad(
        force=float(f),
        deflection=0.0,
        direction=d.copy(),
        wrench=np.asarray(eq.wrench, float).copy(),
        x=np.asarray(eq.x, float).copy(),
        kind="bifurcation",
        mode=_mode(tr, u, True),
        margin=float(mu),
        margin_rate=float("nan"),
        stiffness=float(p0.k),
        estimate=float("nan"),
        converged=True,
        iterations=0,
        residuals=res,
        equilibrium=eq,
    )
