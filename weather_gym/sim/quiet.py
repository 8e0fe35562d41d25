"""Silencing what C code prints: PyBullet's build-time banner, the EGL plugin's vendor lines.

Example:
    >>> from weather_gym.sim.quiet import quiet_c_output
    >>> with quiet_c_output():
    ...     pass
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile


@contextlib.contextmanager
def quiet_c_output(capture: list[str] | None = None):
    """Silence what C code prints to stdout and stderr (the EGL plugin prints GL vendor lines);
    with ``capture`` (a list) the text is appended to it.

    C's stdio buffers its output, so the buffers are flushed before the descriptors are restored;
    otherwise the lines would come out later, interleaved with progress bars.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        yield
        return
    sink = tempfile.TemporaryFile() if capture is not None else None
    target = sink.fileno() if sink is not None else os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(target, 1)
        os.dup2(target, 2)
        yield
    finally:
        _libc_fflush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
        if sink is not None:
            sink.seek(0)
            capture.append(sink.read().decode("utf-8", "replace"))  # type: ignore[union-attr]  # a sink only with a list
            sink.close()
        else:
            os.close(target)


def _libc_fflush() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library to flush
        pass
