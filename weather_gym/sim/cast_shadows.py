"""Cast shadows of the cones on the ground, drawn into the rendered frame (the realistic scene).

PyBullet's shadow map renders nothing under the EGL plugin here, and shadow meshes added as bodies
change the renderer's draw order (same seed, same bytes breaks), so the shadows are composited in
image space after rendering, like the sky: each standing cone's shadow on the ground plane z = 0 is
the convex hull of its square base plate's footprint and of its tip's shadow, ``h * cot(elevation)``
away from the sun (capped at :data:`MAX_SHADOW_M`), less the footprint itself (the ground under the
cone is never seen). The polygons of cones within :data:`MAX_RANGE_M` are clipped at the near plane
in camera coordinates, projected with the camera's intrinsics and filled into a coverage mask
(:data:`SUPERSAMPLE` times finer, then averaged: soft, exact edges). Pixels under the mask are
darkened by :func:`shadow_strength` only where the rendered depth is that of the ground at that
pixel (within :data:`GROUND_BAND_M`), so cones, clutter and anything else standing on the ground
stay as rendered; shadows fall on the ground only, and only cones cast them.
Pure NumPy and OpenCV: no PyBullet, no randomness (same inputs, same bytes).

Example:
    >>> import math
    >>> import numpy as np
    >>> from weather_gym.sim.cast_shadows import shadow_polygons
    >>> sun = (-math.cos(math.radians(30)), 0.0, math.sin(math.radians(30)))  # low in the west (-x)
    >>> poly = shadow_polygons(np.zeros((1, 2)), np.array([0.114]), np.array([0.325]), sun)[0]
    >>> tip = poly[0]                       # the tip's shadow: h * cot(30 deg) east of the cone
    >>> round(float(tip[0]), 3), round(float(tip[1]), 3), round(0.325 / math.tan(math.radians(30)), 3)
    (0.563, 0.0, 0.563)
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from weather_gym.camera.config import CameraConfig

MAX_SHADOW_M = 4.0
"""Longest shadow drawn (m, from the cone's centre to its tip's shadow), for a very low sun."""
MAX_RANGE_M = 40.0
"""Cones farther than this from the camera (horizontally) cast no drawn shadow."""
GROUND_BAND_M = (-0.005, 0.0105)
"""A pixel is ground when the point it shows lies this high above z = 0 (m): the run-off (z = 0),
the asphalt (4 mm) and the contact shadows (8 mm) are; a cone above its lowest centimetre is not."""
MIN_STRENGTH, MAX_STRENGTH = 0.1, 0.6
"""Bounds of :func:`shadow_strength` (the share of the light a shadow takes away)."""
SUPERSAMPLE = 4
"""The shadow mask is filled at this many times the frame's resolution (soft, exact edges)."""
_SHIFT = 4  # sub-pixel bits for cv2.fillPoly


def sun_unit(light_direction) -> np.ndarray:
    """The direction toward the sun (3,), normalised (``Look.light_direction`` points to the light)."""
    d = np.asarray(light_direction, dtype=np.float64)
    return d / np.linalg.norm(d)


def shadow_strength(ambient: float, diffuse: float) -> float:
    """Share of the light a shadow takes away: ``diffuse / (ambient + diffuse)``, clipped to
    [:data:`MIN_STRENGTH`, :data:`MAX_STRENGTH`]: the look's split of the light, as the contact
    shadows use it. (PyBullet's EGL renderer ignores the look's ``ambient`` and ``diffuse`` - measured:
    the ground's level moves by under 0.1 of 255 over ambient 0-0.6 and diffuse 0-0.9 - and lights the
    ground with a fixed split, about 27 levels of 112 direct at a sun overhead; taking that would make
    shadows almost invisible.)"""
    return float(np.clip(diffuse / max(ambient + diffuse, 1e-6), MIN_STRENGTH, MAX_STRENGTH))


