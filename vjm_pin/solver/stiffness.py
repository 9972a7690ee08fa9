"""Loaded Cartesian stiffness and the sensitivities K_q, K_θ (paper §5, eq. 28–33)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from vjm_pin.exceptions import SingularStiffness
from vjm_pin.solver.blocks import Blocks
from vjm_pin.solver.lapack import lapack as _lapack  # scipy's LAPACK without importing scipy.linalg
from vjm_pin.solver.stability import RANK_TOL, SCIPY_LAPACK_MAX_N

METHODS = ("eq30", "eq32", "eq33")
#: Reciprocal condition number below which a matrix to invert is treated as singular.
SINGULAR_RCOND = 1e-13


@dataclass(frozen=True)
class StiffnessResult:
    """Linearisation ``δF = K_C δt``, ``δq = K_q δt``, ``δθ = K_θ δt`` (eq. 29).

    Attributes:
        stiffness: (6, 6) loaded Cartesian stiffness K_C at the end frame, world axes, for
            ``δt = (δp, δφ)`` (m, world rotation vector rad) and ``δF = (force N, moment
            N·m about the frame origin)``; rows/columns of unconstrained task components
            are zero.
        dq_dt: (nq, 6) K_q: passive-joint sensitivity (rad/m, …).
        dtheta_dt: (nθ, 6) K_θ: spring-coordinate sensitivity.
        method: ``"eq30"``, ``"eq32"`` or ``"eq33"``.
        task: Constrained task component indices.
        rigid: (r, 6) orthonormal task directions (zero off the task) along which the end frame
            cannot move to first order (:func:`stiffness_rigid`): K_C is infinite along them
            (``±inf`` entries); empty (0, 6) for a regular K_C.
        finite_part: With ``rigid``: (6, 6) ``V K' Vᵀ``, the stiffness on the other task
            directions ``V`` alone (zero along ``rigid``; where a rigid direction is not along a
            task axis its infinite entries hide these numbers in ``stiffness``); else None.
    """

    stiffness: np.ndarray
    dq_dt: np.ndarray
    dtheta_dt: np.ndarray
    method: str
    task: tuple[int, ...]
    rigid: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    finite_part: np.ndarray | None = None

    def is_symmetric(self, rtol: float = 1e-8) -> bool:
        """Symmetric to ``rtol`` (relative to the largest entry). Loaded by a pure force the
        stiffness is symmetric; a moment (dead load) may make it non-symmetric. Infinite
        entries (:attr:`rigid`) are compared by value."""
        k = self.stiffness
        if self.rigid.size:  # ±inf entries: symmetric where they match, the finite rest by value
            inf = ~np.isfinite(k)
            if np.any(inf != inf.T) or np.any(k[inf] != k.T[inf]):
                return False
            k = np.where(inf, 0.0, k)
        return bool(np.abs(k - k.T).max() <= rtol * max(np.abs(k).max(), 1e-300))

    @property
    def task_stiffness(self) -> np.ndarray:
        """(m, m) K_C restricted to the constrained task components."""
        t = list(self.task)
        return self.stiffness[np.ix_(t, t)]


def _equilibrate(a: np.ndarray, sweeps: int = 4) -> np.ndarray:
    """Symmetric Ruiz scaling ``D A D`` (rows and columns to unit max-norm): VJM matrices
    mix axial link stiffness (~1e9) with Jacobian entries (~1), so conditioning must be
    judged on the scaled matrix."""
    return _ruiz(a, sweeps)[0]


def _ruiz(a: np.ndarray, sweeps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_equilibrate` and its diagonal ``d`` (``S = diag(d) A diag(d)``).

    A sweep divides row and column ``i`` by the square root of the larger of their max-norms.
    Since ``max(D|A|D, D|A|ᵀD) = D max(|A|, |A|ᵀ) D`` for a positive diagonal ``D``, the sweeps
    run on the symmetric ``M = max(|A|, |A|ᵀ)`` (one row maximum each) and ``D`` is applied to
    ``A`` once at the end (equal to the sweep-by-sweep scaling up to rounding)."""
    aa = np.abs(a)
    mm = np.maximum(aa, aa.T)
    d = np.ones(a.shape[0])
    for _ in range(sweeps):
        r = mm.max(axis=1)
        r[r == 0] = 1.0
        r = 1.0 / np.sqrt(r)
        mm *= np.multiply.outer(r, r)
        d *= r
    return a * np.multiply.outer(d, d), d


