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
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from weather_gym.agents.pure_pursuit import PurePursuit, PurePursuitConfig
from weather_gym.core.errors import InputError, check_known

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import Track

__all__ = ["GroundTruthPurePursuit", "config_with"]

GT_DEFAULTS = {"v_max": 10.0, "a_lat_max": 4.0, "a_accel": 2.0}
"""The ground-truth driver is a steady, safe driver, not a racer: it must never leave the track, even
on a wet surface (mu 0.6: a rear-driven car has only ~2.8 m/s^2 of traction, hence a_accel 2)."""


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
    """

    def __init__(self, track: Track, camera: CameraConfig | None = None,
                 config: PurePursuitConfig | None = None, **overrides: Any) -> None:
        self.track = track
        merged = {**GT_DEFAULTS, **overrides} if config is None else overrides
        self.controller = PurePursuit(config_with(config, merged, "gt_pure_pursuit"))
        self.controller.set_path(np.asarray(track.centerline, dtype=np.float64), bool(track.closed))

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
