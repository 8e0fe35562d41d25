"""Pick PyBullet's renderer: the EGL plugin (OpenGL, also on Mesa's software rasteriser) when it
loads and renders, else TinyRenderer (pure CPU). Both are deterministic; they differ from each other.

EGL and ``fork``: once a process has used EGL, a child forked from it (``multiprocessing``'s default
start method on Linux before Python 3.14, e.g. ``gymnasium.vector.AsyncVectorEnv()``) inherits
Mesa's state without its render threads, and its first EGL frame waits for them forever. Such a
child therefore never loads EGL: ``"auto"`` falls back to TinyRenderer (with a warning), ``"egl"``
raises. Start workers with ``spawn`` or ``forkserver`` (``AsyncVectorEnv(..., context="spawn")``)
to keep EGL in them.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import pkgutil
import sys
import warnings

import numpy as np
import pybullet as p

_egl_used = False
"""This process has loaded the EGL plugin."""
_forked_after_egl = False
"""This process was forked from one that had loaded the EGL plugin (EGL would hang here)."""


def _after_fork_in_child() -> None:
    global _forked_after_egl
    _forked_after_egl = _forked_after_egl or _egl_used


os.register_at_fork(after_in_child=_after_fork_in_child)


def _egl_plugin_path() -> str | None:
    loader = pkgutil.get_loader("eglRenderer")
    return loader.get_filename() if loader is not None else None  # type: ignore[attr-defined]


@contextlib.contextmanager
def quiet_c_output():
    """Silence what C code prints to stdout and stderr (the EGL plugin prints GL vendor lines).

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
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        _libc_fflush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def _libc_fflush() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library to flush
        pass


def setup_renderer(client: int, requested: str) -> tuple[str, int | None]:
    """Load the renderer for ``client``. Returns (name, plugin id); name is "egl" or "tiny".

    ``requested`` "auto" tries EGL and falls back to TinyRenderer; "egl" raises if EGL fails.
    The env var ``WEATHER_GYM_RENDERER`` overrides "auto".
    """
    global _egl_used
    if requested == "auto":
        requested = os.environ.get("WEATHER_GYM_RENDERER", "auto")
    if requested == "tiny":
        return "tiny", None
    if _forked_after_egl:
        msg = ("this process was forked from one that already used PyBullet's EGL renderer, and EGL hangs "
               "in such a child; start the worker processes with the 'spawn' or 'forkserver' method "
               "(e.g. AsyncVectorEnv(..., context='spawn')) to render with EGL there")
        if requested == "egl":
            raise RuntimeError(msg)
        warnings.warn(msg + "; using TinyRenderer in this process", RuntimeWarning, stacklevel=3)
        return "tiny", None
    path = _egl_plugin_path()
    plugin = -1
    if path is not None:
        with quiet_c_output():
            plugin = p.loadPlugin(path, "_eglRendererPlugin", physicsClientId=client)
        _egl_used = _egl_used or plugin >= 0
    if plugin >= 0 and _egl_renders(client):
        return "egl", plugin
    if plugin >= 0:
        with quiet_c_output():
            p.unloadPlugin(plugin, physicsClientId=client)
    if requested == "egl":
        raise RuntimeError(
            "the EGL renderer was requested but did not load; install libegl1 and libgl1-mesa-dri, "
            "or use renderer='tiny' / 'auto'"
        )
    return "tiny", None


def _egl_renders(client: int) -> bool:
    try:
        with quiet_c_output():
            _, _, rgba, _, _ = p.getCameraImage(
                8, 8, renderer=p.ER_BULLET_HARDWARE_OPENGL, physicsClientId=client
            )[:5]
        return np.asarray(rgba).size == 8 * 8 * 4
    except p.error:
        return False


def quiet_if_egl(flag: int):
    """:func:`quiet_c_output` around an EGL frame (the plugin prints vendor lines on some frames)."""
    return quiet_c_output() if flag == p.ER_BULLET_HARDWARE_OPENGL else contextlib.nullcontext()


def renderer_flag(name: str) -> int:
    return p.ER_BULLET_HARDWARE_OPENGL if name == "egl" else p.ER_TINY_RENDERER
