"""The motion smear's blend, compiled: the zoom blur weighted by nearness, in one pass over the values.

:func:`~weather_gym.weather.geometry.motion_smear` blends the zoom-blurred frame into the frame by
``w = 255 min(near / Z, 1)`` per pixel: ``round(img (255 - w) / 255) + round(blurred w / 255)``,
saturated. That was eight OpenCV passes with temporary frames (a division of the depth map, its
conversion to bytes, its complement, both spread to three channels, two multiplies and an add);
:func:`near_blend` does the same arithmetic, byte for byte: the weights (one compiled pass over the
depth map, or given), spread to the channels, then one compiled pass over the values that numba
vectorises:

* ``w = cv2.convertScaleAbs(float32(255 near) / Z)``: the float32 quotient rounded half to even,
  saturated to 255, with ``Z`` raised to 1 mm first where the map has nearer values
  (``cv2.max(depth, 1e-3)``);
* ``cv2.multiply(a, b, scale=1 / 255)`` for uint8 is ``(p + 1 + (p >> 8)) >> 8`` with ``p = a b + 127``;
* ``cv2.add``: saturating.

``tests/weather/test_weather_near_blend.py`` checks it against those OpenCV calls. numba compiles the
kernels on first use (cached on disk afterwards where a cache folder is writable: weather_gym.core._jit_cache).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._near_blend import near_blend
    >>> img, blurred = np.full((1, 2, 3), 100, np.uint8), np.full((1, 2, 3), 200, np.uint8)
    >>> out = np.empty_like(img)
    >>> near_blend(img, blurred, np.array([[2.0, 8.0]], np.float32), 2.0, out)  # near at 2 m: w = 255, 64
    >>> out[0, :, 0].tolist()                                                    # 200; 100 + 100 * 64 / 255
    [200, 125]
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache
from weather_gym.core.errors import InputError
from weather_gym.weather._common import into

__all__ = ["near_blend", "near_weight"]

#: Depths nearer than this (metres) count as this near (``cv2.max(depth, 1e-3)``).
_NEAREST_M = np.float32(1e-3)


def near_weight(depth: np.ndarray, near_m: float, who: str | None = None) -> np.ndarray:
    """``w = 255 min(near / Z, 1)`` as uint8 (``H x W``), rounded as :func:`near_blend` does.

    ``who`` (an effect's name): also check, in the same pass, that the depths are finite metres
    >= 0, else an :class:`~weather_gym.core.errors.InputError` naming it (as
    :func:`~weather_gym.weather._common.depth_min`).
    """
    out = np.empty(depth.shape, np.uint8)
    z = np.ascontiguousarray(depth, np.float32)
    if who is None:
        _weights(z, np.float32(255.0 * near_m), out)
    elif not _weights_checked(z, np.float32(255.0 * near_m), out):
        raise InputError(f"{who}: depth must be finite metres >= 0 (got NaN, inf or negative values)")
    return out


def near_blend(img: np.ndarray, blurred: np.ndarray, near: np.ndarray, near_m: float | None, out: np.ndarray) -> None:
    """``round(img (255 - w) / 255) + round(blurred w / 255)`` into ``out`` (uint8 ``H x W x C`` or ``H x W``).

    ``near``: the depth map (float32 metres, ``H x W``) with ``near_m``, or the weights ``w`` themselves
    (uint8 ``H x W``, :func:`near_weight`) with ``near_m`` None. ``out`` may be ``img`` or ``blurred``.
    """
    target = out if out.flags.c_contiguous else np.empty_like(out)
    h, w = img.shape[:2]
    ch = img.shape[2] if img.ndim == 3 else 1
    wts = near_weight(near, near_m) if near_m is not None else np.ascontiguousarray(near, np.uint8)
    if ch == 3:  # the weight of each value: cvtColor spreads them fastest
        wts = cv2.cvtColor(wts, cv2.COLOR_GRAY2RGB)
    elif ch > 1:
        wts = np.repeat(wts, ch, axis=1)
    _blend(np.ascontiguousarray(img).reshape(h, w * ch), np.ascontiguousarray(blurred).reshape(h, w * ch),
           wts.reshape(h, w * ch), target.reshape(h, w * ch))
    into(target, out)


@numba.njit(cache=jit_cache(__file__), nogil=True, inline="always")
def _weight(z: np.float32, c: np.float32) -> np.int32:
    """``convertScaleAbs(c / max(Z, 1 mm))``: the float32 quotient, rounded half to even (adding and
    taking away 1.5 * 2 ** 23, exact below 2 ** 22: the quotient is capped at 256 first), saturated.
    (The OpenCV code raised Z to 1 mm only where the map had nearer values: the same result.)"""
    z = max(z, _NEAREST_M)
    q = min(np.float32(c / z), np.float32(256.0))
    q = np.float32(np.float32(q + np.float32(12582912.0)) - np.float32(12582912.0))
    return np.int32(min(q, np.float32(255.0)))


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _weights(depth: np.ndarray, c: np.float32, out: np.ndarray) -> None:
    for r in range(depth.shape[0]):
        for x in range(depth.shape[1]):
            out[r, x] = _weight(depth[r, x], c)


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _weights_checked(depth: np.ndarray, c: np.float32, out: np.ndarray) -> bool:
    """:func:`_weights`, and whether every depth is finite and >= 0 (NaN is not)."""
    ok = True
    inf = np.float32(np.inf)
    for r in range(depth.shape[0]):
        for x in range(depth.shape[1]):
            z = depth[r, x]
            ok &= (z >= np.float32(0.0)) & (z < inf)
            out[r, x] = _weight(z, c)
    return ok


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False)
def _blend(img: np.ndarray, blurred: np.ndarray, wts: np.ndarray, out: np.ndarray) -> None:
    """:func:`near_blend` on rows of values with a weight per value: one pass numba vectorises, in
    16-bit lanes (exact: ``p <= 255 * 255 + 127`` and ``p + 1 + (p >> 8) < 2**16``)."""
    c1, c8, c127, c255 = np.uint16(1), np.uint16(8), np.uint16(127), np.uint16(255)
    for r in range(img.shape[0]):
        a, b, wr, o = img[r], blurred[r], wts[r], out[r]
        for j in range(img.shape[1]):
            w = np.uint16(wr[j])
            p = np.uint16(np.uint16(a[j]) * (c255 - w) + c127)
            q = np.uint16(np.uint16(b[j]) * w + c127)
            v = np.uint16(((p + c1 + (p >> c8)) >> c8) + ((q + c1 + (q >> c8)) >> c8))
            o[j] = np.uint8(min(v, c255))
