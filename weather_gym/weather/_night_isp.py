"""The night camera's image processor, compiled: colour at half resolution, put back on the luma in one pass.

:class:`~weather_gym.weather.dim.Dim` in ``mode="night"`` works as a YUV 4:2:0 ISP does: the luma
(Rec. 601) at full resolution, the colour (each channel minus the luma) at half resolution in each
direction. Two passes here:

* :func:`chroma_plane`, at half resolution: each channel's offset from the pixel's luma, both through
  the sensor's tone curve (the darkening the auto-exposure cannot make up for), plus the colour
  blotches, times what the chroma suppression leaves (``1 - desaturate``; the blotches' own luma
  stays whole), as int16;
* :func:`combine`, at full resolution: the luma through a table (the black level) plus the colour
  offsets enlarged 2x (bilinear), saturated to 0-255.

numba compiles the kernels on first use (cached on disk afterwards where a cache folder is writable:
weather_gym.core._jit_cache).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._night_isp import chroma_plane, combine
    >>> half = np.zeros((1, 1, 3), np.uint8); half[0, 0] = (200, 100, 100)   # a red pixel
    >>> tone = np.arange(256, dtype=np.float32)                             # the identity tone curve
    >>> c = chroma_plane(half, tone, None, 1.0)                               # no suppression
    >>> c[0, 0].tolist()                                                      # each channel minus the luma (130)
    [70, -30, -30]
    >>> out = np.empty((2, 2, 3), np.uint8)
    >>> combine(np.full((2, 2), 130, np.uint8), np.arange(256, dtype=np.uint8), c, out)
    >>> out[1, 1].tolist()
    [200, 100, 100]
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache

__all__ = ["blotch_grid", "chroma_plane", "combine", "half_size"]


def half_size(h: int, w: int) -> tuple[int, int]:
    """``(rows, cols)`` of the half-resolution colour of an ``h x w`` frame (rounded up)."""
    return (h + 1) // 2, (w + 1) // 2


def blotch_grid(raw: np.ndarray, gauss: np.ndarray, level: np.ndarray, noise: np.ndarray, ref: float,
                sigma: float) -> np.ndarray:
    """The colour blotches on their grid, float32 ``rows x cols x 3`` (``level``'s shape): zero-sum RGB
    offsets, std ``sigma`` times ``min(noise[level] / ref, 4)`` per cell, from 3 random bytes per cell
    (``raw``) through the standard-normal table ``gauss``."""
    out = np.empty((level.shape[0], level.shape[1], 3), np.float32)
    _blotches(np.ascontiguousarray(raw), np.ascontiguousarray(gauss, np.float32), np.ascontiguousarray(level),
              np.ascontiguousarray(noise, np.float32), np.float32(1.0 / max(ref, 1e-6)),
              np.float32(sigma * np.sqrt(1.5)), out)
    return out


def chroma_plane(half: np.ndarray, tone: np.ndarray, blotches: np.ndarray | None, keep: float) -> np.ndarray:
    """Colour offsets of a half-resolution uint8 RGB frame, int16 ``rows x cols x 3``.

    ``round(keep * (tone[c] - tone[luma] + blotch_c - blotch_luma) + blotch_luma)`` per channel
    ``c``: ``tone`` the float32 code -> code table of the sensor's tone curve, ``luma`` the pixel's
    Rec. 601 luma (as OpenCV's ``RGB2GRAY``), ``blotches`` float32 ``rows x cols x 3`` offsets (None:
    none) and ``blotch_luma`` their Rec. 601 luma (the part the chroma suppression leaves, as it keeps
    a pixel's grey), ``keep`` the fraction of the colour the chroma suppression leaves.
    """
    out = np.empty(half.shape, np.int16)
    rows = half.shape[0]
    flat = np.ascontiguousarray(half).reshape(rows, -1)
    b = np.zeros((1, flat.shape[1]), np.float32) if blotches is None else np.ascontiguousarray(blotches, np.float32)
    _chroma(flat, np.ascontiguousarray(tone, np.float32), b.reshape(b.shape[0], -1), blotches is not None,
            np.float32(keep), out.reshape(rows, -1))
    return out


def combine(luma: np.ndarray, tone: np.ndarray, chroma: np.ndarray, out: np.ndarray) -> None:
    """``tone[luma] + up2(chroma)`` per channel, saturated, into ``out`` (uint8 ``h x w x 3``).

    ``luma`` uint8 ``h x w``; ``tone`` a uint8 code -> code table (the black level); ``chroma`` int16
    from :func:`chroma_plane` at :func:`half_size`; ``up2`` OpenCV's bilinear enlargement to ``h x w``
    (at exactly 2x: weights 9, 3, 3, 1 of 16).
    """
    h, w = luma.shape
    big = cv2.resize(np.ascontiguousarray(chroma, np.int16), (w, h), interpolation=cv2.INTER_LINEAR)
    target = out if out.flags.c_contiguous else np.empty_like(out)
    _add(cv2.LUT(luma, np.ascontiguousarray(tone, np.uint8)), big.reshape(h, w * 3), target.reshape(h, w * 3))
    if target is not out:
        np.copyto(out, target)


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _blotches(raw: np.ndarray, gauss: np.ndarray, level: np.ndarray, noise: np.ndarray, inv_ref: np.float32,
              scale: np.float32, out: np.ndarray) -> None:
    rows, cols = level.shape
    for r in range(rows):
        for x in range(cols):
            i = 3 * (r * cols + x)
            a, b, c = gauss[raw[i]], gauss[raw[i + 1]], gauss[raw[i + 2]]
            m = (a + b + c) / np.float32(3.0)
            f = scale * min(noise[level[r, x]] * inv_ref, np.float32(4.0))
            out[r, x, 0] = (a - m) * f
            out[r, x, 1] = (b - m) * f
            out[r, x, 2] = (c - m) * f


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False)
def _chroma(half: np.ndarray, tone: np.ndarray, blot: np.ndarray, with_blot: bool, keep: np.float32,
            out: np.ndarray) -> None:
    """:func:`chroma_plane` on rows of values (``3 cols`` each). Per row the table look-ups come first
    (each value's and each pixel's luma's), then the arithmetic with the channels written out, a loop
    numba vectorises (it does not with a look-up inside)."""
    rows, n = half.shape[0], half.shape[1]
    ta = np.empty(n, np.float32)
    tl = np.empty(n // 3, np.float32)
    zero = np.float32(0.0)  # (+ 0.0: what the blotches' luma adds without blotches)
    for r in range(rows):
        h, o = half[r], out[r]
        for i in range(n):
            ta[i] = tone[h[i]]
        for x in range(n // 3):
            i = 3 * x
            tl[x] = tone[(np.int32(h[i]) * np.int32(4899) + np.int32(h[i + 1]) * np.int32(9617)
                          + np.int32(h[i + 2]) * np.int32(1868) + np.int32(8192)) >> 14]
        if with_blot:
            _blend_blotches(ta, tl, blot[r], keep, o)
        else:
            for x in range(n // 3):
                i = 3 * x
                t = tl[x]
                o[i] = np.int16(np.rint(keep * (ta[i] - t) + zero))
                o[i + 1] = np.int16(np.rint(keep * (ta[i + 1] - t) + zero))
                o[i + 2] = np.int16(np.rint(keep * (ta[i + 2] - t) + zero))


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False, inline="always")
def _blend_blotches(ta: np.ndarray, tl: np.ndarray, b: np.ndarray, keep: np.float32, o: np.ndarray) -> None:
    for x in range(tl.shape[0]):
        i = 3 * x
        t = tl[x]
        b0, b1, b2 = b[i], b[i + 1], b[i + 2]
        bl = np.float32(0.299) * b0 + np.float32(0.587) * b1 + np.float32(0.114) * b2
        v0, v1, v2 = ta[i] - t, ta[i + 1] - t, ta[i + 2] - t
        v0 += b0 - bl
        v1 += b1 - bl
        v2 += b2 - bl
        o[i] = np.int16(np.rint(keep * v0 + bl))
        o[i + 1] = np.int16(np.rint(keep * v1 + bl))
        o[i + 2] = np.int16(np.rint(keep * v2 + bl))


@numba.njit(cache=jit_cache(__file__), nogil=True, boundscheck=False)
def _add(luma: np.ndarray, chroma: np.ndarray, out: np.ndarray) -> None:
    """Each pixel's luma plus its three colour offsets, saturated (rows of values; a table look-up
    here would keep numba from vectorising the loop: OpenCV's LUT comes first)."""
    rows, cols = luma.shape
    c0, c255 = np.int16(0), np.int16(255)
    for r in range(rows):
        yr, cr, o = luma[r], chroma[r], out[r]
        for x in range(cols):
            y = np.int16(yr[x])
            for c in range(3):
                o[3 * x + c] = np.uint8(min(max(y + cr[3 * x + c], c0), c255))
