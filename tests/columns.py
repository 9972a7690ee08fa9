"""The paper's Model C column (three links of the paper beam, 3 m in all) for the speed tests:
the compression direction and a deflection range well past buckling."""

from __future__ import annotations

import numpy as np

from vjm_pin.model.paper_models import PAPER_BEAM

#: Pushing the end towards the base (task vector, m).
COMPRESSION = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def max_deflection() -> float:
    """6 × the column's axial shortening at its Euler load (well past buckling), m."""
    a = PAPER_BEAM["a"] * PAPER_BEAM["b"]
    i_weak = PAPER_BEAM["b"] * PAPER_BEAM["a"] ** 3 / 12.0
    p_euler = np.pi**2 * PAPER_BEAM["E"] * i_weak / 3.0**2
    return 6.0 * p_euler * 3.0 / (PAPER_BEAM["E"] * a)
