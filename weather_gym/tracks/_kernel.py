"""The compiled kernel of :meth:`weather_gym.tracks._track.Track.project` for one point (every env step).

A module of its own so that loading a track does not load numba (about 1.3 s to import): ``Track``
imports it on the first one-point projection.

Example (one point through this kernel, the same floats as the array path):
    >>> import numpy as np
    >>> from weather_gym.tracks import load_track
    >>> t = load_track("small_track")
    >>> p, q = t.project(1.0, 2.0), t.project(np.array([1.0]), np.array([2.0]))
    >>> (p.s, p.lateral, p.heading, p.index) == (q.s[0], q.lateral[0], q.heading[0], q.index[0])
    True
"""

from __future__ import annotations

import math

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache


@numba.njit(cache=jit_cache(__file__), nogil=True)
def project_point(x: float, y: float, ax: np.ndarray, ay: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                   half: np.ndarray, len2: np.ndarray, seg_len: np.ndarray, s_a: np.ndarray, h: np.ndarray,
                   closed: bool, length: float, use_hint: bool, s_hint: float,
                   window: float) -> tuple[float, float, float, float, int]:  # pragma: no cover (compiled)
    """:meth:`weather_gym.tracks._track.Track.project` of one point, operation for operation as the array path computes it:
    ``(s, lateral, sin and cos of the heading, segment index)``."""
    n = ax.shape[0]
    near = np.zeros(n, dtype=np.bool_)
    if use_hint:
        found = False
        closest, closest_ds = 0, np.inf
        for i in range(n):
            ds = s_a[i] - s_hint
            if closed:
                ds = (ds + length / 2.0) % length - length / 2.0
            if abs(ds + half[i]) <= window + half[i]:
                near[i] = True
                found = True
            if abs(ds) < closest_ds:
                closest, closest_ds = i, abs(ds)
        if not found:
            near[closest] = True
    else:
        near[:] = True
    best, best_d2, best_t, best_rx, best_ry = -1, np.inf, 0.0, 0.0, 0.0
    for i in range(n):
        if not near[i]:
            continue
        rx, ry = x - ax[i], y - ay[i]
        t = (rx * dx[i] + ry * dy[i]) / len2[i]
        lo = -np.inf if (not closed and i == 0) else 0.0
        hi = np.inf if (not closed and i == n - 1) else 1.0
        t = min(max(t, lo), hi)
        fx = rx - t * dx[i]
        fy = ry - t * dy[i]
        d2 = fx * fx + fy * fy
        if d2 < best_d2 or best < 0:
            best, best_d2, best_t, best_rx, best_ry = i, d2, t, rx, ry
    cross = dx[best] * best_ry - dy[best] * best_rx
    lateral = math.copysign(math.sqrt(best_d2), cross)
    s = s_a[best] + best_t * seg_len[best]
    if closed:
        s = s % length
    nxt = min(best + 1, h.shape[0] - 1)
    out = h[best] + min(max(best_t, 0.0), 1.0) * (h[nxt] - h[best])
    return s, lateral, math.sin(out), math.cos(out), best
