"""The matrices of the paper evaluated at one configuration and wrench.

``Blocks`` bundles what eq. (5)–(33) need: the spring and passive Jacobians restricted
to the constrained task components, and the four blocks of the Hessian of
``Ψ = g(q, θ)ᵀF`` (eq. 16).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_pin.kinematics.chain import Kinematics, KinematicState
from vjm_pin.model.format import VjmModel


@dataclass(frozen=True)
class Blocks:
    """Jacobians and Hessians at one loaded configuration.

    Attributes:
        J_theta: (m, nθ) Jacobian of the spring coordinates, task rows (m/rad, m/m, …).
        J_q: (m, nq) Jacobian of the passive coordinates, task rows.
        H_tt: (nθ, nθ) ``∂(J_θᵀF)/∂θ``  (N·m/rad …), eq. (16).
        H_tq: (nθ, nq) ``∂(J_θᵀF)/∂q``.
        H_qt: (nq, nθ) ``∂(J_qᵀF)/∂θ``.
        H_qq: (nq, nq) ``∂(J_qᵀF)/∂q``.
        K_theta: (nθ, nθ) spring stiffness.
        state: The full :class:`~vjm_pin.kinematics.chain.KinematicState`.
        chain: For a long serial chain (:data:`CHAIN_MIN_N` free coordinates or more, screw-form
            Hessian, the end wrench alone), what the O(n) algebra of
            :mod:`vjm_pin.solver.chain_algebra` needs (:class:`ChainContext`): eq. (30) and the
            stability verdict then use it; None otherwise (dense algebra).
    """

    J_theta: np.ndarray
    J_q: np.ndarray
    H_tt: np.ndarray
    H_tq: np.ndarray
    H_qt: np.ndarray
    H_qq: np.ndarray
    K_theta: np.ndarray
    state: KinematicState
    chain: ChainContext | None = None


#: Number of free coordinates (nθ + nq) from which :func:`evaluate_blocks` attaches a
#: :class:`ChainContext` and eq. (30) runs in O(n) (measured crossover with the dense path:
#: ~90 on the Model C column, ``scripts/benchmark.py`` ``bench_chain_algebra``).
CHAIN_MIN_N = 96
#: The same without numba (the numpy recursion: crossover between nθ = 144 and 1152).
CHAIN_MIN_N_NUMPY = 480


@dataclass(frozen=True)
class ChainContext:
    """The generators of a chain's matrices at one configuration (:mod:`vjm_pin.solver.chain_algebra`).

    Attributes:
        layout: :class:`~vjm_pin.solver.chain_algebra.ChainLayout` of the model.
        jacobian: (6, nv) ``LOCAL_WORLD_ALIGNED`` end-frame Jacobian, all joints.
        wrench: (6,) the end wrench whose eq. (16) contraction is ``H`` (N, N·m).
        task: constrained task components (the rows of ``J_θ``, ``J_q``).
    """

    layout: object
    jacobian: np.ndarray
    wrench: np.ndarray
    task: tuple[int, ...]


def chain_context(vm: VjmModel, state: KinematicState, wrench: np.ndarray) -> ChainContext | None:
    """:class:`ChainContext` of ``vm`` at ``state`` under the 6-D end ``wrench``, or None when the
    model is short (fewer than :data:`CHAIN_MIN_N` free coordinates, :data:`CHAIN_MIN_N_NUMPY`
    without numba: dense algebra is faster)."""
    n = len(vm.theta_idx) + len(vm.q_idx)
    if n < CHAIN_MIN_N:
        return None
    from vjm_pin.solver.chain_algebra import (  # lazy: long chains only
        chain_layout,
        compiled_available,
    )

    if n < CHAIN_MIN_N_NUMPY and not compiled_available():
        return None

    layout = chain_layout(vm.K_theta, vm.theta_idx, vm.q_idx)
    return ChainContext(layout, state.jacobian, np.array(wrench, dtype=float), tuple(vm.task))


def full_wrench(vm: VjmModel, f_task: np.ndarray) -> np.ndarray:
    """6-D wrench with the task components set from ``f_task`` and zeros elsewhere."""
    w = np.zeros(6)
    w[list(vm.task)] = f_task
    return w


def evaluate_blocks(
    vm: VjmModel, kin: Kinematics, x: np.ndarray, wrench: np.ndarray, state: KinematicState | None = None
) -> Blocks:
    """Evaluate :class:`Blocks` at configuration ``x`` (nq,) under the 6-D ``wrench`` (N, N·m).

    The last result is kept on ``kin``: the same model, ``x`` and ``wrench`` (bit for bit)
    return the same (read-only by convention) :class:`Blocks` — the stability check of an
    equilibrium and the stiffness of a curve point share one evaluation."""
    x = np.asarray(x, dtype=float)
    wrench = np.asarray(wrench, dtype=float)
    key = x.tobytes() + wrench.tobytes()
    last = getattr(kin, "_blocks_last", None)
    if last is not None and last[0] is vm and last[1] == key:
        b = last[2]
        if type(b) is _Lazy or type(b) is LazyBlocks:  # kept lazily (remember_lazy): built now, once
            b = b.build()
            kin._blocks_last = (vm, key, b)
        return b
    nt = len(vm.theta_idx)
    free = np.concatenate([vm.theta_idx, vm.q_idx])
    task = list(vm.task)
    if getattr(kin, "uses_screw", False):  # the Hessian in screw form from J (kinematics.screw)
        if state is None:
            state = kin.evaluate(x, hessian=False)
        hz = kin.psi_hessian(state, wrench, free)
    else:
        if state is None or state.hessian is None:
            state = kin.evaluate(x, hessian=True)
        hz = state.psi_hessian(wrench)[np.ix_(free, free)]  # (θ, q) order; the blocks are views
    jz = state.jacobian[task][:, free]
    # the chain generators equal this H only for the plain screw form (no other Hessian terms)
    plain = getattr(kin, "uses_screw", False) and type(kin).psi_hessian is Kinematics.psi_hessian
    chain = chain_context(vm, state, wrench) if plain else None
    b = Blocks(
        J_theta=jz[:, :nt],
        J_q=jz[:, nt:],
        H_tt=hz[:nt, :nt],
        H_tq=hz[:nt, nt:],
        H_qt=hz[nt:, :nt],
        H_qq=hz[nt:, nt:],
        K_theta=vm.K_theta,
        state=state,
        chain=chain,
    )
    remember_blocks(vm, kin, x, wrench, b)
    return b


def remember_blocks(vm: VjmModel, kin: Kinematics, x: np.ndarray, wrench: np.ndarray, b: Blocks) -> None:
    """Make ``b`` (evaluated at ``x`` under the 6-D ``wrench`` by the caller, in the layout of
    :func:`evaluate_blocks`) the kept result of ``kin`` for :func:`evaluate_blocks`."""
    try:
        kin._blocks_last = (vm, np.asarray(x, float).tobytes() + np.asarray(wrench, float).tobytes(), b)
    except AttributeError:  # a kinematics object with __slots__: no cache
        pass


def remember_lazy(vm: VjmModel, kin: Kinematics, key: bytes, build) -> None:
    """:func:`remember_blocks` for blocks not built yet: ``key`` is ``x.tobytes() + wrench.tobytes()``
    and ``build()`` returns the :class:`Blocks` (called by :func:`evaluate_blocks` when they are
    first asked for at that key; a solve whose blocks nobody asks for never builds them)."""
    try:
        kin._blocks_last = (vm, key, _Lazy(build))
    except AttributeError:  # a kinematics object with __slots__: no cache
        pass


class _Lazy:
    """Blocks not built yet (:func:`remember_lazy`): a marker type, so blocks of any other class kept
    on the same kinematics (the benchmark's frozen release solver) are returned as they are."""

    __slots__ = ("build",)

    def __init__(self, build):
        self.build = build


class LazyBlocks(tuple):
    """Blocks not built yet, as their sources ``(J, H, nθ, K_θ, state)``: ``J`` (m, n) the task rows
    and free columns of the frame Jacobian, ``H`` (n, n) the Hessian of Ψ (eq. 16), both in (θ, q)
    order, arrays no one writes. Kept by ``kin._blocks_last = (vm, key, LazyBlocks((...)))``, as
    :func:`remember_lazy` keeps a builder (a solver's warm step builds one per point: no closure, no
    ``__init__``); :meth:`build` lays them out as :func:`evaluate_blocks` does, views of ``J`` and ``H``."""

    __slots__ = ()

    def build(self) -> Blocks:
        jac, hz, nt, kt, st = self
        return Blocks(jac[:, :nt], jac[:, nt:], hz[:nt, :nt], hz[:nt, nt:], hz[nt:, :nt], hz[nt:, nt:], kt, st)
