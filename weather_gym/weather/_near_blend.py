"""The motion smear's blend, compiled: the zoom blur weighted by nearness, in one pass over the frame.

:func:`~weather_gym.weather.geometry.motion_smear` blends the zoom-blurred frame into the frame by
``w = 255 min(near / Z, 1)`` per pixel: ``round(img (255 - w) / 255) + round(blurred w / 255)``,
saturated. That was eight OpenCV passes with temporary frames (a division of the depth map, its
conversion to bytes, its complement, both spread to three channels, two multiplies and an add);
:func:`near_blend` does the same arithmetic, byte for byte, in one pass:

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

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache
from weather_gym.weather._common import into

__all__ = ["near_blend", "near_weight"]

#: Depths nearer than this (metres) count as this near (``cv2.max(depth, 1e-3)``).
_NEAREST_M = np.float32(1e-3)


def near_weight(depth: np.ndarray, near_m: float) -> np.ndarray:
    """``w = 255 min(near / Z, 1)`` as uint8 (``H x W``), rounded as :func:`near_blend` does."""
    out = np.empty(depth.shape, np.uint8)
    _weights(np.ascontiguousarray(depth, np.float32), np.float32(255.0 * near_m), out)
    return out


def near_blend(img: np.ndarray, blurred: np.ndarray, near: np.ndarray, near_m: float | None, out: np.ndarray) -> None:
    """``round(img (255 - w) / 255) + round(blurred w / 255)`` into ``out`` (uint8 ``H x W x 3``, all three).

    ``near``: the depth map (float32 metres, ``H x W``) with ``near_m``, or the weights ``w`` themselves
    (uint8 ``H x W``, :func:`near_weight`) with ``near_m`` None. ``out`` may be ``img`` or ``blurred``.
    """
    target = out if out.flags.c_contiguous else np.empty_like(out)
    h, w = img.shape[:2]
    rows = (np.ascontiguousarray(img).reshape(h, w * 3), np.ascontiguousarray(blurred).reshape(h, w * 3))
    if near_m is None:
        _blend(*rows, np.ascontiguousarray(near, np.uint8), np.float32(0.0), False, target.reshape(h, w * 3))
    else:
        _blend(*rows, np.ascontiguousarray(near, np.float32), np.float32(255.0 * near_m), True,
               target.reshape(h, w * 3))
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
def _blend(img: np.ndarray, blurred: np.ndarray, near: np.ndarray, c: np.float32, from_depth: bool,
           out: np.ndarray) -> None:
    """:func:`near_blend` on rows of bytes: each row's weights spread to its bytes, then one pass over
    them. Indices are unsigned or slices, so that numba leaves out its negative-index checks."""
    rows, cols = img.shape
    wb = np.empty(cols, np.int32)
    c1, c8, c127, c255 = np.int32(1), np.int32(8), np.int32(127), np.int32(255)
    for r in range(rows):
        nr = near[r]
        for x in range(cols // 3):
            w = _weight(nr[np.uint64(x)], c) if from_depth else np.int32(nr[np.uint64(x)])
            i = np.uint64(3 * x)
            wb[i] = w
            wb[i + np.uint64(1)] = w
            wb[i + np.uint64(2)] = w
        a, b, o = img[r], blurred[r], out[r]
        for j in range(cols):
            k = np.uint64(j)
            w = wb[k]
            p = np.int32(np.int32(a[k]) * (c255 - w) + c127)
            q = np.int32(np.int32(b[k]) * w + c127)
            v = np.int32((p + c1 + (p >> c8)) >> c8) + np.int32((q + c1 + (q >> c8)) >> c8)
            o[k] = min(v, c255)
