"""Stability of a loaded equilibrium (paper §4.2, eq. 19–23)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_pin.solver.blocks import Blocks
from vjm_pin.solver.lapack import lapack as _lapack  # scipy's LAPACK without importing scipy.linalg

#: Largest matrix order for which the hot paths call scipy's LAPACK directly (numpy.linalg's
#: wrappers cost more than small factorisations). numpy and scipy load two different OpenBLAS
#: libraries, each with its own thread pool; above the size where OpenBLAS starts threads,
#: alternating between them lets one pool's spinning threads slow the other down (10x on a
#: 2-core machine at n = 146), so larger matrices go through numpy.linalg (one pool).
SCIPY_LAPACK_MAX_N = 48

#: Relative tolerance on the eigenvalues of the reduced matrix of eq. (23): the
#: equilibrium is stable when every eigenvalue is below ``-STABILITY_TOL · ‖K_θ‖₂``.
STABILITY_TOL = 1e-10
#: Relative tolerance on the singular values of ``[J_θ J_q]`` that defines its rank (eq. 20).
RANK_TOL = 1e-10


@dataclass(frozen=True)
class StabilityResult:
    """Verdict of eq. (23).

    Attributes:
        stable: True when the reduced matrix is negative definite (energy minimum for the
            fixed end location).
        eigenvalues: (d,) eigenvalues of the symmetric part of the reduced matrix, ascending
            (N·m/rad for rotational coordinates). d = null-space dimension.
        null_dim: Dimension of the null space of ``[J_θ J_q]`` (eq. 21).
        tolerance: Absolute threshold used: stable iff ``max(eigenvalues) < -tolerance``.
    """

    stable: bool
    eigenvalues: np.ndarray
    null_dim: int
    tolerance: float

    @property
    def margin(self) -> float:
        """``-max(eigenvalues)``: positive when stable; the distance to instability."""
        return float(-self.eigenvalues.max()) if self.eigenvalues.size else float("inf")


class DeferredStability(StabilityResult):
    """A :class:`StabilityResult` whose verdict and largest eigenvalue are known now and whose
    whole spectrum is computed when first read.

    The O(n) chain kernel (:mod:`vjm_pin.solver.chain_kernel`) certifies the verdict of eq. (23)
    from the largest eigenvalue alone (a Sturm count and inverse iteration); a curve needs no
    more. ``eigenvalues`` keeps its meaning (all ``d`` eigenvalues, ascending): they come from
    :func:`check_stability` on the equilibrium's blocks (dense, O(n³)) the first time they are
    read, e.g. by ``vjm-pin analyze --json``. ``margin`` uses the largest eigenvalue known now.
    Pickled (a map's worker, Dask) as a plain :class:`StabilityResult`, spectrum included.
    """

    def __init__(self, stable: bool, largest: float, null_dim: int, tolerance: float, blocks):
        object.__setattr__(self, "stable", bool(stable))
        object.__setattr__(self, "null_dim", int(null_dim))
        object.__setattr__(self, "tolerance", float(tolerance))
        object.__setattr__(self, "_largest", float(largest))
        object.__setattr__(self, "_blocks", blocks)  # () -> Blocks at the equilibrium
        object.__setattr__(self, "_spectrum", None)

    @property
    def eigenvalues(self) -> np.ndarray:
        ev = self._spectrum
        if ev is None:
            ev = check_stability(self._blocks()).eigenvalues
            ev.setflags(write=False)
            object.__setattr__(self, "_spectrum", ev)
            object.__setattr__(self, "_blocks", None)
        return ev

    @property
    def margin(self) -> float:
        return -self._largest

    def __reduce__(self):
        return (StabilityResult, (self.stable, np.array(self.eigenvalues), self.null_dim, self.tolerance))


class SpectrumLater(StabilityResult):
    """A :class:`StabilityResult` whose verdict is known now and whose eigenvalues are computed from
    the kept matrix of eq. (23) when first read.

    The serial solver's compiled kernel certifies "stable" with a Cholesky factorisation of the
    matrix shifted past the threshold (:func:`vjm_pin.solver.kernel._iterate_into`); a warm-started
    solve of a curve seldom reads the spectrum. ``eigenvalues`` (all ``d``, ascending) and
    ``margin`` are ``spectrum(matrix)`` (the same LAPACK call as the eager verdict: the same numbers)
    the first time either is read. Pickled as a plain :class:`StabilityResult`, spectrum included.
    """

    def __init__(self, stable: bool, null_dim: int, tolerance: float, matrix: np.ndarray, spectrum):
        object.__setattr__(self, "stable", bool(stable))
        object.__setattr__(self, "null_dim", int(null_dim))
        object.__setattr__(self, "tolerance", float(tolerance))
        object.__setattr__(self, "_matrix", matrix)  # (d, d), no one else writes it
        object.__setattr__(self, "_spectrum_of", spectrum)
        object.__setattr__(self, "_spectrum", None)

    @classmethod
    def stable_now(cls, null_dim: int, tolerance: float, matrix: np.ndarray, spectrum) -> SpectrumLater:
        """``SpectrumLater(True, null_dim, tolerance, matrix, spectrum)``, its fields set at once
        (a warm-started solve builds one per point)."""
        obj = object.__new__(cls)
        obj.__dict__.update({"stable": True, "null_dim": int(null_dim), "tolerance": float(tolerance),
                             "_matrix": matrix, "_spectrum_of": spectrum, "_spectrum": None})
        return obj

    @staticmethod
    def stable_fields(null_dim: int, tolerance: float, spectrum) -> dict:
        """The instance fields of :meth:`stable_now` (a certified "stable" verdict of eq. 23) with the
        matrix left None, in their order: a template for a caller that builds many verdicts of one
        solver (``obj = object.__new__(SpectrumLater)``, ``obj.__dict__.update(template)``, then
        ``_matrix`` set: the object :meth:`stable_now` builds, ``tests/test_corrector_route.py``)."""
        return {"stable": True, "null_dim": int(null_dim), "tolerance": float(tolerance), "_matrix": None,
                "_spectrum_of": spectrum, "_spectrum": None}

    @property
    def eigenvalues(self) -> np.ndarray:
        ev = self._spectrum
        if ev is None:
            ev = self._spectrum_of(self._matrix)
            object.__setattr__(self, "_spectrum", ev)
            object.__setattr__(self, "_matrix", None)
        return ev

    def __reduce__(self):
        return (StabilityResult, (self.stable, np.array(self.eigenvalues), self.null_dim, self.tolerance))


def null_space(J_theta: np.ndarray, J_q: np.ndarray, rank_tol: float = RANK_TOL) -> np.ndarray:
    """Orthonormal basis (nθ+nq, d) of the null space of ``[J_θ J_q]`` by SVD (eq. 20–21).

    Rows are ordered (θ, q): the first nθ rows are ``V_θ°``, the rest ``V_q°``.
    """
    a = np.hstack([J_theta, J_q])
    n = a.shape[1]
    if a.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(a, full_matrices=True)
    smax = s.max() if s.size else 0.0
    rank = int(np.sum(s > rank_tol * max(smax, 1e-300)))
    return vt[rank:].T.copy()


def _null_space_fast(J_theta: np.ndarray, J_q: np.ndarray, rank_tol: float = RANK_TOL) -> np.ndarray:
    """A basis of the same null space as :func:`null_space`, cheaper: the complete QR of
    ``[J_θ J_q]ᵀ = Q R``; the singular values of the small ``R`` are those of
    ``[J_θ J_q]``, so the rank test is the same; at full row rank the last columns of
    ``Q`` span the null space (another orthonormal basis: eq. 23's eigenvalues do not
    depend on it). Falls back to the SVD when the rank is deficient."""
    a = np.hstack([J_theta, J_q])
    m, n = a.shape
    if m == 0 or m >= n:
        return null_space(J_theta, J_q, rank_tol)
    if n <= SCIPY_LAPACK_MAX_N:  # LAPACK directly (numpy's wrapper costs more at this size)
        qr, tau, _, info = _lapack.dgeqrf(a.T)
        qfull = np.zeros((n, n), order="F")
        qfull[:, :m] = qr
        q, _, info2 = _lapack.dorgqr(qfull, tau)
        r = np.triu(qr[:m])
        if info or info2:
            return null_space(J_theta, J_q, rank_tol)
    else:
        q, r = np.linalg.qr(a.T, mode="complete")
        r = r[:m]
    s = np.linalg.svd(r, compute_uv=False)
    if not s.min() > rank_tol * max(s.max(), 1e-300):
        return null_space(J_theta, J_q, rank_tol)
    return q[:, m:]


_NORMS: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}


def spectral_norm(k: np.ndarray) -> float:
    """``‖K‖₂`` (largest singular value), remembered per array (a model's ``K_θ`` is the
    same array at every stability check); recomputed if the array changed."""
    hit = _NORMS.get(id(k))
    if hit is not None and hit[0] is k and np.array_equal(hit[1], k):
        return hit[2]
    value = float(np.linalg.norm(k, 2)) if k.size else 1.0
    if len(_NORMS) >= 64:
        _NORMS.pop(next(iter(_NORMS)))
    _NORMS[id(k)] = (k, k.copy(), value)
    return value


def reduced_matrix(b: Blocks, basis: np.ndarray | None = None) -> np.ndarray:
    """The matrix of eq. (23): ``Vᵀ [[H_θθ − K_θ, H_θq], [H_qθ, H_qq]] V`` (symmetric part)."""
    if basis is None:
        basis = null_space(b.J_theta, b.J_q)
    nt = b.H_tt.shape[0]
    big = np.empty((nt + b.H_qq.shape[0],) * 2)  # np.block is slow for small matrices
    big[:nt, :nt] = b.H_tt - b.K_theta
    big[:nt, nt:] = b.H_tq
    big[nt:, :nt] = b.H_qt
    big[nt:, nt:] = b.H_qq
    m = basis.T @ big @ basis
    return 0.5 * (m + m.T)


def check_stability(b: Blocks, tol: float = STABILITY_TOL) -> StabilityResult:
    """Stability of the equilibrium whose matrices are ``b`` (eq. 19–23).

    The virtual work (eq. 17–18) of joint displacements that keep the end fixed
    (eq. 19) is a quadratic form on the null space of ``[J_θ J_q]``; the equilibrium is
    stable iff its matrix (eq. 23) is negative definite. A moment in the wrench makes the
    Hessian blocks non-symmetric (dead moment, see :mod:`vjm_pin.kinematics.chain`); the
    quadratic form only sees the symmetric part. The threshold is relative:
    ``tol · ‖K_θ‖₂``.
    """
    basis = _null_space_fast(b.J_theta, b.J_q)
    m = reduced_matrix(b, basis)
    ev = np.linalg.eigvalsh(m) if m.size else np.zeros(0)
    scale = spectral_norm(b.K_theta) if b.K_theta.size else 1.0
    thr = tol * scale
    stable = bool(ev.size == 0 or ev.max() < -thr)
    return StabilityResult(stable, ev, basis.shape[1], float(thr))


def stability_verdict(b: Blocks, tol: float = STABILITY_TOL) -> bool:
    """``check_stability(b, tol).stable`` (eq. 23, end held in every task row), in O(n) for a
    long serial chain (``b.chain``, :func:`~vjm_pin.solver.chain_algebra.chain_stability`: one
    factorisation of the bordered symmetric part shifted by the threshold, Sylvester's count of
    its negative pivots; the same relative threshold ``tol · ‖K_θ‖₂``). Falls back to
    :func:`check_stability` for short chains and when the count is not reliable (an eigenvalue
    at the threshold, a rank-deficient task Jacobian). Use it where only the verdict is needed
    (a curve point, a Newton acceptance test); :func:`check_stability` also gives the eigenvalues."""
    c = getattr(b, "chain", None)
    if c is not None and len(c.task) == b.J_theta.shape[0]:
        from vjm_pin.solver.chain_algebra import chain_stability

        verdict = chain_stability(c.layout, c.jacobian, c.wrench, c.task, tol)
        if verdict is not None:
            return verdict.stable
    return check_stability(b, tol).stable


def check_stability_held(b: Blocks, held: np.ndarray | None = None, tol: float = STABILITY_TOL) -> StabilityResult:
    """Stability under mixed control: the end held only in the rows ``held`` (paper §4.2).

    The total potential ``½(θ−θ₀)ᵀK_θ(θ−θ₀) − (dead-load work)`` has the Hessian
    ``K − H`` (``H`` the eq. 16 contraction of the end wrench, whose held part is the
    reaction, i.e. the Lagrange multiplier); the equilibrium is a constrained minimum iff
    ``Vᵀ (H − K) V`` is negative definite, ``V`` a basis of the null space of
    ``held · [J_θ J_q]`` (the displacements that keep the held combinations fixed).

    Args:
        b: The blocks at the equilibrium, evaluated with the *total* end wrench (dead load
            plus reaction).
        held: (k, m) matrix of the held combinations of the m task rows of ``b``; ``None``
            holds every task row (eq. 23, :func:`check_stability`); a (0, m) matrix holds
            nothing (pure force control: ``K − H`` itself must be positive definite).
        tol: Relative threshold, as in :func:`check_stability`.

    Returns:
        :class:`StabilityResult` (``null_dim`` is the dimension of ``V``).
    """
    if held is None:
        return check_stability(b, tol)
    held = np.atleast_2d(np.asarray(held, dtype=float))
    jz = np.hstack([b.J_theta, b.J_q])
    if held.shape[1] != jz.shape[0]:
        raise ValueError(f"held has {held.shape[1]} columns, the task has {jz.shape[0]} rows")
    a = held @ jz
    nt = b.H_tt.shape[0]
    if a.shape[0] == 0:
        basis = np.eye(jz.shape[1])
    else:
        basis = null_space(a[:, :nt], a[:, nt:])
    m = reduced_matrix(b, basis)
    ev = np.linalg.eigvalsh(m) if m.size else np.zeros(0)
    scale = spectral_norm(b.K_theta) if b.K_theta.size else 1.0
    thr = tol * scale
    stable = bool(ev.size == 0 or ev.max() < -thr)
    return StabilityResult(stable, ev, basis.shape[1], float(thr))
