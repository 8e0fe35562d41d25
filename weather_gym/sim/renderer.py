"""PyBullet physics clients and their renderer: the EGL plugin (OpenGL, also on Mesa's software
rasteriser) when it loads and renders, else TinyRenderer (pure CPU). Both are deterministic; they
differ from each other. ``"none"`` is a physics-only client (no camera rendering at all).

**EGL contexts.** PyBullet's EGL plugin makes its OpenGL context current when a client loads it and
never again: with two EGL clients in a process, the first one drew with the second one's context
(other textures and meshes: wrong frames), and disconnecting one unbound the context the others
drew with (the next frame crashed the process, exit 139). So every EGL client's context is recorded
when it loads (:func:`connect`) and made current again before the world touches PyBullet
(:func:`activate`); any order of create / close / garbage collection is then safe, and each world
renders what it would render alone. :func:`release` from ``__del__`` (``deferred=True``) only queues
the client; it is disconnected at the next :func:`connect` / :func:`activate` / :func:`release`, so
garbage collection never calls into PyBullet in the middle of another world's frame.

**Fork.** A child forked from a process that has used EGL inherits Mesa's state without its render
threads, and its first EGL frame waits for them forever. Mesa's CPU rasteriser (llvmpipe) without
threads (``LP_NUM_THREADS=0``, set here before the first EGL client unless you set it yourself) has
none to wait for, so such children render with EGL as well. Otherwise (a hardware EGL, or your own
``LP_NUM_THREADS``) a forked child refuses to render - ``RuntimeError`` naming the fix (start workers
with ``spawn`` or ``forkserver``, or ask for ``renderer="tiny"``) - instead of hanging or silently
switching renderer. The renderer in use is ``World.renderer_name`` (``env.unwrapped.renderer``,
``info["renderer"]``) and, for EGL, :func:`renderer_detail` (the OpenGL renderer string).

Example:
    >>> from weather_gym.sim import renderer
    >>> client = renderer.connect(renderer="none")
    >>> renderer.activate(client)   # before PyBullet calls on it (a no-op without EGL)
    >>> client.renderer
    'none'
    >>> renderer.release(client)
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import importlib.util
import os
import threading
import warnings
from dataclasses import dataclass

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.quiet import quiet_c_output

RENDERER_NAMES = ("egl", "tiny", "none")

_egl_used = False
"""This process has loaded the EGL plugin."""
_egl_fork_safe = True
"""Every EGL client of this process renders with threadless llvmpipe (a forked child may use EGL)."""
_forked_after_egl = False
"""This process was forked from one whose EGL state a child cannot use (EGL would hang here)."""
_egl_detail = ""
"""GL_RENDERER of this process's EGL clients (e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``)."""
_fallback_warned = False


@dataclass
class PhysicsClient:
    """A PyBullet client: its id, renderer ("egl", "tiny" or "none"), the EGL plugin id and the
    EGL display / surface / context the plugin made (to make it current again)."""

    id: int
    renderer: str
    plugin: int | None = None
    gui: bool = False
    egl: tuple[int, int, int] | None = None


_pending: list[PhysicsClient] = []
_all_egl: list[PhysicsClient] = []
_state = threading.local()  # .current: the client whose EGL context is current in this thread


@atexit.register
def _disconnect_all_at_exit() -> None:
    """Disconnect the EGL clients quietly at exit (nothing renders any more; the plugin prints)."""
    if _all_egl:
        with quiet_c_output():
            for client in list(_all_egl):
                _disconnect(client)


def _after_fork_in_child() -> None:
    global _forked_after_egl, _pending, _all_egl, _state
    _forked_after_egl = _forked_after_egl or (_egl_used and not _egl_fork_safe)
    # the parent's clients are not this process's to use (their EGL state least of all)
    _pending, _all_egl = [], []
    _state = threading.local()


os.register_at_fork(after_in_child=_after_fork_in_child)


class _EGL:
    """The few libEGL calls needed to switch contexts (the library the plugin loaded)."""

    DRAW = 0x3059

    def __init__(self) -> None:
        lib = ctypes.CDLL("libEGL.so.1")
        for name in ("eglGetCurrentDisplay", "eglGetCurrentContext"):
            getattr(lib, name).restype = ctypes.c_void_p
        lib.eglGetCurrentSurface.restype = ctypes.c_void_p
        lib.eglGetCurrentSurface.argtypes = [ctypes.c_int32]
        lib.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
        lib.eglMakeCurrent.restype = ctypes.c_uint
        self.lib = lib

    def current(self) -> tuple[int, int, int] | None:
        lib = self.lib
        ctx = lib.eglGetCurrentContext()
        if not ctx:
            return None
        return (lib.eglGetCurrentDisplay(), lib.eglGetCurrentSurface(self.DRAW), ctx)

    def make_current(self, handles: tuple[int, int, int]) -> None:
        display, surface, context = handles
        if not self.lib.eglMakeCurrent(display, surface, surface, context):
            raise RuntimeError("eglMakeCurrent failed: this EGL renderer's context can no longer be used")


_egl_lib: _EGL | None = None


def _egl_plugin_path() -> str | None:
    spec = importlib.util.find_spec("eglRenderer")
    return spec.origin if spec is not None and spec.has_location else None


def egl_used() -> bool:
    """Whether a client of this process has rendered with EGL (its frames, not TinyRenderer's)."""
    return _egl_used


def renderer_detail() -> str:
    """What the EGL clients of this process render with (the OpenGL renderer string), or ""."""
    return _egl_detail


def _drain_pending() -> None:
    """Disconnect the clients that ``__del__`` queued."""
    while _pending:
        _disconnect(_pending.pop())


