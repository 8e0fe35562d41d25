"""Area shrinks by exactly 2 or 4, compiled: OpenCV's ``INTER_AREA`` byte for byte, in one pass.

:func:`area_shrink` is ``cv2.resize(img, size, interpolation=cv2.INTER_AREA)`` for a uint8 frame.
Where the frame is exactly 2 or 4 times ``size`` in each direction, OpenCV averages each block
(its own code and Intel IPP's, at every IPP level; checked with ``OPENCV_IPP=avx512|avx2|sse42|disabled``):

* 2 x 2 blocks: ``(sum + 2) >> 2`` (halves rounded up);
* 4 x 4 blocks: the sum times 1/16, rounded half to even.

Those two are one compiled pass here, two to five times faster than OpenCV's at the sizes the
night camera and the motion smear use (``tests/weather/test_weather_area.py`` checks them against
OpenCV); any other size goes to OpenCV. numba compiles the kernels on first use (cached on disk
afterwards where a cache folder is writable: weather_gym.core._jit_cache).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._area import area_shrink
    >>> img = np.arange(4 * 4 * 3, dtype=np.uint8).reshape(4, 4, 3)
    >>> area_shrink(img, (2, 2))[0, 0].tolist()        # (0 + 3 + 12 + 15 + 2) >> 2, per channel
    [8, 9, 10]
    >>> area_shrink(img, (1, 1))[0, 0].tolist()        # means 22.5, 23.5, 24.5, rounded half to even
    [22, 24, 24]
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache

__all__ = ["area_shrink"]


def area_shrink(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``cv2.resize(img, size, interpolation=cv2.INTER_AREA)`` (``size`` = ``(width, height)``) of a
    uint8 ``H x W`` or ``H x W x C`` frame, byte for byte; compiled at exactly 2x or 4x (a new array)."""
    w, h = size
    f = img.shape[0] // h if h > 0 else 0
    if (f not in (2, 4) or img.shape[0] != f * h or img.shape[1] != f * w or img.dtype != np.uint8
            or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] == 1)):
        return cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    ch = img.shape[2] if img.ndim == 3 else 1
    out = np.empty((h, w, ch) if img.ndim == 3 else (h, w), np.uint8)
    src = np.ascontiguousarray(img)
    flat_src, flat_out = src.reshape(src.shape[0], -1), out.reshape(h, -1)
    if f == 2:
        _area2(flat_src, flat_out, ch)
    else:
        _area4(flat_src, flat_out, ch)
    return out


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False)
def _area2(src: np.ndarray, out: np.ndarray, ch: int) -> None:
    """2x on rows of values: each row pair summed, then each pixel pair per channel, ``(sum + 2) >> 2``."""
    n = src.shape[1]
    acc = np.empty(n, np.uint16)
    c2 = np.uint16(2)
    for r in range(out.shape[0]):
        s0, s1 = src[2 * r], src[2 * r + 1]
        for k in range(n):
            acc[k] = np.uint16(s0[k]) + np.uint16(s1[k])
        o = out[r]
        if ch == 3:  # the channels written out: a loop numba vectorises
            for x in range(n // 6):
                i = 6 * x
                o[3 * x] = np.uint8((acc[i] + acc[i + 3] + c2) >> c2)
                o[3 * x + 1] = np.uint8((acc[i + 1] + acc[i + 4] + c2) >> c2)
                o[3 * x + 2] = np.uint8((acc[i + 2] + acc[i + 5] + c2) >> c2)
        else:
            for x in range(n // (2 * ch)):
                i = 2 * ch * x
                for c in range(ch):
                    o[ch * x + c] = np.uint8((acc[i + c] + acc[i + ch + c] + c2) >> c2)


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False)
def _area4(src: np.ndarray, out: np.ndarray, ch: int) -> None:
    """4x on rows of values: each row quadruple summed, then each 4 pixels per channel, the sum
    (at most 16 x 255: 16 bits) divided by 16 rounded half to even."""
    n = src.shape[1]
    step = 4 * ch
    acc = np.empty(n, np.uint16)
    c1, c4, c7 = np.uint16(1), np.uint16(4), np.uint16(7)
    for r in range(out.shape[0]):
        s0, s1, s2, s3 = src[4 * r], src[4 * r + 1], src[4 * r + 2], src[4 * r + 3]
        for k in range(n):
            acc[k] = np.uint16(s0[k]) + np.uint16(s1[k]) + np.uint16(s2[k]) + np.uint16(s3[k])
        o = out[r]
        for x in range(n // step):
            i = step * x
            for c in range(ch):
                v = np.uint16(acc[i + c] + acc[i + ch + c] + acc[i + 2 * ch + c] + acc[i + 3 * ch + c])
                o[ch * x + c] = np.uint8((v + c7 + ((v >> c4) & c1)) >> c4)
