"""Frozen configuration of the car's LiDAR: beams, fields of view, resolution, range, rate, mounting.

No PyBullet import here, so any layer may read these. Two presets:

* :meth:`LidarConfig.hdl32e` (the default): a 32-beam spinning unit with the figures of the Velodyne
  HDL-32E data sheet (Velodyne, "HDL-32E User's Manual and Programming Guide", 63-9113 Rev. M, and the
  HDL-32E data sheet 97-0038): 32 lasers from -30.67 to +10.67 degrees (1.33 degrees apart), 360
  degrees around, 0.16 degrees between firings at 10 Hz (0.08-0.33 degrees at 5-20 Hz), 100 m range,
  range accuracy < 2 cm. 32 x 2250 = 72 000 beams per turn.
* :meth:`LidarConfig.solid_state`: a forward-facing MEMS unit with the figures of the RoboSense
  RS-LiDAR-M1 data sheet: 120 x 25 degrees, 0.2 x 0.2 degrees, 10 Hz, 150 m on a 10 % target.

Both sit on the front wing of a Formula Student car (``mount_x`` 2.25 m ahead of the rear axle, just
ahead of the body, ``mount_z`` 0.3 m above the ground), where teams put them to see the cones' full
height; a spinning unit there sees the car's own nose behind it.

Example:
    >>> from weather_gym.sim.lidar_config import LidarConfig
    >>> cfg = LidarConfig()
    >>> cfg.channels, cfg.columns, cfg.rays, round(float(cfg.elevations_deg[1] - cfg.elevations_deg[0]), 2)
    (32, 2250, 72000, 1.33)
    >>> LidarConfig.solid_state().rays
    75000
    >>> LidarConfig(channels=0)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: LidarConfig.channels must be an integer in [1, 512], got 0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from weather_gym.core.errors import InputError
from weather_gym.core.schema import check_fields

__all__ = ["LidarConfig", "MAX_RAYS"]

MAX_RAYS = 500_000
"""Most beams one scan may cast (a Velodyne VLS-128 at 10 Hz fires about 230 000)."""


@dataclass(frozen=True)
class LidarConfig:
    """A LiDAR mounted on the car (see the module doc for the presets' sources).

    Attributes:
        name: a label for reports.
        channels: number of beams stacked vertically (rings), evenly spaced over ``vfov_deg``.
        vfov_low_deg, vfov_high_deg: elevation of the lowest and the highest beam (degrees, up positive).
        hfov_deg: horizontal field of view (360 for a spinning unit), centred on ``yaw_deg``.
        h_res_deg: azimuth step between firings (degrees).
        rate_hz: scans per second (the env casts a scan every ``control_hz / rate_hz`` steps).
        max_range, min_range: returns farther than ``max_range`` or nearer than ``min_range`` (m) are none.
        range_noise_m: standard deviation of the range of a return in clear air (m).
        ref_reflectivity: the detection threshold: a return is detected while its received power
            (intensity / range^2) is at least that of a target of this reflectivity at ``max_range``
            (an assumption: the HDL-32E's 100 m for a 10 % target is the data sheet's best case).
        mount_x, mount_y, mount_z: the sensor's origin in the car frame (m from the rear axle's centre
            on the ground: x forward, y left, z up).
        yaw_deg, pitch_deg: the sensor's heading on the car and its downward tilt (degrees).
    """

    name: str = "HDL-32E"
    channels: Annotated[int, Field(ge=1, le=512)] = 32
    vfov_low_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = -30.67
    vfov_high_deg: Annotated[float, Field(ge=-90.0, le=90.0)] = 10.67  # and >= vfov_low_deg
    hfov_deg: Annotated[float, Field(ge=1e-3, le=360.0)] = 360.0
    h_res_deg: Annotated[float, Field(ge=1e-3, le=45.0)] = 0.16
    rate_hz: Annotated[float, Field(ge=0.1, le=100.0)] = 10.0
    max_range: Annotated[float, Field(ge=1.0, le=1000.0)] = 100.0
    min_range: Annotated[float, Field(ge=0.0, le=1000.0)] = 1.0  # and <= max_range
    range_noise_m: Annotated[float, Field(ge=0.0, le=1.0)] = 0.02
    ref_reflectivity: Annotated[float, Field(ge=1e-4, le=1.0)] = 0.1
    mount_x: float = 2.25
    mount_y: float = 0.0
    mount_z: Annotated[float, Field(ge=0.01, le=5.0)] = 0.3
    yaw_deg: float = 0.0
    pitch_deg: Annotated[float, Field(ge=-45.0, le=45.0)] = 0.0

    def __post_init__(self) -> None:
        check_fields(self)  # each field against its annotation; then the ranges that depend on another field
        _in_range(self, "vfov_high_deg", self.vfov_low_deg, 90.0)
        _in_range(self, "min_range", 0.0, self.max_range)
        if self.rays > MAX_RAYS:
            raise InputError(f"LidarConfig: {self.channels} channels x {self.columns} columns = {self.rays} beams per "
                             f"scan, more than {MAX_RAYS}; take fewer channels or a coarser h_res_deg")

    @classmethod
    def hdl32e(cls) -> LidarConfig:
        """The default: a Velodyne HDL-32E at 10 Hz (see the module doc)."""
        return cls()

    @classmethod
    def solid_state(cls) -> LidarConfig:
        """A forward-facing solid-state unit (RoboSense RS-LiDAR-M1 figures; see the module doc)."""
        return cls(name="solid-state 120x25", channels=125, vfov_low_deg=-12.4, vfov_high_deg=12.4, hfov_deg=120.0,
                   h_res_deg=0.2, max_range=150.0, min_range=0.5, range_noise_m=0.03)

    @property
    def spinning(self) -> bool:
        """Covers the full circle (its columns wrap around)."""
        return self.hfov_deg >= 360.0 - 1e-9

    @property
    def columns(self) -> int:
        """Firings per scan (azimuth steps)."""
        return max(1, int(round(self.hfov_deg / self.h_res_deg)))

    @property
    def rays(self) -> int:
        """Beams per scan: ``channels * columns``."""
        return self.channels * self.columns

    @property
    def elevations_deg(self) -> np.ndarray:
        """(channels,) elevation of each ring in the sensor frame, lowest first (ring 0)."""
        if self.channels == 1:
            return np.array([0.5 * (self.vfov_low_deg + self.vfov_high_deg)])
        return np.linspace(self.vfov_low_deg, self.vfov_high_deg, self.channels)

    @property
    def azimuths_deg(self) -> np.ndarray:
        """(columns,) azimuth of each firing in the sensor frame (positive left), in increasing order."""
        if self.spinning:
            return -180.0 + self.h_res_deg * np.arange(self.columns)
        return -0.5 * self.hfov_deg + self.h_res_deg * (np.arange(self.columns) + 0.5)


def _in_range(cfg: LidarConfig, name: str, lo: float, hi: float) -> None:
    v = getattr(cfg, name)
    if not lo <= v <= hi:
        raise InputError(f"LidarConfig.{name} must lie in [{lo:g}, {hi:g}], got {v!r}")
