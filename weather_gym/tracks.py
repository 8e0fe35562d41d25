"""Cone tracks: the EUFS layouts shipped in ``tracks/``, an oval, seeded random tracks, user CSV files.

A :class:`Track` holds the cones (class ids index :data:`CONE_CLASSES`) and a centerline in the
driving direction (blue cones on the left), with its half widths, the start pose and where a lap
or run is complete. Files use the Formula Student simulators' cone CSV
(``tag,x,y[,direction,x_variance,y_variance,xy_covariance]``), see ``tracks/README.md``.

Arc length ``s`` runs along the centerline from its first point. Closed tracks start at the
start/finish line (``start_line_s = 0``, ``finish_s = length``) and the start pose sits a few
metres before it. Open tracks (acceleration, skidpad) begin 5 m behind the start pose; the
timing line is at ``start_line_s`` and the run is complete at ``finish_s``.

Example:
    >>> from weather_gym.tracks import load_track
    >>> t = load_track("small_track")
    >>> t.event, t.closed, round(t.length)
    ('trackdrive', True, 150)
    >>> p = t.project(*t.point_at(30.0)[:2])
    >>> round(float(p.s), 3), round(float(p.lateral), 3)
    (30.0, 0.0)
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import matplotlib.pyplot as plt
import numpy as np
from scipy.spatial import cKDTree

from weather_gym import _track_geometry as geo
from weather_gym._io import atomic_write
from weather_gym.cone_spec import CONE_BODY_RGB, CONE_CLASSES
from weather_gym.errors import FileFormatError, InputError, LimitError, MissingInputError
from weather_gym.paths import data_dir
from weather_gym.registry import Registry

__all__ = [
    "CONE_CLASSES", "EVENTS", "TRACKS", "Projection", "Track", "generate_random_track", "is_track_file", "load_track",
    "oval", "read_cone_csv",
]

EVENTS = ("trackdrive", "acceleration", "skidpad")
CSV_HEADER = "tag,x,y,direction,x_variance,y_variance,xy_covariance"
DUPLICATE_TOL_M = 0.01
MAX_TRACK_FILE_BYTES = 10_000_000
"""Largest cone CSV read (EUFS tracks are a few kB)."""
MAX_CONES = 10_000
"""Most cones in a track (the largest shipped track has a few hundred)."""
MAX_COORDINATE_M = 100_000.0
"""Cone positions lie within this distance of the origin (100 km)."""
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
    index: int | np.ndarray


def _frozen(a, dtype, shape_tail: tuple[int, ...], what: str) -> np.ndarray:
    arr = np.array(a, dtype=dtype, copy=True)
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
    def _segs(self):
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
        return np.arctan2(np.sin(out), np.cos(out))

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

    def project(self, x, y, s_hint: float | None = None, window: float = 15.0) -> Projection:
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
        """:meth:`project` of one point: the same arithmetic on 1-D arrays and floats, fewer array calls
        (tests/test_tracks.py checks that both paths give the same floats)."""
        _, _, seg_len, len2, s_a, _ = self._segs
        ax, ay, dx, dy, half = self._seg_columns
        if s_hint is None:
            cand = None
        else:
            ds = s_a - float(s_hint)
            if self.closed:
                ds = np.mod(ds + self.length / 2.0, self.length) - self.length / 2.0
            near = np.abs(ds + half) <= window + half
            cand = np.flatnonzero(near)
            if not cand.size:
                cand = np.array([int(np.argmin(np.abs(ds)))])
        if cand is None:
            relx, rely, dcx, dcy, l2 = x - ax, y - ay, dx, dy, len2
        else:
            relx, rely, dcx, dcy, l2 = x - ax[cand], y - ay[cand], dx[cand], dy[cand], len2[cand]
        t = (relx * dcx + rely * dcy) / l2
        if self.closed:
            t = np.minimum(np.maximum(t, 0.0), 1.0)
        else:
            n = len(ax)
            idx_all = np.arange(n) if cand is None else cand
            lo = np.where(idx_all == 0, -np.inf, 0.0)
            hi = np.where(idx_all == n - 1, np.inf, 1.0)
            t = np.minimum(np.maximum(t, lo), hi)
        fx = relx - t * dcx
        fy = rely - t * dcy
        dist2 = fx * fx + fy * fy
        k = int(np.argmin(dist2))
        idx = k if cand is None else int(cand[k])
        tk = float(t[k])
        cross = float(dx[idx]) * float(rely[k]) - float(dy[idx]) * float(relx[k])
        lateral = math.copysign(math.sqrt(float(dist2[k])), cross)
        s = float(s_a[idx]) + tk * float(seg_len[idx])
        if self.closed:
            s = s % self.length
        heading = self._heading_at(np.array([idx]), np.array([tk]))
        return Projection(s, lateral, float(heading[0]), idx)

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

    def boundary_distance(self, x, y, s_hint: float | None = None, window: float = 15.0) -> tuple:
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

    def plot(self, ax=None, *, title: str | None = None):
        """Draw cones in their colours, the centerline and the start pose; returns the matplotlib axes."""

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 7))
        line = np.concatenate([self.centerline, self.centerline[:1]]) if self.closed else self.centerline
        ax.plot(line[:, 0], line[:, 1], "--", color="0.45", lw=0.8, label="centerline")
        for cid, cname in enumerate(CONE_CLASSES):
            pts = self.cones_xy[self.cone_classes == cid]
            if len(pts):
                ax.scatter(pts[:, 0], pts[:, 1], s=22 if cname == "big_orange" else 12, color=CONE_BODY_RGB[cname],
                           edgecolors="k", linewidths=0.3, label=cname, zorder=3)
        x, y, yaw = self.start_pose
        scale = max(3.0, 0.06 * float(np.ptp(self.cones_xy, axis=0).max()))
        ax.annotate("", xy=(x + scale * math.cos(yaw), y + scale * math.sin(yaw)), xytext=(x, y),
                    arrowprops=dict(arrowstyle="-|>", color="crimson", lw=1.8), zorder=4)
        ax.plot([x], [y], "o", color="crimson", ms=4, zorder=4, label="start")
        if not self.closed:
            fx, fy, _ = self.point_at(self.finish_s)
            ax.plot([fx], [fy], "x", color="crimson", ms=7, mew=2, zorder=4, label="finish")
        ax.set_aspect("equal")
        ax.set_title(title or f"{self.name}: {self.length:.0f} m, {len(self.cones_xy)} cones ({self.event})",
                     fontsize=9)
        ax.tick_params(labelsize=7)
        return ax


# ---------------------------------------------------------------------------------------------- CSV


def _fail(path, line_no: int | None, msg: str):
    where = f"{path}: line {line_no}: " if line_no is not None else f"{path}: "
    raise FileFormatError(where + msg)


def read_cone_csv(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """Read and validate a cone CSV: ``(cones_xy (N, 2), cone_classes (N,), start_pose or None)``.

    Rows tagged ``car_start`` give the start pose ``(x, y, yaw)`` (yaw from the ``direction``
    column; ``None`` if the file has none); ``midpoint`` rows are markers and are skipped; blank
    lines and ``#`` comments are ignored. Errors name the file and the 1-based line.

    Example:
        >>> from weather_gym.paths import data_dir
        >>> xy, cls, start = read_cone_csv(data_dir("tracks") / "eufs" / "acceleration.csv")
        >>> xy.shape, start
        ((46, 2), (-53.0, 0.0, 0.0))
    """
    path = Path(path)
    if not path.exists():
        raise MissingInputError(f"track file {path} not found")
    if not path.is_file():
        raise FileFormatError(f"track file {path} is not a regular file")
    if path.stat().st_size > MAX_TRACK_FILE_BYTES:
        raise LimitError(f"track file {path} is {path.stat().st_size / 1e6:.1f} MB; a cone CSV is at most "
                         f"{MAX_TRACK_FILE_BYTES / 1e6:.0f} MB")
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a UTF-8 text file ({exc.reason})") from None
    body = [(i + 1, ln.strip()) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    expected = f"a header line 'tag,x,y' or '{CSV_HEADER}'"
    if not body:
        _fail(path, None, f"empty file; expected {expected} followed by one cone per line")
    head_no, head = body[0]
    header = [h.strip().lower() for h in head.split(",")]
    if header[:3] != ["tag", "x", "y"]:  # the line is not quoted: the file may be anything (a system file)
        _fail(path, head_no, f"missing header: expected {expected}; is this a cone CSV file?")
    has_direction = len(header) > 3 and header[3] == "direction"
    tags, xy, line_nos, start, start_line = [], [], [], None, None
    valid = ", ".join(CONE_CLASSES)
    for no, text in body[1:]:
        fields = [f.strip() for f in text.split(",")]
        if len(fields) < 3:
            _fail(path, no, f"expected at least 3 comma-separated fields (tag,x,y), got {len(fields)}")
        tag = fields[0].lower()
        if tag == "midpoint":
            continue
        if tag not in CONE_CLASSES and tag != "car_start":
            _fail(path, no, f"unknown cone colour tag {fields[0]!r}; expected one of {valid} "
                            "(or car_start / midpoint)")
        vals = []
        for col, raw in (("x", fields[1]), ("y", fields[2])):
            try:
                v = float(raw)
            except ValueError:
                _fail(path, no, f"{col} = {raw!r} is not a number")
            if not math.isfinite(v):
                _fail(path, no, f"{col} = {raw!r}: positions must be finite numbers")
            if abs(v) > MAX_COORDINATE_M:
                raise LimitError(f"{path}: line {no}: {col} = {raw}: positions must lie within "
                                 f"+-{MAX_COORDINATE_M:g} m")
            vals.append(v)
        if tag == "car_start":
            if start is not None:
                _fail(path, no, f"second car_start row (the first is in line {start_line})")
            yaw = None
            if has_direction and len(fields) > 3 and fields[3]:
                try:
                    yaw = float(fields[3])
                except ValueError:
                    _fail(path, no, f"direction = {fields[3]!r} is not a number")
                if not math.isfinite(yaw):
                    _fail(path, no, f"direction = {fields[3]!r}: must be a finite angle in radians")
            start, start_line = (vals[0], vals[1], yaw), no
            continue
        tags.append(CONE_CLASSES.index(tag))
        xy.append(vals)
        line_nos.append(no)
        if len(xy) > MAX_CONES:
            raise LimitError(f"{path}: more than {MAX_CONES} cones; a track has at most {MAX_CONES}")
    if not xy:
        _fail(path, None, "no cones after the header")
    cones = np.array(xy, dtype=np.float64)
    classes = np.array(tags, dtype=np.int64)
    pairs = sorted(cKDTree(cones).query_pairs(DUPLICATE_TOL_M))
    if pairs:
        i, j = min(pairs, key=lambda p: max(p))
        _fail(path, line_nos[j], f"{CONE_CLASSES[classes[j]]} cone at ({cones[j, 0]:g}, {cones[j, 1]:g}) "
                                 f"duplicates the cone in line {line_nos[i]} (closer than 1 cm)")
    for cid, what in ((0, "left"), (1, "right")):
        if not (classes == cid).any():
            _fail(path, None, f"no {CONE_CLASSES[cid]} cones: a track needs a {what} ({CONE_CLASSES[cid]}) boundary")
    return cones, classes, start


def track_from_csv(path: str | os.PathLike, *, name: str | None = None, event: str | None = None) -> Track:
    """Build a :class:`Track` from a cone CSV. ``event``: None infers trackdrive (closed loop) or
    acceleration (open lane); "skidpad" builds the skidpad sequence from circle fits."""
    path = Path(path)
    if event is not None and event not in EVENTS:
        raise InputError(f"unknown event {event!r}; expected one of {', '.join(EVENTS)}")
    cones, classes, start = read_cone_csv(path)
    builder = geo.skidpad_from_cones if event == "skidpad" else geo.layout_from_cones
    fields = builder(cones, classes, start, str(path))
    if event is not None and fields["event"] != event:
        raise InputError(f"{path}: event {event!r} expected, but the cones form a "
                         f"{'closed loop' if fields['closed'] else 'open lane'} ({fields['event']})")
    return Track(name=name or path.stem, cones_xy=cones, cone_classes=classes, source=str(path), **fields)


# ---------------------------------------------------------------------------------------------- generated


def _check_range(what: str, value, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError(f"{what} must be a number in [{lo}, {hi}]; got {value!r}")
    if not lo <= float(value) <= hi:
        raise InputError(f"{what} must be in [{lo}, {hi}]; got {value!r}")
    return float(value)


def oval(straight: float = 40.0, radius: float = 15.0, width: float = 3.5, spacing: float | None = None) -> Track:
    """A counter-clockwise stadium oval: two straights joined by half circles (blue cones inside).

    Example:
        >>> round(oval().length, 1)
        174.2
    """
    straight = _check_range("oval straight", straight, 0.0, 500.0)
    radius = _check_range("oval radius", radius, MIN_RADIUS_M, 200.0)
    width = _check_range("oval width", width, 2.0, 10.0)
    if spacing is not None:
        spacing = _check_range("oval spacing", spacing, 1.0, 10.0)
    half = straight / 2.0
    arc = np.linspace(-np.pi / 2, np.pi / 2, 181)
    pts = np.concatenate([
        np.column_stack([np.linspace(0.0, half, 50, endpoint=False), np.full(50, -radius)]),
        np.column_stack([half + radius * np.cos(arc), radius * np.sin(arc)])[:-1],
        np.column_stack([np.linspace(half, -half, 100, endpoint=False), np.full(100, radius)]),
        np.column_stack([-half - radius * np.cos(arc), -radius * np.sin(arc)])[:-1],
        np.column_stack([np.linspace(-half, 0.0, 50, endpoint=False), np.full(50, -radius)]),
    ])
    line = geo.resample(pts, closed=True)
    args = f"straight={straight:g}, radius={radius:g}, width={width:g}, spacing={spacing}"
    return Track(name="oval", source=f"generated:oval({args})", **geo.ring_layout(line, width, spacing, MIN_RADIUS_M))


def generate_random_track(seed: int, *, length: float | None = None, width: float | None = None,
                          spacing: float | None = None, start_pair: float | None = None) -> Track:
    """A random closed track: same seed and arguments, same bytes.

    ``length`` (m, default: drawn in [150, 400]) and ``width`` (default: drawn in [3, 4]) come
    from their own child streams of ``SeedSequence(seed)``, so fixing one leaves the others as
    they were. Cone spacing: ``spacing`` metres, or 4.5 m on straights tightening to 3.5 m in
    the tightest corners. The centerline radius stays >= 7 m (so >= :data:`MIN_RADIUS_M`), the
    track never comes within ``width + 3`` m of itself, and the start line is on its straightest part,
    marked by one big orange cone per side or, with ``start_pair``, by two ``start_pair`` metres apart.
    As a track spec: ``"random:SEED"`` or with arguments, ``"random:SEED,start_pair=0.3,width=3.5"``.

    Example:
        >>> t = generate_random_track(3)
        >>> t.source, t.event
        ('generated:random(seed=3)', 'trackdrive')
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"random track seed must be a non-negative integer; got {seed!r}")
    if length is not None:
        length = _check_range("random track length", length, 100.0, 1000.0)
    if width is not None:
        width = _check_range("random track width", width, 2.0, 8.0)
    if spacing is not None:
        spacing = _check_range("random track spacing", spacing, 1.0, 10.0)
    if start_pair is not None:
        start_pair = _check_range("random track start_pair", start_pair, 0.2, 3.0)
    return _random_track(int(seed), length, width, spacing, start_pair)


