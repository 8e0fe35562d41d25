"""One exclusive lock for long writers: a second writer into the same output folder is refused up front.

:func:`exclusive_folder` holds an exclusive ``flock`` on the folder itself (no lock file is left
behind, and the kernel releases the lock when the process ends, however it ends). A second holder,
in this process or another, gets :class:`~weather_gym.core.errors.OutputExistsError` with the message
the caller gave, at once: it never waits. On a file system without locks the block runs unlocked. Used by ``dataset import`` and ``evaluate``'s results
folder; any long writer (render, gap, surrogate logs, training) can hold one the same way.

:func:`waiting_lock` is the other kind, for a shared cache: one process computes an entry while the
others *wait* on the same lock file, then read what it wrote.

Example:
    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> with exclusive_folder(d, busy="another import writes there"):
    ...     with exclusive_folder(d, busy="another import writes there"):
    ...         pass
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.OutputExistsError: another import writes there
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator

from weather_gym.core.errors import OutputExistsError, OutputPathError

__all__ = ["exclusive_folder", "waiting_lock"]


@contextlib.contextmanager
def exclusive_folder(folder: str | os.PathLike, *, busy: str) -> Iterator[None]:
    """Hold an exclusive lock on the existing ``folder`` for the block; ``busy``: the message of the
    :class:`OutputExistsError` raised when another writer holds it (no lock on platforms without ``flock``)."""
    try:
        import fcntl
    except ModuleNotFoundError:  # pragma: no cover - Windows: no lock
        yield
        return
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise OutputPathError(f"cannot lock the output folder {folder}: {exc.strerror or exc}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            locked = True
        except BlockingIOError:
            raise OutputExistsError(busy) from None
        except OSError as exc:  # a file system without locks (some network mounts): go on without one
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EINVAL):
                raise OutputPathError(f"cannot lock the output folder {folder}: {exc.strerror or exc}") from None
            locked = False
        try:
            yield
        finally:
            if locked:
                fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


@contextlib.contextmanager
def waiting_lock(path: str | os.PathLike) -> Iterator[bool]:
    """Hold an exclusive ``flock`` on the lock file ``path`` (created if needed), waiting for any other
    holder (another process computing the same cache entry) to finish first. Yields whether it locked:
    False where the file cannot be created or the file system has no locks (then the block runs
    unlocked; the caller's atomic writes keep readers safe).

    Example:
        >>> import tempfile, os
        >>> with waiting_lock(os.path.join(tempfile.mkdtemp(), "entry.lock")) as locked:
        ...     locked
        True
    """
    try:
        import fcntl
    except ModuleNotFoundError:  # pragma: no cover - Windows: no lock
        yield False
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            locked = True
        except OSError:
            locked = False
        try:
            yield locked
        finally:
            if locked:
                fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)
