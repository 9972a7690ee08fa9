"""Loop closures: residual, Jacobian and multiplier Hessian (kinematics layer).

A closure (``<vjm:closure>``, :class:`~vjm_pin.model.format.Closure`) holds frame a on frame b.
With the frame origins ``p_a``, ``p_b`` (m) and orientations ``R_a``, ``R_b`` in world,
the relative placement is

    s(x) = (R_bᵀ (p_a − p_b),  log3(R_bᵀ R_a))        (6,), m and rad, frame b's axes,

and the closure residual ``c(x)`` is ``s`` in the listed components (order as written): the
mechanism is assembled where ``c = 0`` (the loader checks this at the file's reference
configuration to 1e-9).

Derivatives, with ``x`` the VJM coordinates (nq = nv, so ∂/∂x is the ordinary derivative),
``J_a = [J^v_a; J^ω_a]`` the ``LOCAL_WORLD_ALIGNED`` frame Jacobians of
:mod:`vjm_pin.kinematics.chain`, ``r = p_a − p_b``, ``R = R_bᵀ R_a`` and ``J_log = Jlog3(R)``
(Pinocchio's right-Jacobian inverse: ``δlog3(R) = J_log ω_local``; :func:`jlog3`)::

    ∂s_p/∂x = R_bᵀ (J^v_a − J^v_b + [r]× J^ω_b)
    ∂s_r/∂x = J_log R_aᵀ (J^ω_a − J^ω_b)

Multiplier contraction (the closure reaction). For multipliers ``λ`` (one per row of ``c``,
zero-padded to ``(λ_p, λ_r)``), ``Cᵀλ`` is the generalised force of a pair of equal and
opposite wrenches (world axes, at the frame origins)::

    W_a = (f, m),   W_b = (−f, f × r − m),   f = R_b λ_p (N),   m = R_a J_logᵀ λ_r (N·m)

so that ``Cᵀλ = J_aᵀ W_a + J_bᵀ W_b``. Its derivative ``∂(Cᵀλ)/∂x = Σ_k λ_k ∂²c_k/∂x²`` is
the eq. (16) contraction of both frames' kinematic Hessians with these wrenches held fixed
(as for the end wrench: ``KinematicState.psi_hessian``) plus the terms from the wrenches
turning with the configuration (``f`` and ``m`` follow ``R_b`` and ``log3``, ``r`` moves)::

    ∂(Cᵀλ)/∂x = H_a:W_a + H_b:W_b + (J^v_a − J^v_b)ᵀ ∂f + (J^ω_a − J^ω_b)ᵀ ∂m + J^ω_bᵀ ∂(f × r)
    ∂f = −[f]× J^ω_b
    ∂(f × r) = [f]× (J^v_a − J^v_b) + [r]× [f]× J^ω_b
    ∂m = −[m]× J^ω_b + R_b D(θ; λ_r) ∂s_r/∂x,   D = ∂(J_log(θ) λ_r)/∂θ,  θ = log3(R)

(using ``R_a J_logᵀ = R_b J_log``). Unlike the contraction with a dead moment, this matrix
is symmetric: it is the Hessian of the scalar ``λᵀc(x)``. ``tests/test_closures.py`` checks
all of it against central differences.

Redundancy. Closure rows (and the solver's held task rows) may be dependent — a planar loop
closed in all six components has three identically zero rows. :func:`constraint_rank`
reports the rank and which rows are redundant; :func:`min_norm_multipliers` chooses the
multipliers of a redundant set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import ArgumentError, InputError
from vjm_pin.kinematics.chain import KinematicState, contract_hessian
from vjm_pin.kinematics.frames import FrameKinematics
from vjm_pin.kinematics.screw import psi_hessian_screw, screw_applicable, support_mask
from vjm_pin.model.format import COMPONENTS, Closure, VjmModel, relative_placement

#: Default relative tolerance of :func:`constraint_rank` and :func:`min_norm_multipliers`.
RANK_RTOL = 1e-10


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix: ``skew(a) @ b == np.cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _beta(t: float) -> tuple[float, float]:
    """``β(t) = 1/t² − (1 + cos t)/(2 t sin t)`` (the ``[θ]×²`` coefficient of
    ``Jlog3 = I + ½[θ]× + β [θ]×²``) and ``β'(t)/t``; Taylor series below t = 0.1 rad
    (from ``β = 1/t² − ½cot(t/2)/t``; truncation error < 1e-16 there)."""
    if t < 0.1:
        t2 = t * t
        beta = 1 / 12 + t2 / 720 + t2**2 / 30240 + t2**3 / 1209600 + t2**4 / 47900160
        return beta, 1 / 360 + t2 / 7560 + t2**2 / 201600 + t2**3 / 5987520
    half = 0.5 * t
    cot = np.cos(half) / np.sin(half)
    beta = 1 / t**2 - 0.5 * cot / t
    dbeta_t = -2 / t**4 + 0.5 * cot / t**3 + 0.25 / (t * t * np.sin(half) ** 2)
    return float(beta), float(dbeta_t)


def jlog3(theta: np.ndarray) -> np.ndarray:
    """(3, 3) ``Jlog3(exp3(θ)) = I + ½[θ]× + β(|θ|)[θ]×²``: Pinocchio's ``Jlog3`` (the right
    Jacobian inverse, ``δlog3(R) = Jlog3 ω_local``) evaluated from ``θ`` with a series near
    zero. (``pin.Jlog3`` of pin 4.1 is off by up to ~4e-10 near |θ| = 5e-4 rad, which
    spoils finite-difference checks; this one is accurate to round-off.)"""
    theta = np.asarray(theta, float)
    beta, _ = _beta(math.sqrt(float(theta.dot(theta))))  # np.linalg.norm's arithmetic, without its overhead
    s = skew(theta)
    return np.eye(3) + 0.5 * s + beta * (s @ s)


def jlog3_derivative(theta: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """(3, 3) ``D = ∂(Jlog3(exp3(θ)) λ)/∂θ`` for a fixed ``λ`` (3,).

    With ``Jlog3 = I + ½[θ]× + β(|θ|)[θ]×²`` and ``[θ]×²λ = θ(θ·λ) − |θ|²λ``."""
    theta = np.asarray(theta, float)
    lam = np.asarray(lam, float)
    t = math.sqrt(float(theta.dot(theta)))  # np.linalg.norm's arithmetic
    beta, dbeta_t = _beta(t)
    tl = float(theta @ lam)
    sq = theta * tl - t * t * lam
    return (
        -0.5 * skew(lam)
        + beta * (tl * np.eye(3) + np.outer(theta, lam) - 2.0 * np.outer(lam, theta))
        + dbeta_t * np.outer(sq, theta)
    )


@dataclass(frozen=True)
class ClosureFrames:
    """One closure evaluated at a configuration (the pieces its Hessian needs).

    Attributes:
        closure: The :class:`~vjm_pin.model.format.Closure`.
        a, b: :class:`~vjm_pin.kinematics.chain.KinematicState` of frame_a and frame_b.
        placement: (6,) full relative placement ``s`` (m, rad; frame b's axes).
        jacobian: (6, nv) ``∂s/∂x`` (all six components).
        jlog: (3, 3) ``Jlog3(R_bᵀ R_a)``.
        screw: The eq. (16) contractions of :meth:`hessian` come from the frame Jacobians in
            screw form (:func:`~vjm_pin.kinematics.screw.psi_hessian_screw`; chains of 1-DoF
            revolute/prismatic joints) instead of Pinocchio's kinematic Hessians (then ``a`` and
            ``b`` carry none).
        support: ``(cols, mask, runs)`` of :meth:`hessian_block` when known in advance (the
            joints that support frame a or frame b: :meth:`ClosureSet.support`), else None
            (found from the Jacobians' nonzero columns: the same columns).
    """

    closure: Closure
    a: KinematicState
    b: KinematicState
    placement: np.ndarray
    jacobian: np.ndarray
    jlog: np.ndarray
    screw: bool = False
    support: tuple | None = None

    def wrenches(self, lam6: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reaction wrench pair (W_a, W_b), each (6,) (N, N·m, world axes, at the frame
        origins), whose generalised force ``J_aᵀW_a + J_bᵀW_b`` is ``(∂s/∂x)ᵀ λ6``."""
        lam6 = np.asarray(lam6, float)
        f = self.b.rotation @ lam6[:3]
        m = self.a.rotation @ self.jlog.T @ lam6[3:]
        r = self.a.position - self.b.position
        fxr = np.array([f[1] * r[2] - f[2] * r[1], f[2] * r[0] - f[0] * r[2], f[0] * r[1] - f[1] * r[0]])
        return np.concatenate([f, m]), np.concatenate([-f, fxr - m])

    def hessian(self, lam6: np.ndarray) -> np.ndarray:
        """(nv, nv) ``∂((∂s/∂x)ᵀ λ6)/∂x`` (symmetric): eq. (16) contractions plus the terms of
        the turning reaction (module docstring)."""
        a, b = self.a, self.b
        if not self.screw and (a.hessian is None or b.hessian is None):
            raise InputError(
                "this closure state was evaluated without Hessians: evaluate(x, hessian=True)"
            )
        if self.screw:
            cols, block = self.hessian_block(lam6)
            nv = a.jacobian.shape[1]
            out = np.zeros((nv, nv))
            out[np.ix_(cols, cols)] = block
            return out
        lam6 = np.asarray(lam6, float)
        w_a, w_b = self.wrenches(lam6)
        return self._terms(lam6, w_a, a.jacobian, b.jacobian, self.jacobian[3:]) + (
            contract_hessian(a.hessian, w_a) + contract_hessian(b.hessian, w_b)
        )

    def _terms(self, lam6, w_a, ja, jb, jr):
        """The terms of the turning reaction (module docstring; ``w_a`` the reaction wrench on
        frame a) on the columns of ``ja``, ``jb`` (the frames' Jacobians) and ``jr`` (``∂s_r/∂x``)."""
        a, b = self.a, self.b
        f, m = w_a[:3], w_a[3:]
        r = a.position - b.position
        jv = ja[:3] - jb[:3]
        jw = ja[3:] - jb[3:]
        jwb = jb[3:]
        sf = skew(f)
        d_f = -sf @ jwb
        d_fr = sf @ jv + skew(r) @ sf @ jwb
        d_m = -skew(m) @ jwb + b.rotation @ jlog3_derivative(self.placement[3:], lam6[3:]) @ jr
        return jv.T @ d_f + jw.T @ d_m + jwb.T @ d_fr

    def hessian_block(self, lam6: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cols, block): :meth:`hessian` on the joints that move frame a or frame b (the nonzero
        columns of their Jacobians, ascending; the matrix is zero elsewhere), in screw form
        (``screw=True`` states only)."""
        if not self.screw:
            raise InputError("hessian_block needs a closure state evaluated in screw form")
        a, b = self.a, self.b
        lam6 = np.asarray(lam6, float)
        if self.support is not None:
            cols, mask, _ = self.support
        else:
            cols = np.flatnonzero(np.any(a.jacobian != 0, axis=0) | np.any(b.jacobian != 0, axis=0))
            mask = support_mask(a.jacobian.shape[1], cols)
        ja, jb = a.jacobian[:, cols], b.jacobian[:, cols]
        w_a, w_b = self.wrenches(lam6)
        block = (
            psi_hessian_screw(ja, w_a, mask)
            + psi_hessian_screw(jb, w_b, mask)
            + self._terms(lam6, w_a, ja, jb, self.jacobian[3:, cols])
        )
        return cols, block


def closure_frames(
    closure: Closure, a: KinematicState, b: KinematicState, screw: bool = False, support=None
) -> ClosureFrames:
    """Evaluate one closure from the states of its two frames (module docstring formulas);
    ``screw``: its Hessian from the Jacobians in screw form, ``support`` its columns
    (:class:`ClosureFrames`)."""
    r = a.position - b.position
    s = relative_placement(a.position, a.rotation, b.position, b.rotation)
    jlog = jlog3(s[3:])
    jp = b.rotation.T @ (a.jacobian[:3] - b.jacobian[:3] + skew(r) @ b.jacobian[3:])
    jr = jlog @ a.rotation.T @ (a.jacobian[3:] - b.jacobian[3:])
    return ClosureFrames(closure, a, b, s, np.vstack([jp, jr]), jlog, screw, support if screw else None)


@dataclass(frozen=True)
class ClosureState:
    """All closures of a mechanism at one configuration.

    Attributes:
        residual: (m,) ``c(x)``: the held components of every closure, closure order then
            the order written (m, rad); zero when assembled.
        jacobian: (m, nv) ``C = ∂c/∂x`` (m/m, m/rad, rad/m, rad/rad).
        labels: (m,) row names ``"<closure>.<component>"``.
        frames: One :class:`ClosureFrames` per closure.
    """

    residual: np.ndarray
    jacobian: np.ndarray
    labels: tuple[str, ...]
    frames: tuple[ClosureFrames, ...]

    def _split(self, lam) -> list[np.ndarray]:
        lam = np.asarray(lam, float).reshape(-1)
        if lam.shape != self.residual.shape or not np.all(np.isfinite(lam)):
            raise InputError(
                f"closure multipliers must be {self.residual.size} finite numbers (one per row: "
                f"{' '.join(self.labels)}), got shape {lam.shape}"
            )
        out, k = [], 0
        for cf in self.frames:
            lam6 = np.zeros(6)
            idx = cf.closure.indices
            lam6[list(idx)] = lam[k : k + len(idx)]
            out.append(lam6)
            k += len(idx)
        return out

    def generalized_force(self, lam) -> np.ndarray:
        """(nv,) ``Cᵀλ`` (N·m, N): the generalised force of the reaction wrenches."""
        return self.jacobian.T @ np.asarray(lam, float)

    def hessian(self, lam) -> np.ndarray:
        """(nv, nv) ``∂(Cᵀλ)/∂x = Σ_k λ_k ∂²c_k/∂x²`` for fixed multipliers ``λ`` (m,)."""
        nv = self.jacobian.shape[1]
        out = np.zeros((nv, nv))
        for cf, lam6 in zip(self.frames, self._split(lam)):
            if np.any(lam6):
                if cf.screw:  # on the joints that move the closure's frames only
                    cols, block = cf.hessian_block(lam6)
                    _add_block(out, cols, block, cf.support[2] if cf.support is not None else None)
                else:
                    out += cf.hessian(lam6)
        return out

    def reaction_wrenches(self, lam) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Closure name → (W_a, W_b): the wrenches (6,) (N, N·m, world axes, at the frame
        origins) on frame_a and frame_b whose generalised force is this closure's part of
        ``Cᵀλ``."""
        return {
            cf.closure.name: cf.wrenches(lam6) for cf, lam6 in zip(self.frames, self._split(lam))
        }


def _runs(cols: np.ndarray) -> list | None:
    """The contiguous runs of ``cols`` (ascending, distinct) as ``(first, end, i0, i1)``
    (``cols[i0:i1] == range(first, end)``), or None beyond four runs (:func:`_add_block`)."""
    breaks = np.flatnonzero(np.diff(cols) != 1) + 1
    if len(breaks) > 3:
        return None
    edges = [0, *breaks.tolist(), len(cols)]
    return [(int(cols[i]), int(cols[j - 1]) + 1, i, j) for i, j in pairwise(edges)]


def _add_block(out: np.ndarray, cols: np.ndarray, block: np.ndarray, runs=None) -> None:
    """``out[np.ix_(cols, cols)] += block`` (``cols`` ascending, distinct) by slices over the
    contiguous runs of ``cols`` (a closure's columns: one or two legs, a few runs): the same
    additions, without the fancy-indexed copy and write-back. ``runs``: :func:`_runs` of ``cols``
    when known."""
    if runs is None:
        runs = _runs(cols)
    if runs is None:
        out[np.ix_(cols, cols)] += block
        return
    for r0, r1, i0, i1 in runs:
        for c0, c1, j0, j1 in runs:
            out[r0:r1, c0:c1] += block[i0:i1, j0:j1]


class ClosureSet:
    """The closures of a model, evaluated together.

    Args:
        vm: The :class:`~vjm_pin.model.format.VjmModel` (its ``closures``), or a ``pin.Model``
            with ``closures`` given.
        closures: Override or supply the closures (default: ``vm.closures``).
        frames: A :class:`~vjm_pin.kinematics.frames.FrameKinematics` to share with other users (it
            must include :attr:`frame_ids`); a private one by default.
        screw: Evaluate the multiplier Hessian from the frame Jacobians in screw form
            (:func:`~vjm_pin.kinematics.screw.psi_hessian_screw`: no 6 × nv × nv kinematic
            Hessians, the same matrix to round-off) when every joint is a 1-DoF revolute or
            prismatic joint (:func:`~vjm_pin.kinematics.screw.screw_applicable`); ignored otherwise.
    """

    def __init__(
        self,
        vm,
        closures: Sequence[Closure] | None = None,
        frames: FrameKinematics | None = None,
        screw: bool = False,
    ):
        model = vm.model if isinstance(vm, VjmModel) else vm
        if not isinstance(model, pin.Model):
            raise ArgumentError(
                f"vm must be a VjmModel or a pinocchio.Model, got {type(vm).__name__}"
            )
        if closures is None:
            if not isinstance(vm, VjmModel):
                raise ArgumentError("closures must be given with a pinocchio.Model")
            closures = vm.closures
        from vjm_pin.exceptions import FrameNotFound

        names = [f.name for f in model.frames]
        pairs = []
        for c in closures:
            if not isinstance(c, Closure):
                raise ArgumentError(f"closures must be Closure objects, got {type(c).__name__}")
            for attr in ("frame_a", "frame_b"):
                if not model.existFrame(getattr(c, attr)):
                    raise FrameNotFound(getattr(c, attr), names, f"closure '{c.name}' {attr}")
            pairs.append((int(model.getFrameId(c.frame_a)), int(model.getFrameId(c.frame_b))))
        self.model = model
        self.closures: tuple[Closure, ...] = tuple(closures)
        self.pairs: tuple[tuple[int, int], ...] = tuple(pairs)
        self.frame_ids: tuple[int, ...] = tuple(dict.fromkeys(f for p in pairs for f in p))
        if frames is not None and not set(self.frame_ids) <= set(frames.frame_ids):
            raise ArgumentError("the shared FrameKinematics does not evaluate every closure frame")
        self.frames = frames or FrameKinematics(model, self.frame_ids)
        self.labels: tuple[str, ...] = tuple(
            f"{c.name}.{comp}" for c in self.closures for comp in c.components
        )
        if screw:
            screw = screw_applicable(model)
        self.screw = bool(screw)
        self._indices = tuple(list(c.indices) for c in self.closures)
        self._support = tuple(self.support(i) for i in range(len(pairs))) if self.screw else None

    def support(self, i: int) -> tuple[np.ndarray, np.ndarray, list | None]:
        """``(cols, mask, runs)`` of closure ``i`` in screw form: ``cols`` the velocity indices of
        the joints that support frame a or frame b (ascending; every other column of both frame
        Jacobians is zero, and these are not at any configuration: a 1-DoF revolute or prismatic
        joint's column holds its unit axis), ``mask`` their
        :func:`~vjm_pin.kinematics.screw.support_mask`, ``runs`` their contiguous runs."""
        model = self.model
        cols = set()
        for fid in self.pairs[i]:
            for j in model.supports[model.frames[fid].parentJoint]:
                if j > 0:
                    jm = model.joints[j]
                    cols.update(range(jm.idx_v, jm.idx_v + jm.nv))
        c = np.array(sorted(cols), int)
        return c, support_mask(model.nv, c), _runs(c)

    @property
    def n_rows(self) -> int:
        """Number of constraint rows (held components of all closures)."""
        return len(self.labels)

    def evaluate(self, x: np.ndarray, hessian: bool = True) -> ClosureState:
        """Residual, Jacobian and (with ``hessian``) what :meth:`ClosureState.hessian` needs, at ``x``."""
        screw = hessian and self.screw
        states = self.frames.evaluate(x, hessian=hessian and not screw)
        frames, res, jac = [], [], []
        support = self._support or (None,) * len(self.closures)
        for c, (fa, fb), idx, sup in zip(self.closures, self.pairs, self._indices, support):
            cf = closure_frames(c, states[fa], states[fb], screw, sup)
            frames.append(cf)
            res.append(cf.placement[idx])
            jac.append(cf.jacobian[idx])
        nv = self.model.nv
        return ClosureState(
            residual=np.concatenate(res) if res else np.zeros(0),
            jacobian=np.vstack(jac) if jac else np.zeros((0, nv)),
            labels=self.labels,
            frames=tuple(frames),
        )

    def residual_from(self, placements) -> np.ndarray:
        """``c(x)`` alone, from the placements of the closure frames at ``x`` (``{frame id:
        (position (3,), rotation (3, 3))}``, world): no Jacobians (a line search's trial points).
        The same numbers as :meth:`evaluate`'s ``residual`` from the same placements."""
        res = [
            relative_placement(*placements[fa], *placements[fb])[idx]
            for (fa, fb), idx in zip(self.pairs, self._indices)
        ]
        return np.concatenate(res) if res else np.zeros(0)


# --------------------------------------------------------------------------- redundancy
@dataclass(frozen=True)
class ConstraintRank:
    """Rank of a stacked constraint Jacobian and its redundant rows.

    Attributes:
        rank: Numerical rank.
        independent: Indices of a maximal set of independent rows (pivot order).
        redundant: Indices of the other rows (sorted): each is a combination of the
            independent ones (to the tolerance), so its constraint is implied locally.
        labels: The row names, if given.
        singular_values: Singular values of the row-normalised matrix (descending).
        tolerance: The threshold used: ``rtol`` × the largest singular value.
    """

    rank: int
    independent: tuple[int, ...]
    redundant: tuple[int, ...]
    labels: tuple[str, ...] | None
    singular_values: np.ndarray
    tolerance: float

    @property
    def n_redundant(self) -> int:
        return len(self.redundant)

    @property
    def redundant_labels(self) -> tuple[str, ...]:
        """Names of the redundant rows (indices as strings if no labels were given)."""
        return tuple(self.labels[i] if self.labels else str(i) for i in self.redundant)


def row_rank(jacobian: np.ndarray, rtol: float = RANK_RTOL):
    """The rank test of :func:`constraint_rank` alone (no pivoting: which rows are independent is
    not decided): ``(a, scaled, singular values, tolerance, rank)``, ``a`` the (m, nv) float
    array, ``scaled`` its rows normalised (zero rows kept zero). A caller that finds
    ``rank == m`` knows every row is independent without :func:`constraint_rank`'s QR.

    Raises:
        InputError: not a finite 2-D array.
    """
    a = np.asarray(jacobian, dtype=float)
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise InputError(f"jacobian must be a finite (rows, nv) array, got shape {a.shape}")
    m = a.shape[0]
    norms = np.linalg.norm(a, axis=1)
    big = float(norms.max()) if m else 0.0
    nonzero = norms > rtol * big if big > 0 else np.zeros(m, bool)
    scaled = np.zeros_like(a)
    scaled[nonzero] = a[nonzero] / norms[nonzero, None]
    sv = np.linalg.svd(scaled, compute_uv=False) if m and a.shape[1] else np.zeros(0)
    tol = rtol * float(sv[0]) if sv.size else 0.0
    rank = int(np.sum(sv > tol)) if sv.size else 0
    return a, scaled, sv, tol, rank


def constraint_rank(
    jacobian: np.ndarray, labels: Sequence[str] | None = None, rtol: float = RANK_RTOL
) -> ConstraintRank:
    """Rank of a stacked constraint Jacobian (closure rows and held task rows, (m, nv)) and
    which rows are redundant.

    Each row is first scaled to unit norm (rows mix m and rad: normalising makes the test
    independent of each row's unit); rows of norm ≤ ``rtol`` × the largest row norm are zero
    rows, hence redundant. The rank is the number of singular values of the normalised matrix
    above ``rtol`` × the largest (default ``RANK_RTOL`` = 1e-10: Pinocchio Jacobians are exact
    to ~1e-15, while a geometrically redundant row of a real mechanism is dependent to
    round-off). The independent rows are the first ``rank`` pivots of a QR factorisation with
    column pivoting of the normalised matrix's transpose (ties go to the earlier row, so list
    the rows you prefer to keep first); the others are redundant.

    Raises:
        InputError: not a finite 2-D array, or labels of the wrong length.
    """
    from scipy.linalg import qr

    a, scaled, sv, tol, rank = row_rank(jacobian, rtol)
    if labels is not None:
        labels = tuple(labels)
        if len(labels) != a.shape[0]:
            raise InputError(f"labels has {len(labels)} names for {a.shape[0]} rows")
    m = a.shape[0]
    if rank:
        _, _, piv = qr(scaled.T, mode="economic", pivoting=True)
        independent = tuple(int(i) for i in piv[:rank])
    else:
        independent = ()
    redundant = tuple(i for i in range(m) if i not in independent)
    return ConstraintRank(rank, independent, redundant, labels, sv, tol)


@dataclass(frozen=True)
class Multipliers:
    """Minimum-norm multipliers of a (possibly redundant) constraint set.

    Attributes:
        lam: (m,) the multipliers, in the units of the generalised force per row unit
            (N for translation rows, N·m for rotation rows of a closure).
        residual: (nv,) ``Cᵀλ − g``: zero (to round-off) when ``g`` is in the range of ``Cᵀ``
            (the constraints can balance it); otherwise the part no reaction can carry.
        rank: Numerical rank of ``C`` used.
    """

    lam: np.ndarray
    residual: np.ndarray
    rank: int


def min_norm_multipliers(
    jacobian: np.ndarray, force: np.ndarray, rtol: float = RANK_RTOL
) -> Multipliers:
    """The multipliers ``λ`` of least norm that minimise ``‖Cᵀλ − g‖`` (``numpy.linalg.lstsq``).

    With redundant rows, ``Cᵀλ = g`` has a family of solutions (the reactions of an
    over-constrained mechanism are statically indeterminate); the minimum-norm one has no
    component in the null space of ``Cᵀ``. For a planar loop closed in six components the
    out-of-plane rows are zero and get zero multipliers. The norm mixes the rows' units (N and
    N·m) as given. Singular values below ``rtol`` × the largest are treated as zero.

    Args:
        jacobian: (m, nv) constraint Jacobian ``C``.
        force: (nv,) the generalised force ``g`` the reactions must balance (N·m, N).
    """
    c = np.asarray(jacobian, float)
    g = np.asarray(force, float).reshape(-1)
    if (
        c.ndim != 2
        or g.shape != (c.shape[1],)
        or not (np.all(np.isfinite(c)) and np.all(np.isfinite(g)))
    ):
        raise InputError(
            f"need a finite (m, nv) jacobian and (nv,) force, got {c.shape} and {g.shape}"
        )
    lam, _, rank, _ = np.linalg.lstsq(c.T, g, rcond=rtol)
    return Multipliers(lam, c.T @ lam - g, int(rank))


__all__ = [
    "COMPONENTS",
    "ClosureFrames",
    "ClosureSet",
    "ClosureState",
    "ConstraintRank",
    "Multipliers",
    "closure_frames",
    "constraint_rank",
    "jlog3",
    "jlog3_derivative",
    "min_norm_multipliers",
    "row_rank",
    "skew",
]
