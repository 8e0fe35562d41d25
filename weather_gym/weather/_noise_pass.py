"""The sensor noise's per-value pass, compiled: one table look-up per value, no temporary frames.

:func:`~weather_gym.weather._common.add_sensor_noise` gives every value ``v`` of a frame
``mean[v] +- a``, saturated to 0-255, with a fresh random sign per value and ``a`` from the value's
sigma and a magnitude read from the noise bank through the frame's window. Every combination of
sign, value and magnitude is in one 128 KiB table (:func:`~weather_gym.weather._common.noise_table`),
so :func:`noise_pass` reads the frame once and writes the result once, where five OpenCV passes
(a look-up, a split, a multiply, a subtract and a masked add) each wrote a temporary frame.

``tests/weather/test_weather_noise_pass.py`` checks the result against those OpenCV passes. numba
compiles the kernel on first use (cached on disk afterwards where a cache folder is writable: weather_gym.core._jit_cache).

Example:
    >>> import numpy as np
    >>> from weather_gym.weather._noise_pass import noise_pass
    >>> img = np.full((1, 2, 8), 100, np.uint8)           # one frame: 2 rows of 8 values
    >>> table = np.zeros(1 << 17, np.uint8)
    >>> table[(0 << 16) | (100 << 8) | 3] = 90            # sign 0 (minus), value 100, magnitude 3
    >>> table[(1 << 16) | (100 << 8) | 3] = 110           # sign 1 (plus)
    >>> bank = np.full(64, 3, np.uint8)
    >>> signs = np.array([[0b11110000, 0b00000001]], np.uint8)  # most significant bit first
    >>> out = np.empty_like(img)
    >>> noise_pass(img, out, table, bank, np.array([0]), np.array([8]), signs)
    >>> out[0].tolist()
    [[110, 110, 110, 110, 90, 90, 90, 90], [90, 90, 90, 90, 90, 90, 90, 110]]
"""

from __future__ import annotations

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache

__all__ = ["noise_pass"]


def noise_pass(frames: np.ndarray, outs: np.ndarray, table: np.ndarray, bank: np.ndarray, starts: np.ndarray,
               pitches: np.ndarray, signs: np.ndarray) -> None:
    """Noise of ``frames`` (uint8 ``N x rows x cols``) into ``outs`` (same shape).

    Value ``(i, r, c)``, byte ``v``, becomes ``table[s << 16 | v << 8 | m]``: ``m`` is
    ``bank[starts[i] + r * pitches[i] + c]`` and ``s`` bit ``r * cols + c`` of ``signs[i]`` (uint8,
    most significant bit of each byte first, as ``numpy.unpackbits``).
    """
    _noise(frames, outs, table, bank, np.asarray(starts, np.int64), np.asarray(pitches, np.int64), signs)


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _noise(frames: np.ndarray, outs: np.ndarray, table: np.ndarray, bank: np.ndarray, starts: np.ndarray,
           pitches: np.ndarray, signs: np.ndarray) -> None:
    """:func:`noise_pass`. Indices are unsigned or slices, so that numba leaves out its negative-index
    checks; rows of whole sign bytes go eight values per byte, with the byte's bit moved to bit 16."""
    n_frames, rows, cols = frames.shape
    u1, u3, u7, u8, u9, u16 = np.uint64(1), np.uint64(3), np.uint64(7), np.uint64(8), np.uint64(9), np.uint64(16)
    plus = np.uint64(1 << 16)
    for i in range(n_frames):
        sgn = signs[i]
        for r in range(rows):
            f, o = frames[i, r], outs[i, r]
            z = bank[np.uint64(starts[i] + r * pitches[i]):]
            if cols % 8 == 0:
                s = sgn[np.uint64(r * (cols // 8)):]
                for q in range(cols // 8):
                    bits = np.uint64(s[np.uint64(q)]) << u9
                    for t in range(8):
                        c = np.uint64(q * 8 + t)
                        o[c] = table[((bits << np.uint64(t)) & plus) | (np.uint64(f[c]) << u8) | np.uint64(z[c])]
            else:
                j0 = np.uint64(r * cols)
                for cc in range(cols):
                    c = np.uint64(cc)
                    j = j0 + c
                    up = np.uint64((sgn[j >> u3] >> (u7 - (j & u7))) & u1)
                    o[c] = table[(up << u16) | (np.uint64(f[c]) << u8) | np.uint64(z[c])]