def shadow_polygons(xy: np.ndarray, half_side: np.ndarray, height: np.ndarray, light_direction,
                    max_length: float = MAX_SHADOW_M) -> np.ndarray:
    """Ground polygons (K, 4, 2) of the shadows of upright cones standing at ``xy`` (N, 2) on square
    base plates of half side ``half_side`` (N,; axis-aligned, as the cone mesh has them) with
    ``height`` (N,), under a sun in ``light_direction`` (toward the light).

    Vertex 0 is the tip's shadow, ``height * cot(elevation)`` (at most ``max_length``) from the cone's
    centre, pointing away from the sun; then the plate's corners that face it, from one tangent corner
    to the other (the middle one repeated when only two face it). The polygon is the convex hull of
    the plate's footprint and the tip's shadow less the footprint (the ground under the cone is never
    seen). Cones whose tip's shadow falls on their own plate (a high sun), and every cone under a sun
    at or below the horizon, give no polygon: K counts the others, in input order.
    """
    d = sun_unit(light_direction)
    horiz = math.hypot(d[0], d[1])
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    half = np.broadcast_to(np.asarray(half_side, dtype=np.float64), xy.shape[:1])
    height = np.broadcast_to(np.asarray(height, dtype=np.float64), xy.shape[:1])
    if d[2] <= 0 or horiz < 1e-9:
        return np.empty((0, 4, 2))
    away = -d[:2] / horiz
    length = np.minimum(height * horiz / d[2], max_length)
    off = length[:, None] * away  # tip's shadow relative to the centre
    keep = np.abs(off).max(axis=1) > half * (1 + 1e-9)
    xy, half, off = xy[keep], half[keep], off[keep]
    signs = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])  # counter-clockwise
    corners = signs[None] * half[:, None, None]  # (K, 4, 2) relative to the centre
    # a corner faces the tip's shadow when the tip lies outside one of the two sides meeting there
    rel = off[:, None, :] - corners  # corner -> tip
    faces = ((rel * signs[None]) > 0).any(axis=2)  # (K, 4)
    # the facing corners are consecutive (cyclically); list them starting after a non-facing one
    first = np.argmax(~faces & np.roll(faces, -1, axis=1), axis=1) + 1  # the first facing corner
    n_face = faces.sum(axis=1)  # 2 (tip in front of a side) or 3 (tip off a corner)
    idx = (first[:, None] + np.array([0, 1, 2])[None]) % 4
    idx[:, 2] = np.where(n_face == 3, idx[:, 2], idx[:, 1])
    chain = np.take_along_axis(corners, idx[:, :, None], axis=1)
    return np.concatenate([off[:, None, :], chain], axis=1) + xy[:, None, :]


def camera_rotation(heading: float, pitch: float) -> np.ndarray:
    """World -> camera rotation (3, 3): rows are the camera's right, down and forward axes (no roll)."""
    ch, sh, cp, sp = math.cos(heading), math.sin(heading), math.cos(pitch), math.sin(pitch)
    fwd = np.array([ch * cp, sh * cp, -sp])
    right = np.array([sh, -ch, 0.0])
    return np.stack([right, np.cross(fwd, right), fwd])


def clip_near(poly: np.ndarray, near: float) -> np.ndarray:
    """The part of a camera-space polygon (k, 3) with z >= ``near`` (Sutherland-Hodgman, one plane)."""
    out = []
    n = len(poly)
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            out.append(a + (b - a) * ((near - a[2]) / (b[2] - a[2])))
    return np.asarray(out, dtype=np.float64).reshape(-1, 3)


def ground_depth_band(camera: CameraConfig, eye_height: float, pitch: float,
                      band: tuple[float, float] = GROUND_BAND_M) -> tuple[np.ndarray, np.ndarray]:
    """Per image row (H,): the range of z-depth (m) a pixel of that row has when it shows the ground
    at a height within ``band`` (rows at or above the horizon: an empty range). The ground's depth at
    a pixel depends only on its row (no roll): ``eye_height / (cos(pitch) * dy + sin(pitch))``."""
    v = np.arange(camera.height, dtype=np.float64) + 0.5
    den = math.cos(pitch) * (v - camera.cy) / camera.fy + math.sin(pitch)
    ok = den > 1e-9
    g = np.where(ok, eye_height / np.where(ok, den, 1.0), np.inf)
    lo = np.where(ok, g * (1.0 - band[1] / eye_height), np.inf)
    hi = np.where(ok, g * (1.0 - band[0] / eye_height), -np.inf)
    return lo.astype(np.float32), hi.astype(np.float32)


def _coverage(uv: np.ndarray, x0: int, y0: int, width: int, height: int) -> np.ndarray:
    """How much of each pixel of the window (``x0, y0``, ``width`` x ``height``) the image polygon
    ``uv`` covers (uint8, 255 = all): filled at :data:`SUPERSAMPLE` x the resolution with hard edges,
    then averaged down. cv2.fillPoly fills every sample whose centre lies within half a sample of the
    polygon; its outline, drawn at half the value, takes that half sample back on average (so thin,
    far shadows stay as thin as they are)."""
    ss = SUPERSAMPLE
    one = np.zeros((height * ss, width * ss), np.uint8)
    origin = np.array([x0 + 0.5 / ss, y0 + 0.5 / ss])  # cv2 puts integer coordinates at sample centres
    pts = np.clip(np.rint((uv - origin) * float(ss << _SHIFT)), -(2**28), 2**28).astype(np.int32)
    cv2.fillPoly(one, [pts], 255, lineType=cv2.LINE_8, shift=_SHIFT)
    cv2.polylines(one, [pts], True, 128, lineType=cv2.LINE_8, shift=_SHIFT)
    return cv2.resize(one, (width, height), interpolation=cv2.INTER_AREA) if ss > 1 else one