def _rcond(a: np.ndarray) -> float:
    """Reciprocal 2-norm condition number of the equilibrated matrix (0 when singular)."""
    if a.size == 0:
        return 1.0
    s = np.linalg.svd(_equilibrate(a), compute_uv=False)
    return float(s.min() / s.max()) if s.max() > 0 else 0.0


def _inverse_if_regular(a: np.ndarray):
    """``(A⁻¹, True)`` when ``_rcond(a) ≥ SINGULAR_RCOND`` is certain without an SVD, else
    ``(None, False)`` (then the caller applies :func:`_rcond` itself).

    With the equilibrated ``S = D A D`` and its inverse from one LU, the Hölder bounds
    ``‖S‖₂ ≤ √(‖S‖₁‖S‖∞)`` (and the same for ``S⁻¹``) give a lower bound of the reciprocal
    2-norm condition number that :func:`_rcond` computes exactly; when it clears the
    threshold (with a factor 10 for the rounding of ``S⁻¹``) the matrix is regular and
    ``A⁻¹ = D S⁻¹ D``. Near-singular matrices go to the exact test."""
    n = a.shape[0]
    if n == 0:
        return None, False
    s, d = _ruiz(a)
    if n > SCIPY_LAPACK_MAX_N:  # one OpenBLAS thread pool (see SCIPY_LAPACK_MAX_N)
        try:
            inv = np.linalg.inv(s)
        except np.linalg.LinAlgError:
            return None, False
    else:
        lu, piv, info = _lapack.dgetrf(s)
        if info:
            return None, False
        inv, info = _lapack.dgetri(lu, piv)
        if info:
            return None, False
    if not np.isfinite(inv).all():
        return None, False
    sa, ia = np.abs(s), np.abs(inv)
    norm_s = np.sqrt(sa.sum(axis=0).max() * sa.sum(axis=1).max())
    norm_i = np.sqrt(ia.sum(axis=0).max() * ia.sum(axis=1).max())
    if not norm_s * norm_i * SINGULAR_RCOND * 10.0 <= 1.0:
        return None, False
    return inv * d[:, None] * d, True


def _diagnose(b: Blocks, what: str) -> str:
    m = b.J_theta.shape[0]
    jall = np.hstack([b.J_theta, b.J_q])
    s = np.linalg.svd(jall, compute_uv=False) if jall.size else np.zeros(0)
    rank = int(np.sum(s > RANK_TOL * max(s.max() if s.size else 0.0, 1e-300)))
    if rank < m:
        u = np.linalg.svd(jall)[0][:, -1]
        return (
            f"{what} is singular: the end frame cannot move along task direction {np.round(u, 3).tolist()} "
            "to first order (a rigid direction, e.g. a straight chain of rigid links): the stiffness there is infinite"
        )
    if b.J_q.size:
        sq = np.linalg.svd(b.J_q, compute_uv=False)
        if sq.min() <= RANK_TOL * max(sq.max(), 1e-300):
            return f"{what} is singular: the passive joints are redundant (some passive motion does not move the end frame)"
    return f"{what} is singular: the equilibrium is at a critical point (bifurcation/buckling) of the loaded chain"


