"""EGL frames that redraw only the part of PyBullet's shadow map that changed since the last frame.

PyBullet's EGL plugin draws a 4096x4096 shadow map before every frame (bullet3's
``GLInstancingRenderer``): a depth image of the scene seen from the light, over a fixed square of
the world (``SHADOW_MAP_HALF_SIZE_M`` either side of the origin, projected along the light). What it
holds depends only on the light's direction and on where the scene's shapes are, not on the camera.
Between two frames of a drive almost nothing moves: the car's body, now and then a knocked cone.
So a frame can keep the map of the frame before and redraw (clear and draw, with a GL scissor) only
the texels over which something moved: the frames keep their bytes, and the pass that cost most of
the default frame shrinks to a few texels (``weather-gym bench sim --naive``).

How it is done: the plugin's ``glViewport`` entry (in its GL pointer table:
:class:`~weather_gym.sim.egl.gl_table.GLTableEntry`) is pointed at one that, when the shadow map's framebuffer is bound and a frame
of :meth:`ShadowMapReuse.frame` is being drawn (the camera's frames and the chase view's), sets the
scissor to that frame's changed texels. A shadow map drawn any other way (a ``getCameraImage`` of
your own on the same client) is drawn as the plugin draws it, and the next frame redraws the whole
map. A signal's exception (Ctrl-C, SIGTERM) raised while the hook runs, which ctypes would print and
drop, is raised once PyBullet's call returns (:meth:`_ViewportHook._unraisable`).

What counts as moved: any body whose base pose changed since the last frame drawn this way (the
world's bodies have no links), bounded by a sphere around its visual shapes (the world declares the
size of its meshes: :meth:`ShadowMapReuse.declare`); the whole map is redrawn after a change of
light direction, of the set of bodies, of the look (:meth:`ShadowMapReuse.invalidate`), or when a
moved body's bounds cannot be had (a plane, an undeclared mesh whose OBJ file cannot be read, a body
with links).

**Off by default; an explicit opt-in that checks itself.** This writes into PyBullet's plugin (one
entry of its GL pointer table), so the default frames do not use it: ``WEATHER_GYM_SHADOW_MAP_REUSE=1``
switches it on for a process. On first use it verifies itself (:func:`_probe`): only on a PyBullet
build it was checked on (``VERIFIED_BUILDS``), and only where a probe scene's frame drawn with a kept
map equals, byte for byte, the same frame with the whole map redrawn; otherwise it stays off and
:func:`unavailable_reason` says why. ``sys.unraisablehook`` is replaced only while one of its frames
is in flight (restored after). A Ctrl-C or SIGTERM whose handler runs in the hook during a
``getCameraImage`` of your own on a reusing client is printed and lost by ctypes: do not switch it
on where you draw frames of your own on the env's physics client and need such signals.

Example:
    >>> from weather_gym.sim.egl.shadow_reuse import texel_rect
    >>> texel_rect([(0.0, 0.0, 0.0, 0.5)], (0.0, 0.0, 1.0), size=(4096, 4096))
    (1943, 1943, 210, 210)
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import threading
import types
from collections.abc import Iterator, Mapping, Sequence
from functools import lru_cache
from importlib.metadata import version
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.sim import renderer as _renderer
from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.egl.elf_symbols import SymbolUnavailable
from weather_gym.sim.egl.gl_table import (
    FOUR_INTS,
    GL_SCISSOR_TEST,
    ONE_ENUM,
    GLTableEntry,
    draw_framebuffer,
    gl_function,
)

SHADOW_MAP_HALF_SIZE_M = 10.0  # bullet3 GLInstancingRenderer's m_shadowMapWorldSize
MARGIN_M = 0.05  # added to every body's bounding radius
MARGIN_TEXELS = 2  # added around every changed rectangle
_ENV = "WEATHER_GYM_SHADOW_MAP_REUSE"
VERIFIED_BUILDS = ("3.2.7",)
"""PyBullet versions whose plugin's shadow-map size and light basis this module was checked against."""


