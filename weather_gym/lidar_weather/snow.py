"""Snowfall on a LiDAR scan by rate (mm/h of melted water): extinction, loss, range noise and flake returns.

Snow particles follow the Gunn-Marshall distribution of melted diameters (``N(D) = 3800 S**-0.87
exp(-Lambda D)`` per m^3 per mm, ``Lambda = 2.55 S**-0.48`` per mm; Gunn & Marshall 1958, as Hahner et
al. 2022 and LISA use it). A flake of density ``flake_density`` (0.1 of water's) is ``density**-1/3``
times its melted diameter across; its extinction is twice its cross-section (the large-particle
limit), so ``alpha = 2 (pi / 4) * 2 N0 / Lambda**3 * density**-2/3`` (units folded in). Range noise
takes Goodin et al. 2019's rain formula at the melted rate (an assumption: no published snow
counterpart was at hand); flake returns as :mod:`weather_gym.lidar_weather._precip` describes, with
white flakes (``flake_reflectivity`` 0.9, assumed).

**k**: ``S = k * max_rate``; ``max_rate = 5`` mm/h (heavy snowfall). ``SNOW_SEVERITIES`` (0.5, 1, 2,
3, 5 mm/h) are this project's choice, not a published grid.

Example:
    >>> from weather_gym.lidar_weather import Snow
    >>> snow = Snow(rate=1.0)
    >>> round(snow.k, 2), round(snow.alpha, 4)
    (0.2, 0.0033)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather._precip import precipitation
from weather_gym.lidar_weather.base import LidarEffect

__all__ = ["SNOW_SEVERITIES", "Snow"]

SNOW_SEVERITIES: tuple[float, ...] = (0.5, 1.0, 2.0, 3.0, 5.0)
"""Snowfall rate (mm/h melted) of severities 1-5 (this project's choice)."""
_SNOW = label_id("snow")


@dataclass(frozen=True)
class Snow(LidarEffect):
    """Snowfall by rate (see the module doc)."""

    name: ClassVar[str] = "snow"
    SEVERITIES: ClassVar = SNOW_SEVERITIES
    PHYSICAL: ClassVar = ("rate", "mm/h melted")
    PARAM_BOUNDS: ClassVar = {"max_rate": (0.1, 50.0), "rate": (0.0, 50.0), "flake_reflectivity": (0.0, 1.0),
                              "flake_density": (0.01, 1.0), "divergence": (1e-4, 0.05),
                              "ref_reflectivity": (1e-3, 1.0), "max_range_m": (1.0, 1000.0),
                              "min_range_m": (0.0, 50.0)}

    max_rate: float = SNOW_SEVERITIES[-1]
    rate: float | None = None
    flake_reflectivity: float = 0.9
    flake_density: float = 0.1
    divergence: float = 0.003
    ref_reflectivity: float = 0.1
    max_range_m: float = 100.0
    min_range_m: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.rate is not None:
            self._set_k_from(f"rate = {self.rate:g} mm/h", self.rate, self.max_rate, "max_rate")

    def physical_at(self, k: float) -> float:
        return k * self.max_rate

    def _distribution(self) -> tuple[float, float]:
        s = max(self.physical, 1e-9)
        return 3800.0 * s ** -0.87, 2.55 * s ** -0.48  # N0 (1/m^3/mm), Lambda (1/mm)

    @property
    def alpha(self) -> float:
        """Extinction (1/m) at this rate (see the module doc)."""
        n0, lam = self._distribution()
        return math.pi * n0 / lam ** 3 * 1e-6 * self.flake_density ** (-2.0 / 3.0)

    def _apply(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        n0, lam = self._distribution()
        flake_d = 1e-3 / lam * self.flake_density ** (-1.0 / 3.0)
        return precipitation(cloud, rng, alpha=self.alpha, rate=self.physical, n_total=n0 / lam, mean_d_m=flake_d,
                             particle_reflectivity=self.flake_reflectivity, label=_SNOW, divergence=self.divergence,
                             ref_reflectivity=self.ref_reflectivity, max_range_m=self.max_range_m,
                             min_range_m=self.min_range_m)