class ShadowCaster:
    """Draws cone shadows into frames of one camera (caches the ground's depth per mount)."""

    def __init__(self, camera: CameraConfig, max_range: float = MAX_RANGE_M,
                 max_length: float = MAX_SHADOW_M) -> None:
        self.camera = camera
        self.max_range = float(max_range)
        self.max_length = float(max_length)
        self._band_key: tuple[float, float] | None = None
        self._band: tuple[np.ndarray, np.ndarray] | None = None

    def _ground_band(self, eye_height: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
        key = (float(eye_height), float(pitch))
        if key != self._band_key or self._band is None:
            self._band = ground_depth_band(self.camera, eye_height, pitch)
            self._band_key = key
        return self._band

    def image_polygons(self, eye: np.ndarray, heading: float, pitch: float, xy: np.ndarray, half_side: np.ndarray,
                       height: np.ndarray, light_direction) -> list[np.ndarray]:
        """The shadows of the cones at ``xy`` as image polygons (each (k, 2) float pixel coordinates,
        pixel centres at ``i + 0.5``), only those in front of the camera and overlapping the frame."""
        cam = self.camera
        eye = np.asarray(eye, dtype=np.float64)
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        near = (np.hypot(xy[:, 0] - eye[0], xy[:, 1] - eye[1]) < self.max_range)
        polys = shadow_polygons(xy[near], np.asarray(half_side)[near], np.asarray(height)[near], light_direction,
                                self.max_length)
        if len(polys) == 0:
            return []
        rot = camera_rotation(heading, pitch)
        rel = np.concatenate([polys - eye[:2], np.full(polys.shape[:2] + (1,), -eye[2])], axis=-1)
        pc = rel @ rot.T  # (K, P, 3) camera coordinates: right, down, forward
        front = pc[..., 2] >= cam.near
        whole = front.all(axis=1)
        # wholly in front: projected together; partly: clipped at the near plane first, one by one
        parts = [pc[whole]] + [clip_near(q, cam.near)[None] for q in pc[front.any(axis=1) & ~whole]]
        out = []
        for q in parts:
            if q.shape[1] < 3:
                continue
            uv = np.stack([cam.fx * q[..., 0] / q[..., 2] + cam.cx, cam.fy * q[..., 1] / q[..., 2] + cam.cy], axis=-1)
            lo, hi = uv.min(axis=1), uv.max(axis=1)
            seen = (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] <= cam.width) & (lo[:, 1] <= cam.height)
            out.extend(uv[seen])
        return out

    def apply(self, rgb: np.ndarray, depth: np.ndarray, eye: np.ndarray, heading: float, pitch: float,
              xy: np.ndarray, half_side: np.ndarray, height: np.ndarray, light_direction, strength: float) -> None:
        """Darken ``rgb`` (H, W, 3 uint8, in place) by ``strength`` where a shadow falls on ground pixels
        (``depth``: the rendered z-depth, H x W metres)."""
        cam = self.camera
        if strength <= 0:
            return
        polys = self.image_polygons(eye, heading, pitch, xy, half_side, height, light_direction)
        if not polys:
            return
        allv = np.concatenate(polys)
        x0 = int(np.clip(math.floor(allv[:, 0].min()), 0, cam.width))
        y0 = int(np.clip(math.floor(allv[:, 1].min()), 0, cam.height))
        x1 = int(np.clip(math.ceil(allv[:, 0].max()), 0, cam.width))
        y1 = int(np.clip(math.ceil(allv[:, 1].max()), 0, cam.height))
        if x1 <= x0 or y1 <= y0:
            return
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        for uv in polys:  # one polygon at a time, merged by the maximum: overlapping shadows do not add up
            (u0, v0), (u1, v1) = np.floor(uv.min(axis=0)), np.ceil(uv.max(axis=0))
            px0, py0, px1, py1 = max(x0, int(u0)), max(y0, int(v0)), min(x1, int(u1)), min(y1, int(v1))
            if px1 <= px0 or py1 <= py0:
                continue
            window = mask[py0 - y0:py1 - y0, px0 - x0:px1 - x0]
            np.maximum(window, _coverage(uv, px0, py0, px1 - px0, py1 - py0), out=window)
        lo, hi = self._ground_band(float(eye[2]), pitch)
        d = depth[y0:y1, x0:x1]
        ground = (d >= lo[y0:y1, None]) & (d <= hi[y0:y1, None])
        mask[~ground] = 0
        rows, cols = np.nonzero(mask)
        if rows.size == 0:
            return
        gain = 1.0 - np.float32(strength) * (mask[rows, cols].astype(np.float32) / np.float32(255.0))
        region = rgb[y0:y1, x0:x1]
        px = region[rows, cols].astype(np.float32) * gain[:, None]
        region[rows, cols] = np.rint(px).astype(np.uint8)