@functools.lru_cache(maxsize=32)
def _random_track(seed: int, length: float | None, width: float | None, spacing: float | None,
                  start_pair: float | None = None) -> Track:
    r_len, r_width, r_shape = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    length_m = float(r_len.uniform(150.0, 400.0)) if length is None else length
    width_m = float(r_width.uniform(3.0, 4.0)) if width is None else width
    line = geo.random_centerline(r_shape, length_m, min_radius=MIN_RADIUS_M + 1.0, clearance=width_m + 3.0)
    i0 = geo.straightest_index(line, closed=True)
    line = geo.resample(line, closed=True, start_s=float(geo.cumulative_length(line, True)[0][i0]))
    extras = "".join(f", {k}={v:g}" for k, v in (("length", length), ("width", width), ("spacing", spacing),
                                                  ("start_pair", start_pair)) if v is not None)
    return Track(name="random", source=f"generated:random(seed={seed}{extras})",
                 **geo.ring_layout(line, width_m, spacing, MIN_RADIUS_M, start_pair))


# ---------------------------------------------------------------------------------------------- registry

TRACKS: Registry = Registry("track")
"""Track name -> factory(**kwargs) -> Track."""

SHIPPED: dict[str, tuple[str, str]] = {
    "acceleration": ("eufs/acceleration.csv", "acceleration"),
    "b_shape": ("eufs/B_shape_02_03_2023.csv", "trackdrive"),
    "fsds_training": ("eufs/FSDS_Training.csv", "trackdrive"),
    "hairpin": ("eufs/Hairpin_02_03_2023.csv", "trackdrive"),
    "jellybean": ("eufs/Jellybean_02_03_2023.csv", "trackdrive"),
    "peanut": ("eufs/peanut.csv", "trackdrive"),
    "skidpad": ("eufs/skidpad.csv", "skidpad"),
    "small_track": ("eufs/small_track.csv", "trackdrive"),
}
"""Shipped layouts: name -> (file under ``tracks/``, event)."""


