"""Fog on a LiDAR scan: the empirical model fitted to fog-chamber data by Bijelic et al. 2020.

Re-implemented from the paper (M. Bijelic et al., "Seeing Through Fog Without Seeing Fog: Deep
Multimodal Sensor Fusion in Unseen Adverse Weather", CVPR 2020, supplement: LiDAR fog simulation),
not from its code. With extinction ``beta`` (1/m):

* each return's largest detectable range is ``d_max = -ln(n / (rho + g)) / (2 beta)`` (``rho``: the
  return's normalised intensity; noise level ``n = 0.04`` and gain ``g = 0.45``, the paper's HDL-64E
  S3D values);
* returns nearer than ``d_max`` stay, with the intensity attenuated over the two-way path,
  ``rho * exp(-2 beta d)`` (the attenuation that defines ``d_max``; the paper's released code scales by
  ``exp(-beta d)``);
* a return beyond ``d_max`` is lost from its target; with probability ``1 - exp(-beta d_max)`` the beam
  returns from the fog instead: at the backscatter range ``-ln(0.5) / beta`` when the target lay
  beyond it, otherwise (5 % of those beams) at a range drawn uniformly between ``d_min = 2 m`` and the
  smaller of ``d_max`` and the target's range; those returns carry label ``fog``.

The meteorological optical range (visibility) is ``MOR = ln(20) / beta``, so a target of reflectance
0.1 / 0.5 / 0.9 is seen out to ``d_max = 1.31 / 1.58 / 1.76 / beta = 0.44 / 0.53 / 0.59 MOR``
(tests/lidar_weather/test_lidar_physics.py checks this). ``beta`` is constant over a scan (the paper
lets it vary smoothly in space and time).

**k**: ``beta = k * max_beta``; ``max_beta = 0.06`` /m (MOR 50 m) is severity 5 of Dong et al. 2023's
grid (``SEVERITIES``: 0.005, 0.01, 0.02, 0.03, 0.06 /m). ``Fog(mor=80)`` sets ``k`` from the visibility.

Example:
    >>> import numpy as np
    >>> from weather_gym.lidar_weather import Fog
    >>> fog = Fog(mor=50.0)
    >>> round(fog.k, 2), round(fog.beta, 4)
    (1.0, 0.0599)
    >>> round(float(fog.d_max(np.array([0.1]))[0]) / 50.0, 2)   # a 10 % target: 0.44 MOR
    0.44
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather.base import LidarEffect

__all__ = ["FOG_SEVERITIES", "Fog", "mor_of"]

LN20 = math.log(20.0)
"""MOR = ln(20) / beta: the range at which a beam keeps 5 % of its power."""
FOG_SEVERITIES: tuple[float, ...] = (0.005, 0.01, 0.02, 0.03, 0.06)
"""Extinction (1/m) of severities 1-5 (Dong et al. 2023, 3D Common Corruptions: MOR about 600-50 m)."""
_FOG = label_id("fog")


def mor_of(beta: float) -> float:
    """Meteorological optical range (m) of extinction ``beta`` (1/m)."""
    return LN20 / beta


@dataclass(frozen=True)
class Fog(LidarEffect):
    """Fog by extinction / visibility (see the module doc)."""

    name: ClassVar[str] = "fog"
    SEVERITIES: ClassVar = FOG_SEVERITIES
    PHYSICAL: ClassVar = ("extinction beta", "1/m")
    PARAM_BOUNDS: ClassVar = {"max_beta": (1e-3, 0.5), "noise": (1e-3, 0.5), "gain": (0.01, 5.0),
                              "d_min": (0.0, 20.0), "random_share": (0.0, 1.0), "mor": (LN20 / 0.5, 1e5)}

    max_beta: float = FOG_SEVERITIES[-1]
    noise: float = 0.04
    gain: float = 0.45
    d_min: float = 2.0
    random_share: float = 0.05
    mor: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.mor is not None:
            self._set_k_from(f"mor = {self.mor:g} m", LN20 / self.mor, self.max_beta, "max_beta")

    @property
    def beta(self) -> float:
        """Extinction coefficient (1/m)."""
        return self.k * self.max_beta

    def physical_at(self, k: float) -> float:
        return k * self.max_beta

    def d_max(self, rho: np.ndarray) -> np.ndarray:
        """Largest detectable range (m) of returns of normalised intensity ``rho``."""
        return -np.log(self.noise / (np.asarray(rho, np.float64) + self.gain)) / (2.0 * self.beta)

    def _apply(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        beta = self.beta
        d = cloud.ranges.astype(np.float64)
        rho = cloud.intensity.astype(np.float64)
        d_max = self.d_max(rho)
        u_lost, u_rand, u_share = rng.random(len(d)), rng.random(len(d)), rng.random(len(d))
        scattered = u_lost < 1.0 - np.exp(-beta * d_max)
        d_back = -math.log(0.5) / beta
        stays = d <= d_max
        gone = ~stays
        back = gone & scattered & (d > d_back)
        rand_range = self.d_min + u_rand * (np.minimum(d_max, d) - self.d_min)
        random = gone & scattered & ~back & (u_share < self.random_share) & (rand_range > self.d_min)
        new_d = np.where(back, d_back, np.where(random, rand_range, d))
        keep = stays | back | random
        scale = np.where(d > 0, new_d / np.maximum(d, 1e-9), 1.0)
        intensity = rho * np.exp(-2.0 * beta * new_d)
        label = np.where(stays, cloud.label, _FOG).astype(np.uint8)
        cone = np.where(stays, cloud.cone, -1).astype(np.int32)
        out = cloud.replace(xyz=(cloud.xyz * scale[:, None]).astype(np.float32),
                            intensity=intensity.astype(np.float32), label=label, cone=cone)
        return out.select(np.flatnonzero(keep))
