"""Reading files from a source or dataset folder without leaving it: one confinement for every reader.

A folder of frames and labels (an import's source, a dataset) is untrusted: a symbolic link in it
(a frame, ``classes.txt``, a label or calibration file, a JSON, a linked sub-folder) may lead
anywhere on the machine. Every file a command reads from such a folder goes through here:

* :func:`confined` resolves the path and refuses it (:class:`OutsideRootError`) unless it stays
  inside the folder. The message names the path in the folder (the link), never what it points to,
  and nothing is read through it, so nothing private is quoted, copied or stored.
* :func:`walk_files` lists a folder's files (linked sub-folders that stay inside are followed once;
  one that leads out is refused; hidden entries and ``__MACOSX`` are skipped).
* :func:`read_text` / :func:`read_bytes` read a confined regular file; text must be UTF-8 (a byte
  order mark is allowed), else :class:`FileFormatError` naming the file and the first bad byte.

Paths given on the command line (``--annotations FILE``, ``--mask FILE``) are the user's own choice
and are not confined; paths *found in* or *named by* a folder are.

Example:
    >>> import os, tempfile
    >>> from pathlib import Path
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "classes.txt").write_text("blue_cone\\n")
    >>> read_text(d / "classes.txt", root=d)
    'blue_cone\\n'
    >>> os.symlink("/etc/hostname", d / "names.txt")
    >>> read_text(d / "names.txt", root=d)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.OutsideRootError: ...names.txt is a symbolic link (or lies under one) that leads outside ...
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from weather_gym.core.errors import FileFormatError, MissingInputError, OutsideRootError

__all__ = ["confined", "confined_file", "read_bytes", "read_text", "walk_files"]


def confined(path: str | os.PathLike, root: str | os.PathLike) -> Path:
    """``path`` (inside the folder ``root``, as found or named there) resolved; :class:`OutsideRootError`
    naming ``path`` when a symbolic link or ``..`` takes it out of ``root``."""
    base = Path(os.path.realpath(root))
    real = Path(os.path.realpath(path))
    if real != base and not real.is_relative_to(base):
        raise OutsideRootError(f"{path} is a symbolic link (or lies under one) that leads outside {root}; files "
                               f"read from {root} must stay inside it (copy the file in instead of linking it)")
    return real


def confined_file(path: str | os.PathLike, root: str | os.PathLike | None) -> Path:
    """:func:`confined` (when ``root`` is given), and the path must be a regular file (not a folder, pipe or
    device, which could block or never end): :class:`MissingInputError` / :class:`FileFormatError` naming it."""
    real = confined(path, root) if root is not None else Path(path)
    try:
        st = os.stat(real)
    except FileNotFoundError:
        raise MissingInputError(f"{path} not found") from None
    except OSError as exc:
        raise MissingInputError(f"{path} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise FileFormatError(f"{path} is not a regular file")
    return real


def read_bytes(path: str | os.PathLike, *, root: str | os.PathLike | None = None) -> bytes:
    """The bytes of the regular file ``path`` (confined to ``root`` when given)."""
    real = confined_file(path, root)
    try:
        fd = os.open(real, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise MissingInputError(f"{path} cannot be read: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as f:
        return f.read()


def read_text(path: str | os.PathLike, *, root: str | os.PathLike | None = None) -> str:
    """The UTF-8 text of ``path`` (a byte order mark is dropped); :class:`FileFormatError` naming the file
    and the first byte that is not UTF-8."""
    data = read_bytes(path, root=root)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path} is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
                              "save it as UTF-8") from None


HIDDEN_DIRS = frozenset({"__MACOSX"})
"""Folders an archive tool adds (macOS resource forks): skipped with the hidden (``.name``) entries."""


def walk_files(folder: str | os.PathLike[str], root: str | os.PathLike[str], *, hidden: bool = False) -> list[Path]:
    """Every file under ``folder`` (itself inside ``root``), as paths under ``folder``, sorted. Linked
    sub-folders are followed once when they stay inside ``root``; one that leads out is refused.
    Hidden files and folders (``.name``, ``__MACOSX``) are skipped unless ``hidden``."""
    seen: set[str] = set()
    files = []
    def unreadable(exc: OSError) -> None:
        raise MissingInputError(f"{exc.filename} cannot be read: {exc.strerror or exc}")

    for dirpath, dirnames, filenames in os.walk(folder, onerror=unreadable, followlinks=True):
        if not hidden:
            dirnames[:] = [d for d in dirnames if not d.startswith(".") and d not in HIDDEN_DIRS]
            filenames = [f for f in filenames if not f.startswith(".")]
        real = str(confined(dirpath, root))
        dirnames.sort()
        if real in seen:  # a link back to a folder already listed
            dirnames[:] = []
            continue
        seen.add(real)
        files += [Path(dirpath) / f for f in filenames]
    return sorted(files)