def _embed(vm_task, kc, kq, kt, method) -> StiffnessResult:
    task = list(vm_task)
    k6 = np.zeros((6, 6))
    if task and task == list(range(task[0], task[-1] + 1)):
        task = slice(task[0], task[-1] + 1)  # contiguous components: plain slices
        k6[task, task] = kc
    else:
        k6[np.ix_(task, task)] = kc
    q6 = np.zeros((kq.shape[0], 6))
    q6[:, task] = kq
    t6 = np.zeros((kt.shape[0], 6))
    t6[:, task] = kt
    return StiffnessResult(k6, q6, t6, method, tuple(vm_task))


def eq28_matrix(b: Blocks) -> np.ndarray:
    """The matrix of eq. (28): ``[[0, J_q, J_θ], [J_qᵀ, H_qq, H_qθ], [J_θᵀ, H_θq, H_θθ − K_θ]]``."""
    m, nq = b.J_q.shape
    e = m + nq
    a = np.empty((e + b.J_theta.shape[1],) * 2)  # np.block is slow for small matrices
    a[:m, :m] = 0.0
    a[:m, m:e] = b.J_q
    a[:m, e:] = b.J_theta
    a[m:e, :m] = b.J_q.T
    a[m:e, m:e] = b.H_qq
    a[m:e, e:] = b.H_qt
    a[e:, :m] = b.J_theta.T
    a[e:, m:e] = b.H_tq
    a[e:, e:] = b.H_tt - b.K_theta
    return a


def stiffness_eq30(b: Blocks, task=(0, 1, 2, 3, 4, 5)) -> StiffnessResult:
    """K_C, K_q, K_θ by the full inverse of the matrix of eq. (28) (eq. 30).

    Works with passive joints (K_C rank-deficient: a passive motion of the end gives
    zero stiffness) and reduced task spaces (only the constrained rows enter J). The
    matrix itself is invertible as long as the end can move in every constrained
    direction and the passive joints are independent; otherwise
    :class:`SingularStiffness` says which.
    """
    if getattr(b, "chain", None) is not None:  # a long serial chain: O(n) recursion (chain_algebra)
        fast = _eq30_chain(b)
        if fast is not None:
            return _embed(task, *fast, "eq30")
    a = eq28_matrix(b)
    m, nq = b.J_theta.shape[0], b.J_q.shape[1]
    inv, regular = _inverse_if_regular(a)
    if regular:
        x = inv[:, :m]  # the right-hand side is [I_m; 0]
    else:
        if _rcond(a) < SINGULAR_RCOND:
            raise SingularStiffness(_diagnose(b, "the matrix of eq. (28)"), np.linalg.svd(a, compute_uv=False))
        rhs = np.zeros((a.shape[0], m))
        rhs[:m] = np.eye(m)
        x = np.linalg.solve(a, rhs)
    return _embed(task, x[:m], x[m : m + nq], x[m + nq :], "eq30")


#: Smallest pivot reciprocal condition (:class:`~vjm_pin.solver.chain_algebra.Factor`) for which
#: eq. (30) keeps the O(n) chain result; below it (near a critical point, where the dense path
#: decides whether the matrix is singular) the dense path runs.
CHAIN_TRUST_RCOND = 1e-8


def _eq30_chain(b: Blocks):
    """``(K_C, K_q, K_θ)`` of eq. (30) by the O(n) chain recursion on ``b.chain``
    (:class:`~vjm_pin.solver.chain_algebra.ChainKKT`: the same bordered matrix, refined solves),
    or None when its pivots or residual are not trustworthy (then the dense path decides)."""
    from vjm_pin.solver.chain_algebra import SOLVE_RTOL, ChainKKT

    c = b.chain
    nt = b.J_theta.shape[1]
    if len(c.task) != b.J_theta.shape[0] or c.layout.n != nt + b.J_q.shape[1]:
        return None
    kkt = ChainKKT(c.layout, c.jacobian, c.wrench, c.task)
    if not kkt.reliable or kkt.factor.rcond < CHAIN_TRUST_RCOND:
        return None
    kc, dxdt, res = kkt.stiffness()
    if not res <= SOLVE_RTOL or not np.isfinite(kc).all() or not np.isfinite(dxdt).all():
        return None
    return kc, dxdt[nt:], dxdt[:nt]