def light_basis(light_direction: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The shadow map's x and y axes in the world (unit vectors across the light), as bullet3 builds
    them: ``b3PlaneSpace1`` of the light direction gives (p, q); the light's look-at matrix then has
    x = -q and y = p."""
    n = np.asarray(light_direction, dtype=np.float64)
    n = n / np.linalg.norm(n)
    if abs(n[2]) > math.sqrt(0.5):
        a = n[1] * n[1] + n[2] * n[2]
        k = 1.0 / math.sqrt(a)
        pv = np.array([0.0, -n[2] * k, n[1] * k])
        qv = np.array([a * k, -n[0] * pv[2], n[0] * pv[1]])
    else:
        a = n[0] * n[0] + n[1] * n[1]
        k = 1.0 / math.sqrt(a)
        pv = np.array([-n[1] * k, n[0] * k, 0.0])
        qv = np.array([-n[2] * pv[1], n[2] * pv[0], a * k])
    return -qv, pv


def texel_rect(spheres: Sequence[tuple[float, float, float, float]], light_direction: Sequence[float],
               size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The scissor ``(x, y, width, height)`` (GL window coordinates of the map) covering every sphere
    ``(x, y, z, radius)`` in metres, seen along the light; ``(0, 0, 0, 0)`` when none falls on the map."""
    if not spheres:
        return 0, 0, 0, 0
    sx, sy = light_basis(light_direction)
    s = np.asarray(spheres, dtype=np.float64)
    scale = np.array(size, dtype=np.float64) / (2.0 * SHADOW_MAP_HALF_SIZE_M)  # texels per metre
    centre = np.stack([s[:, :3] @ sx, s[:, :3] @ sy], axis=1) * scale + np.array(size) / 2.0
    reach = s[:, 3:4] * scale + MARGIN_TEXELS
    lo = np.floor((centre - reach).min(axis=0)).astype(np.int64)
    hi = np.ceil((centre + reach).max(axis=0)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, np.array(size))
    if (hi <= lo).any():
        return 0, 0, 0, 0
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


@lru_cache(maxsize=64)
def _obj_radius(path: str) -> float | None:
    """The largest distance of an OBJ file's vertices from its origin, or None when unreadable."""
    if not path.lower().endswith(".obj"):
        return None
    try:
        with open(path) as f:
            verts = [line.split()[1:4] for line in f if line.startswith("v ")]
        return float(np.sqrt((np.asarray(verts, dtype=np.float64) ** 2).sum(axis=1).max())) if verts else 0.0
    except (OSError, ValueError):
        return None


def _body_bounds(body: int, client: int) -> list[tuple[np.ndarray, float]] | None:
    """Spheres ``(centre relative to the body's centre of mass, radius)`` around each visual shape of
    ``body``, in the body's frame; None when they cannot be had (links, a plane, a non-OBJ mesh)."""
    if p.getNumJoints(body, physicsClientId=client) > 0:
        return None
    inertial = np.asarray(p.getDynamicsInfo(body, -1, physicsClientId=client)[3], dtype=np.float64)
    bounds = []
    for shape in p.getVisualShapeData(body, physicsClientId=client):
        kind, dims, path, pos = shape[2], shape[3], shape[4], shape[5]
        if kind == p.GEOM_MESH:
            r = _obj_radius(path.decode() if isinstance(path, bytes) else str(path))
            if r is None:
                return None
            r *= max(abs(float(d)) for d in dims)
        elif kind == p.GEOM_SPHERE:
            r = float(dims[0])
        elif kind == p.GEOM_BOX:
            r = float(np.linalg.norm(dims))  # whether the dimensions are half or full extents
        elif kind in (p.GEOM_CYLINDER, p.GEOM_CAPSULE):
            r = float(dims[0]) + float(dims[1])
        else:
            return None
        bounds.append((np.asarray(pos, dtype=np.float64) - inertial, r + MARGIN_M))
    return bounds


class _ViewportHook:
    """The plugin's ``glViewport``, pointed at one that scissors the shadow-map pass to ``rect``."""

    def __init__(self) -> None:
        self._viewport = gl_function("glViewport", FOUR_INTS)
        self._scissor = gl_function("glScissor", FOUR_INTS)
        self._enable, self._disable = gl_function("glEnable", ONE_ENUM), gl_function("glDisable", ONE_ENUM)
        self.frames = threading.local()  # .plan: the frame this thread is drawing (a ShadowMapReuse)
        self.unplanned: dict[int, int] = {}  # EGL context -> shadow maps drawn whole outside a planned frame
        self._scissored = False
        self._interruptions = 0
        self._on_unraisable = self._unraisable
        self._previous_unraisable: Any = sys.unraisablehook
        self._entry = GLTableEntry("glViewport", FOUR_INTS(self._hooked))
        self.ensure()

    @property
    def generation(self) -> int:
        """Times every map had to be drawn whole again (the table reloaded, a frame interrupted)."""
        return self._entry.repointed + self._interruptions

    @staticmethod
    def current_context() -> int:
        """The current EGL context (0: none)."""
        handles = _renderer._egl_lib.current() if _renderer._egl_lib is not None else None
        return handles[2] if handles else 0

    def ensure(self) -> bool:
        """Point the table at the hook again where the plugin reloaded it (it does for every new EGL
        context); False when the table holds something else than the driver's or the hook's function."""
        return self._entry.ensure()

    @contextlib.contextmanager
    def catching_signals(self) -> Iterator[None]:
        """``sys.unraisablehook`` at :meth:`_unraisable` while one planned frame is drawn, chained to
        whatever was there and put back after (unless something replaced it in the meantime)."""
        previous = sys.unraisablehook
        self._previous_unraisable, sys.unraisablehook = previous, self._on_unraisable
        try:
            yield
        finally:
            if sys.unraisablehook is self._on_unraisable:
                sys.unraisablehook = previous

    def _unraisable(self, args) -> None:
        """``sys.unraisablehook``: an exception that left :meth:`_hooked` (a signal's, such as Ctrl-C or
        SIGTERM, whose handler ran in the callback) would be printed and dropped by ctypes. It is raised
        once PyBullet returns instead (by :meth:`ShadowMapReuse.frame`), and every map is drawn whole
        again (the GL calls of this callback may not have run). Installed only while a planned frame
        is in flight (:meth:`catching_signals`)."""
        if not self._from_hook(args):
            self._previous_unraisable(args)
            return
        self._interruptions += 1
        self._disable(GL_SCISSOR_TEST)  # whatever this callback had done: no scissor from here on
        self._scissored = False
        self.frames.interrupted = getattr(self.frames, "interrupted", None) or args.exc_value

    def _from_hook(self, args) -> bool:
        """Whether an unraisable exception left :meth:`_hooked` (Python 3.11-3.12 pass the callback as
        ``object``; later versions only name it in ``err_msg``)."""
        obj = args.object
        if isinstance(obj, types.MethodType):
            return obj.__func__ is _ViewportHook._hooked and obj.__self__ is self
        return obj is None and repr(self._hooked) in (getattr(args, "err_msg", None) or "")

    def _hooked(self, x: int, y: int, w: int, h: int) -> None:
        """The plugin's ``glViewport``: the driver's, then the scissor of a planned shadow-map pass."""
        self._viewport(x, y, w, h)
        if draw_framebuffer() != 0:  # the shadow map's framebuffer (the frame itself is drawn to the window's)
            plan = getattr(self.frames, "plan", None)
            rect = plan.rect_for((w, h)) if plan is not None else None
            if rect is None:
                if plan is None:
                    context = self.current_context()
                    self.unplanned[context] = self.unplanned.get(context, 0) + 1
                return
            self._enable(GL_SCISSOR_TEST)
            self._scissor(*rect)
            self._scissored = True
        elif self._scissored:
            self._disable(GL_SCISSOR_TEST)
            self._scissored = False


_hook: _ViewportHook | None = None
_reason: str | None = None


def unavailable_reason() -> str | None:
    """None when shadow maps are reused in this process (switched on with
    ``WEATHER_GYM_SHADOW_MAP_REUSE=1``, the EGL plugin loaded, its ``glViewport`` entry found and the
    probe passed), else why not. Looked up once, after the plugin loaded."""
    global _hook, _reason
    if _hook is not None or _reason is not None:
        return _reason
    switch = os.environ.get(_ENV, "0")
    if switch not in ("0", "1", ""):
        raise InputError(f"{_ENV} must be 1 (reuse shadow maps) or 0 (the default: off), got {switch!r}")
    if switch != "1":
        return f"off (the default; {_ENV}=1 switches it on)"
    if (build := version("pybullet")) not in VERIFIED_BUILDS:
        _reason = f"PyBullet {build} is not a build this was verified on ({', '.join(VERIFIED_BUILDS)})"
        return _reason
    try:
        hook = _ViewportHook()
    except SymbolUnavailable as exc:
        if exc.lasting:
            _reason = str(exc)
        return str(exc)
    except (LookupError, OSError) as exc:
        _reason = str(exc)
        return _reason
    _hook = hook
    if (mismatch := _probe()) is not None:
        hook._entry.release()
        _hook, _reason = None, f"switched off: {mismatch}"
    return _reason


PROBE_LIGHT = (0.45, -0.3, 0.84)


def _probe() -> str | None:
    """Draw a probe scene's frame with a kept map and with the whole map redrawn: None when the two
    are the same bytes, else what differed. A box moves between the frames, so a scissor on the
    wrong texels (another map size or light basis) leaves its old shadow behind and shows."""
    previous = getattr(_renderer._state, "current", None)
    client = _renderer.connect(renderer="egl")
    try:
        _renderer.activate(client)
        c = client.id
        ground = p.createVisualShape(p.GEOM_BOX, halfExtents=[8.0, 8.0, 0.01], physicsClientId=c)
        p.createMultiBody(0, -1, ground, [0.0, 0.0, -0.01], physicsClientId=c)
        box = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.3, 0.3, 0.6], physicsClientId=c)
        bodies = [p.createMultiBody(0, -1, box, [x, y, 0.6], physicsClientId=c)
                  for x, y in ((-2.5, 1.5), (-4.5, 3.0), (-1.5, 4.0))]
        # the boxes stand on the far side of the plane through the origin across the light: the
        # plugin's light frustum clips what is nearer the light (see the module's description)
        view = p.computeViewMatrix([-2.5, -2.0, 6.0], [-2.5, 2.0, 0.0], [0, 0, 1])
        proj = p.computeProjectionMatrixFOV(70, 1.0, 0.1, 30)
        reuse = ShadowMapReuse(c)
        for body in bodies:
            reuse.declare(body, 0.7)

        def frame() -> np.ndarray:
            with _renderer.quiet_c_output(), reuse.frame(PROBE_LIGHT):
                rgb = p.getCameraImage(128, 128, view, proj, renderer=p.ER_BULLET_HARDWARE_OPENGL,
                                       lightDirection=list(PROBE_LIGHT), physicsClientId=c)[2]
            return np.asarray(rgb, dtype=np.uint8)

        for _ in range(3):
            frame()  # the whole map twice, then kept
        p.resetBasePositionAndOrientation(bodies[0], [-3.3, 2.2, 0.6], [0, 0, 0, 1], physicsClientId=c)
        kept = frame()
        if reuse.redrawn_whole != 2:
            return "the probe's frame was not drawn with a kept map"
        reuse.invalidate()
        whole = frame()
        if not np.array_equal(kept, whole):
            return f"a probe frame differs from the whole-map frame in {int((kept != whole).sum())} values"
        return None
    finally:
        _renderer.release(client)
        _renderer.activate(previous)


