"""Configuration of ``ConeTrackEnv`` (frozen dataclasses; scenario TOML files map onto them).

Example:
    >>> from weather_gym.envs.config import EnvConfig
    >>> cfg = EnvConfig(track="peanut", laps=2)
    >>> cfg.camera.width, cfg.sim.control_hz
    (672, 30.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from weather_gym.camera import CameraConfig
from weather_gym.errors import InputError
from weather_gym.sim.config import CarConfig, OdometryConfig, SimConfig

RENDER_VIEWS = ("chase", "camera")
"""Views ``ConeTrackEnv.render()`` can return (``EnvConfig.render_view``)."""


@dataclass(frozen=True)
class RewardConfig:
    """Reward = progress * metres gained along the centerline + cone_hit per new cone touched
    + off_track on leaving the track + time per step."""

    progress: float = 1.0
    cone_hit: float = -2.0
    off_track: float = -10.0
    time: float = 0.0

    def __post_init__(self) -> None:
        for name in ("progress", "cone_hit", "off_track", "time"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"RewardConfig.{name} must be a finite number, got {v!r}")


@dataclass(frozen=True)
class EnvConfig:
    """Everything a ``ConeTrackEnv`` is built from.

    Attributes:
        track: registered track name, ``"random:SEED"`` or a path to a cone CSV file.
        track_seed: seed for generated tracks when ``track`` is ``"random"``.
        laps: the episode terminates after this many laps (or when an open event is finished);
            0 = never terminate on laps.
        max_episode_steps: truncation limit (time limit), in env steps.
        terminate_off_track: end the episode when the car leaves the track.
        off_track_margin: metres beyond the cone line the car's reference point may go before it
            counts as off track (0.6 m = all four wheels out for a 1.2 m wide car).
        randomize_look: draw a random appearance from the episode's RNG at every reset.
        render_view: what ``render()`` returns with ``render_mode="rgb_array"``: ``"chase"`` (a
            camera behind the car, for people) or ``"camera"`` (the car's camera frame; through a
            ``WeatherWrapper`` it is the weathered frame the agent sees, so Gymnasium's and our
            ``RecordVideo`` record the weather).
    """

    track: str = "small_track"
    track_seed: int | None = None
    laps: int = 1
    max_episode_steps: int = 3000
    terminate_off_track: bool = True
    off_track_margin: float = 0.6
    randomize_look: bool = False
    render_view: str = "chase"
    sim: SimConfig = field(default_factory=SimConfig)
    car: CarConfig = field(default_factory=CarConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.track, str) or not self.track:
            raise InputError(f"EnvConfig.track must be a non-empty string, got {self.track!r}")
        if not isinstance(self.laps, int) or isinstance(self.laps, bool) or self.laps < 0:
            raise InputError(f"EnvConfig.laps must be an integer >= 0, got {self.laps!r}")
        if not isinstance(self.max_episode_steps, int) or isinstance(self.max_episode_steps, bool) or self.max_episode_steps < 1:
            raise InputError(f"EnvConfig.max_episode_steps must be an integer >= 1, got {self.max_episode_steps!r}")
        if not (isinstance(self.off_track_margin, (int, float)) and math.isfinite(self.off_track_margin)
                and self.off_track_margin >= 0):
            raise InputError(f"EnvConfig.off_track_margin must be a finite number >= 0, got {self.off_track_margin!r}")
        if self.render_view not in RENDER_VIEWS:
            raise InputError(f"EnvConfig.render_view must be one of {', '.join(RENDER_VIEWS)}, got {self.render_view!r}")
        for name, cls in (("sim", SimConfig), ("car", CarConfig), ("camera", CameraConfig),
                          ("odometry", OdometryConfig), ("reward", RewardConfig)):
            if not isinstance(getattr(self, name), cls):
                raise InputError(f"EnvConfig.{name} must be a {cls.__name__}, got {type(getattr(self, name)).__name__}")
