"""The ground-truth driver: pure pursuit along the track's centre line with the TRUE pose.

It reads ``info["pose"]`` (x, y, yaw in the track frame, rear axle) and ``info["speed"]`` and never
looks at the observation, so it drives the same whatever the weather does to the camera. It is the
default driver of ``weather-gym lap``, of dataset rendering and of the env tests.

Example:
    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.agents.gt_pure_pursuit import GroundTruthPurePursuit
    >>> line = np.c_[np.linspace(0, 50, 101), np.zeros(101)]
    >>> track = SimpleNamespace(centerline=line, closed=False)       # anything with these two
    >>> agent = GroundTruthPurePursuit(track, CameraConfig(), v_max=8.0)
    >>> agent.reset(info={"pose": (0.0, 0.5, 0.0), "speed": 0.0})
    >>> a = agent.act(None, {"pose": (0.0, 0.5, 0.0), "speed": 0.0})
    >>> bool(a[0] < 0), bool(a[1] > 0)      # 0.5 m left of the line: steer right, accelerate
    (True, True)

``narrow_width`` (m, 0 = off) makes it slow where the road is tight: at a point where the track is
narrower than ``narrow_width`` (left plus right half width, the narrowest within 1.5 m either side),
the corner limit ``a_lat_max`` is scaled by ``(width / narrow_width) ** 2``; wider roads drive as
before. 3.0 m leaves every shipped layout as it was (all are wider); ``weather-gym train
--teacher-narrow-width`` hands it to the cloned teacher (default 0: off).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.ndimage import minimum_filter1d

from weather_gym.agents.pure_pursuit import PurePursuit, PurePursuitConfig, speed_profile
from weather_gym.core.errors import InputError, check_known

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import Track

__all__ = ["GroundTruthPurePursuit", "config_with", "narrow_lateral_limit"]

GT_DEFAULTS = {"v_max": 10.0, "a_lat_max": 4.0, "a_accel": 2.0}
"""The ground-truth driver is a steady, safe driver, not a racer: it must never leave the track, even
on a wet surface (mu 0.6: a rear-driven car has only ~2.8 m/s^2 of traction, hence a_accel 2)."""


NARROW_WINDOW_M = 1.5
"""The width at a point is the narrowest within this distance (m) along the line either side."""


def narrow_lateral_limit(width: np.ndarray, a_lat_max: float, narrow_width: float, step: float,
                         closed: bool) -> np.ndarray:
    """Per-point corner limit (m/s^2): ``a_lat_max`` scaled by ``(w / narrow_width) ** 2`` below
    ``narrow_width``, ``w`` the narrowest ``width`` within ``NARROW_WINDOW_M`` either side (points
    ``step`` m apart).

    Example:
        >>> import numpy as np
        >>> w = np.array([3.5, 3.5, 2.4, 3.5, 3.5, 3.5, 3.5, 3.5])
        >>> narrow_lateral_limit(w, 4.0, 3.0, 1.0, closed=False).round(2).tolist()
        [2.56, 2.56, 2.56, 2.56, 2.56, 4.0, 4.0, 4.0]
    """
    h = int(round(NARROW_WINDOW_M / step))
    low = minimum_filter1d(np.asarray(width, dtype=np.float64), 2 * h + 1, mode="wrap" if closed else "nearest")
    return a_lat_max * np.minimum(low / narrow_width, 1.0) ** 2


def config_with(base: PurePursuitConfig | None, overrides: dict[str, Any], who: str) -> PurePursuitConfig:
    """``base`` (or the default config) with ``overrides`` applied; unknown names raise ValueError."""
    check_known(overrides, {f.name for f in dataclasses.fields(PurePursuitConfig)}, what=who, kind="option")
    return dataclasses.replace(base or PurePursuitConfig(), **overrides)


class GroundTruthPurePursuit:
    """Follows ``track.centerline`` using the true pose and speed from ``info``.

    Args:
        track: a ``weather_gym.tracks.Track`` (only ``centerline`` and ``closed`` are used).
        camera: unused (part of the factory signature).
        config: a ``PurePursuitConfig``; keyword overrides (``v_max=...``, ``a_lat_max=...``) apply on top.
        narrow_width: slow where the track is narrower than this (m; 0: never); the track then needs
            ``half_width_left`` and ``half_width_right``.
    """

    def __init__(self, track: Track, camera: CameraConfig | None = None,
                 config: PurePursuitConfig | None = None, narrow_width: float = 0.0, **overrides: Any) -> None:
        if isinstance(narrow_width, bool) or not isinstance(narrow_width, (int, float)) \
                or not math.isfinite(narrow_width) or narrow_width < 0:
            raise InputError(f"gt_pure_pursuit: narrow_width must be a number of metres >= 0 (0: off), got {narrow_width!r}")
        self.track = track
        self.narrow_width = float(narrow_width)
        merged = {**GT_DEFAULTS, **overrides} if config is None else overrides
        self.controller = PurePursuit(config_with(config, merged, "gt_pure_pursuit"))
        self.controller.set_path(np.asarray(track.centerline, dtype=np.float64), bool(track.closed))
        if self.narrow_width > 0:
            self._slow_where_narrow()

    def _slow_where_narrow(self) -> None:
        """Recompute the speed profile with the corner limit lowered where the road is narrow."""
        if not hasattr(self.track, "half_widths_at"):
            raise InputError("gt_pure_pursuit: narrow_width needs a track with half widths (a weather_gym Track)")
        pp, cfg = self.controller, self.controller.config
        assert pp.path is not None and pp.curvature is not None  # set_path came first
        s = np.arange(len(pp.path)) * cfg.resample_step  # the resampled line keeps the centre line's arc length
        left, right = self.track.half_widths_at(s)
        a_lat = narrow_lateral_limit(np.asarray(left) + np.asarray(right), cfg.a_lat_max, self.narrow_width,
                                     cfg.resample_step, pp.closed)
        pp.profile = speed_profile(pp.curvature, cfg.resample_step, closed=pp.closed, v_max=cfg.v_max,
                                   a_lat_max=a_lat, a_accel=cfg.a_accel, a_brake=cfg.a_brake, v_end=cfg.v_end)

    def reset(self, seed: int | None = None, info: dict | None = None) -> None:
        self.controller.reset()
        if info is not None and "pose" in info:
            x, y, _ = _pose(info)
            self.controller._project(x, y)  # start the progress search at the car, not anywhere on the loop

    def act(self, obs: Any, info: dict | None = None) -> np.ndarray:
        if info is None or "pose" not in info or "speed" not in info:
            raise InputError('gt_pure_pursuit needs the step info with "pose" (x, y, yaw) and "speed"')
        x, y, yaw = _pose(info)
        return self.controller.command(x, y, yaw, float(info["speed"]))

    @property
    def cross_track_error(self) -> float:
        return self.controller.cross_track_error


def _pose(info: dict) -> tuple[float, float, float]:
    pose = np.asarray(info["pose"], dtype=np.float64).reshape(-1)
    if pose.shape[0] < 3:
        raise InputError(f'info["pose"] must be (x, y, yaw), got {pose.tolist()}')
    return float(pose[0]), float(pose[1]), float(pose[2])
