"""Pure-pursuit steering with a curvature-based speed profile (shared by every driving agent).

The controller follows a polyline path given in the same frame as the pose it is handed (the track
frame for the ground-truth driver, the odometry frame for the perception stack). The reference point
is the centre of the rear axle, as for the car's pose.

* Steering: pure pursuit, ``delta = atan(2 L sin(alpha) / L_d)`` towards the path point one
  look-ahead distance ``L_d = clip(lookahead_min + lookahead_time * v, ..., lookahead_max)`` ahead,
  mapped linearly to the action ``delta / max_steer``.
* Speed: ``v = min(v_max, sqrt(a_lat_max / |kappa|))`` along the path, then a forward pass
  (acceleration limit) and a backward pass (braking limit); a proportional loop on the profile speed
  a little ahead of the car gives the throttle / brake action.

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.pure_pursuit import PurePursuit, speed_profile
    >>> t = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    >>> circle = np.c_[10 * np.cos(t), 10 * np.sin(t)]           # radius 10 m, counter-clockwise
    >>> pp = PurePursuit()
    >>> pp.set_path(circle, closed=True)
    >>> round(float(pp.profile.max()), 1)                          # sqrt(5 m/s^2 * 10 m)
    7.1
    >>> action = pp.command(10.0, 0.0, np.pi / 2, speed=5.0)       # on the circle, heading along it
    >>> action.dtype, bool(action[0] > 0)                          # steers left
    (dtype('float32'), True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from weather_gym.core.errors import InputError
from weather_gym.core.schema import NonNegative, Positive, check_fields

__all__ = ["PurePursuitConfig", "PurePursuit", "resample_path", "path_curvature", "speed_profile"]


@dataclass(frozen=True)
class PurePursuitConfig:
    """Car limits (defaults = weather_gym's Formula Student car) and controller tuning.

    Attributes:
        wheelbase: metres between the axles.
        max_steer: front wheel angle at action +-1, rad.
        max_accel, max_brake: m/s^2 at action +1 / -1 (used to turn an acceleration into a pedal).
        dt: control period, s (30 Hz).
        v_max: top speed the profile allows, m/s.
        a_lat_max: lateral acceleration the profile allows in corners, m/s^2 (tyres give ~ mu * g).
        a_accel, a_brake: longitudinal accelerations the profile plans with and the speed loop never
            exceeds, m/s^2 (a rear-driven car has ~ mu * g * 0.48 of traction: lower a_accel on wet).
        v_end: profile speed at the end of an open path (0 = stop there).
        lookahead_min, lookahead_time, lookahead_max: look-ahead distance ``min + time * v``, capped.
        speed_gain: proportional gain of the speed loop, 1/s.
        preview_time: the speed loop tracks the profile this far ahead (s) to absorb actuator lag.
        resample_step: spacing of the internal path resampling, m.
        curvature_window: arc length (m) over which the heading is differenced for curvature.
        search_back, search_ahead: window (m) around the last projection in which the car is looked
            for, so a path that passes near itself (hairpins, figure eights) is followed in order.
    """

    wheelbase: Positive = 1.55
    max_steer: Annotated[float, Field(gt=0, lt=math.pi / 2)] = 0.45  # below pi/2 rad
    max_accel: Positive = 6.0
    max_brake: Positive = 10.0
    dt: Positive = 1.0 / 30.0
    v_max: Positive = 10.0
    a_lat_max: Positive = 5.0
    a_accel: Positive = 3.0
    a_brake: Positive = 5.0
    v_end: NonNegative = 0.0
    lookahead_min: Positive = 2.5
    lookahead_time: NonNegative = 0.3
    lookahead_max: Positive = 10.0
    speed_gain: Positive = 2.0
    preview_time: NonNegative = 0.3
    resample_step: Positive = 0.25
    curvature_window: Positive = 1.5
    search_back: NonNegative = 3.0
    search_ahead: Positive = 12.0

    def __post_init__(self) -> None:
        check_fields(self)
        if self.lookahead_max < self.lookahead_min:
            raise InputError(
                f"PurePursuitConfig.lookahead_max ({self.lookahead_max}) must be >= lookahead_min ({self.lookahead_min})"
            )


def _as_path(xy: np.ndarray) -> np.ndarray:
    p = np.asarray(xy, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"path must be an (M, 2) array of x, y points, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise InputError("path contains non-finite points")
    return p


def resample_path(xy: np.ndarray, step: float, closed: bool) -> np.ndarray:
    """Points every ``step`` metres along the polyline (duplicate points dropped).

    A closed path is resampled around the loop and returned without repeating its first point.
    """
    p = _as_path(xy)
    if closed and len(p) > 1 and np.allclose(p[0], p[-1]):
        p = p[:-1]
    if closed:
        p = np.vstack([p, p[:1]])
    seg = np.hypot(*np.diff(p, axis=0).T)
    keep = np.r_[True, seg > 1e-9]
    p = p[keep]
    if len(p) < 2:
        raise InputError("path needs at least two distinct points")
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
    n = max(int(math.ceil(s[-1] / step)), 1)
    if closed:
        si = np.linspace(0.0, s[-1], n, endpoint=False)
    else:
        si = np.linspace(0.0, s[-1], n + 1)
    return np.c_[np.interp(si, s, p[:, 0]), np.interp(si, s, p[:, 1])]


def path_curvature(xy: np.ndarray, closed: bool, window: float = 1.5) -> np.ndarray:
    """Signed curvature (1/m, positive = left turn) of a uniformly spaced path.

    The heading is differenced across ``window`` metres, which smooths the noise of a path built
    from cone midpoints.
    """
    p = _as_path(xy)
    m = len(p)
    if m < 3:
        return np.zeros(m)
    step = float(np.median(np.hypot(*np.diff(p, axis=0).T)))
    h = max(int(round(window / 2 / max(step, 1e-9))), 1)
    idx = np.arange(m)
    if closed:
        ahead, behind = p[(idx + h) % m], p[(idx - h) % m]
        d_plus, d_minus = ahead - p, p - behind
    else:
        ia, ib = np.minimum(idx + h, m - 1), np.maximum(idx - h, 0)
        d_plus, d_minus = p[ia] - p, p - p[ib]
        # at the ends, use the one-sided chord twice (curvature from the neighbouring interior point)
        d_plus[ia == idx] = d_minus[ia == idx]
        d_minus[ib == idx] = d_plus[ib == idx]
    th_plus = np.arctan2(d_plus[:, 1], d_plus[:, 0])
    th_minus = np.arctan2(d_minus[:, 1], d_minus[:, 0])
    dth = np.angle(np.exp(1j * (th_plus - th_minus)))
    arc = 0.5 * (np.hypot(*d_plus.T) + np.hypot(*d_minus.T))
    return np.where(arc > 1e-9, dth / np.maximum(arc, 1e-9), 0.0)


def speed_profile(
    curvature: np.ndarray,
    step: float,
    *,
    closed: bool,
    v_max: float,
    a_lat_max: float | np.ndarray,
    a_accel: float,
    a_brake: float,
    v_start: float | None = None,
    v_end: float = 0.0,
) -> np.ndarray:
    """Speed (m/s) along a uniformly spaced path: corner limit, then acceleration and braking passes.

    ``a_lat_max`` is one limit or one per point (a driver that slows where the road is narrow);
    ``v_start`` (open paths) caps the first point's speed (e.g. the car's current speed); ``v_end``
    is the speed the car must be down to at the end of an open path.
    """
    k = np.abs(np.asarray(curvature, dtype=np.float64))
    v_lim = np.minimum(v_max, np.sqrt(a_lat_max / np.maximum(k, 1e-9)))
    m = len(v_lim)
    if m == 0:
        return v_lim
    if closed:  # periodic: three laps of passes, keep the middle one
        v = np.tile(v_lim, 3)
        for i in range(1, 3 * m):
            v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * a_accel * step))
        for i in range(3 * m - 2, -1, -1):
            v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * a_brake * step))
        return v[m : 2 * m].copy()
    v = v_lim.copy()
    if v_start is not None:
        v[0] = min(v[0], max(v_start, 0.0))
    for i in range(1, m):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * a_accel * step))
    v[-1] = min(v[-1], v_end)
    for i in range(m - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * a_brake * step))
    return v


class PurePursuit:
    """Pure-pursuit path follower with a speed profile; ``command(x, y, yaw, speed)`` -> action.

    Call ``set_path`` whenever the path changes (every step for a planner, once for a fixed
    centre line). The action is float32 ``(steering, throttle/brake)`` in [-1, 1].
    """

    def __init__(self, config: PurePursuitConfig | None = None) -> None:
        self.config = config or PurePursuitConfig()
        self.path: np.ndarray | None = None
        self.profile: np.ndarray | None = None
        self.curvature: np.ndarray | None = None
        self.closed = False
        self._index: int | None = None
        self.target: np.ndarray | None = None  # last look-ahead point, for plots
        self.cross_track_error = 0.0

    # ---- path ------------------------------------------------------------------------------------
    def set_path(self, xy: np.ndarray, closed: bool, *, v_start: float | None = None,
                 v_end: float | None = None, keep_progress: bool = False) -> None:
        """Follow the polyline ``xy`` (M, 2). ``keep_progress`` keeps the search window of a fixed path."""
        cfg = self.config
        self.path = resample_path(xy, cfg.resample_step, closed)
        self.closed = bool(closed)
        self.curvature = path_curvature(self.path, self.closed, cfg.curvature_window)
        self.profile = speed_profile(
            self.curvature, cfg.resample_step, closed=self.closed, v_max=cfg.v_max, a_lat_max=cfg.a_lat_max,
            a_accel=cfg.a_accel, a_brake=cfg.a_brake, v_start=v_start,
            v_end=cfg.v_end if v_end is None else v_end,
        )
        if not keep_progress:
            self._index = None

    def reset(self) -> None:
        """Forget the progress along the path (the next command searches the whole path)."""
        self._index = None

    # ---- geometry --------------------------------------------------------------------------------
    def _project(self, x: float, y: float) -> int:
        p = self.path
        assert p is not None  # set_path() came first
        m = len(p)
        step = self.config.resample_step
        if self._index is None:
            candidates = np.arange(m)
        else:
            back = int(self.config.search_back / step)
            ahead = int(self.config.search_ahead / step)
            candidates = np.arange(self._index - back, self._index + ahead + 1)
            candidates = candidates % m if self.closed else candidates[(candidates >= 0) & (candidates < m)]
        d2 = (p[candidates, 0] - x) ** 2 + (p[candidates, 1] - y) ** 2
        self._index = int(candidates[int(np.argmin(d2))])
        return self._index

    def _point_ahead(self, index: int, distance: float) -> np.ndarray:
        """The path point ``distance`` metres after ``index`` (extended straight past an open end)."""
        p, step = self.path, self.config.resample_step
        assert p is not None  # set_path() came first
        n = distance / step
        i0 = int(math.floor(n))
        frac = n - i0
        m = len(p)
        if self.closed:
            a, b = p[(index + i0) % m], p[(index + i0 + 1) % m]
            return a + frac * (b - a)
        j = index + i0
        if j + 1 < m:
            return p[j] + frac * (p[j + 1] - p[j])
        d = p[-1] - p[-2]
        d = d / max(float(np.hypot(*d)), 1e-9)
        return p[-1] + d * (distance - (m - 1 - index) * step)

    # ---- control ---------------------------------------------------------------------------------
    def command(self, x: float, y: float, yaw: float, speed: float) -> np.ndarray:
        """Action float32 ``(steering, throttle/brake)`` for the car at pose (x, y, yaw) and ``speed``."""
        if self.path is None:
            raise RuntimeError("PurePursuit.command called before set_path")
        cfg = self.config
        v = max(float(speed), 0.0)
        i = self._project(x, y)
        p = self.path
        # signed cross-track error (positive = car left of the path)
        j = (i + 1) % len(p) if self.closed else min(i + 1, len(p) - 1)
        t = p[j] - p[i] if j != i else p[i] - p[max(i - 1, 0)]
        t = t / max(float(np.hypot(*t)), 1e-9)
        self.cross_track_error = float(t[0] * (y - p[i, 1]) - t[1] * (x - p[i, 0]))

        ld = min(max(cfg.lookahead_min + cfg.lookahead_time * v, cfg.lookahead_min), cfg.lookahead_max)
        target = self._point_ahead(i, ld)
        self.target = target
        dx, dy = target[0] - x, target[1] - y
        c, s = math.cos(yaw), math.sin(yaw)
        xb, yb = c * dx + s * dy, -s * dx + c * dy
        dist = max(math.hypot(xb, yb), 1e-6)
        delta = math.atan2(2.0 * cfg.wheelbase * yb, dist * dist)  # = atan(2 L sin(alpha) / L_d)
        steer = float(np.clip(delta / cfg.max_steer, -1.0, 1.0))

        n_prev = int(round(v * cfg.preview_time / cfg.resample_step))
        k = (i + n_prev) % len(p) if self.closed else min(i + n_prev, len(p) - 1)
        v_ref = float(self.profile[k])  # type: ignore[index]  # set with the path
        if not self.closed and i >= len(p) - 1:
            v_ref = min(v_ref, cfg.v_end)
        a_cmd = min(max(cfg.speed_gain * (v_ref - v), -cfg.a_brake), cfg.a_accel)
        pedal = a_cmd / cfg.max_accel if a_cmd >= 0 else a_cmd / cfg.max_brake
        return np.array([steer, float(np.clip(pedal, -1.0, 1.0))], dtype=np.float32)

    @property
    def index(self) -> int | None:
        """Index of the path point nearest to the car at the last command."""
        return self._index

    @property
    def progress(self) -> float | None:
        """Arc length (m) along the path of the car's last projection (None before any command)."""
        return None if self._index is None else self._index * self.config.resample_step

    def set_progress(self, s: float) -> None:
        """Resume the progress search at arc length ``s``: for a path rebuilt with the same
        parameterisation (a figure eight refitted to drifting odometry, say)."""
        if self.path is None:
            raise RuntimeError("PurePursuit.set_progress called before set_path")
        i = int(round(float(s) / self.config.resample_step))
        self._index = i % len(self.path) if self.closed else min(max(i, 0), len(self.path) - 1)
