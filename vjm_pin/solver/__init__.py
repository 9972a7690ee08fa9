"""Solver layer: equilibrium (eq. 5–11), stability (eq. 19–23), stiffness (eq. 28–33).

Pure functions on numpy arrays and small dataclasses; no printing, no file I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from vjm_pin.solver.threads import one_blas_thread

if TYPE_CHECKING:
    from vjm_pin.kinematics.chain import Kinematics
    from vjm_pin.model.format import VjmModel
    from vjm_pin.solver.blocks import Blocks, evaluate_blocks, full_wrench
    from vjm_pin.solver.equilibrium import (
        COMPONENTS,
        EquilibriumResult,
        EquilibriumSolver,
        solve_equilibrium,
        solve_for_wrench,
    )
    from vjm_pin.solver.mechanism import MechanismResult, MechanismSolver
    from vjm_pin.solver.stability import (
        StabilityResult,
        check_stability,
        check_stability_held,
        null_space,
        reduced_matrix,
    )
    from vjm_pin.solver.stiffness import (
        StiffnessResult,
        eq28_matrix,
        stiffness_eq30,
        stiffness_eq32,
        stiffness_eq33,
        stiffness_from_blocks,
        stiffness_rigid,
    )

#: Public name → the submodule defining it. Imported on first use (PEP 562 ``__getattr__``): a
#: one-shot ``vjm-pin analyze`` of a serial robot then never loads the mechanism solver (issue 14).
_LAZY = {
    "Blocks": "blocks",
    "evaluate_blocks": "blocks",
    "full_wrench": "blocks",
    "COMPONENTS": "equilibrium",
    "EquilibriumResult": "equilibrium",
    "EquilibriumSolver": "equilibrium",
    "solve_equilibrium": "equilibrium",
    "solve_for_wrench": "equilibrium",
    "MechanismResult": "mechanism",
    "MechanismSolver": "mechanism",
    "StabilityResult": "stability",
    "check_stability": "stability",
    "check_stability_held": "stability",
    "null_space": "stability",
    "reduced_matrix": "stability",
    "StiffnessResult": "stiffness",
    "eq28_matrix": "stiffness",
    "stiffness_eq30": "stiffness",
    "stiffness_eq32": "stiffness",
    "stiffness_eq33": "stiffness",
    "stiffness_from_blocks": "stiffness",
    "stiffness_rigid": "stiffness",
}


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


def blocks_at(vm: VjmModel, x: np.ndarray, wrench: np.ndarray, kin: Kinematics | None = None) -> Blocks:
    """:class:`Blocks` of model ``vm`` at configuration ``x`` under the 6-D ``wrench``."""
    from vjm_pin.kinematics.chain import Kinematics
    from vjm_pin.solver.blocks import evaluate_blocks

    kin = kin or Kinematics(vm.model, vm.frame_id)
    return evaluate_blocks(vm, kin, np.asarray(x, float), np.asarray(wrench, float))


@one_blas_thread  # one BLAS thread inside the library (vjm_pin.solver.threads)
def loaded_stiffness(vm: VjmModel, eq: EquilibriumResult, method: str = "eq30", kin: Kinematics | None = None) -> StiffnessResult:
    """Loaded Cartesian stiffness K_C (and K_q, K_θ) at the equilibrium ``eq`` (eq. 30/32/33).

    Raises:
        NoEquilibrium: ``eq`` did not converge (its stiffness would be that of no equilibrium).
        SingularStiffness: the matrix to invert is singular (the message says why)."""
    from vjm_pin.exceptions import NoEquilibrium
    from vjm_pin.solver.stiffness import stiffness_from_blocks

    if not getattr(eq, "converged", True):
        raise NoEquilibrium(
            "loaded stiffness of an equilibrium that did not converge: it describes no equilibrium "
            f"(path {eq.path!r}, residuals {eq.residuals})",
            eq,
            eq.residual(),
        )
    return stiffness_from_blocks(blocks_at(vm, eq.x, eq.wrench, kin), vm.task, method)


@one_blas_thread  # one BLAS thread inside the library (vjm_pin.solver.threads)
def unloaded_stiffness(vm: VjmModel, method: str = "eq30", kin: Kinematics | None = None) -> StiffnessResult:
    """Stiffness at the unloaded reference configuration (H = 0: Table 1 of the paper)."""
    from vjm_pin.solver.stiffness import stiffness_from_blocks

    return stiffness_from_blocks(blocks_at(vm, vm.reference, np.zeros(6), kin), vm.task, method)


__all__ = [
    "COMPONENTS",
    "Blocks",
    "EquilibriumResult",
    "EquilibriumSolver",
    "MechanismResult",
    "MechanismSolver",
    "StabilityResult",
    "StiffnessResult",
    "blocks_at",
    "check_stability",
    "check_stability_held",
    "eq28_matrix",
    "evaluate_blocks",
    "full_wrench",
    "loaded_stiffness",
    "null_space",
    "reduced_matrix",
    "solve_equilibrium",
    "solve_for_wrench",
    "stiffness_eq30",
    "stiffness_eq32",
    "stiffness_eq33",
    "stiffness_from_blocks",
    "stiffness_rigid",
    "unloaded_stiffness",
]
