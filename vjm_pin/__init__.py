"""vjm_pin: loaded-mode stiffness analysis of manipulators with passive joints.

Implements Pashkevich, Klimchik, Chablat, "Enhanced stiffness modeling of manipulators
with passive joints" (Mechanism and Machine Theory 46, 2011) on Pinocchio: VJM models as
URDF, loaded equilibrium, its stability, the loaded Cartesian stiffness and
force–deflection curves with buckling.
"""

from typing import TYPE_CHECKING

from vjm_pin.exceptions import (
    EquilibriumCheckError,
    FrameNotFound,
    InputError,
    JointNotFound,
    ModelError,
    NoEquilibrium,
    RoleError,
    SingularStiffness,
    SpecError,
    StiffnessMatrixError,
    UrdfParseError,
    VjmError,
)

# The names below load Pinocchio and SciPy (seconds): they are imported on first use
# (PEP 562 ``__getattr__``), so ``import vjm_pin.cli`` is quick and the ``vjm-pin`` command
# handles a Ctrl-C during those imports (no traceback). Add a new export to both lists.
if TYPE_CHECKING:
    from vjm_pin.model.format import SpringGroup, VjmModel, load_vjm
    from vjm_pin.model.generator import generate_vjm, load_spec
    from vjm_pin.solver import (
        EquilibriumResult,
        EquilibriumSolver,
        StabilityResult,
        StiffnessResult,
        check_stability,
        check_stability_held,
        loaded_stiffness,
        solve_equilibrium,
        solve_for_wrench,
        unloaded_stiffness,
    )

_LAZY = {
    ".model.generator": ("generate_vjm", "load_spec"),
    ".model.format": ("SpringGroup", "VjmModel", "load_vjm"),
    ".solver": (
        "EquilibriumResult",
        "EquilibriumSolver",
        "StabilityResult",
        "StiffnessResult",
        "check_stability",
        "check_stability_held",
        "loaded_stiffness",
        "solve_equilibrium",
        "solve_for_wrench",
        "unloaded_stiffness",
    ),
}
_LAZY_NAMES = {name: module for module, names in _LAZY.items() for name in names}


def __getattr__(name: str):
    module = _LAZY_NAMES.get(name)
    if module is None:
        raise AttributeError(f"module 'vjm_pin' has no attribute '{name}'")
    import importlib

    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY_NAMES))

__version__ = "0.1.0"

__all__ = [
    "EquilibriumCheckError",
    "EquilibriumResult",
    "EquilibriumSolver",
    "FrameNotFound",
    "InputError",
    "JointNotFound",
    "ModelError",
    "NoEquilibrium",
    "RoleError",
    "SingularStiffness",
    "SpecError",
    "SpringGroup",
    "StabilityResult",
    "StiffnessMatrixError",
    "StiffnessResult",
    "UrdfParseError",
    "VjmError",
    "VjmModel",
    "check_stability",
    "check_stability_held",
    "generate_vjm",
    "load_spec",
    "load_vjm",
    "loaded_stiffness",
    "solve_equilibrium",
    "solve_for_wrench",
    "unloaded_stiffness",
]
