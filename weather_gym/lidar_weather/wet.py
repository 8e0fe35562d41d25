"""A wet road on a LiDAR scan: a water film makes the ground return less (and far ground returns vanish).

A beam reaching wet asphalt passes the water's surface twice; each time only the Fresnel
transmittance ``T(theta)`` (unpolarised, air to water, refractive index 1.33) gets through, the rest is
reflected away from the sensor. At the grazing angles a car's LiDAR sees the road under, ``T`` is
small, so ground returns weaken and those below the sensor's threshold are lost (Hahner et al. 2022
model the wet ground by a water film of about 0.2 mm; Filgueira et al. 2017 measured that pavement
loses the most points in rain). A film thinner than ``full_film_mm`` (0.2 mm) covers only that share
of the road (the rest stays dry). Only ``ground`` returns change.

**k**: film thickness ``k * max_film_mm`` (``max_film_mm`` = 1 mm: heavy rain; 0.2 mm: wet;
``WET_SEVERITIES`` 0.05, 0.1, 0.2, 0.5, 1 mm, this project's choice).

Example:
    >>> from weather_gym.lidar_weather import WetRoad
    >>> from weather_gym.lidar_weather.wet import fresnel_transmittance
    >>> round(float(fresnel_transmittance(1.0)), 3), round(float(fresnel_transmittance(0.05)), 3)
    (0.98, 0.268)
    >>> WetRoad(film_mm=0.2).k
    0.2
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather.base import LidarEffect, detectable

__all__ = ["WET_SEVERITIES", "WetRoad", "fresnel_transmittance"]

WET_SEVERITIES: tuple[float, ...] = (0.05, 0.1, 0.2, 0.5, 1.0)
"""Water film (mm) of severities 1-5 (this project's choice)."""
N_WATER = 1.33
_GROUND = label_id("ground")


def fresnel_transmittance(cos_i, n: float = N_WATER) -> np.ndarray:
    """Unpolarised Fresnel transmittance from air into a medium of index ``n`` at incidence ``acos(cos_i)``."""
    ci = np.clip(np.asarray(cos_i, dtype=np.float64), 1e-9, 1.0)
    st = np.sqrt(1.0 - ci * ci) / n
    ct = np.sqrt(1.0 - st * st)
    rs = ((ci - n * ct) / (ci + n * ct)) ** 2
    rp = ((ct - n * ci) / (ct + n * ci)) ** 2
    return 1.0 - 0.5 * (rs + rp)


@dataclass(frozen=True)
class WetRoad(LidarEffect):
    """A water film on the road (see the module doc)."""

    name: ClassVar[str] = "wet"
    SEVERITIES: ClassVar = WET_SEVERITIES
    PHYSICAL: ClassVar = ("water film", "mm")
    PARAM_BOUNDS: ClassVar = {"max_film_mm": (0.01, 10.0), "film_mm": (0.0, 10.0), "full_film_mm": (0.01, 5.0),
                              "ref_reflectivity": (1e-3, 1.0), "max_range_m": (1.0, 1000.0)}

    max_film_mm: float = WET_SEVERITIES[-1]
    film_mm: float | None = None
    full_film_mm: float = 0.2
    ref_reflectivity: float = 0.1
    max_range_m: float = 100.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.film_mm is not None:
            self._set_k_from(f"film_mm = {self.film_mm:g}", self.film_mm, self.max_film_mm, "max_film_mm")

    def physical_at(self, k: float) -> float:
        return k * self.max_film_mm

    def _apply(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        ground = cloud.label == _GROUND
        r = cloud.ranges.astype(np.float64)
        cos_i = np.abs(cloud.xyz[:, 2].astype(np.float64)) / np.maximum(r, 1e-9)  # a level sensor over flat ground
        share = min(1.0, self.physical / self.full_film_mm)
        factor = (1.0 - share) + share * fresnel_transmittance(cos_i) ** 2
        intensity = np.where(ground, cloud.intensity * factor, cloud.intensity)
        keep = ~ground | detectable(intensity, r, self.ref_reflectivity, self.max_range_m)
        return cloud.replace(intensity=intensity.astype(np.float32)).select(np.flatnonzero(keep))
