"""Output files: checked before the work starts, written atomically.

Every file vjm_pin writes for a user (plots, pages, map tables) goes through this module:

- :func:`check_output` runs *before* any computation: the folder must exist and be
  writable, the extension must be one the writer knows, and the path must not be one of
  the run's input files (a model or a spring specification is never overwritten). An
  existing output file is overwritten, as matplotlib's ``savefig`` does.
- :func:`atomic_output` gives the writer a temporary file in the same folder and renames it
  over the target only when the writer finished: an interrupted or failed run leaves no
  half-written file and keeps a previous output intact.

This is I/O of the outer layers (analysis, viz, CLI); the solver layer never writes files.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from vjm_pin.exceptions import OutputError

#: Extensions matplotlib writes without extra packages (``savefig`` picks the format from them).
PLOT_EXTENSIONS = (
    ".png",
    ".pdf",
    ".svg",
    ".svgz",
    ".eps",
    ".ps",
    ".jpg",
    ".jpeg",
    ".tif",
    ".tiff",
    ".webp",
)
#: Extensions of the self-contained meshcat page.
HTML_EXTENSIONS = (".html", ".htm")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _is_input(p: Path, inp) -> bool:
    q = Path(inp)
    if _same_file(p, q):
        return True
    try:
        return p.resolve() == q.resolve()
    except (OSError, RuntimeError):  # a symlink loop: not the same file as far as we can tell
        return False


def _check_folder(folder: Path, what: str, p: Path) -> None:
    """The folder exists, is a folder and a file can really be created in it.

    ``os.access`` answers for the permission bits only (root passes it everywhere), so a
    probe file is created and removed as well: that also catches read-only mounts and
    pseudo file systems such as ``/proc``.
    """
    if not folder.exists():
        raise OutputError(f"{what} '{p}': folder '{folder}' does not exist")
    if not folder.is_dir():
        raise OutputError(f"{what} '{p}': '{folder}' is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{what} '{p}': folder '{folder}' is not writable")
    try:
        fd, probe = tempfile.mkstemp(prefix=".vjm-pin-probe.", dir=folder)
    except OSError as e:
        raise OutputError(
            f"{what} '{p}': folder '{folder}' is not writable ({e.strerror or e})"
        ) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)


def check_output(
    path,
    extensions: Iterable[str],
    *,
    what: str = "output",
    inputs: Iterable = (),
) -> Path:
    """Check that ``path`` can be written as a ``what`` file; return it as a :class:`Path`.

    Nothing is written (a probe file is created and removed in the folder). Checked in this
    order: not empty, not one of ``inputs``, a known extension, not a folder, the folder
    exists and a file can be created in it, an existing file there is writable.

    Args:
        path: The output path (str or Path).
        extensions: The known extensions, with the dot (``(".png", ".pdf")``); an empty
            iterable accepts any.
        what: What the file is, for the message (``"plot"``, ``"--html"``).
        inputs: Paths of the run's input files (None entries are skipped); writing over
            one of them is refused, whatever the extension.

    Raises:
        OutputError: empty path, unknown extension, missing folder, folder not writable,
            the path is a folder, or it is an input file.
    """
    if path is None or str(path).strip() == "":
        raise OutputError(f"{what}: empty file name")
    p = Path(path)
    for inp in inputs:
        if inp is not None and _is_input(p, inp):
            raise OutputError(f"{what} '{p}' is the input file '{inp}': refusing to overwrite it")
    exts = tuple(e.lower() for e in extensions)
    if exts and p.suffix.lower() not in exts:
        raise OutputError(
            f"{what} '{p}': unknown extension '{p.suffix}' (known: {', '.join(exts)})"
        )
    if p.is_dir():
        raise OutputError(f"{what} '{p}' is a folder, not a file")
    _check_folder(p.parent, what, p)
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputError(f"{what} '{p}' exists and is not writable")
    return p


def check_output_dir(path, *, what: str = "output folder", inputs: Iterable = ()) -> Path:
    """Check that the folder ``path`` exists and is writable, or can be created (its
    nearest existing parent is a writable folder); nothing is created here (a probe file
    is created and removed in the nearest existing folder).

    Raises:
        OutputError: empty path, the path (or a parent) is a file, it is one of ``inputs``,
            or neither it nor its nearest existing parent is a writable folder.
    """
    if path is None or str(path).strip() == "":
        raise OutputError(f"{what}: empty folder name")
    p = Path(path)
    for inp in inputs:
        if inp is not None and _is_input(p, inp):
            raise OutputError(f"{what} '{p}' is the input file '{inp}': refusing to overwrite it")
    if p.exists() and not p.is_dir():
        raise OutputError(f"{what} '{p}' is a file, not a folder")
    probe = p.absolute()
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"{what} '{p}': '{probe}' is a file, not a folder")
    _check_folder(probe, what, p)
    return p


@contextlib.contextmanager
def atomic_output(path, mode: str | None = None) -> Iterator:
    """Write ``path`` atomically.

    Without ``mode``, yields the temporary :class:`Path` (same folder, same extension, so
    writers that pick the format from the name keep working); with ``mode`` (``"w"``,
    ``"wb"``), yields an open file object on it. On success the temporary file replaces
    ``path`` (:func:`os.replace`); on any exception (``KeyboardInterrupt`` included) it is
    removed and ``path`` is left as it was.
    """
    p = Path(path)
    tmp_path = named = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=f"{p.suffix}.part", dir=p.parent)
        os.close(fd)
        tmp_path = Path(tmp)
        # keep the final extension for writers that infer the format from the file name
        named = tmp_path.with_name(tmp_path.name[: -len(".part")])
        os.replace(tmp_path, named)
        if mode is None:
            yield named
        else:
            kwargs = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
            with open(named, mode, **kwargs) as fh:
                yield fh
        try:
            st = os.stat(p)
            os.chmod(named, st.st_mode & 0o7777)
        except FileNotFoundError:
            os.chmod(named, 0o666 & ~_umask())
        os.replace(named, p)
    except BaseException:
        for t in (named, tmp_path):
            if t is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(t)
        raise


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m
