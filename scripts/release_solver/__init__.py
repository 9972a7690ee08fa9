"""A frozen copy of the serial solver as released before issue 14's kernel work (commit dbe652d:
``vjm_pin/kinematics/chain.py``, ``vjm_pin/solver/{blocks,stability,equilibrium}.py`` with the
imports among them made relative). For ``scripts/benchmark.py`` only: the "release" side of the
side-by-side ratios. Not part of the package; never edit it (regenerate with ``git show``)."""

from .equilibrium import EquilibriumSolver  # noqa: F401
