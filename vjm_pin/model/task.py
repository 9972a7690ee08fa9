"""Task vectors: the one check for "3 or 6 numbers, finite, in the task".

A deflection, a wrench or a direction of the task frame is given as

- 6 numbers ``(x, y, z, rx, ry, rz)`` (m and rad, or N and N·m; world axes),
- 3 numbers: the translational part, the rotational part zero,
- or, where a caller allows it, one number per task component (in task order).

:func:`task_vector` turns any of these into a (6,) float array, refusing NaN/inf, other
counts, and non-zero components outside the task (the end is free there: nothing can be
prescribed or carried), each with one line naming the quantity and its unit.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from vjm_pin.exceptions import InputError
from vjm_pin.model.format import COMPONENTS


def task_vector(
    values,
    task: Sequence[int] = tuple(range(6)),
    name: str = "vector",
    unit: str = "m, rad",
    *,
    task_sized: bool = False,
    outside_task: str = "refuse",
) -> np.ndarray:
    """``values`` as a (6,) float array in the task frame's components.

    Args:
        values: 6 numbers, 3 (translation; rotation zero) or, with ``task_sized``, one per
            task component (this reading wins when the task has 3 components).
        task: Indices (0–5) of the task components, in order.
        name, unit: How the quantity is named in messages ("deflection", "m, rad").
        task_sized: Accept ``len(task)`` numbers as the task components.
        outside_task: ``"refuse"`` (non-zero components outside the task are an error) or
            ``"keep"``.

    Raises:
        InputError: not numbers, a wrong count, NaN/inf, or (``"refuse"``) a non-zero
            component outside the task.
    """
    try:
        a = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise InputError(f"{name} must be numbers ({unit}), got {values!r}") from None
    task = tuple(int(i) for i in task)
    if a.size == 6:
        out = a.copy()
    elif task_sized and a.size == len(task):  # before "3 = translation": a task (x, z, ry) reads
        out = np.zeros(6)  # 3 numbers as its own components, never as a translation
        out[list(task)] = a
    elif a.size == 3:
        out = np.concatenate([a, np.zeros(3)])
    else:
        counts = ["3", "6"] + ([str(len(task))] if task_sized and len(task) not in (3, 6) else [])
        raise InputError(f"{name} must have {' or '.join(counts)} components ({unit}), got {a.size}")
    if not np.all(np.isfinite(out)):
        raise InputError(f"{name} contains NaN or infinite values: {a.tolist()}")
    if outside_task == "refuse":
        off = [COMPONENTS[i] for i in range(6) if i not in task and out[i] != 0.0]
        if off:
            names = [COMPONENTS[i] for i in task]
            raise InputError(
                f"{name} has components {off} outside the task {names}: the end is free there"
            )
    elif outside_task != "keep":
        raise ValueError(f"outside_task must be 'refuse' or 'keep', got {outside_task!r}")
    return out
