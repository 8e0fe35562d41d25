"""Shared physics of rain and snow on a LiDAR scan: extinction, lost returns, range noise, particle returns.

Re-implemented from the papers, not their code:

* **extinction and loss** (Goodin et al. 2019, "Predicting the Influence of Rain on LIDAR in ADAS",
  Electronics 8(1):89): the return's power falls by ``exp(-2 alpha r)`` over the two-way path; a
  return whose power drops below the sensor's threshold is lost (:func:`~.base.detectable`);
* **range noise** (Goodin et al. 2019): a kept return's range gets Gaussian noise of standard
  deviation ``sigma = 0.02 r (1 - exp(-R))**2`` (``R`` the rate in mm/h);
* **particle returns** (the structure of LISA, Kilic et al. 2021, arXiv 2107.07004, simplified):
  particles in the beam's cone (divergence ``theta``) return ``rho_p * min((D / (theta r))**2, 1)`` at
  range ``r``; a particle of the distribution's mean diameter ``D`` is detectable out to
  ``r_d = sqrt(D r_max sqrt(rho_p / rho_ref) / theta)``. The expected number of particles in the beam
  within ``r_d`` (and before the target) is ``lambda = N_T pi theta**2 r_d**3 / 12`` (``N_T``: particles per
  m^3 of the size distribution); with probability ``1 - exp(-lambda)`` one is drawn uniformly in the
  cone's volume, and its return replaces the target's when it is the stronger (the strongest return
  wins). Only beams that had a return are considered (a scan holds no beams that returned nothing).

Example:
    >>> import numpy as np
    >>> from weather_gym.lidar_weather._precip import precipitation
    >>> from weather_gym.core.point_cloud import PointCloud
    >>> pc = PointCloud.from_arrays(xyz=[[30.0, 0, 0]], intensity=[0.8], ring=[0])
    >>> out = precipitation(pc, np.random.default_rng(0), alpha=0.02, rate=5.0, n_total=2000.0, mean_d_m=3e-4,
    ...                     particle_reflectivity=0.05, label=5, divergence=0.003, ref_reflectivity=0.1,
    ...                     max_range_m=100.0, min_range_m=1.0)
    >>> round(float(out.intensity[0]), 3)   # 0.8 exp(-2 * 0.02 * 30)
    0.241
"""

from __future__ import annotations

import math

import numpy as np

from weather_gym.core.point_cloud import PointCloud
from weather_gym.lidar_weather.base import detectable


def precipitation(cloud: PointCloud, rng: np.random.Generator, *, alpha: float, rate: float, n_total: float,
                  mean_d_m: float, particle_reflectivity: float, label: int, divergence: float,
                  ref_reflectivity: float, max_range_m: float, min_range_m: float) -> PointCloud:
    """``cloud`` through precipitation of extinction ``alpha`` (1/m), rate ``rate`` (mm/h), ``n_total``
    particles per m^3 of mean diameter ``mean_d_m`` (see the module doc)."""
    r = cloud.ranges.astype(np.float64)
    n = len(r)
    u_noise, u_hit, u_where = rng.standard_normal(n), rng.random(n), rng.random(n)
    intensity = cloud.intensity.astype(np.float64) * np.exp(-2.0 * alpha * r)
    sigma = 0.02 * r * (1.0 - math.exp(-rate)) ** 2
    new_r = np.maximum(r + sigma * u_noise, 1e-3)
    # particle returns near the sensor
    r_d = math.sqrt(mean_d_m * max_range_m * math.sqrt(particle_reflectivity / ref_reflectivity) / divergence)
    reach = np.minimum(r_d, r)
    lam = n_total * math.pi * divergence ** 2 * reach ** 3 / 12.0
    hit = u_hit < 1.0 - np.exp(-lam)
    r_p = reach * np.cbrt(u_where)
    p_int = particle_reflectivity * np.minimum((mean_d_m / (divergence * np.maximum(r_p, 1e-6))) ** 2, 1.0)
    p_int = p_int * np.exp(-2.0 * alpha * r_p)
    # the stronger return wins: received power is intensity / r^2
    wins = hit & (r_p >= min_range_m) & (p_int * r * r > intensity * r_p * r_p) & detectable(p_int, r_p, ref_reflectivity,
                                                                                           max_range_m)
    out_r = np.where(wins, r_p, new_r)
    out_i = np.where(wins, p_int, intensity)
    keep = wins | detectable(intensity, r, ref_reflectivity, max_range_m)
    scale = out_r / np.maximum(r, 1e-9)
    out = cloud.replace(xyz=(cloud.xyz * scale[:, None]).astype(np.float32), intensity=out_i.astype(np.float32),
                        label=np.where(wins, label, cloud.label).astype(np.uint8),
                        cone=np.where(wins, -1, cloud.cone).astype(np.int32))
    return out.select(np.flatnonzero(keep))