def _reduced(b: Blocks):
    kf = b.K_theta - b.H_tt
    if _rcond(kf) < SINGULAR_RCOND:
        raise SingularStiffness(
            "K_θ − H_θθ is singular (eq. 31): the springs alone have a zero-stiffness mode under this load; use eq. (30)",
            np.linalg.eigvals(kf),
        )
    k = np.linalg.inv(kf)  # k_θ^F
    a11 = b.J_theta @ k @ b.J_theta.T
    a12 = b.J_q + b.J_theta @ k @ b.H_tq
    a21 = b.J_q.T + b.H_qt @ k @ b.J_theta.T
    a22 = b.H_qq + b.H_qt @ k @ b.H_tq
    return k, a11, a12, a21, a22


def stiffness_eq32(b: Blocks, task=(0, 1, 2, 3, 4, 5)) -> StiffnessResult:
    """K_C and K_q by inverting the reduced (m+nq) matrix of eq. (31)–(32); δθ eliminated
    with ``k_θ^F = (K_θ − H_θθ)⁻¹``, and ``K_θ = k_θ^F (J_θᵀ K_C + H_θq K_q)``."""
    k, a11, a12, a21, a22 = _reduced(b)
    big = np.block([[a11, a12], [a21, a22]])
    if _rcond(big) < SINGULAR_RCOND:
        raise SingularStiffness(_diagnose(b, "the matrix of eq. (32)"), np.linalg.svd(big, compute_uv=False))
    m = a11.shape[0]
    rhs = np.zeros((big.shape[0], m))
    rhs[:m] = np.eye(m)
    x = np.linalg.solve(big, rhs)
    kc, kq = x[:m], x[m:]
    kt = k @ (b.J_theta.T @ kc + b.H_tq @ kq)
    return _embed(task, kc, kq, kt, "eq32")


def stiffness_eq33(b: Blocks, task=(0, 1, 2, 3, 4, 5)) -> StiffnessResult:
    """K_C by the block (Frobenius) closed form of eq. (33)::

        K_C = A⁻¹ + A⁻¹ B S⁻¹ C A⁻¹,  A = J_θ k J_θᵀ,  B = J_q + J_θ k H_θq,
        C = J_qᵀ + H_qθ k J_θᵀ,  S = H_qq + H_qθ k H_θq − C A⁻¹ B,

    whose first term is the classical stiffness of a chain without passive joints. It
    needs ``A`` invertible: every constrained direction must be reachable by the springs
    alone (not only through passive joints). ``K_q = −S⁻¹ C A⁻¹``.
    """
    k, a, bb, c, d = _reduced(b)
    if _rcond(a) < SINGULAR_RCOND:
        raise SingularStiffness(
            "J_θ k_θ^F J_θᵀ is singular (eq. 33): the springs alone cannot move the end in some "
            "constrained direction; use eq. (30)",
            np.linalg.svd(a, compute_uv=False),
        )
    ai = np.linalg.inv(a)
    if bb.shape[1]:
        s = d - c @ ai @ bb
        if _rcond(s) < SINGULAR_RCOND:
            raise SingularStiffness(_diagnose(b, "the Schur complement of eq. (33)"), np.linalg.svd(s, compute_uv=False))
        si = np.linalg.inv(s)
        kc = ai + ai @ bb @ si @ c @ ai
        kq = -si @ c @ ai
    else:
        kc = ai
        kq = np.zeros((0, a.shape[0]))
    kt = k @ (b.J_theta.T @ kc + b.H_tq @ kq)
    return _embed(task, kc, kq, kt, "eq33")


