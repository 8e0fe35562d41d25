"""Whether numba may cache compiled kernels on disk here: decided once per process, at run time.

``numba.njit(cache=True)`` raises at import (``RuntimeError: cannot cache function ...: no locator
available``) where none of numba's cache folders is writable: a read-only install (a Docker image run
as a non-root user, a read-only root file system) with no writable home (``HOME=/nonexistent``).
Every module that compiles a kernel asks :func:`jit_cache` instead of writing ``cache=True``::

    @numba.njit(cache=jit_cache(__file__), nogil=True)

:func:`jit_cache` looks at the folders numba itself would use, in numba's order (its cache locators:
``NUMBA_CACHE_DIR``, the module's ``__pycache__``, the user cache folder ``$XDG_CACHE_HOME/numba`` or
``~/.cache/numba``) and answers True when one of them can be created and written (numba's own test:
``os.makedirs`` and a temporary file). Otherwise it answers False: the kernels are compiled in memory
on first use in every process (a few seconds), and one note says so on stderr, once per process. It
never raises. Set ``NUMBA_CACHE_DIR`` to a writable folder to cache there.

Example:
    >>> import weather_gym.core._jit_cache as jc
    >>> isinstance(jc.jit_cache(jc.__file__), bool)
    True
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
from pathlib import Path

__all__ = ["jit_cache", "cache_folders"]

NOTE = ("note: numba finds no writable cache folder (NUMBA_CACHE_DIR, the package's __pycache__, the user "
        "cache folder): compiling in memory, a few seconds each run; set NUMBA_CACHE_DIR to a writable folder "
        "to cache the compiled code")


def _user_cache_dir() -> str:
    """numba's user-wide cache folder (``numba.misc.appdirs.user_cache_dir('numba')``), without importing numba."""
    if sys.platform == "win32":  # pragma: no cover - CSIDL_LOCAL_APPDATA
        return os.path.join(os.environ.get("LOCALAPPDATA", os.path.expanduser("~")), "numba", "Cache")
    if sys.platform == "darwin":  # pragma: no cover
        return os.path.join(os.path.expanduser("~/Library/Caches"), "numba")
    return os.path.join(os.getenv("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "numba")


def cache_folders(module_file: str | os.PathLike) -> list[str]:
    """The folders numba would try for the kernels of ``module_file``, in its order."""
    folders = []
    if os.environ.get("NUMBA_CACHE_DIR"):
        folders.append(os.environ["NUMBA_CACHE_DIR"])
    folders.append(os.path.join(os.path.dirname(os.path.abspath(module_file)), "__pycache__"))
    folders.append(_user_cache_dir())
    return folders


def _writable(folder: str) -> bool:
    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except (OSError, ValueError):  # ValueError: a name with a NUL byte
        return False
    return True


@functools.cache
def _decide(folder: str) -> bool:
    ok = any(_writable(f) for f in cache_folders(Path(folder) / "_"))
    if not ok:
        _note()
    return ok


@functools.cache
def _note() -> None:
    try:
        print(NOTE, file=sys.stderr, flush=True)
    except (OSError, ValueError, AttributeError):  # no stderr (closed, or None under pythonw): stay silent
        pass


def jit_cache(module_file: str | os.PathLike) -> bool:
    """``cache=`` for ``numba.njit`` in ``module_file``: True where numba can write its cache, else False (a note)."""
    try:
        return _decide(os.path.dirname(os.path.abspath(module_file)))
    except Exception:  # never raise: compiling without a cache always works  # noqa: BLE001
        return False
