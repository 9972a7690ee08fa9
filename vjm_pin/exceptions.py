"""Exceptions of vjm_pin.

Every error that vjm_pin raises on bad input or on a failed computation is a
subclass of :class:`VjmError`, carries the data needed to understand it, and
has a one-line message naming the element (joint, frame, file, key) at fault.
"""

from __future__ import annotations

from collections.abc import Sequence


class VjmError(Exception):
    """Base class of all vjm_pin errors."""


class ModelError(VjmError):
    """A model (URDF, VJM tags, spring specification) is malformed or inconsistent."""


class UrdfParseError(ModelError):
    """The URDF text could not be parsed (XML or Pinocchio parser error)."""


class JointNotFound(ModelError):
    """A joint name does not exist in the model.

    Attributes:
        name: The unknown joint name.
        candidates: The joint names that do exist.
    """

    def __init__(self, name: str, candidates: Sequence[str], context: str = ""):
        self.name = name
        self.candidates = list(candidates)
        where = f" ({context})" if context else ""
        shown = ", ".join(self.candidates[:30]) + (" ..." if len(self.candidates) > 30 else "")
        super().__init__(f"unknown joint '{name}'{where}; joints are: {shown}")


class FrameNotFound(ModelError):
    """A frame (or link) name does not exist in the model.

    Attributes:
        name: The unknown frame name.
        candidates: The frame names that do exist.
    """

    def __init__(self, name: str, candidates: Sequence[str], context: str = ""):
        self.name = name
        self.candidates = list(candidates)
        where = f" ({context})" if context else ""
        shown = ", ".join(self.candidates[:40]) + (" ..." if len(self.candidates) > 40 else "")
        super().__init__(f"unknown frame '{name}'{where}; frames are: {shown}")


class RoleError(ModelError):
    """A joint has no role, several roles, or a role that does not fit its use."""


class StiffnessMatrixError(ModelError):
    """A spring stiffness matrix is of the wrong size, not symmetric or not positive definite."""


class SpecError(ModelError):
    """A spring specification (YAML or dict) has an unknown key or a wrong value."""


class InputError(VjmError):
    """A numerical input (target, wrench, configuration) is of the wrong size or not finite."""


class OutputError(InputError):
    """An output path cannot be written (missing or read-only folder, unknown extension,
    or it is one of the run's input files). Raised before any work starts."""


class NoEquilibrium(VjmError):
    """The equilibrium iteration did not converge.

    Attributes:
        result: The last iterate as an :class:`~vjm_pin.solver.EquilibriumResult`
            (``converged`` is ``False``), for inspection.
        residual: Norm of the residual of eq. (5) at the last iterate.
    """

    def __init__(self, message: str, result=None, residual: float = float("nan")):
        self.result = result
        self.residual = residual
        super().__init__(message)


class SingularStiffness(VjmError):
    """A stiffness matrix needed for the computation is singular.

    Attributes:
        eigenvalues: Eigenvalues or singular values that show the singularity.
    """

    def __init__(self, message: str, eigenvalues=None):
        self.eigenvalues = eigenvalues
        super().__init__(message)