def stiffness_from_blocks(b: Blocks, task=(0, 1, 2, 3, 4, 5), method: str = "eq30") -> StiffnessResult:
    """Dispatch to :func:`stiffness_eq30`, :func:`stiffness_eq32` or :func:`stiffness_eq33`."""
    if method == "eq30":
        return stiffness_eq30(b, task)
    if method == "eq32":
        return stiffness_eq32(b, task)
    if method == "eq33":
        return stiffness_eq33(b, task)
    raise ValueError(f"unknown stiffness method '{method}'; choose one of {METHODS}")


# --------------------------------------------------------------------------- rigid task directions
#: Entries of the projector ``R Rᵀ`` on the rigid task directions above this are infinite in
#: :func:`stiffness_rigid` (the projector's entries are O(1); rounding leaves ~1e-16).
RIGID_ENTRY_TOL = 1e-12


def _rigid_split(b: Blocks) -> tuple[np.ndarray, np.ndarray]:
    """``(V, R)``: orthonormal columns (task rows of ``b``) spanning the task directions the end
    frame can move along to first order (the range of ``[J_θ J_q]``) and the rest (its left
    null space: rigid directions), split at the rank test of :func:`_diagnose`."""
    m = b.J_theta.shape[0]
    jall = np.hstack([b.J_theta, b.J_q])
    if not jall.size:
        return np.zeros((m, 0)), np.eye(m)
    u, s, _ = np.linalg.svd(jall)
    rank = int(np.sum(s > RANK_TOL * max(s.max() if s.size else 0.0, 1e-300)))
    return u[:, :rank], u[:, rank:]


def rigid_directions(b: Blocks) -> np.ndarray:
    """(r, m) orthonormal rows: the task directions (the task rows of ``b``; m along translations,
    rad along rotations) along which the end frame cannot move to first order, e.g. along a
    straight chain of rigid links: the left null space of ``[J_θ J_q]`` (singular values at most
    ``RANK_TOL`` × the largest, the test of the "rigid direction" diagnosis of
    :class:`SingularStiffness`). (0, m) when the end can move in every task direction."""
    return _rigid_split(b)[1].T.copy()


def stiffness_rigid(b: Blocks, task=(0, 1, 2, 3, 4, 5), method: str = "eq30") -> StiffnessResult:
    """K_C, K_q, K_θ where the end frame cannot move along some task directions ``R``
    (:func:`rigid_directions`; e.g. a straight chain of rigid links, Model A S): the matrix of
    eq. (28) is singular there, and the stiffness along ``R`` is infinite.

    ``method`` (eq. 30, 32 or 33) is applied to the task rows ``Vᵀ J`` that the end can move
    along (``V`` orthonormal, ``VᵀR = 0``), giving ``K'`` on those directions; then
    ``K_C = V K' Vᵀ`` with the entries where the projector ``R Rᵀ`` is non-zero set to
    ``±inf`` (its sign): the limit of a stiffness that grows without bound along ``R``. For an
    ``R`` along a task axis (the straight column: ``x``) that is one infinite diagonal entry
    and the finite stiffness of the other directions. ``K_q = K_q' Vᵀ`` and ``K_θ = K_θ' Vᵀ``
    (a displacement along ``R`` cannot be imposed: its component is ignored). The result's
    ``rigid`` holds ``R`` (6-vectors) and ``finite_part`` ``V K' Vᵀ`` (6, 6).

    Raises:
        SingularStiffness: no rigid direction (the matrix is singular for another reason, or not
            at all: use :func:`stiffness_from_blocks`), or the stiffness on the other directions
            is singular too (then that reason).
    """
    v, r = _rigid_split(b)
    m = b.J_theta.shape[0]
    if r.shape[1] == 0:
        raise SingularStiffness(
            "the end frame can move along every task direction to first order: no rigid direction", np.zeros(0)
        )
    k = v.shape[1]
    nt, nq = b.J_theta.shape[1], b.J_q.shape[1]
    if k:
        sub = Blocks(
            J_theta=v.T @ b.J_theta,
            J_q=v.T @ b.J_q,
            H_tt=b.H_tt,
            H_tq=b.H_tq,
            H_qt=b.H_qt,
            H_qq=b.H_qq,
            K_theta=b.K_theta,
            state=b.state,
        )
        part = stiffness_from_blocks(sub, tuple(range(k)), method)
        kc = v @ part.stiffness[:k, :k] @ v.T
        kq = part.dq_dt[:, :k] @ v.T
        kt = part.dtheta_dt[:, :k] @ v.T
    else:
        kc, kq, kt = np.zeros((m, m)), np.zeros((nq, m)), np.zeros((nt, m))
    proj = r @ r.T
    big = np.abs(proj) > RIGID_ENTRY_TOL
    finite = _embed(task, kc, kq, kt, method).stiffness
    out = _embed(task, np.where(big, np.copysign(np.inf, proj), kc), kq, kt, method)
    rig = np.zeros((r.shape[1], 6))
    rig[:, list(task)] = r.T
    return replace(out, rigid=rig, finite_part=finite)


