"""Dead loads anywhere: wrenches at frames and link weights (kinematics layer).

A :class:`Load` is a dead (constant, world-axes) wrench ``w = (f, μ)`` at a frame of the
model: the force ``f`` (N) acts at the frame origin, ``μ`` (N·m) is a pure moment. Its
generalised force and the derivative of it are those of the end wrench in eq. (5) and
eq. (16)::

    Q(x) = Σ_l J_lᵀ w_l,      ∂Q/∂x = Σ_l H_l : w_l     (H:w)[i, j] = Σ_k w_k ∂J[k, i]/∂x_j

with ``J_l`` the ``LOCAL_WORLD_ALIGNED`` Jacobian of frame ``l`` (:mod:`vjm_pin.kinematics.chain`).
``∂Q/∂x`` is symmetric when every load is a pure force (it then has the potential
``V = −Σ f_l·p_l(x)``) and not in general with moments (footnote 2 of the paper).

Link weights (gravity ``g``, m/s², world axes) are forces ``m_i g`` at the centres of mass
of the bodies of the Pinocchio model (URDF inertials; links on fixed joints merged into their
parent body): the same logic as the former ``vjm_pin.loads`` — ``Q_g = −g(x)`` and
``∂Q_g/∂x = −∂g/∂x`` of Pinocchio's generalised gravity on a copy of the model carrying
``g`` (the caller's model is never changed), evaluated in the thread's shared ``pin.Data`` of the
original model (:func:`~vjm_pin.kinematics.shared.data_for`; same joint tree).

Sign: ``Q`` is the force the loads *apply*; at a static equilibrium of springs and passive
joints it is balanced by the spring torques (eq. 5: ``K_θ(θ − θ₀) = Q_θ + …``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import ArgumentError, FrameNotFound, InputError
from vjm_pin.kinematics.chain import contract_hessian
from vjm_pin.kinematics.frames import FrameKinematics
from vjm_pin.kinematics.shared import data_for
from vjm_pin.model.format import VjmModel

#: Standard gravity (m/s²), ISO 80000-3 (the value of the former ``vjm_pin.loads``).
STANDARD_GRAVITY = 9.80665

#: What a load is, for messages.
LOAD_FORMAT = "FRAME FX FY FZ [MX MY MZ] (N, N·m, world axes)"


def _finite_vector(v, sizes: tuple[int, ...], what: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(
            f"{what} must be {' or '.join(map(str, sizes))} numbers, got {v!r}"
        ) from None
    if a.size not in sizes or not np.all(np.isfinite(a)):
        raise InputError(
            f"{what} must be {' or '.join(map(str, sizes))} finite numbers, got {a.tolist()}"
        )
    return a


@dataclass(frozen=True)
class Load:
    """A dead wrench at a frame.

    Attributes:
        frame: Frame name (a link or URDF frame of the model).
        wrench: (6,) force (N) at the frame origin and moment (N·m), world axes. Three
            numbers are a pure force.
    """

    frame: str
    wrench: np.ndarray

    def __post_init__(self):
        if not isinstance(self.frame, str) or not self.frame:
            raise ArgumentError(f"load frame must be a frame name (str), got {self.frame!r}")
        w = _finite_vector(self.wrench, (3, 6), f"load at '{self.frame}': wrench")
        if w.size == 3:
            w = np.concatenate([w, np.zeros(3)])
        w.setflags(write=False)
        object.__setattr__(self, "wrench", w)

    @classmethod
    def weight(cls, frame: str, mass_kg: float, gravity=(0.0, 0.0, -STANDARD_GRAVITY)) -> Load:
        """The weight of a point mass ``mass_kg`` (kg) at the frame origin (a payload)."""
        m = float(mass_kg)
        if not np.isfinite(m) or m < 0:
            raise InputError(
                f"mass at '{frame}' must be a finite non-negative number of kg, got {mass_kg!r}"
            )
        return cls(frame, m * _finite_vector(gravity, (3,), "gravity (m/s²)"))


def parse_load_args(values: Sequence) -> tuple[Load, ...]:
    """Loads from command-line words: each item is ``[FRAME, FX, FY, FZ]`` or
    ``[FRAME, FX, FY, FZ, MX, MY, MZ]`` (strings; N, N·m, world axes), as argparse gives a
    repeatable option with ``nargs="+", action="append"``. A single flat list is one load.

    Frames are checked against a model later (:class:`DeadLoads`).

    Raises:
        InputError: a wrong count or a word that is not a finite number (one line naming it).
    """
    if values is None:
        return ()
    items = list(values)
    if items and all(isinstance(v, str) for v in items):
        items = [items]
    loads = []
    for item in items:
        if isinstance(item, str) or not isinstance(item, Sequence):
            raise InputError(f"a load is {LOAD_FORMAT}, got {item!r}")
        words = [str(w) for w in item]
        shown = " ".join(words)
        if len(words) not in (4, 7):
            raise InputError(
                f"load '{shown}': expected {LOAD_FORMAT}, got {max(len(words) - 1, 0)} numbers"
            )
        nums = []
        for w in words[1:]:
            try:
                v = float(w)
            except ValueError:
                raise InputError(
                    f"load '{shown}': '{w}' is not a number; expected {LOAD_FORMAT}"
                ) from None
            if not np.isfinite(v):
                raise InputError(f"load '{shown}': '{w}' is not finite")
            nums.append(v)
        loads.append(Load(words[0], np.array(nums)))
    return tuple(loads)


@dataclass(frozen=True)
class LoadState:
    """The dead loads at one configuration.

    Attributes:
        force: (nv,) generalised force ``Q = Σ J_lᵀ w_l + Q_g`` (N·m, N).
        derivative: (nv, nv) ``∂Q/∂x`` (eq. 16 contraction plus the gravity term), or None
            when evaluated without Hessians.
        potential: Potential energy ``V`` (J) with ``Q = −∂V/∂x`` when every load is a pure
            force (``−Σ f_l·p_l`` plus the weights' ``−Σ m_i gᵀc_i``); None if a load has a
            moment (a dead moment has no potential in general).
    """

    force: np.ndarray
    derivative: np.ndarray | None
    potential: float | None


class DeadLoads:
    """Dead wrenches at frames and link weights of a model, evaluated together.

    Args:
        vm: The :class:`~vjm_pin.model.format.VjmModel` (or its ``pin.Model``).
        loads: The :class:`Load` list (frames must exist: :class:`FrameNotFound`).
        gravity: (3,) gravity acceleration (m/s², world axes) for the link weights, or None.
        frames: A :class:`~vjm_pin.kinematics.frames.FrameKinematics` to share (it must evaluate
            :attr:`frame_ids`); a private one by default.
    """

    def __init__(
        self, vm, loads: Sequence[Load] = (), gravity=None, frames: FrameKinematics | None = None
    ):
        model = vm.model if isinstance(vm, VjmModel) else vm
        if not isinstance(model, pin.Model):
            raise ArgumentError(
                f"vm must be a VjmModel or a pinocchio.Model, got {type(vm).__name__}"
            )
        if isinstance(loads, Load):
            loads = (loads,)
        names = [f.name for f in model.frames]
        ids = []
        for ld in loads:
            if not isinstance(ld, Load):
                raise ArgumentError(f"loads must be Load objects, got {type(ld).__name__} {ld!r}")
            if not model.existFrame(ld.frame):
                raise FrameNotFound(ld.frame, names, "load")
            ids.append(int(model.getFrameId(ld.frame)))
        self.model = model
        self.loads: tuple[Load, ...] = tuple(loads)
        self.load_frame_ids: tuple[int, ...] = tuple(ids)
        self.frame_ids: tuple[int, ...] = tuple(dict.fromkeys(ids))
        if frames is not None and not set(self.frame_ids) <= set(frames.frame_ids):
            raise ArgumentError("the shared FrameKinematics does not evaluate every load frame")
        self.frames = frames or FrameKinematics(model, self.frame_ids)
        self.gravity = None if gravity is None else _finite_vector(gravity, (3,), "gravity (m/s²)")
        self._gmodel = None
        if self.gravity is not None and np.any(self.gravity):
            self._gmodel = model.copy()  # never change the caller's model
            self._gmodel.gravity.linear = self.gravity

    def evaluate(self, x: np.ndarray, hessian: bool = True) -> LoadState:
        """Generalised force, its derivative (with ``hessian``) and potential at ``x`` (nq,)."""
        nv = self.model.nv
        states = self.frames.evaluate(x, hessian=hessian) if self.frame_ids else {}
        x = np.asarray(x, float)
        force = np.zeros(nv)
        deriv = np.zeros((nv, nv)) if hessian else None
        pot: float | None = 0.0
        for ld, fid in zip(self.loads, self.load_frame_ids):
            st = states[fid]
            force += st.jacobian.T @ ld.wrench
            if hessian:
                deriv += contract_hessian(st.hessian, ld.wrench)
            if pot is not None:
                pot = None if np.any(ld.wrench[3:]) else pot - float(ld.wrench[:3] @ st.position)
        if self._gmodel is not None:
            gm, gd = self._gmodel, data_for(self.model)  # each call below recomputes at x
            force -= np.asarray(pin.computeGeneralizedGravity(gm, gd, x))
            if hessian:
                deriv -= np.asarray(pin.computeGeneralizedGravityDerivatives(gm, gd, x))
            if pot is not None:
                pot += float(pin.computePotentialEnergy(gm, gd, x))
        return LoadState(force, deriv, pot)


def dead_load_state(
    vm, x, loads: Sequence[Load] = (), gravity=None, hessian: bool = True
) -> LoadState:
    """One-shot :meth:`DeadLoads.evaluate` (builds the evaluator each call; keep a
    :class:`DeadLoads` for repeated use)."""
    return DeadLoads(vm, loads, gravity).evaluate(x, hessian=hessian)