@functools.cache
def _shipped(name: str) -> Track:
    rel, event = SHIPPED[name]
    return track_from_csv(data_dir("tracks") / rel, name=name, event=event)


for _name in SHIPPED:
    TRACKS.register(_name, functools.partial(_shipped, _name))
TRACKS.register("oval", oval)
TRACKS.register("random", generate_random_track)


def is_track_file(spec: str | os.PathLike) -> bool:
    """Whether :func:`load_track` reads ``spec`` as a cone CSV path (not a registered name or ``random:SEED``).

    Example:
        >>> is_track_file("peanut"), is_track_file("random:3"), is_track_file("my/track.csv")
        (False, False, True)
    """
    if isinstance(spec, os.PathLike):
        return True
    name = spec.strip()
    if name == "random" or name.startswith("random:") or name in TRACKS:
        return False
    return name.lower().endswith(".csv") or "/" in name or os.sep in name or Path(name).is_file()


RANDOM_TRACK_ARGS = ("length", "width", "spacing", "start_pair")
"""Keyword arguments of :func:`generate_random_track` a ``random:SEED,KEY=VALUE,...`` spec may set."""


def _random_args(spec: str, args: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in args:
        key, eq, raw = (part.strip() for part in item.partition("="))
        if not eq or key not in RANDOM_TRACK_ARGS:
            raise InputError(f"track {spec!r}: expected KEY=VALUE with KEY in {', '.join(RANDOM_TRACK_ARGS)} after "
                             f"'random:SEED,', got {item!r}")
        try:
            out[key] = float(raw)
        except ValueError:
            raise InputError(f"track {spec!r}: {key} must be a number (metres), got {raw!r}") from None
    return out


def load_track(spec: str | os.PathLike | Track, *, seed: int | None = None, event: str | None = None) -> Track:
    """A track from a registered name, ``"random:SEED"`` (or ``"random"`` with ``seed=``), a CSV path,
    or a :class:`Track` (returned as is). ``seed`` only matters for ``"random"``; ``"random:SEED"``
    keeps its own seed. ``event`` applies to CSV files (see :func:`track_from_csv`).

    Example:
        >>> load_track("random:7").source
        'generated:random(seed=7)'
    """
    if isinstance(spec, Track):
        return spec
    if isinstance(spec, os.PathLike):
        return track_from_csv(spec, event=event)
    if not isinstance(spec, str):
        raise InputError(f"track spec must be a track name, 'random:SEED', a CSV path or a Track; got {spec!r}")
    name = spec.strip()
    if name == "random" or name.startswith("random:"):
        kwargs: dict[str, float] = {}
        if ":" in name:
            raw, *args = name.split(":", 1)[1].split(",")
            try:
                seed = int(raw)
            except ValueError:
                raise InputError(f"track {spec!r}: 'random:SEED' needs an integer seed, got {raw!r}") from None
            kwargs = _random_args(spec, args)
        elif seed is None:
            raise InputError("track 'random' needs a seed: use 'random:SEED' or load_track('random', seed=SEED)")
        return generate_random_track(seed, **kwargs)
    if name in TRACKS:
        track = TRACKS.get(name)()
        if event is not None and event != track.event:
            raise InputError(f"track {name!r} is a {track.event} track, not {event!r}")
        return track
    if is_track_file(name):
        return track_from_csv(name, event=event)
    raise InputError(f"unknown track {name!r}; valid names: {', '.join(TRACKS.names())}, "
                     "'random:SEED', or a path to a cone CSV file")
