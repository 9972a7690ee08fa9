"""One ``pin.Data`` per Pinocchio model and thread, shared by every kinematics user (kinematics layer).

Why: Pinocchio 4.1 allocates second-order derivative tensors of size nv³ in every ``pin.Data``
(``createData`` of the 231-coordinate ``orthoglide-loop-q0`` takes seconds and ~600 MB), so a
solver must not create one per evaluator (issue 14: "one ``pin.Data`` per worker, none per pose").

Why sharing is safe: a ``pin.Data`` is only a scratch buffer. Every user in this package
(:class:`~vjm_pin.kinematics.frames.FrameKinematics`, the link weights of
:class:`~vjm_pin.kinematics.dead_loads.DeadLoads`, the mechanism solver's reference scales)
recomputes, in one call and at its own configuration, everything it reads from the Data
(``computeJointJacobians``/``forwardKinematics``/``computeGeneralizedGravity`` … at ``x``) and
copies what it keeps, before any other user can run on that thread. So interleaving users at
different configurations gives the same numbers, bit for bit, as private Datas
(``tests/test_shared_data.py``). A Data is not thread-safe, hence one per thread.

A model copy with the same joint tree (e.g. one carrying gravity) may use the Data of the model it
was copied from: ``data_for(original)``.

The cache holds the Data while the model object is alive (a weak reference to the model; the
entry is dropped when the model is collected).
"""

from __future__ import annotations

import threading
import weakref

import pinocchio as pin

from vjm_pin.exceptions import ArgumentError

_local = threading.local()


def _cache() -> dict[int, tuple[weakref.ref, pin.Data]]:
    c = getattr(_local, "cache", None)
    if c is None:
        c = _local.cache = {}
    return c


def data_for(model: pin.Model) -> pin.Data:
    """This thread's shared ``pin.Data`` of ``model`` (created on first use).

    Contract for callers: recompute what you read at your own configuration in the same call
    (module docstring); never keep references into the Data across calls.

    Raises:
        ArgumentError: ``model`` is not a ``pinocchio.Model``.
    """
    if not isinstance(model, pin.Model):
        raise ArgumentError(f"model must be a pinocchio.Model, got {type(model).__name__}")
    cache = _cache()
    key = id(model)
    hit = cache.get(key)
    if hit is not None and hit[0]() is model:
        return hit[1]
    return _remember(cache, key, model, model.createData())


def _remember(cache: dict, key: int, model: pin.Model, data: pin.Data) -> pin.Data:
    """Store ``data`` as ``model``'s shared Data in ``cache`` (this thread's), dropped with the model."""

    def _drop(_ref, cache=cache, key=key):
        entry = cache.get(key)
        if entry is not None and entry[0] is _ref:
            cache.pop(key, None)

    cache[key] = (weakref.ref(model, _drop), data)
    return data


def share_data(model: pin.Model, like: pin.Model) -> pin.Data:
    """Let ``model`` use ``like``'s shared ``pin.Data`` on this thread instead of a new one: for
    models of one joint tree (the same mechanism loaded at several reference configurations,
    whose frame placements differ at round-off), where ``createData`` of a large model costs
    about a second. Safe for the reason the Data is shared at all (module docstring: every user
    recomputes what it reads, from its own model). Returns the Data.

    Raises:
        ArgumentError: either is not a ``pinocchio.Model``, or they differ in their joint tree
            (parents, joint types, sizes, frame count; and Pinocchio's ``model.check(data)``).
    """
    if not isinstance(model, pin.Model):
        raise ArgumentError(f"model must be a pinocchio.Model, got {type(model).__name__}")
    data = data_for(like)
    if model is like:
        return data
    same = (
        isinstance(like, pin.Model) and model.nq == like.nq and model.nv == like.nv
        and model.njoints == like.njoints and model.nframes == like.nframes
        and list(model.parents) == list(like.parents) and list(model.idx_vs) == list(like.idx_vs)
        and [j.shortname() for j in model.joints] == [j.shortname() for j in like.joints]
        and model.check(data)
    )
    if not same:
        raise ArgumentError("share_data needs models of the same joint tree (the Data does not fit the model)")
    return _remember(_cache(), id(model), model, data)


def shared_data_count() -> int:
    """Number of shared Datas alive on this thread (for tests and diagnostics)."""
    return sum(1 for ref, _ in _cache().values() if ref() is not None)


__all__ = ["data_for", "share_data", "shared_data_count"]
