"""The last step of the refractive drops, compiled: each drop's content scaled up to its box and blended in.

For every drop, in order, :func:`blend_drops` does what three OpenCV calls per drop did, byte for
byte, in one pass without Python between the drops:

* ``cv2.resize(content, (2n - 1, 2n - 1), interpolation=cv2.INTER_LINEAR)`` of the drop's ``n x n``
  content: OpenCV's fixed-point bilinear upscaling (11-bit weights, a horizontal pass in integers, then
  its vectorised vertical pass ``((h0 >> 4) * b0 >> 16) + ((h1 >> 4) * b1 >> 16) + 2 >> 2``). The
  horizontal source column is clamped at the content's edge (weight 0 beyond it); vertically the weights
  stay fractional and the source row is clamped, as in OpenCV (:func:`resize_tables`);
* ``cv2.multiply(roi, keep, dst=roi, scale=1 / 255)``, i.e. ``round(roi * keep / 255)``;
* ``cv2.add(roi, big, dst=roi)``, saturating.

``tests/weather/test_weather_lens_drops.py`` checks the result against those OpenCV calls drop by drop.
numba compiles the kernel on first use (cached on disk afterwards where a cache folder is writable: weather_gym.core._jit_cache).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._drop_blend import resize_tables
    >>> xo, xa, yo, ya = resize_tables(64)
    >>> xo[3, :5].tolist(), xa[3, 1].tolist()   # a 3 x 3 content scaled to 5 x 5: columns
    ([0, 0, 1, 1, 2], [1229, 819])
    >>> yo[3, :5].tolist(), ya[3, 0].tolist()   # rows: row -1 is read as row 0, weights stay fractional
    ([-1, 0, 1, 1, 2], [410, 1638])
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache
from weather_gym.weather._common import into

__all__ = ["blend_drops", "resize_tables"]

#: OpenCV's fixed-point scale of its bilinear resize weights (INTER_RESIZE_COEF_SCALE).
_COEF_SCALE = 2048


@lru_cache(maxsize=8)
def resize_tables(nmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's INTER_LINEAR coefficients of an ``n -> 2n - 1`` upscaling, for every ``n <= nmax``.

    ``(xo, xa, yo, ya)``, indexed ``[n, d]`` for output column / row ``d < 2n - 1``: the source column
    (clamped to the content) and its two weights, the source row (not clamped: rows are clamped when
    read) and its two weights; int32, read-only.
    """
    side = 2 * nmax - 1
    xo, yo = (np.zeros((nmax + 1, side), np.int32) for _ in range(2))
    xa, ya = (np.zeros((nmax + 1, side, 2), np.int32) for _ in range(2))
    one = np.float32(1.0)
    for n in range(1, nmax + 1):
        m = 2 * n - 1
        scale = 1.0 / (m / n)  # OpenCV: 1 / inv_scale in double
        f = ((np.arange(m, dtype=np.float64) + 0.5) * scale - 0.5).astype(np.float32)
        s = np.floor(f).astype(np.int64)
        f = (f - s.astype(np.float32)).astype(np.float32)
        yo[n, :m] = s
        ya[n, :m, 0] = np.rint((one - f) * np.float32(_COEF_SCALE))
        ya[n, :m, 1] = np.rint(f * np.float32(_COEF_SCALE))
        edge = (s < 0) | (s >= n - 1)
        f[edge] = 0.0
        xo[n, :m] = np.clip(s, 0, n - 1)
        xa[n, :m, 0] = np.rint((one - f) * np.float32(_COEF_SCALE))
        xa[n, :m, 1] = np.rint(f * np.float32(_COEF_SCALE))
    for a in (xo, xa, yo, ya):
        a.setflags(write=False)
    return xo, xa, yo, ya