# --------------------------------------------------------------------------- mechanisms with loop closures
#: Stiffness formulas of a mechanism with loop closures (:func:`stiffness_with_closures`).
CLOSURE_METHODS = ("eq28", "eq30", "eq32", "eq33")


def border_closures(b: Blocks, c_theta: np.ndarray, c_q: np.ndarray) -> Blocks:
    """The blocks of eq. (28) with closure rows bordered like passive-joint rows.

    The linearised closures ``C_θ δθ + C_q δq = 0`` and their multipliers ``δμ`` (the change of
    the closure reactions) enter eq. (28) exactly as further passive coordinates with zero
    stiffness: ``δq' = (δq, δμ)`` with::

        J_q' = [J_q, 0],   H_qq' = [[H_qq, C_qᵀ], [C_q, 0]],   H_qθ' = [[H_qθ], [C_θ]],   H_θq' = [H_θq, C_θᵀ]

    (the H blocks are those of the Lagrangian: eq. 16 contractions of the end wrench, of the
    dead loads and of the closure multipliers). Eq. (30), (32) and (33) applied to these blocks
    give the mechanism's K_C (the first ``nq`` rows of ``K_q`` are the passive sensitivities,
    the rest ``∂μ/∂t``). With no closure rows the blocks are ``b`` itself.

    Args:
        b: The blocks at the equilibrium (J task rows; H blocks of the Lagrangian).
        c_theta: (k, nθ) independent closure rows, spring columns (m/rad, rad/rad, ...).
        c_q: (k, nq) the same rows, passive columns.
    """
    c_theta = np.asarray(c_theta, float).reshape(-1, b.J_theta.shape[1])
    c_q = np.asarray(c_q, float).reshape(c_theta.shape[0], b.J_q.shape[1])
    k = c_theta.shape[0]
    if k == 0:
        return b
    m, nq = b.J_q.shape
    h_qq = np.zeros((nq + k, nq + k))
    h_qq[:nq, :nq] = b.H_qq
    h_qq[:nq, nq:] = c_q.T
    h_qq[nq:, :nq] = c_q
    return Blocks(
        J_theta=b.J_theta,
        J_q=np.hstack([b.J_q, np.zeros((m, k))]),
        H_tt=b.H_tt,
        H_tq=np.hstack([b.H_tq, c_theta.T]),
        H_qt=np.vstack([b.H_qt, c_theta]),
        H_qq=h_qq,
        K_theta=b.K_theta,
        state=b.state,
    )


