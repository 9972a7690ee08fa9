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


class ArgumentError(InputError):
    """A library function was called with an argument of the wrong type or an unknown value.
    The message names the argument and the allowed values (types, names or range)."""


class UnknownVjmTag(ModelError):
    """An element or attribute in the ``vjm`` namespace (``urn:vjm-pin:1``) that the format
    does not define, or a ``vjm`` element in a place where it does not belong.

    Attributes:
        name: The unknown element (``vjm:...``) or attribute name.
        parent: The element it was found in (``robot``, ``vjm:spring``, ...).
        line: Line number in the file (None if not known).
        candidates: The names that are allowed there.
    """

    def __init__(self, message: str, name: str, parent: str, line: int | None, candidates: Sequence[str]):
        self.name = name
        self.parent = parent
        self.line = line
        self.candidates = list(candidates)
        super().__init__(message)


class SpecProblems(SpecError):
    """A spring specification with one or more problems, all reported at once (one line).

    Attributes:
        source: Where the specification came from (file name, ``<YAML text>`` or ``<dict>``).
        problems: One ``"yaml.path: what is wrong"`` string per problem, document order.
    """

    def __init__(self, source: str, problems: Sequence[str]):
        self.source = source
        self.problems = list(problems)
        n = len(self.problems)
        head = f"spring specification {source}: " + (f"{n} problems: " if n > 1 else "")
        super().__init__(head + "; ".join(self.problems))


class MapInterrupted(KeyboardInterrupt):
    """A workspace map was interrupted (Ctrl-C); the workers are already stopped.

    A :class:`KeyboardInterrupt`, not a :class:`VjmError`: code that handles Ctrl-C in
    general still sees it. It carries what was finished.

    Attributes:
        result: The poses finished before the interrupt (possibly none), in the order they were
            requested: a :class:`~vjm_pin.analysis.maps.MapResult` from ``run_map``, a
            :class:`~vjm_pin.analysis.maps.MapSummary` (rows already in the CSV file) from
            ``stream_map``.
        requested: The number of poses the map was asked for.
    """

    def __init__(self, result, requested: int):
        self.result = result
        self.requested = int(requested)
        done = 0 if result is None else int(result.poses.shape[0])
        super().__init__(f"map interrupted after {done} of {self.requested} poses")


class SchedulerError(InputError):
    """No Dask scheduler can be used at an address (malformed, nothing listens, or what
    answers is not a scheduler).

    Attributes:
        address: The address as given. reason: What went wrong.
    """

    def __init__(self, address, reason: str, name: str = "Dask scheduler"):
        self.address = address
        self.reason = reason
        super().__init__(f"{name} '{address}': {reason}; expected tcp://HOST:PORT (e.g. tcp://127.0.0.1:8786)")


class EquilibriumCheckError(NoEquilibrium):
    """An equilibrium failed its own check (eq. 5 residual per unit, the stability verdicts
    recomputed, or K_C against re-solved neighbouring equilibria), also after a retry.

    Attributes:
        result: The checked :class:`~vjm_pin.solver.EquilibriumResult`.
        checks: What was measured (dict of numbers and verdicts).
    """

    def __init__(self, message: str, result=None, checks=None):
        self.checks = dict(checks or {})
        super().__init__(message, result, float(self.checks.get("statics_relative", float("nan"))))


class ClosureViolated(ModelError):
    """A loop closure (``<vjm:closure>``) is not satisfied at the model's reference
    configuration: the file is not assembled.

    Attributes:
        closure: The closure name. component: The violated component (``x`` … ``rz``).
        violation: Its value there (m or rad).
    """

    def __init__(self, message: str, closure: str, component: str, violation: float):
        self.closure = closure
        self.component = component
        self.violation = violation
        super().__init__(message)


class LoadError(VjmError):
    """A dead load, payload or gravity that cannot be applied (a bad mass, a model that
    cannot carry it in the asked analysis)."""


class UnknownRobot(ModelError):
    """A robot name that is neither a file, a bundled model nor an ``example-robot-data`` robot.

    Attributes:
        name: The unknown name.
        candidates: Known robot names.
    """

    def __init__(self, name: str, candidates):
        import difflib

        self.name = name
        self.candidates = list(candidates)
        self.close = difflib.get_close_matches(name, self.candidates, n=3)
        hint = f"; did you mean {', '.join(self.close)}?" if self.close else ""
        # one line: the full list (dozens of names) is in `candidates` and in `vjm-pin models`
        super().__init__(
            f"unknown model or robot '{name}': not a file, not a bundled model and not an "
            f"example-robot-data robot ({len(self.candidates)} known names){hint}"
        )


class AmbiguousFrame(FrameNotFound):
    """No default end frame: the robot's tree branches. Attributes: ``link`` (where it
    branches), ``branches`` (the child joints), ``candidates`` (leaf links with movable
    joints on their path)."""

    def __init__(self, link: str, branches, candidates):
        self.name = "<default>"
        self.link = link
        self.branches = list(branches)
        self.candidates = list(candidates)
        ModelError.__init__(
            self,
            f"the robot branches at link '{link}' into joints {self.branches}: choose the end frame; "
            f"candidates: {', '.join(self.candidates)}",
        )


class NoCriticalPoint(VjmError):
    """:func:`~vjm_pin.analysis.critical.critical_load` found no critical point: the followed
    branch stays stable under a force along the direction up to ``max_deflection`` (m or rad),
    or the search could not bracket one (the message says which)."""

    def __init__(self, message: str, max_deflection: float = float("nan")):
        self.max_deflection = max_deflection
        super().__init__(message)


class FreeMechanism(InputError):
    """With the end held only along the direction (``free=True``, ``--free``) the model is a
    mechanism at the start of the path: the loaded stiffness matrix on the motions the run
    leaves free (closures and the one held row) is singular there (e.g. passive joints with no
    load on them), so the end has no stiffness across the direction and the path is undefined.
    Raised before any tracing by ``trace_curve`` and ``critical_load``.

    Attributes:
        model: The model's name.
        components: The task components (names, ``"x"`` … ``"rz"``) the zero-stiffness motions
            move the end in (empty: an internal mechanism that leaves the end in place).
        eigenvalues: The zero eigenvalues (within the stability tolerance) of that matrix.
    """

    def __init__(self, message: str, model: str = "", components=(), eigenvalues=()):
        self.model = model
        self.components = tuple(components)
        self.eigenvalues = tuple(eigenvalues)
        super().__init__(message)