def blend_drops(out: np.ndarray, content: np.ndarray, keeps: list[np.ndarray], half: np.ndarray, cx: np.ndarray,
                cy: np.ndarray, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> None:
    """Blend drops into ``out`` (uint8 ``H x W x 3``) in order, in place.

    Drop ``j`` (centre ``cx, cy``, box half-side ``half``, its part in the frame ``[x0, x1) x [y0, y1)``)
    has its content as the next ``(half + 1) ** 2`` RGB pixels of ``content`` (the drops one after
    another) and the frame's remaining weight ``keeps[j]`` over its whole box (``2 half + 1`` square,
    RGB uint8, 255 = 1).
    """
    n = np.asarray(half, np.int64) + 1
    if n.size == 0:
        return
    cstart = np.zeros(len(n), np.int64)
    np.cumsum((n * n)[:-1], out=cstart[1:])
    wstart = np.zeros(len(n), np.int64)
    np.cumsum([k.size for k in keeps[:-1]], out=wstart[1:])
    nmax = int(n.max())
    tables = resize_tables(max(64, 1 << (nmax - 1).bit_length()))
    target = out if out.flags.c_contiguous else np.ascontiguousarray(out)
    _blend(target.reshape(target.shape[0], -1), np.ascontiguousarray(content).reshape(-1), np.concatenate(
        [k.reshape(-1) for k in keeps]), n, cstart, wstart, *(np.asarray(a, np.int64) for a in (cx, cy, x0, y0, x1, y1)),
        *tables)  # type: ignore[call-arg]  # mypy cannot count the arguments a generator unpacks to
    into(target, out)


@numba.njit(nogil=True, inline="always")
def _blend_row(orow: np.ndarray, h0: np.ndarray, h1: np.ndarray, b0: int | np.int32, b1: int | np.int32,
               keep: np.ndarray) -> None:
    """One output row of a drop: OpenCV's vertical resize pass, then multiply by keep / 255 and add."""
    b0, b1 = np.int32(b0), np.int32(b1)
    s2, s4, s8, s16 = np.int32(2), np.int32(4), np.int32(8), np.int32(16)
    zero, one, c127, c255 = np.int32(0), np.int32(1), np.int32(127), np.int32(255)
    for k in range(orow.shape[0]):
        v = np.int32(np.int32(np.int32(np.int32(np.int32(h0[k] >> s4) * b0) >> s16)
                              + np.int32(np.int32(np.int32(h1[k] >> s4) * b1) >> s16) + s2) >> s2)
        v = min(max(v, zero), c255)
        p = np.int32(np.int32(orow[k]) * np.int32(keep[k]) + c127)  # round(o * keep / 255) = (p + 1 + (p >> 8)) >> 8
        o = np.int32(np.int32(np.int32(p + one + np.int32(p >> s8)) >> s8) + v)
        orow[k] = min(o, c255)


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _blend(out2: np.ndarray, content: np.ndarray, keep: np.ndarray, nn: np.ndarray, cstart: np.ndarray,
           wstart: np.ndarray, cx: np.ndarray, cy: np.ndarray, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray,
           y1: np.ndarray, xo: np.ndarray, xa: np.ndarray, yo: np.ndarray, ya: np.ndarray) -> None:
    """:func:`blend_drops` on flat arrays: ``out2`` the frame as rows of bytes, ``content`` and ``keep`` the
    drops' bytes one after another from ``cstart`` (pixels) and ``wstart`` (bytes), the tables of
    :func:`resize_tables`. Indices are unsigned or slices, so that numba leaves out its negative-index
    checks and the loops vectorise."""
    nmax = xo.shape[0] - 1
    hbuf = np.empty(nmax * (2 * nmax - 1) * 3, np.int32)
    i0, i1 = np.empty((2 * nmax - 1) * 3, np.uint32), np.empty((2 * nmax - 1) * 3, np.uint32)
    a0, a1 = np.empty((2 * nmax - 1) * 3, np.int32), np.empty((2 * nmax - 1) * 3, np.int32)
    for j in range(nn.shape[0]):
        n = nn[j]
        hf = n - 1
        side = 2 * n - 1
        bx, by = x0[j] - cx[j] + hf, y0[j] - cy[j] + hf  # the frame part's corner in the drop's box
        ww, hh = x1[j] - x0[j], y1[j] - y0[j]
        ww3 = ww * 3
        n3 = n * 3
        cs = cstart[j] * 3
        # OpenCV's horizontal pass, over every content row, for the box's columns in the frame
        for i in range(ww):  # per byte of a row: the two source bytes and their weights
            s0 = xo[n, bx + i]
            s1 = min(s0 + 1, n - 1)
            for c in range(3):
                i0[i * 3 + c] = s0 * 3 + c
                i1[i * 3 + c] = s1 * 3 + c
                a0[i * 3 + c] = xa[n, bx + i, 0]
                a1[i * 3 + c] = xa[n, bx + i, 1]
        g0, g1, w0_, w1_ = i0[:ww3], i1[:ww3], a0[:ww3], a1[:ww3]
        for r in range(n):
            crow = content[cs + r * n3:cs + (r + 1) * n3]
            hrow = hbuf[r * ww3:(r + 1) * ww3]
            for k in range(ww3):
                hrow[k] = np.int32(crow[g0[k]]) * w0_[k] + np.int32(crow[g1[k]]) * w1_[k]
        ox = x0[j] * 3
        for t in range(hh):
            dy = by + t
            sy = yo[n, dy]
            r0, r1 = min(max(sy, 0), n - 1) * ww3, min(max(sy + 1, 0), n - 1) * ww3
            w0 = wstart[j] + (dy * side + bx) * 3
            _blend_row(out2[y0[j] + t, ox:ox + ww3], hbuf[r0:r0 + ww3], hbuf[r1:r1 + ww3], ya[n, dy, 0], ya[n, dy, 1],
                       keep[w0:w0 + ww3])
