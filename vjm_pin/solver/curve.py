"""Force–deflection curves and buckling detection (paper §6.1, Fig. 4–6).

The end of the chain is moved step by step along a fixed direction ``d`` (deflection
``s·d``, ``s`` in m for a translation, rad for a rotation); at every step the loaded
equilibrium of eq. (5) is solved by continuation from the previous one
(:class:`~vjm_pin.solver.EquilibriumSolver` warm start; its perturbed restarts leave an
equilibrium that has become unstable, so the *stable* branch is followed), its stability
is checked (eq. 23) and the tangent stiffness along ``d`` is ``dᵀ K_C d`` with ``K_C`` of
eq. (30). From a stable point the next one is first tried from the tangent predictor
(eq. 29, ``δq = K_q δt``, ``δθ = K_θ δt``) with plain Newton steps only; when that does not
give a stable equilibrium the point is solved from the previous equilibrium as above.

Critical point rule (buckling)
------------------------------
Between two consecutive points ``a`` (stable) and ``b`` there is a critical point when

1. ``b`` is unstable (the followed equilibrium lost stability and no stable one was
   found), or
2. the tangent stiffness drops sharply: ``k_a > 0`` and ``k_b < DROP_RATIO · k_a`` with
   :data:`DROP_RATIO` = 0.5 (the followed stable equilibrium jumped to another branch:
   bifurcation, e.g. the straight, axially stiff column of Models B/C turning into the
   bent one; ``k_a = inf`` for a straight chain of rigid links, Model A).

It is then located by bisection on ``s``: a trial point, solved from ``a``'s state, is
"before" when it is stable and its stiffness is at least ``DROP_RATIO · k_a``, else
"after". Bisection stops when the force is known to ``refine_tol`` (relative): the force
change across the bracket on the pre-critical side, ``k·Δs``, or the change of the
post-critical force between two bisections is below ``refine_tol·|F|``. The critical
force is the force at the end of the pre-critical branch (or, when that branch is a
rigid point, the limit of the post-critical force).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..exceptions import InputError, NoEquilibrium, SingularStiffness
from ..model import VjmModel
from .equilibrium import EquilibriumResult, EquilibriumSolver
from .stability import RANK_TOL, null_space
from .stiffness import stiffness_from_blocks

#: A step whose tangent stiffness falls below this fraction of the previous one is a critical point.
DROP_RATIO = 0.5
#: Sub-steps of the continuation that follows the pre-critical branch past a detected drop.
CONTINUATION_SUBSTEPS = 8
#: Samples per level of the search for the closest approach to instability.
MARGIN_SAMPLES = 8
#: Maximum bisections when refining a critical point.
MAX_BISECTIONS = 60


@dataclass(frozen=True)
class CurvePoint:
    """One point of a force–deflection curve.

    Attributes:
        deflection: Scalar deflection ``s`` along the direction (m, or rad for a rotation).
        force: External force (N, or N·m) along the direction that holds the end there,
            ``dᵀ F``: positive when it pushes the end along the direction.
        wrench: (6,) full external wrench at equilibrium (N, N·m), world axes.
        stable: Stability verdict of eq. (23).
        stiffness: Tangent stiffness ``dᵀ K_C d`` (N/m) with K_C of eq. (30); ``inf`` when
            the end cannot move along ``d`` to first order (straight chain of rigid
            links), ``nan`` when K_C is singular for another reason.
        equilibrium: The :class:`EquilibriumResult`.
    """

    deflection: float
    force: float
    wrench: np.ndarray
    stable: bool
    stiffness: float
    equilibrium: EquilibriumResult = field(repr=False)


@dataclass(frozen=True)
class CriticalPoint:
    """A critical (buckling) point, located to ``refine_tol`` in force.

    Attributes:
        force: Critical force (N) along the direction.
        deflection: Critical deflection (m or rad) along the direction.
        stiffness_before: Tangent stiffness (N/m) just before (pre-critical branch).
        stiffness_after: Tangent stiffness (N/m) just after (the branch followed next).
        index: Index in ``Curve.points`` of the first point after it.
        force_after: Force (N) of the followed branch just after the critical deflection.
        bisections: Number of bisections used.
    """

    force: float
    deflection: float
    stiffness_before: float
    stiffness_after: float
    index: int
    force_after: float = float("nan")
    bisections: int = 0


@dataclass(frozen=True)
class Curve:
    """A traced force–deflection curve.

    Attributes:
        direction: (6,) unit direction of the deflection, world axes (translation, rotation).
        points: The followed (stable when one exists) branch, ``s = 0 … max_deflection``.
        critical: Critical points found on it (see the module docstring for the rule).
        branches: Unstable (or other) branches traced with ``all_branches=True``; else ``()``.
    """

    direction: np.ndarray
    points: tuple[CurvePoint, ...]
    critical: tuple[CriticalPoint, ...]
    branches: tuple[tuple[CurvePoint, ...], ...] = ()

    @property
    def deflections(self) -> np.ndarray:
        return np.array([p.deflection for p in self.points])

    @property
    def forces(self) -> np.ndarray:
        return np.array([p.force for p in self.points])


def _direction(vm: VjmModel, direction) -> np.ndarray:
    d = np.asarray(direction, dtype=float).ravel()
    if d.size == 3:
        d = np.concatenate([d, np.zeros(3)])
    if d.size != 6 or not np.all(np.isfinite(d)):
        raise InputError(
            f"direction must be 3 or 6 finite numbers, got {np.asarray(direction).tolist()}"
        )
    n = np.linalg.norm(d)
    if n == 0:
        raise InputError("direction must not be zero")
    d = d / n
    names = ["x", "y", "z", "rx", "ry", "rz"]
    off = [names[i] for i in range(6) if i not in vm.task and abs(d[i]) > 0]
    if off:
        raise InputError(
            f"direction has components {off} outside the task {vm.task_names}: the end is free there"
        )
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
    return _stiffness_along(vm, eq, direction, kin)[0]


def _stiffness_along(vm, eq: EquilibriumResult, direction: np.ndarray, kin):
    """(:func:`tangent_stiffness`, the :class:`StiffnessResult` of eq. 30 or None when singular)."""
    from . import blocks_at

    b = blocks_at(vm, eq.x, eq.wrench, kin)  # kept by the solver when it evaluated them
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


def _point(vm, eq: EquilibriumResult, s: float, d: np.ndarray, kin) -> CurvePoint:
    return _point_and_stiffness(vm, eq, s, d, kin)[0]


def _point_and_stiffness(vm, eq: EquilibriumResult, s: float, d: np.ndarray, kin):
    k, st = _stiffness_along(vm, eq, d, kin)
    point = CurvePoint(
        deflection=float(s),
        force=float(d @ eq.wrench),
        wrench=np.asarray(eq.wrench, float).copy(),
        stable=bool(eq.stable),
        stiffness=k,
        equilibrium=eq,
    )
    return point, st


def _predicted(vm, solver: EquilibriumSolver, a: CurvePoint, st, s: float, d: np.ndarray):
    """Equilibrium at ``s`` from the tangent predictor of the stable point ``a``: its
    configuration moved by eq. (29), ``δq = K_q δt``, ``δθ = K_θ δt`` with ``δt = (s − s_a) d``,
    then the plain local Newton iteration only. None when that does not give an acceptable
    equilibrium: the caller then solves from ``a`` itself, as without a predictor."""
    dt = (s - a.deflection) * d
    x0 = a.equilibrium.x.copy()
    x0[vm.theta_idx] += st.dtheta_dt @ dt
    x0[vm.q_idx] += st.dq_dt @ dt
    if not np.all(np.isfinite(x0)):
        return None, 0
    eq = solver._solve_local(s * d, x0)
    return eq, solver._fast_its


def _is_drop(k_a: float, k_b: float) -> bool:
    if np.isnan(k_a) or np.isnan(k_b):
        return False
    if np.isinf(k_a):
        return not np.isinf(k_b)
    # only a stiff (positive) state can lose stiffness sharply; a softening post-critical
    # branch (k ≤ 0, force falling) is not a new critical point
    return k_a > 0 and k_b < DROP_RATIO * k_a


def _same_branch(a: CurvePoint, m: CurvePoint) -> bool:
    """A trial point ``m`` is still on the pre-critical branch of ``a``."""
    return m.stable and not _is_drop(a.stiffness, m.stiffness)


def _max_eig(eq: EquilibriumResult) -> float:
    ev = eq.stability.eigenvalues if eq.stability is not None else np.zeros(0)
    return float(ev.max()) if ev.size else -np.inf


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


def _refine_eigen(
    vm, d, a: CurvePoint, b: CurvePoint, index: int, kin, refine_tol: float, solver: EquilibriumSolver
):
    """Bifurcation from the pre-critical branch: continue that branch past it (Newton
    without the stability safeguard, warm start from ``a``) and find where the largest
    eigenvalue of the matrix of eq. (23) crosses zero (Illinois regula falsi). Returns
    None when the pre-critical branch does not continue to ``b``'s deflection as an
    unstable equilibrium (e.g. a fold): the caller then bisects."""
    if not np.isfinite(a.stiffness):
        return None
    # (the caller's Kinematics is shared: a new pin.Data costs seconds for subdivided models)
    unstable = solver._sibling(follow_stable=False, tol=solver.tol, restarts=0)
    task = list(vm.task)
    # continuation in sub-steps, each checked against the tangent predictor, keeps to the
    # branch connected to ``a``; stop at the first sub-step where eq. (23) fails
    lo, pb = a, None
    try:
        for j in range(1, CONTINUATION_SUBSTEPS + 1):
            s = a.deflection + (b.deflection - a.deflection) * j / CONTINUATION_SUBSTEPS
            eq = unstable.solve(s * d, x0=lo.equilibrium.x, wrench0=lo.equilibrium.wrench[task])
            if not eq.converged:
                return None
            m = _point(vm, eq, s, d, kin)
            pred = lo.stiffness * (s - lo.deflection)
            if not np.isfinite(m.stiffness) or abs(m.force - lo.force - pred) > 0.5 * abs(
                pred
            ) + 1e-9 * abs(m.force):
                return None  # jumped to another branch (or a fold): not a continued branch
            if _max_eig(eq) > 0:
                pb = m
                break
            lo = m
    except NoEquilibrium:
        return None
    if pb is None:
        return None
    flo, fhi = _max_eig(lo.equilibrium), _max_eig(pb.equilibrium)
    hi = pb
    def evaluate(s, lo_, _hi):
        try:  # warm start from the stable end of the bracket, as it moves
            eq = unstable.solve(s * d, x0=lo_.equilibrium.x, wrench0=lo_.equilibrium.wrench[task])
        except NoEquilibrium:
            return None
        return (_point(vm, eq, s, d, kin), _max_eig(eq)) if eq.converged else None

    def done(lo_, hi_, m, s):
        k = max(abs(lo_.stiffness), abs(hi_.stiffness))
        return abs(hi_.deflection - lo_.deflection) * k <= 0.5 * refine_tol * max(abs(m.force), 1e-300)

    lo, flo, hi, fhi, n, ok = illinois(evaluate, lo, flo, hi, fhi, lambda p: p.deflection, done, MAX_BISECTIONS)
    if not ok:
        return None
    # the root by linear interpolation of the eigenvalue, force likewise
    w = flo / (flo - fhi) if fhi != flo else 0.5
    s_c = lo.deflection + w * (hi.deflection - lo.deflection)
    f_c = lo.force + w * (hi.force - lo.force)
    return CriticalPoint(
        force=float(f_c),
        deflection=float(s_c),
        stiffness_before=float(lo.stiffness),
        stiffness_after=float(b.stiffness),
        index=index,
        force_after=float(b.force),
        bisections=n,
    )


def _refine_margin(
    vm, solver, d, start: CurvePoint, b: CurvePoint, index: int, kin, refine_tol: float
):
    """Imperfect bifurcation: the followed stable branch stays stable but its stiffness
    collapses. The critical point is the closest approach to instability: the maximum of
    the largest eigenvalue of the matrix of eq. (23) along the followed branch, searched by
    continuation from ``start`` on nested grids. Returns None if no interior maximum."""
    task = list(vm.task)
    lo_eq, lo_s, hi_s = start.equilibrium, start.deflection, b.deflection
    best = None
    for _level in range(MAX_BISECTIONS):
        pts = []
        eq = lo_eq
        for j in range(MARGIN_SAMPLES + 1):
            s = lo_s + (hi_s - lo_s) * j / MARGIN_SAMPLES
            if j:
                try:
                    eq = solver.solve(s * d, x0=eq.x, wrench0=eq.wrench[task])
                except NoEquilibrium:
                    return None
            pts.append(_point(vm, eq, s, d, kin))
        ev = [_max_eig(p.equilibrium) for p in pts]
        jm = int(np.argmax(ev))
        if (jm == 0 or jm == MARGIN_SAMPLES) and best is None:
            return None
        jm = min(max(jm, 1), MARGIN_SAMPLES - 1)
        best = pts[jm]
        k = max(abs(pts[jm - 1].stiffness), abs(pts[jm + 1].stiffness))
        if k * (pts[jm + 1].deflection - pts[jm - 1].deflection) <= refine_tol * max(
            abs(best.force), 1e-300
        ):
            break
        lo_eq, lo_s, hi_s = pts[jm - 1].equilibrium, pts[jm - 1].deflection, pts[jm + 1].deflection
    return best


def _refine(
    vm,
    solver,
    d,
    a: CurvePoint,
    b: CurvePoint,
    index: int,
    kin,
    refine_tol: float,
    before: CurvePoint | None = None,
) -> CriticalPoint:
    found = _refine_eigen(vm, d, a, b, index, kin, refine_tol, solver)
    if found is not None:
        return found
    if b.stable:
        m = _refine_margin(vm, solver, d, before or a, b, index, kin, refine_tol)
        if m is not None:
            return CriticalPoint(
                force=m.force,
                deflection=m.deflection,
                stiffness_before=a.stiffness,
                stiffness_after=b.stiffness,
                index=index,
                force_after=b.force,
                bisections=0,
            )
    lo, hi = a, b
    prev_after = b.force
    n = 0
    for n in range(1, MAX_BISECTIONS + 1):
        scale = max(abs(lo.force), abs(hi.force), 1e-300)
        ds = hi.deflection - lo.deflection
        pre_known = np.isfinite(lo.stiffness) and abs(lo.stiffness * ds) <= refine_tol * scale
        if pre_known and lo.deflection != 0.0 or ds <= 1e-14 * max(abs(hi.deflection), 1e-300):
            break
        s = 0.5 * (lo.deflection + hi.deflection)
        try:
            eq = solver.solve(
                s * d, x0=a.equilibrium.x, wrench0=a.equilibrium.wrench[list(vm.task)]
            )
        except NoEquilibrium:
            break
        m = _point(vm, eq, s, d, kin)
        if _same_branch(a, m):
            lo = m
        else:
            hi = m
            if np.isinf(lo.stiffness) and abs(m.force - prev_after) <= 0.5 * refine_tol * abs(
                m.force
            ):
                prev_after = m.force
                break
            prev_after = m.force
    rigid_pre = (
        np.isinf(lo.stiffness)
        or lo.deflection == 0.0
        and abs(lo.force) < 1e-12 * max(abs(hi.force), 1e-300)
    )
    force = hi.force if rigid_pre else lo.force
    defl = hi.deflection if rigid_pre else lo.deflection
    return CriticalPoint(
        force=float(force),
        deflection=float(defl),
        stiffness_before=float(a.stiffness if rigid_pre else lo.stiffness),
        stiffness_after=float(hi.stiffness),
        index=index,
        force_after=float(hi.force),
        bisections=n,
    )


def _trace_branch(vm, d, start_eq: EquilibriumResult, s_values, kin, solver) -> list[CurvePoint]:
    pts = []
    prev = start_eq
    for s in s_values:
        try:
            eq = solver.solve(s * d, x0=prev.x, wrench0=prev.wrench[list(vm.task)])
        except NoEquilibrium:
            break
        if not eq.converged:
            break
        pts.append(_point(vm, eq, s, d, kin))
        prev = eq
    return pts


def _distinct(eq: EquilibriumResult, others, tol=1e-6) -> bool:
    return all(np.linalg.norm(eq.x - o.x) > tol * max(1.0, np.linalg.norm(o.x)) for o in others)


def _other_branches(vm, d, points, critical, s_grid, kin, solver) -> tuple[tuple[CurvePoint, ...], ...]:
    """Branches that leave the critical points: seeds at the first step after each
    critical point, from the pre-critical state itself (the trivial branch continued) and
    from it displaced along ± each eigenvector of the reduced matrix of eq. (23), solved
    with ``follow_stable=False`` and continued by warm starts."""
    from . import blocks_at

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
                eq = unstable.solve(rest[0] * d, x0=x0, wrench0=base.wrench[list(vm.task)])
            except NoEquilibrium:
                continue
            if not eq.converged or eq.stable or not _distinct(eq, seen):
                continue
            first = _point(vm, eq, rest[0], d, kin)
            pts = [first] + _trace_branch(vm, d, eq, rest[1:], kin, unstable)
            seen.extend(p.equilibrium for p in pts[:1])
            branches.append(tuple(pts))
    return tuple(branches)


def _unloaded(vm, solver, d, kin) -> EquilibriumResult | None:
    """The unloaded reference as the first point when the chain is rigid along ``d``
    there (straight chain of rigid links, Model A S): the force at zero deflection is then
    indeterminate and the solver's perturbed start would pick an arbitrary one; the
    unloaded state (zero wrench) is the natural start of the curve."""
    from . import blocks_at
    from .stability import check_stability

    x = np.asarray(vm.reference, float).copy()
    stat = vm.K_theta @ (x[vm.theta_idx] - vm.theta0)
    if stat.size and np.abs(stat).max() > 0:
        return None
    b = blocks_at(vm, x, np.zeros(6), kin)
    probe = EquilibriumResult(
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
        stability=check_stability(b),
    )
    if not np.isinf(tangent_stiffness(vm, probe, d, kin)):
        return None
    return probe


def trace_curve(
    vm: VjmModel,
    direction,
    max_deflection: float,
    steps: int = 100,
    *,
    solver: EquilibriumSolver | None = None,
    refine_tol: float = 1e-4,
    all_branches: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Curve:
    """Trace the force–deflection curve of ``vm`` along ``direction`` (paper §6.1, Fig. 4–5).

    Args:
        vm: The model.
        direction: (3,) or (6,) direction of the end deflection, world axes; normalised;
            must lie in the task components and be a pure translation or rotation.
        max_deflection: Final deflection along the direction (m or rad), > 0.
        steps: Number of equal steps (the curve has ``steps + 1`` points, from 0).
        solver: Equilibrium solver (default ``EquilibriumSolver(vm)``, follows the stable branch).
        refine_tol: Relative force tolerance of the critical points.
        all_branches: Also trace the branches that leave each critical point
            (unstable ones, as in Fig. 4) into ``Curve.branches``.
        progress: Optional ``callable(done, total)`` called after every step.

    Returns:
        The :class:`Curve`.
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
    solver = solver or EquilibriumSolver(vm)
    kin = solver.kin
    s_grid = [max_deflection * i / steps for i in range(steps + 1)]
    points: list[CurvePoint] = []
    critical: list[CriticalPoint] = []
    prev = None
    prev_stiffness = None  # StiffnessResult of the last point (tangent predictor)
    task = list(vm.task)
    for i, s in enumerate(s_grid):
        if prev is None:
            eq = _unloaded(vm, solver, d, kin) or solver.solve(s * d)
        else:
            eq, spent = None, 0
            if prev_stiffness is not None and points[-1].stable:
                eq, spent = _predicted(vm, solver, points[-1], prev_stiffness, s, d)
            if eq is None:
                eq = solver.solve(s * d, x0=prev.x, wrench0=prev.wrench[task])
                if spent:
                    eq = replace(eq, iterations=eq.iterations + spent)
        p, prev_stiffness = _point_and_stiffness(vm, eq, s, d, kin)
        if points:
            a = points[-1]
            if a.stable and (not p.stable or _is_drop(a.stiffness, p.stiffness)):
                before = points[-2] if len(points) > 1 and points[-2].stable else None
                c = _refine(vm, solver, d, a, p, i, kin, refine_tol, before)
                h = max_deflection / steps
                if not critical or abs(c.deflection - critical[-1].deflection) > 0.01 * h:
                    critical.append(c)  # else the same transition, seen again one step later
        points.append(p)
        prev = eq
        if progress is not None:
            progress(i + 1, steps + 1)
    branches = _other_branches(vm, d, points, critical, s_grid, kin, solver) if all_branches else ()
    return Curve(direction=d, points=tuple(points), critical=tuple(critical), branches=branches)
