"""An :class:`~vjm_pin.solver.equilibrium.EquilibriumResult` whose derived fields are computed when
first read: the result of every continuation step of a serial curve
(:meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._corrector_result`), where most of them are
never read.

``q``, ``theta``, ``deflection`` (``log3`` of the end rotation), ``position``, ``rotation`` and
``energy`` (``½(θ−θ₀)ᵀK_θ(θ−θ₀)``) are computed by the same expressions as
:meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._pack`, from the converged iteration's own
arrays (never handed out), when first read, and then kept: the same numbers, bit for bit. The
other fields are set at once. It is an ``EquilibriumResult`` in every other respect
(``isinstance``, :func:`dataclasses.replace`, ``repr``, frozen); a copy or a pickle is a plain
``EquilibriumResult`` with every field computed.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from vjm_pin.solver.equilibrium import EquilibriumResult

#: The fields computed when first read.
DEFERRED = ("q", "theta", "deflection", "position", "rotation", "energy")


class _Field:
    """A data descriptor for one deferred field: the value in the instance's ``__dict__``, else
    computed (:meth:`DeferredResult._derive`) and stored there. Setting stores (the dataclass
    ``__init__`` of :func:`dataclasses.replace` sets every field through ``object.__setattr__``)."""

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return getattr(EquilibriumResult, self.name, self)  # the dataclass default, if any
        d = obj.__dict__
        if self.name in d:
            return d[self.name]
        v = d[self.name] = obj._derive(self.name)
        return v

    def __set__(self, obj, value):
        obj.__dict__[self.name] = value


def _plain(fields: dict) -> EquilibriumResult:
    obj = object.__new__(EquilibriumResult)
    obj.__dict__.update(fields)
    return obj


class DeferredResult(EquilibriumResult):
    """:class:`~vjm_pin.solver.equilibrium.EquilibriumResult` with the fields of :data:`DEFERRED`
    computed when first read (module docstring). Built by :func:`deferred_result` only."""

    q = _Field("q")
    theta = _Field("theta")
    deflection = _Field("deflection")
    position = _Field("position")
    rotation = _Field("rotation")
    energy = _Field("energy")

    def _derive(self, name: str):
        x, state, consts = self.__dict__["_src"]
        p0, r0, theta_idx, theta0, q_idx, k_theta = consts
        pos, rot = state.position, state.rotation
        if name == "q":
            return x[q_idx]
        if name == "theta":
            return x[theta_idx]
        if name == "deflection":  # kinematics.chain.deflection
            return np.concatenate([pos - p0, pin.log3(rot @ r0.T)])
        if name == "position":
            return pos.copy()
        if name == "rotation":
            return rot.copy()
        d = x[theta_idx] - theta0  # energy(x)
        return 0.5 * float(d @ k_theta @ d)

    def _fields(self) -> dict:
        """Every field, computed, in the dataclass order."""
        return {name: getattr(self, name) for name in EquilibriumResult.__dataclass_fields__}

    def __reduce__(self):
        return _plain, (self._fields(),)

    def __copy__(self):
        return _plain(self._fields())

    def __deepcopy__(self, memo):
        import copy

        return _plain({k: copy.deepcopy(v, memo) for k, v in self._fields().items()})


def deferred_result(fields: dict, src: tuple) -> DeferredResult:
    """The :class:`DeferredResult` with the eager ``fields`` (every field of ``EquilibriumResult``
    but :data:`DEFERRED`) and the sources of the others, ``src`` = ``(x, state, (p0, r0, theta_idx,
    theta0, q_idx, K_theta))``: the converged configuration and its
    :class:`~vjm_pin.kinematics.chain.KinematicState` (the end placement: arrays no one else writes)
    and the solver's and model's constants. (:meth:`~vjm_pin.solver.equilibrium.EquilibriumSolver._corrector_result`
    builds the same object inline.)"""
    obj = object.__new__(DeferredResult)
    d = obj.__dict__
    d.update(fields)
    d["_src"] = src
    return obj
