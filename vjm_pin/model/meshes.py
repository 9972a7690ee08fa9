"""Mesh files of a URDF: ``package://``, ``file://`` and relative names made absolute.

ROS URDFs name their meshes ``package://<pkg>/meshes/x.stl``; the files live wherever the
package was installed. The search path is, in order: the folders the user gives
(``package_dirs``), the folders of ``ROS_PACKAGE_PATH`` (``os.pathsep``-separated), the
URDF's own folder, and the robot folders of ``example-robot-data``. Each name is resolved
with ``yourdfpy``'s file-name handlers (``package://`` stripped and looked up in a folder and
its parents, relative names against the folder), the first existing file wins.

:func:`resolve_meshes` returns the URDF text with every found mesh as an absolute path (so
Pinocchio's geometry loader needs no package path of its own) and the list of names that
were not found: the caller warns about each instead of silently drawing a stick figure.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

#: A ``<mesh filename="...">`` attribute (either quote).
_MESH = re.compile(r"""(<mesh\b[^>]*?\bfilename\s*=\s*)(["'])(.*?)\2""", re.S)


@dataclass(frozen=True)
class MeshResolution:
    """Result of :func:`resolve_meshes`.

    Attributes:
        urdf: The URDF text, found meshes rewritten as absolute paths.
        found: Original name → absolute path.
        missing: Names that no folder of the search path holds (in file order, unique).
        search_path: The folders searched, in order.
    """

    urdf: str
    found: dict
    missing: tuple
    search_path: tuple


def search_path(package_dirs=(), urdf_dir: str | Path | None = None) -> tuple[str, ...]:
    """Folders searched for meshes: ``package_dirs``, ``ROS_PACKAGE_PATH``, the URDF's folder,
    example-robot-data's robots folder (existing folders only, no duplicates)."""
    dirs: list[str] = [str(d) for d in package_dirs]
    dirs += [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    if urdf_dir is not None:
        dirs.append(str(urdf_dir))
    try:
        import example_robot_data as erd

        dirs.append(str(Path(erd.getModelPath("ur_description/urdf/ur5_robot.urdf"))))
    except (ImportError, OSError, ValueError):  # pragma: no cover - a declared dependency
        pass
    out: list[str] = []
    for d in dirs:
        p = str(Path(d).expanduser().resolve())
        if p not in out and Path(p).is_dir():
            out.append(p)
    return tuple(out)


def _locate(name: str, dirs) -> str | None:
    from yourdfpy import filename_handler_magic

    if name.startswith("file://"):
        name = name[len("file://") :]
    if os.path.isabs(name):
        return name if os.path.isfile(name) else None
    for d in dirs:
        cand = filename_handler_magic(name, dir=d)
        if cand and os.path.isfile(cand):
            return str(Path(cand).resolve())
        if name.startswith("package://"):  # <dir>/<pkg>/... where <dir> holds the package
            cand = os.path.join(d, name[len("package://") :])
            if os.path.isfile(cand):
                return str(Path(cand).resolve())
    return None


def resolve_meshes(urdf_text: str, package_dirs=(), urdf_dir: str | Path | None = None) -> MeshResolution:
    """Resolve every ``<mesh filename=...>`` of ``urdf_text`` (see the module docstring)."""
    dirs = search_path(package_dirs, urdf_dir)
    found: dict[str, str] = {}
    missing: list[str] = []

    def sub(m: re.Match) -> str:
        name = m.group(3)
        path = found.get(name) or _locate(name, dirs)
        if path is None:
            if name not in missing:
                missing.append(name)
            return m.group(0)
        found[name] = path
        return f"{m.group(1)}{m.group(2)}{path}{m.group(2)}"

    text = _MESH.sub(sub, urdf_text)
    return MeshResolution(text, found, tuple(missing), dirs)
