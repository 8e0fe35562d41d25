"""Refractive water drops on the lens: each drop is a small spherical-cap lens of its own.

A drop sitting on the camera's front glass is far closer than the focus distance, so it is seen
out of focus, and it refracts: the camera ray through a point of the drop at normalised distance
``rho`` from its centre leaves the curved water surface at incidence ``alpha = asin(rho sin(theta))``
(``theta``: the contact angle, the cap's half-angle) and is bent by ``delta = asin(n sin(alpha)) -
alpha`` (``n = 1.333``) towards the drop's axis. The pixel therefore sees the scene point
``fx tan(delta)`` pixels away on the *opposite* side of the centre: the drop shows an inverted,
minified (wide-angle) image of the scene around it, shifted up by ``look_up`` of its field (the
sky in the drop's lower half, the ground in its upper half, as in Halimeh & Roser 2009 and the
wet-lens pairs of Porav et al. 2019). Where ``n sin(alpha) >= 1`` the ray is totally reflected
and near it the Fresnel transmission falls: a dark rim, strengthened by ``rim`` for flat drops
that have no total reflection. A small specular ``highlight`` sits in the upper left of each drop.
The drop's content is sampled from a quarter-size copy of the frame blurred by ``blur`` (image
heights, in scene space; the drop's centre is placed at a whole pixel of the copy) and its edge is
blurred by ``defocus`` (image heights): out of focus.

**Speed**: the per-drop sampling map, weights and highlight depend only on the drop's integer
radius, its contact angle (10 degree bins) and the frame geometry; they are computed once
(:func:`_drop_maps`, cached). The contents of all drops of a frame, each at half its box's size
(the content is blurred anyway), are made together: one ``cv2.remap``, one shade multiply and one
highlight add over all their pixels (OpenCV computes every pixel on its own, so this is byte for
byte each drop's own calls), sampled from the small copy padded with its edge pixels out to where
the drops reach (:func:`_pad_to_reach`). One compiled pass (:mod:`weather_gym.weather._drop_blend`,
numba, loaded with the first drop) then scales each drop's content up to its box and blends it in,
in order: byte for byte OpenCV's ``resize``, ``multiply`` and ``add`` of each drop.

Example:
    >>> import numpy as np
    >>> img = np.zeros((376, 672, 3), np.uint8); img[:188] = 255   # bright sky, dark ground
    >>> x, y, r, th, u = drop_layout(376, 672, np.random.default_rng(0), count=3, radius=0.05, contact_deg=60)
    >>> out = render_lens_drops(img, [336.0], [280.0], [30.0], [60.0])
    >>> int(out[280 + 20, 336, 0]) > 150   # the lower part of a drop on the ground shows the sky
    True
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import Any, cast

import cv2
import numpy as np

_FloatArray = np.ndarray | Sequence[float]

__all__ = ["IOR_WATER", "drop_layout", "render_lens_drops"]

#: Refractive index of water.
IOR_WATER = 1.333
#: Spread of the drop radii (log-normal sigma) and their clip, as factors of the mean radius.
RADIUS_SIGMA, RADIUS_CLIP = 0.35, (0.4, 1.8)
#: Half-width of the uniform spread of contact angles around ``contact_deg`` (degrees), and the
#: angles' absolute range.
CONTACT_SPREAD_DEG, CONTACT_RANGE_DEG = 20.0, (15.0, 90.0)
#: Downscale factor of the copy the drop contents are sampled from.
SAMPLE_SCALE = 4
_THETA_BIN = 10.0
#: Width (pixels) of the rows the drops' contents are computed in together (OpenCV's remap takes < 32767).
_ATLAS_W = 4096


def drop_layout(h: int, w: int, rng: np.random.Generator, count: int, radius: float,
                contact_deg: float) -> tuple[np.ndarray, ...]:
    """``count`` drops at full severity: ``x, y, r`` (px), contact angle (deg), visibility draw ``u``.

    Centres uniform over the frame, radii log-normal around ``radius * h`` (clipped to
    ``RADIUS_CLIP``), contact angles uniform within ``CONTACT_SPREAD_DEG`` of ``contact_deg``. A
    drop is shown at severity ``k`` when ``u < k`` (so the drops of a lower k are a subset).
    """
    x = rng.uniform(0.0, w, size=count)
    y = rng.uniform(0.0, h, size=count)
    f = np.clip(np.exp(rng.normal(0.0, RADIUS_SIGMA, size=count)), *RADIUS_CLIP)
    th = np.clip(contact_deg + rng.uniform(-CONTACT_SPREAD_DEG, CONTACT_SPREAD_DEG, size=count), *CONTACT_RANGE_DEG)
    u = rng.uniform(0.0, 1.0, size=count)
    return x, y, radius * h * f, th, u


def _fresnel_out(alpha: np.ndarray, n: float) -> tuple[np.ndarray, np.ndarray]:
    """Deflection towards the axis and transmission of a ray leaving water at incidence ``alpha``."""
    s = n * np.sin(alpha)
    tir = s >= 1.0
    beta = np.arcsin(np.minimum(s, 1.0))
    ca, cb = np.cos(alpha), np.cos(beta)
    rs = ((n * ca - cb) / np.maximum(n * ca + cb, 1e-9)) ** 2
    rp = ((n * cb - ca) / np.maximum(n * cb + ca, 1e-9)) ** 2
    t = np.where(tir, 0.0, 1.0 - 0.5 * (rs + rp))
    return beta - alpha, t


@lru_cache(maxsize=1024)
def _drop_maps(r: int, theta_deg: float, fx: float, look_up: float, edge: float, rim: float,
               highlight: float, sx: float, sy: float) -> tuple[Any, ...]:
    """Cached per-drop arrays on the drop's padded box (side ``2 (r + pad) + 1``).

    Returns ``pad``; at half the box's size (``n = r + pad + 1``, flattened to ``n * n`` pixels
    row by row), the sampling offsets in the small copy's pixels relative to the drop centre
    mapped there (OpenCV's fixed-point pair: integer offsets and interpolation indices), the
    drop's shading (transmission and rim, RGB uint8 with 255 = 1) times the drop's opacity and
    its highlight (RGB uint8); at full size the frame's remaining weight ``1 - alpha`` (RGB uint8,
    255 = 1); all read-only; and the reach of the integer offsets, ``(x min, x max, y min, y max)``.
    """
    pad = int(math.ceil(2.0 * edge)) + 1
    c = np.arange(-(r + pad), r + pad + 1, dtype=np.float64)
    dx, dy = np.meshgrid(c, c)
    d = np.hypot(dx, dy)
    rho = np.minimum(d / r, 1.0)
    sin_t = math.sin(math.radians(theta_deg))
    delta, trans = _fresnel_out(np.arcsin(rho * sin_t), IOR_WATER)
    mag = fx * np.tan(np.minimum(delta, 1.2))
    field = fx * math.tan(float(_fresnel_out(np.arcsin(np.array(0.7 * sin_t)), IOR_WATER)[0]))
    ux, uy = dx / np.maximum(d, 1e-9), dy / np.maximum(d, 1e-9)
    offx = dx - ux * mag
    offy = dy - uy * mag - look_up * field
    inside = np.clip(r + 0.5 - d, 0.0, 1.0)
    shade = np.maximum(trans, 0.12) * (1.0 - rim * np.clip((rho - 0.6) / 0.4, 0.0, 1.0) ** 2)
    sig = max(0.12 * r, 0.6)
    spot = np.exp(-((dx + 0.35 * r) ** 2 + (dy + 0.4 * r) ** 2) / (2 * sig * sig))
    alpha, add = inside.astype(np.float32), (inside * spot * (255.0 * highlight)).astype(np.float32)
    shade = shade.astype(np.float32)
    if edge > 0.3:
        alpha, shade, add = (cv2.GaussianBlur(a, (0, 0), edge) for a in (alpha, shade, add))  # type: ignore[assignment]  # cv2's stubs drop the float32 dtype
    n = r + pad + 1  # the content is made at half size, then scaled up to the box

    def half(a: np.ndarray) -> np.ndarray:
        return cv2.resize(np.asarray(a, np.float32), (n, n), interpolation=cv2.INTER_AREA)

    def rgb(a: np.ndarray) -> np.ndarray:
        return cast(np.ndarray, cv2.cvtColor(np.rint(np.clip(a, 0, 255)).astype(np.uint8), cv2.COLOR_GRAY2RGB))

    mxy, mf = cv2.convertMaps(half(offx / sx), half(offy / sy), cv2.CV_16SC2)
    out = [mxy.reshape(-1, 2), mf.reshape(-1), rgb(half(alpha * shade * 255.0)).reshape(-1, 3),
           rgb(half(add)).reshape(-1, 3), rgb((1.0 - alpha) * 255.0)]
    for a in out:
        a.setflags(write=False)
    reach = (int(mxy[..., 0].min()), int(mxy[..., 0].max()), int(mxy[..., 1].min()), int(mxy[..., 1].max()))
    return (pad, *out, reach)


def _small_copy(img: np.ndarray, blur_px: float) -> tuple[np.ndarray, float, float]:
    """The frame at ``1 / SAMPLE_SCALE`` size, blurred by ``blur_px`` full-size pixels; scales x, y."""
    h, w = img.shape[:2]
    hs, ws = max(1, round(h / SAMPLE_SCALE)), max(1, round(w / SAMPLE_SCALE))
    small = cv2.resize(img, (ws, hs), interpolation=cv2.INTER_LINEAR) if (hs, ws) != (h, w) else img
    sx, sy = w / ws, h / hs
    sigma = blur_px / sx
    if sigma > 0.3:
        small = cv2.GaussianBlur(small, (0, 0), sigma)
    return small, sx, sy


def _pad_to_reach(small: np.ndarray, shx: np.ndarray, shy: np.ndarray, reach: np.ndarray
                  ) -> tuple[np.ndarray, tuple[int, int]]:
    """``small`` with its edge pixels repeated out to where the drops sample (at most its own size
    on each side); the pad's left and top widths.

    Identical samples, faster: OpenCV's ``remap`` with ``BORDER_REPLICATE`` clamps a sample
    outside the image to its edge, as the repeated pixels do, but takes a slow path for every
    sample that needs the clamp. No pad where the shifted coordinates could leave int16.
    """
    hs, ws = small.shape[:2]
    lo_x, hi_x = int((shx + reach[:, 0]).min()), int((shx + reach[:, 1]).max())
    lo_y, hi_y = int((shy + reach[:, 2]).min()), int((shy + reach[:, 3]).max())
    left, right = min(max(-lo_x, 0), ws), min(max(hi_x + 2 - ws, 0), ws)
    top, bottom = min(max(-lo_y, 0), hs), min(max(hi_y + 2 - hs, 0), hs)
    if not (left or right or top or bottom) or max(hi_x + left, hi_y + top, -lo_x, -lo_y) > 32000:
        return small, (0, 0)
    return cv2.copyMakeBorder(small, top, bottom, left, right, cv2.BORDER_REPLICATE), (left, top)


def render_lens_drops(img: np.ndarray, x: _FloatArray, y: _FloatArray, r: _FloatArray,
                      theta: _FloatArray, out: np.ndarray | None = None, *,
                      hfov_deg: float = 90.0, look_up: float = 0.3, defocus: float = 0.006,
                      blur: float = 0.02, rim: float = 0.6, highlight: float = 0.5) -> np.ndarray:
    """Draw refracting drops (centres ``x, y``, radii ``r`` in px, contact angles ``theta`` in deg).

    The drop contents are sampled from ``img`` (not from drops drawn before), the drops are
    composited one after another into ``out`` (a copy of ``img`` when None). ``defocus`` and
    ``blur`` are in image heights; ``hfov_deg`` is the camera's horizontal field of view.
    """
    if out is None:
        out = img.copy()
    else:
        np.copyto(out, img)
    h, w = img.shape[:2]
    if len(r) == 0:
        return out
    small, sx, sy = _small_copy(img, blur * h)
    fx = round(0.5 * w / math.tan(math.radians(hfov_deg) / 2), 1)
    edge = round(defocus * h, 2)
    sx_k, sy_k = round(sx, 6), round(sy, 6)
    ri = np.maximum(np.rint(np.asarray(r, np.float64)), 1).astype(np.int64)
    tb = np.minimum(_THETA_BIN * np.rint(np.asarray(theta, np.float64) / _THETA_BIN), 90.0)
    ix = np.rint(np.asarray(x, np.float64)).astype(np.int64)
    iy = np.rint(np.asarray(y, np.float64)).astype(np.int64)
    shx, shy = np.rint((ix + 0.5) / sx - 0.5), np.rint((iy + 0.5) / sy - 0.5)  # centres in the copy
    maps = [_drop_maps(rad, t, fx, look_up, edge, rim, highlight, sx_k, sy_k) for rad, t in zip(ri.tolist(), tb.tolist())]
    pad = maps[0][0]  # the same for every drop (it depends on the edge blur only)
    half = ri + pad
    x0, y0 = np.maximum(ix - half, 0), np.maximum(iy - half, 0)
    x1, y1 = np.minimum(ix + half + 1, w), np.minimum(iy + half + 1, h)
    on = (x0 < x1) & (y0 < y1)
    if not on.any():
        return out
    maps = [m for m, o in zip(maps, on.tolist(), strict=True) if o]
    half, ix, iy, shx, shy, x0, y0, x1, y1 = (a[on] for a in (half, ix, iy, shx, shy, x0, y0, x1, y1))
    # every drop's content at half size in one remap, multiply and add (each pixel is computed on
    # its own, so this is each drop's own remap), laid out as rows of _ATLAS_W pixels
    count = (half + 1) ** 2
    total = int(count.sum())
    rows = -(-total // _ATLAS_W)
    xy, frac, gain, add = (np.zeros((rows * _ATLAS_W, *shape), dt) for shape, dt in (
        ((2,), np.int16), ((), np.uint16), ((3,), np.uint8), ((3,), np.uint8)))
    for j, dst in ((1, xy), (2, frac), (3, gain), (4, add)):
        np.concatenate([m[j] for m in maps], out=dst[:total])
    small, (left, top) = _pad_to_reach(small, shx, shy, np.array([m[6] for m in maps]))
    # the drops' centres in the (padded) copy fit int16 (see _pad_to_reach)
    shift = np.repeat(np.stack([shx + left, shy + top], axis=1).astype(np.int16), count, axis=0)
    cv2.add(xy[:total], shift, dst=xy[:total])  # each drop's map moved to its centre (saturating, as per drop)
    src = cv2.remap(small, xy.reshape(rows, _ATLAS_W, 2), frac.reshape(rows, _ATLAS_W), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    cv2.multiply(src, gain.reshape(rows, _ATLAS_W, 3), dst=src, scale=1.0 / 255.0)
    cv2.add(src, add.reshape(rows, _ATLAS_W, 3), dst=src)
    # then per drop, in order: its content scaled up to its box and blended in (compiled; numba loads here)
    from weather_gym.weather._drop_blend import blend_drops

    blend_drops(out, src.reshape(-1, 3)[:total], [m[5] for m in maps], half, ix, iy, x0, y0, x1, y1)
    return out
