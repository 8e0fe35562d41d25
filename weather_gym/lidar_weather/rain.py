"""Rain on a LiDAR scan by rate (mm/h): Goodin et al. 2019 extinction, loss and range noise, and drop returns.

* extinction ``alpha = 0.01 R**0.6`` (1/m, ``R`` in mm/h; Goodin et al. 2019, Electronics 8(1):89), over
  the two-way path; returns below the sensor's threshold are lost;
* range noise ``sigma = 0.02 r (1 - exp(-R))**2`` (Goodin et al. 2019);
* drop returns near the sensor: Marshall-Palmer drops (``N(D) = 8000 exp(-Lambda D)`` per m^3 per mm,
  ``Lambda = 4.1 R**-0.21`` per mm; Marshall & Palmer 1948, as LISA uses them), returning
  ``drop_reflectivity`` (an assumed value) as :mod:`weather_gym.lidar_weather._precip` describes.

**k**: ``R = k * max_rate``; ``max_rate = 7.29`` mm/h is severity 5 of Dong et al. 2023's grid
(``RAIN_SEVERITIES``: 0.20, 0.73, 1.56, 3.13, 7.29 mm/h). ``Rain(rate=20)`` with ``max_rate=25`` goes
further (natural rain rarely exceeds 25 mm/h).

Example:
    >>> from weather_gym.lidar_weather import Rain
    >>> rain = Rain(rate=5.0)
    >>> round(rain.k, 3), round(rain.alpha, 4)
    (0.686, 0.0263)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather._precip import precipitation
from weather_gym.lidar_weather.base import LidarEffect

__all__ = ["RAIN_SEVERITIES", "Rain"]

RAIN_SEVERITIES: tuple[float, ...] = (0.20, 0.73, 1.56, 3.13, 7.29)
"""Rain rate (mm/h) of severities 1-5 (Dong et al. 2023, 3D Common Corruptions)."""
_RAIN = label_id("rain")


@dataclass(frozen=True)
class Rain(LidarEffect):
    """Rain by rate (see the module doc)."""

    name: ClassVar[str] = "rain"
    SEVERITIES: ClassVar = RAIN_SEVERITIES
    PHYSICAL: ClassVar = ("rate", "mm/h")
    PARAM_BOUNDS: ClassVar = {"max_rate": (0.1, 200.0), "rate": (0.0, 200.0), "drop_reflectivity": (0.0, 1.0),
                              "divergence": (1e-4, 0.05), "ref_reflectivity": (1e-3, 1.0),
                              "max_range_m": (1.0, 1000.0), "min_range_m": (0.0, 50.0)}

    max_rate: float = RAIN_SEVERITIES[-1]
    rate: float | None = None
    drop_reflectivity: float = 0.05
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

    @property
    def alpha(self) -> float:
        """Extinction (1/m) at this rate: ``0.01 R**0.6`` (Goodin et al. 2019)."""
        return 0.01 * self.physical ** 0.6

    def _apply(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        r = self.physical
        lam = 4.1 * r ** -0.21  # Marshall-Palmer slope, 1/mm
        return precipitation(cloud, rng, alpha=self.alpha, rate=r, n_total=8000.0 / lam, mean_d_m=1e-3 / lam,
                             particle_reflectivity=self.drop_reflectivity, label=_RAIN, divergence=self.divergence,
                             ref_reflectivity=self.ref_reflectivity, max_range_m=self.max_range_m,
                             min_range_m=self.min_range_m)


