"""Bundled models: the generated VJM URDFs in ``models/urdf/`` and name resolution."""

from __future__ import annotations

import os
from pathlib import Path

from .exceptions import ModelError
from .model import VjmModel, load_vjm


def models_dir() -> Path:
    """Folder of the bundled VJM URDFs (``$VJM_PIN_MODELS`` or ``<repo>/models/urdf``)."""
    env = os.environ.get("VJM_PIN_MODELS")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / "models" / "urdf"


def bundled_models() -> dict[str, Path]:
    """Name → path of every bundled model (file stem without ``.urdf``)."""
    d = models_dir()
    return {p.stem: p for p in sorted(d.glob("*.urdf"))} if d.is_dir() else {}


def resolve_model(name_or_path: str) -> VjmModel:
    """Load a VJM model from a path or the name of a bundled model.

    Raises:
        ModelError: neither a file nor a known model name (the message lists the names).
    """
    p = Path(name_or_path)
    if p.suffix == ".urdf" or p.is_file():
        if not p.is_file():
            raise ModelError(f"model file not found: {p}")
        return load_vjm(p)
    models = bundled_models()
    if name_or_path in models:
        return load_vjm(models[name_or_path])
    raise ModelError(
        f"unknown model '{name_or_path}': not a file and not a bundled model "
        f"({', '.join(models) or 'none found in ' + str(models_dir())})"
    )
