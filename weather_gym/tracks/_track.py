"""The :class:`Track` value: cones, centerline, half widths, start pose and where a run is complete,
with the queries the simulator and agents ask of it (projection onto the centerline, boundary
distances, points along it). Built by :mod:`weather_gym.tracks` (registered names, random tracks,
cone CSV files), which re-exports everything here.

Example:
    >>> from weather_gym.tracks import load_track
    >>> t = load_track("oval")
    >>> p = t.project(*t.point_at(12.0)[:2])
    >>> round(float(p.s), 3), round(float(p.lateral), 3)
    (12.0, 0.0)
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, cast

import numpy as np

from weather_gym.core._io import atomic_write
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.tracks import _geometry as geo

__all__ = ["CSV_HEADER", "EVENTS", "MIN_RADIUS_M", "Projection", "StartPose", "Track"]

EVENTS = ("trackdrive", "acceleration", "skidpad")
CSV_HEADER = "tag,x,y,direction,x_variance,y_variance,xy_covariance"
MIN_RADIUS_M = 6.0
"""Generated tracks keep every centerline radius at or above this (a car can drive it)."""
StartPose = tuple[float, float, float]


class Projection(NamedTuple):
    """Foot point of a position on the centerline (arrays when the query was an array).

    ``s``: arc length; ``lateral``: signed distance, positive = left of the centerline;
    ``heading``: centerline direction there; ``index``: centerline point at or before the foot.
    """

    s: float | np.ndarray
    lateral: float | np.ndarray
    heading: float | np.ndarray
    index: int | np.ndarray  # type: ignore[assignment]  # the field shadows tuple.index on purpose (public name)


def _frozen(a: object, dtype: type, shape_tail: tuple[int, ...], what: str) -> np.ndarray:
    arr: np.ndarray = np.array(a, dtype=dtype, copy=True)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        raise InputError(f"Track.{what} must have shape (N, {', '.join(map(str, shape_tail))}); got {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Track:
    """An immutable cone track (arrays are read-only; derived quantities are cached)."""

    name: str
    cones_xy: np.ndarray
    cone_classes: np.ndarray
    centerline: np.ndarray
    closed: bool
    event: str
    start_pose: StartPose
    half_width_left: np.ndarray
    half_width_right: np.ndarray
    finish_s: float
    source: str
    start_line_s: float = 0.0
    """Arc length of the start (timing) line: 0 for closed tracks."""

    def __post_init__(self) -> None:
        put = functools.partial(object.__setattr__, self)
        put("cones_xy", _frozen(self.cones_xy, np.float64, (2,), "cones_xy"))
        put("cone_classes", _frozen(self.cone_classes, np.int64, (), "cone_classes"))
        put("centerline", _frozen(self.centerline, np.float64, (2,), "centerline"))
        m = len(self.centerline)
        put("half_width_left", _frozen(self.half_width_left, np.float64, (), "half_width_left"))
        put("half_width_right", _frozen(self.half_width_right, np.float64, (), "half_width_right"))
        put("start_pose", tuple(float(v) for v in self.start_pose))
        put("closed", bool(self.closed))
        put("finish_s", float(self.finish_s))
        put("start_line_s", float(self.start_line_s))
        if len(self.cone_classes) != len(self.cones_xy):
            raise InputError(f"track {self.name!r}: {len(self.cones_xy)} cones but {len(self.cone_classes)} classes")
        if m < 3 or len(self.half_width_left) != m or len(self.half_width_right) != m:
            raise InputError(f"track {self.name!r}: centerline ({m} points) and half widths disagree")
        if len(self.cone_classes) and not ((self.cone_classes >= 0) & (self.cone_classes < len(CONE_CLASSES))).all():
            raise InputError(f"track {self.name!r}: cone class ids must be 0..{len(CONE_CLASSES) - 1}")
        if self.event not in EVENTS:
            raise InputError(f"track {self.name!r}: unknown event {self.event!r}; expected one of {EVENTS}")
        if len(self.start_pose) != 3 or not all(map(math.isfinite, self.start_pose)):
            raise InputError(f"track {self.name!r}: start_pose must be 3 finite numbers (x, y, yaw)")

    def __repr__(self) -> str:
        return (f"Track({self.name!r}, event={self.event!r}, closed={self.closed}, cones={len(self.cones_xy)}, "
                f"length={self.length:.1f} m, source={self.source!r})")

    # ------------------------------------------------------------------ derived geometry
    @functools.cached_property
    def _arc(self) -> tuple[np.ndarray, float]:
        return geo.cumulative_length(self.centerline, self.closed)

    @property
    def length(self) -> float:
        """Centerline length in metres (closed: including the closing segment)."""
        return self._arc[1]

    @functools.cached_property
    def s(self) -> np.ndarray:
        """Arc length of each centerline point, ``s[0] = 0``."""
        out = self._arc[0].copy()
        out.flags.writeable = False
        return out

    @functools.cached_property
    def heading(self) -> np.ndarray:
        """Centerline direction (rad, counter-clockwise from +x) at each point."""
        out = geo.headings(self.centerline, self.closed)
        out.flags.writeable = False
        return out

    @functools.cached_property
    def curvature(self) -> np.ndarray:
        """Signed curvature (1/m, positive = left turn) at each point."""
        out = geo.curvatures(self.centerline, self.closed)
        out.flags.writeable = False
        return out

    @functools.cached_property
    def _segs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        a, d = geo.segments(self.centerline, self.closed)
        seg_len = np.hypot(d[:, 0], d[:, 1])
        h0 = np.arctan2(d[:, 1], d[:, 0])
        return a, d, seg_len, np.maximum(seg_len**2, 1e-18), self.s[: len(a)], h0

    @functools.cached_property
    def _unwrapped_heading(self) -> np.ndarray:
        h = self.heading
        return np.unwrap(np.concatenate([h, h[:1]]) if self.closed else h)

    def _heading_at(self, idx: np.ndarray, t: np.ndarray) -> np.ndarray:
        h = self._unwrapped_heading
        nxt = np.minimum(idx + 1, len(h) - 1)
        out = h[idx] + np.minimum(np.maximum(t, 0.0), 1.0) * (h[nxt] - h[idx])  # = clip (faster)
        return cast(np.ndarray, np.arctan2(np.sin(out), np.cos(out)))

    def point_at(self, s: float | np.ndarray) -> tuple:
        """``(x, y, heading)`` at arc length ``s``; closed tracks wrap, open ones extend their ends straight."""
        a, d, seg_len, _, s_a, _ = self._segs
        q = np.asarray(s, dtype=np.float64)
        if self.closed:
            q = np.mod(q, self.length)
        idx = np.clip(np.searchsorted(s_a, q, side="right") - 1, 0, len(a) - 1)
        t = (q - s_a[idx]) / np.maximum(seg_len[idx], 1e-12)
        x = a[idx, 0] + t * d[idx, 0]
        y = a[idx, 1] + t * d[idx, 1]
        h = self._heading_at(idx, t)
        if q.ndim == 0:
            return float(x), float(y), float(h)
        return x, y, h

    def project(self, x: float | np.ndarray, y: float | np.ndarray, s_hint: float | None = None, window: float = 15.0) -> Projection:
        """Nearest centerline point to ``(x, y)`` (scalars or arrays of one shape).

        With ``s_hint`` only the centerline within ``±window`` metres of arc length around it is
        searched: use the last known ``s`` on self-crossing paths such as the skidpad. On open
        tracks, points beyond the ends project onto the extended end segments (``s`` < 0 or > length).
        """
        a, d, seg_len, len2, s_a, _ = self._segs
        if isinstance(x, float | int) and isinstance(y, float | int):  # one point (every env step)
            return self._project_one(float(x), float(y), s_hint, window)
        px, py = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        scalar = px.ndim == 0
        pts = np.column_stack([px.ravel(), py.ravel()])
        cand = np.arange(len(a))
        if s_hint is not None:
            ds = s_a - float(s_hint)
            if self.closed:
                ds = np.mod(ds + self.length / 2.0, self.length) - self.length / 2.0
            near = np.abs(ds + seg_len / 2.0) <= window + seg_len / 2.0
            cand = np.nonzero(near)[0] if near.any() else np.array([int(np.argmin(np.abs(ds)))])
        rel = pts[:, None, :] - a[None, cand, :]
        dcx, dcy = d[cand, 0], d[cand, 1]
        t = (rel[..., 0] * dcx + rel[..., 1] * dcy) / len2[cand]
        if self.closed:
            t = np.minimum(np.maximum(t, 0.0), 1.0)  # = np.clip(t, 0, 1), faster on small arrays
        else:
            lo = np.zeros(len(cand))
            hi = np.ones(len(cand))
            lo[cand == 0] = -np.inf
            hi[cand == len(a) - 1] = np.inf
            t = np.minimum(np.maximum(t, lo), hi)
        fx = rel[..., 0] - t * dcx
        fy = rel[..., 1] - t * dcy
        dist2 = fx * fx + fy * fy
        k = np.argmin(dist2, axis=1)
        rows = np.arange(len(pts))
        idx, tk = cand[k], t[rows, k]
        cross = d[idx, 0] * rel[rows, k, 1] - d[idx, 1] * rel[rows, k, 0]
        lateral = np.copysign(np.sqrt(dist2[rows, k]), cross)
        s = s_a[idx] + tk * seg_len[idx]
        if self.closed:
            s = np.mod(s, self.length)
        heading = self._heading_at(idx, tk)
        if scalar:
            return Projection(float(s[0]), float(lateral[0]), float(heading[0]), int(idx[0]))
        shape = px.shape
        return Projection(s.reshape(shape), lateral.reshape(shape), heading.reshape(shape), idx.reshape(shape))

    @functools.cached_property
    def _seg_columns(self) -> tuple[np.ndarray, ...]:
        a, d, seg_len, _, _, _ = self._segs
        return (np.ascontiguousarray(a[:, 0]), np.ascontiguousarray(a[:, 1]), np.ascontiguousarray(d[:, 0]),
                np.ascontiguousarray(d[:, 1]), seg_len / 2.0)

    def _project_one(self, x: float, y: float, s_hint: float | None, window: float) -> Projection:
        """:meth:`project` of one point: the same arithmetic in one compiled call (every env step;
        tests/tracks/test_tracks.py checks that both paths give the same floats)."""
        # numba is loaded on the first call, not with a track
        from weather_gym.tracks._kernel import project_point

        _, _, seg_len, len2, s_a, _ = self._segs
        ax, ay, dx, dy, half = self._seg_columns
        s, lateral, sin_h, cos_h, idx = project_point(
            x, y, ax, ay, dx, dy, half, len2, seg_len, s_a, self._unwrapped_heading, self.closed, self.length,
            s_hint is not None, 0.0 if s_hint is None else float(s_hint), float(window))
        # NumPy's arctan2, as the array path's (libm's atan2 differs from it in the last bit)
        return Projection(s, lateral, float(np.arctan2(sin_h, cos_h)), idx)

    def half_widths_at(self, s: float | np.ndarray) -> tuple:
        """Left and right half widths interpolated at arc length ``s``."""
        q = np.asarray(s, dtype=np.float64)
        xp, left, right = self.s, self.half_width_left, self.half_width_right
        if self.closed:
            q = np.mod(q, self.length)
            xp = np.append(xp, self.length)
            left, right = np.append(left, left[0]), np.append(right, right[0])
        out = np.interp(q, xp, left), np.interp(q, xp, right)
        return (float(out[0]), float(out[1])) if q.ndim == 0 else out

    def boundary_distance(self, x: float | np.ndarray, y: float | np.ndarray, s_hint: float | None = None, window: float = 15.0) -> tuple:
        """Distance from ``(x, y)`` to the left and right boundary lines, positive while inside."""
        p = self.project(x, y, s_hint=s_hint, window=window)
        left, right = self.half_widths_at(p.s)
        return left - p.lateral, right + p.lateral

    # ------------------------------------------------------------------ output
    def to_csv(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the cones (and a ``car_start`` row) in the EUFS CSV format (safely; refuses to overwrite)."""
        rows = [CSV_HEADER]
        for (x, y), c in zip(self.cones_xy.tolist(), self.cone_classes.tolist(), strict=True):
            rows.append(f"{CONE_CLASSES[c]},{x!r},{y!r},0.0,0.01,0.01,0.0")
        x, y, yaw = self.start_pose
        rows.append(f"car_start,{x!r},{y!r},{yaw!r},0.0,0.0,0.0")
        return atomic_write(path, "\n".join(rows) + "\n", overwrite=overwrite)
