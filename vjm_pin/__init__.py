"""vjm_pin: loaded-mode stiffness analysis of manipulators with passive joints.

Implements Pashkevich, Klimchik, Chablat, "Enhanced stiffness modeling of manipulators
with passive joints" (Mechanism and Machine Theory 46, 2011) on Pinocchio: VJM models as
URDF, loaded equilibrium, its stability, the loaded Cartesian stiffness and
force–deflection curves with buckling.
"""

from .exceptions import (
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
from .generator import generate_vjm, load_spec
from .model import SpringGroup, VjmModel, load_vjm
from .solver import (
    EquilibriumResult,
    EquilibriumSolver,
    StabilityResult,
    StiffnessResult,
    check_stability,
    loaded_stiffness,
    solve_equilibrium,
    solve_for_wrench,
    unloaded_stiffness,
)

__version__ = "0.1.0"

__all__ = [
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
    "generate_vjm",
    "load_spec",
    "load_vjm",
    "loaded_stiffness",
    "solve_equilibrium",
    "solve_for_wrench",
    "unloaded_stiffness",
]
