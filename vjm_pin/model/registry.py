"""Bundled models: the generated VJM URDFs in ``models/urdf/`` and name resolution."""

from __future__ import annotations

import os
from pathlib import Path

from vjm_pin.exceptions import ArgumentError, ModelError
from vjm_pin.model.format import VjmModel, load_vjm


def models_dir() -> Path:
    """Folder of the bundled VJM URDFs.

    ``$VJM_PIN_MODELS`` if set; else the package's own copy ``vjm_pin/data`` (what a wheel
    carries, see ``setup.py``); else ``<checkout>/models/urdf`` (an editable install, where
    the models are generated).
    """
    env = os.environ.get("VJM_PIN_MODELS")
    if env:
        return Path(env)
    packaged = Path(__file__).resolve().parents[1] / "data"
    if any(packaged.glob("*.urdf")):
        return packaged
    return Path(__file__).resolve().parents[2] / "models" / "urdf"


def bundled_models() -> dict[str, Path]:
    """Name → path of every bundled model (file stem without ``.urdf``)."""
    d = models_dir()
    return {p.stem: p for p in sorted(d.glob("*.urdf"))} if d.is_dir() else {}


def is_vjm_urdf(path: Path) -> bool:
    """Whether the file at ``path`` carries VJM tags (namespace ``urn:vjm-pin:1``)."""
    from vjm_pin.model.format import NS

    try:
        return NS in Path(path).read_text()
    except UnicodeDecodeError:
        raise ModelError(f"{path}: not a URDF text file (not UTF-8)") from None
    except OSError as e:
        raise ModelError(f"cannot read model file {path}: {e.strerror or e}") from None


def model_path(name: str) -> Path | None:
    """The URDF file of ``name`` (a file path, or a bundled model name), or None (a robot
    name, an unknown name)."""
    p = Path(name)
    if p.is_file():
        return p
    return bundled_models().get(str(name))


def resolve(name_or_path: str, *, frame=None, q=None, pose_name=None, springs=None):
    """Load a model from a VJM URDF, a bundled model name, a plain (rigid) URDF or the name of
    an ``example-robot-data`` robot.

    Rigid URDFs and robots get the defaults of :mod:`vjm_pin.model.robots` (actuator springs,
    rigid links), optionally the spring spec ``springs``, the end ``frame``, the named SRDF
    pose ``pose_name`` and the joint positions ``q`` ({name: rad or m}). For a VJM URDF or a
    bundled model only ``q`` applies (:meth:`VjmModel.with_positions`).

    Every model kind loads: open chains, and mechanisms with loop closures (``vm.closures``,
    solved by :class:`~vjm_pin.solver.MechanismSolver`; the serial
    :class:`~vjm_pin.solver.EquilibriumSolver` refuses them).

    Returns:
        (vm, robot): the :class:`VjmModel`, and the :class:`~vjm_pin.model.robots.RobotModel` it was
        built from (None for VJM URDFs and bundled models).

    Raises:
        ModelError: a missing file, or options a VJM model cannot take.
        UnknownRobot: neither a file, a bundled model nor a robot (lists the names).
    """
    from vjm_pin.model.robots import UnknownRobot, build_robot, robot_names

    if not isinstance(name_or_path, (str, Path)) or not str(name_or_path).strip():
        raise ArgumentError(
            "name_or_path must be a model name or a URDF path (str or pathlib.Path), "
            f"got {type(name_or_path).__name__} {name_or_path!r}"
        )
    if q is not None and not isinstance(q, dict):
        raise ArgumentError(f"q must be a dict {{joint name: value (rad or m)}}, got {type(q).__name__} {q!r}")
    p = Path(name_or_path)
    if p.is_dir():
        raise ModelError(f"{p}: is a folder, not a model file")
    vjm_path = None
    if p.is_file():
        if is_vjm_urdf(p):
            vjm_path = p
        else:
            rm = build_robot(p, frame=frame, q=q, pose_name=pose_name, springs=springs)
            return rm.vm, rm
    elif p.suffix == ".urdf":
        raise ModelError(f"model file not found: {p}")
    else:
        models = bundled_models()
        if name_or_path in models:
            vjm_path = models[name_or_path]
        elif name_or_path in robot_names():
            rm = build_robot(name_or_path, frame=frame, q=q, pose_name=pose_name, springs=springs)
            return rm.vm, rm
        else:
            raise UnknownRobot(name_or_path, list(models) + robot_names())
    given = [k for k, v in (("frame", frame), ("pose_name", pose_name), ("springs", springs)) if v is not None]
    if given:
        raise ModelError(
            f"options {', '.join(given)} apply to rigid URDFs and robots; '{name_or_path}' is a VJM model "
            "whose frame and springs are in its tags"
        )
    vm = load_vjm(vjm_path)
    if q:
        vm = vm.with_positions(q)
    return vm, None


def resolve_model(name_or_path: str, **robot_options) -> VjmModel:
    """Load a VJM model from a path or a name (see :func:`resolve`; options: ``frame``,
    ``q``, ``pose_name``, ``springs``).

    Raises:
        ModelError: neither a file nor a known model name (the message lists the names).
    """
    return resolve(name_or_path, **robot_options)[0]