def planned_frame(reuse: ShadowMapReuse | None, light: Mapping[str, Any]) -> contextlib.AbstractContextManager:
    """``reuse.frame`` for the light direction of ``light`` (``getCameraImage``'s light arguments), or a
    plain frame (the plugin draws its whole map) where there is no reuse or no light direction."""
    if reuse is None or "lightDirection" not in light:
        return contextlib.nullcontext()
    return reuse.frame(light["lightDirection"])


class ShadowMapReuse:
    """Per physics client: which texels of its shadow map each frame must redraw.

    ``with reuse.frame(light_direction): p.getCameraImage(...)`` draws one EGL frame whose shadow map
    is redrawn only where a body moved since the last such frame of this client.
    """

    def __init__(self, client: int) -> None:
        self.client = client
        self._bodies: tuple[int, ...] = ()
        self._bounds: dict[int, list[tuple[np.ndarray, float]] | None] = {}
        self._declared: dict[int, list[tuple[np.ndarray, float]]] = {}
        self._poses: dict[int, tuple] = {}
        self._light: tuple[float, ...] | None = None
        self._whole_left = 0  # frames still to be drawn with the whole map
        self._context = 0
        self._seen = (-1, -1)  # the hook's generation and this context's unplanned maps, at the last frame
        self._spheres: list[tuple[float, float, float, float]] | None = None  # what moved; None: the whole map
        self.redrawn_whole = 0  # frames whose map was drawn whole (first, after a change, unbounded motion)

    def declare(self, body: int, radius: float) -> None:
        """Every visual shape of ``body`` lies within ``radius`` metres of its centre of mass (for
        meshes, whose size PyBullet does not report: undeclared, a moving mesh redraws the whole map)."""
        if not (math.isfinite(radius) and radius >= 0):
            raise InputError(f"radius must be a finite distance >= 0, got {radius!r}")
        self._declared[body] = [(np.zeros(3), float(radius) + MARGIN_M)]
        self._bounds.pop(body, None)

    def invalidate(self) -> None:
        """The next frame redraws the whole map (after a change the poses do not show: a look, a shape)."""
        self._light = None

    def rect_for(self, size: tuple[int, int]) -> tuple[int, int, int, int] | None:
        """The scissor of the frame being drawn on a map of ``size`` texels; None for the whole map."""
        if self._spheres is None:
            return None
        return texel_rect(self._spheres, self._light, size)  # type: ignore[arg-type]  # set with the spheres

    def _plan(self, light: tuple[float, ...]) -> None:
        c = self.client
        bodies = tuple(p.getBodyUniqueId(i, physicsClientId=c) for i in range(p.getNumBodies(physicsClientId=c)))
        poses = {b: p.getBasePositionAndOrientation(b, physicsClientId=c) for b in bodies}
        assert _hook is not None
        self._context = _hook.current_context()
        seen = (_hook.generation, _hook.unplanned.get(self._context, 0))
        changed = light != self._light or bodies != self._bodies or seen != self._seen
        # after a change the plugin's next map can still miss shapes (a renderer's first frame does:
        # see World.render), so the map is drawn whole twice before parts of it are kept
        self._whole_left = 2 if changed else max(self._whole_left - 1, 0)
        whole = self._whole_left > 0
        if bodies != self._bodies:
            self._bounds = {}
        spheres: list[tuple[float, float, float, float]] | None = []
        if not whole:
            for b, pose in poses.items():
                if pose == self._poses[b]:
                    continue
                if b not in self._bounds:
                    self._bounds[b] = self._declared.get(b) or _body_bounds(b, c)
                bounds = self._bounds[b]
                if bounds is None:
                    spheres = None
                    break
                for pos, orn in (self._poses[b], pose):
                    rot = np.asarray(p.getMatrixFromQuaternion(orn), dtype=np.float64).reshape(3, 3)
                    spheres.extend((*(np.asarray(pos) + rot @ centre), r) for centre, r in bounds)  # type: ignore[union-attr]  # a list until the break above
        if whole or spheres is None:
            self.redrawn_whole += 1
            spheres = None
        self._spheres, self._light, self._bodies, self._poses = spheres, light, bodies, poses

    @contextlib.contextmanager
    def frame(self, light_direction: Sequence[float]) -> Iterator[None]:
        """Draw the frame(s) inside with this client's shadow map redrawn only where needed."""
        if unavailable_reason() is not None or _hook is None or not _hook.ensure():
            self.invalidate()  # drawn whole, as the plugin draws it
            yield
            return
        self._plan(tuple(float(v) for v in light_direction))
        _hook.frames.plan, _hook.frames.interrupted = self, None
        try:
            with _hook.catching_signals():
                yield
        finally:
            _hook.frames.plan = None
            self._seen = (_hook.generation, _hook.unplanned.get(self._context, 0))
        interrupted, _hook.frames.interrupted = _hook.frames.interrupted, None
        if interrupted is not None:
            raise interrupted
