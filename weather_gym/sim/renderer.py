"""Pick PyBullet's renderer: the EGL plugin (OpenGL, also on Mesa's software rasteriser) when it
loads and renders, else TinyRenderer (pure CPU). Both are deterministic; they differ from each other.
"""

from __future__ import annotations

import os
import pkgutil

import numpy as np
import pybullet as p


def _egl_plugin_path() -> str | None:
    loader = pkgutil.get_loader("eglRenderer")
    return loader.get_filename() if loader is not None else None  # type: ignore[attr-defined]


def _quiet_fd():
    """Context manager silencing C-level stdout (the EGL plugin prints GL vendor lines)."""
    import contextlib

    @contextlib.contextmanager
    def cm():
        try:
            fd = os.dup(1)
        except OSError:
            yield
            return
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 1)
            yield
        finally:
            os.dup2(fd, 1)
            os.close(fd)
            os.close(devnull)

    return cm()


def setup_renderer(client: int, requested: str) -> tuple[str, int | None]:
    """Load the renderer for ``client``. Returns (name, plugin id); name is "egl" or "tiny".

    ``requested`` "auto" tries EGL and falls back to TinyRenderer; "egl" raises if EGL fails.
    The env var ``WEATHER_GYM_RENDERER`` overrides "auto".
    """
    if requested == "auto":
        requested = os.environ.get("WEATHER_GYM_RENDERER", "auto")
    if requested == "tiny":
        return "tiny", None
    path = _egl_plugin_path()
    plugin = -1
    if path is not None:
        with _quiet_fd():
            plugin = p.loadPlugin(path, "_eglRendererPlugin", physicsClientId=client)
    if plugin >= 0 and _egl_renders(client):
        return "egl", plugin
    if plugin >= 0:
        p.unloadPlugin(plugin, physicsClientId=client)
    if requested == "egl":
        raise RuntimeError(
            "the EGL renderer was requested but did not load; install libegl1 and libgl1-mesa-dri, "
            "or use renderer='tiny' / 'auto'"
        )
    return "tiny", None


def _egl_renders(client: int) -> bool:
    try:
        with _quiet_fd():
            _, _, rgba, _, _ = p.getCameraImage(
                8, 8, renderer=p.ER_BULLET_HARDWARE_OPENGL, physicsClientId=client
            )[:5]
        return np.asarray(rgba).size == 8 * 8 * 4
    except p.error:
        return False


def renderer_flag(name: str) -> int:
    return p.ER_BULLET_HARDWARE_OPENGL if name == "egl" else p.ER_TINY_RENDERER
