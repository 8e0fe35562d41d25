"""The paths a command reads: confinement of a path read from a file, and the declared inputs that
no output may touch. :mod:`weather_gym.core._io` checks every output against them (and re-exports these).

Example:
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> resolve_inside(d, "images/000000.png", what="annotations.json image 0").name
    '000000.png'
    >>> resolve_inside(d, "/etc/passwd", what="annotations.json image 3")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.OutsideRootError: annotations.json image 3: '/etc/passwd' is an absolute path; ...
"""

from __future__ import annotations

import contextvars
import os
from pathlib import Path

from weather_gym.core.errors import OutputPathError, OutsideRootError

__all__ = ["check_not_input", "declare_inputs", "resolve_inside"]


# ------------------------------------------------------------------------------------ confinement
def resolve_inside(root: str | os.PathLike, relative: str | os.PathLike, *, what: str) -> Path:
    """``root / relative``, resolved, after checking that it stays inside ``root``.

    ``relative`` comes from a file (a dataset's ``file_name``, a scenario's track CSV, ...);
    ``what`` says where (``"DIR/annotations.json: image 3 'file_name'"``) and starts the message
    of the :class:`OutsideRootError` raised for an absolute path, a ``..`` that climbs out, or a
    symlink inside ``root`` that points outside it.
    """
    if not isinstance(relative, (str, os.PathLike)) or not os.fspath(relative):
        raise OutsideRootError(f"{what}: expected a relative path inside {root}, got {relative!r}")
    text = os.fspath(relative)
    if "\x00" in text:
        raise OutsideRootError(f"{what}: {text!r} contains a NUL byte")
    if Path(text).is_absolute() or Path(text).drive:
        raise OutsideRootError(f"{what}: {text!r} is an absolute path; paths here must be relative to {root}")
    base = Path(root).resolve()
    target = (base / text).resolve()
    if not target.is_relative_to(base):
        raise OutsideRootError(f"{what}: {text!r} leads outside {root} (to {target}); "
                               f"paths here must stay inside {root}")
    return target


# ------------------------------------------------------------------------- an input is never an output
_INPUTS: contextvars.ContextVar[tuple[tuple[Path, Path, str], ...]] = contextvars.ContextVar(
    "weather_gym_inputs", default=())


def declare_inputs(*paths: str | os.PathLike | None) -> None:
    """Declare what the running command reads (files or folders; ``None`` is skipped).

    From then on (in this context: the CLI runs each command in a fresh one) :func:`check_output`,
    :func:`check_not_input` and every writer here refuse an output that is, or lies inside, one of
    them, ``overwrite`` or not.

    Example:
        >>> import contextvars, tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> def cmd():
        ...     declare_inputs(d / "log.npz")
        ...     check_not_input(d / "log.npz")
        >>> contextvars.copy_context().run(cmd)
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.OutputPathError: output ... is an input of this command (...); ...
    """
    entries = list(_INPUTS.get())
    for p in paths:
        if p is not None:
            entries.append((Path(os.path.abspath(p)), Path(p).resolve(), str(p)))
    _INPUTS.set(tuple(entries))


def check_not_input(path: str | os.PathLike, *, what: str = "output") -> None:
    """Refuse (:class:`OutputPathError`) an output ``path`` that is, or lies inside, a declared input."""
    a, r = Path(os.path.abspath(path)), Path(path).resolve()
    for ia, ir, name in _INPUTS.get():
        same = a == ia or r == ir
        if same or a.is_relative_to(ia) or r.is_relative_to(ir):
            where = "is an input" if same else "lies inside an input"
            raise OutputPathError(f"{what} {path} {where} of this command ({name}); an input is never an "
                                  "output, --overwrite or not: choose another path")