def eq28_closures_matrix(b: Blocks, c_theta: np.ndarray, c_q: np.ndarray) -> np.ndarray:
    """The bordered matrix of eq. (28) with the closure rows, unknowns ``(δF, δμ, δθ, δq)``::

        [[0, 0, J_θ, J_q], [0, 0, C_θ, C_q], [J_θᵀ, C_θᵀ, H_θθ − K_θ, H_θq], [J_qᵀ, C_qᵀ, H_qθ, H_qq]]
    """
    m, nt = b.J_theta.shape
    k, nq = c_theta.shape[0], b.J_q.shape[1]
    e = m + k
    n = e + nt + nq
    a = np.zeros((n, n))
    a[:m, e : e + nt] = b.J_theta
    a[:m, e + nt :] = b.J_q
    a[m:e, e : e + nt] = c_theta
    a[m:e, e + nt :] = c_q
    a[e:, :e] = a[:e, e:].T
    a[e : e + nt, e : e + nt] = b.H_tt - b.K_theta
    a[e : e + nt, e + nt :] = b.H_tq
    a[e + nt :, e : e + nt] = b.H_qt
    a[e + nt :, e + nt :] = b.H_qq
    return a


def stiffness_with_closures(
    b: Blocks, c_theta: np.ndarray, c_q: np.ndarray, task=(0, 1, 2, 3, 4, 5), method: str = "eq28"
) -> StiffnessResult:
    """K_C, K_q, K_θ of a mechanism with (independent) closure rows ``C = [C_θ C_q]``.

    ``method``: ``"eq28"`` solves the bordered system of :func:`eq28_closures_matrix` for the
    right-hand side ``[δt; 0; 0; 0]``; ``"eq30"``, ``"eq32"``, ``"eq33"`` apply the paper's
    formulas to :func:`border_closures` (the closure multipliers as zero-stiffness passive
    coordinates), so eq. (32) eliminates ``δθ`` with ``k_θ^F = (K_θ − H_θθ)⁻¹`` and eq. (33)
    needs ``J_θ k_θ^F J_θᵀ`` invertible, as for a serial chain. All four agree where they apply.
    The returned ``method`` is ``"<method>-closures"``.

    Raises:
        SingularStiffness: the matrix the method inverts is singular (a critical point, a task
            direction the mechanism cannot move in, or a block eq. 32/33 needs).
        ValueError: an unknown method.
    """
    if method not in CLOSURE_METHODS:
        raise ValueError(f"unknown stiffness method '{method}'; choose one of {CLOSURE_METHODS}")
    c_theta = np.asarray(c_theta, float).reshape(-1, b.J_theta.shape[1])
    c_q = np.asarray(c_q, float).reshape(c_theta.shape[0], b.J_q.shape[1])
    nq = b.J_q.shape[1]
    if method != "eq28":
        try:
            r = stiffness_from_blocks(border_closures(b, c_theta, c_q), task, method)
        except SingularStiffness as exc:
            if "(eq. 31)" in str(exc) or "(eq. 33)" in str(exc):
                raise  # K_θ − H_θθ or J_θ k_θ^F J_θᵀ: the same blocks as for a serial chain
            raise SingularStiffness(
                f"the matrix of eq. ({method[2:]}) with the closure rows is singular: the equilibrium is at a "
                "critical point (bifurcation/buckling) of the loaded mechanism, or the task frame cannot move "
                "in some task direction",
                exc.eigenvalues,
            ) from None
        return StiffnessResult(r.stiffness, r.dq_dt[:nq], r.dtheta_dt, f"{method}-closures", r.task)
    a = eq28_closures_matrix(b, c_theta, c_q)
    m = b.J_theta.shape[0]
    e = m + c_theta.shape[0]
    if _rcond(a) < SINGULAR_RCOND:  # judged on the equilibrated matrix (units mix)
        raise SingularStiffness(
            "the bordered matrix of eq. (28) with the closure rows is singular: the equilibrium is at a "
            "critical point (bifurcation/buckling) of the loaded mechanism",
            np.linalg.svd(a, compute_uv=False),
        )
    rhs = np.zeros((a.shape[0], m))
    rhs[:m] = np.eye(m)
    x = np.linalg.solve(a, rhs)
    nt = b.J_theta.shape[1]
    return _embed(task, x[:m], x[e + nt :], x[e : e + nt], "eq28-closures")