def _disconnect(client: PhysicsClient) -> None:
    try:
        connected = p.isConnected(physicsClientId=client.id)
    except p.error:  # pragma: no cover
        connected = False
    if client.egl is not None:
        if connected:
            # the plugin frees its OpenGL objects with whatever context is current: make it its own
            _egl_lib.make_current(client.egl)  # type: ignore[union-attr]  # loaded: the client has an EGL context
        _state.current = None  # and its closeWindow() unbinds it
        if client in _all_egl:
            _all_egl.remove(client)
    try:
        if connected:
            if client.plugin is not None:
                with quiet_c_output():
                    p.disconnect(physicsClientId=client.id)
            else:
                p.disconnect(physicsClientId=client.id)
    except p.error:  # pragma: no cover - already gone
        pass


def activate(client: PhysicsClient | None) -> None:
    """Make ``client``'s EGL context current (a no-op for other renderers, or when it already is).

    Call before any PyBullet call on ``client`` (``World`` does, in every method)."""
    if _pending:
        _drain_pending()
    if client is None or client.egl is None or getattr(_state, "current", None) is client:
        return
    assert _egl_lib is not None
    _egl_lib.make_current(client.egl)
    _state.current = client


def connect(*, renderer: str = "auto", gui: bool = False) -> PhysicsClient:
    """A physics client rendering with ``renderer`` ("auto", "egl", "tiny" or "none").

    "auto" is EGL when it loads and renders, else TinyRenderer (with a warning, once); the env var
    ``WEATHER_GYM_RENDERER`` (``egl``/``tiny``) overrides "auto". "egl" raises when EGL cannot be used.
    """
    if renderer not in ("auto", *RENDERER_NAMES):
        raise InputError(f"renderer must be one of auto, {', '.join(RENDERER_NAMES)}; got {renderer!r}")
    if renderer == "auto":
        renderer = os.environ.get("WEATHER_GYM_RENDERER", "auto") or "auto"
        if renderer not in ("auto", "egl", "tiny"):
            raise InputError(f"WEATHER_GYM_RENDERER must be egl or tiny, got {renderer!r}")
    _drain_pending()
    if renderer in ("auto", "egl") and not gui and _forked_after_egl:
        raise RuntimeError(
            "this process was forked from one that already used PyBullet's EGL renderer, and EGL "
            f"{'(' + _egl_detail + ') ' if _egl_detail else ''}hangs in such a child; start the worker "
            "processes with the 'spawn' or 'forkserver' method (weather_gym.make_vec_env does; "
            "gym.make_vec(..., vector_kwargs={'context': 'forkserver'}), SubprocVecEnv's default) "
            "to render with EGL there, or ask for renderer='tiny' (different frames)")
    client_id = p.connect(p.GUI if gui else p.DIRECT)
    if client_id < 0:
        raise RuntimeError("PyBullet could not start a physics client")
    client = PhysicsClient(client_id, "tiny", None, gui)
    try:
        if renderer in ("tiny", "none"):
            client.renderer = renderer
        else:
            _load_egl(client, required=renderer == "egl")
    except BaseException:
        _disconnect(client)
        raise
    return client


def _load_egl(client: PhysicsClient, required: bool) -> None:
    global _egl_used, _egl_fork_safe, _egl_detail, _fallback_warned, _egl_lib
    if not _egl_used and "LP_NUM_THREADS" not in os.environ:
        os.environ["LP_NUM_THREADS"] = "0"  # threadless llvmpipe: forked children can render too
    path = _egl_plugin_path()
    plugin = -1
    text: list[str] = []
    if path is not None:
        try:
            _egl_lib = _egl_lib or _EGL()
        except OSError:  # no libEGL.so.1: the plugin cannot load either
            path = None
    if path is not None:
        _state.current = None  # loading makes the new client's context current
        with quiet_c_output(capture=text):
            plugin = p.loadPlugin(path, "_eglRendererPlugin", physicsClientId=client.id)
    if plugin >= 0 and _egl_renders(client.id, capture=text):
        client.egl = _egl_lib.current()  # type: ignore[union-attr]  # loaded with the plugin; the context this client's plugin made (and drew the test frame with)
    if client.egl is not None:
        _state.current = client
        detail = next((line.split("=", 1)[1].strip() for line in "".join(text).splitlines()
                       if line.startswith("GL_RENDERER=")), "")
        if not _egl_used:
            _egl_detail = detail
        _egl_fork_safe = _egl_fork_safe and "llvmpipe" in detail and os.environ.get("LP_NUM_THREADS") == "0"
        _egl_used = True
        client.renderer, client.plugin = "egl", plugin
        _all_egl.append(client)
        return
    if plugin >= 0:
        with quiet_c_output():
            p.unloadPlugin(plugin, physicsClientId=client.id)
        client.egl, _state.current = None, None
    if required:
        raise RuntimeError(
            "the EGL renderer was requested but did not load; install libegl1 and libgl1-mesa-dri, "
            "or use renderer='tiny' / 'auto'"
        )
    if not _fallback_warned:
        _fallback_warned = True
        warnings.warn("PyBullet's EGL renderer did not load here; rendering with TinyRenderer (other frames "
                      "than EGL's; install libegl1 and libgl1-mesa-dri for EGL)", RuntimeWarning, stacklevel=4)
    client.renderer = "tiny"


def release(client: PhysicsClient | None, *, deferred: bool = False) -> None:
    """Disconnect ``client``. ``deferred=True`` (from ``__del__``) only queues it: the next
    :func:`connect`, :func:`activate` or :func:`release` disconnects it."""
    if client is None:
        return
    if deferred:
        _pending.append(client)  # list.append: safe at any point, no PyBullet call
        return
    _drain_pending()
    _disconnect(client)


def _egl_renders(client: int, capture: list[str] | None = None) -> bool:
    try:
        with quiet_c_output(capture=capture):
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
