"""The LiDAR weather against the published relations.

* Fog (Bijelic et al. 2020): a target of reflectance 0.1-0.9 is seen out to 0.44-0.59 x MOR; kept
  returns are attenuated by exp(-2 beta d); backscatter sits at -ln(0.5) / beta.
* Rain (Goodin et al. 2019): the share of lost returns and the range noise rise with the rain rate;
  the noise's spread is 0.02 r (1 - exp(-R))^2.
* Snow: more particle returns with the rate; a wet road: fewer ground returns, nothing else touched.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather import RAIN_SEVERITIES, SNOW_SEVERITIES, Fog, Rain, Snow, WetRoad

TARGET, FOG, RAIN, SNOW = label_id("cone"), label_id("fog"), label_id("rain"), label_id("snow")


def targets(rho: float, ranges: np.ndarray) -> PointCloud:
    """Targets of normalised intensity ``rho`` straight ahead at ``ranges``, many copies each."""
    n = len(ranges)
    xyz = np.c_[ranges, np.zeros(n), np.zeros(n)]
    return PointCloud.from_arrays(xyz=xyz, intensity=np.full(n, rho), ring=np.zeros(n), cone=np.zeros(n),
                                  label=np.full(n, TARGET))


@pytest.mark.parametrize("mor", [50.0, 100.0, 300.0])
@pytest.mark.parametrize("rho, lo, hi", [(0.1, 0.42, 0.46), (0.5, 0.51, 0.55), (0.9, 0.57, 0.61)])
def test_fog_detection_range_is_044_to_059_mor(mor, rho, lo, hi):
    fog = Fog(mor=mor, max_beta=0.1)
    ranges = np.repeat(np.linspace(1.0, mor, 2000), 5)
    out = fog(targets(rho, ranges), np.random.default_rng(0))
    seen = out.ranges[out.label == TARGET]
    ratio = float(seen.max()) / mor
    assert lo <= ratio <= hi
    assert 0.44 - 0.02 <= ratio <= 0.59 + 0.02  # the published bracket
    # every target nearer than d_max stays
    d_max = float(fog.d_max(np.array([rho]))[0])
    assert (ranges <= d_max).sum() == (out.label == TARGET).sum()


def test_fog_attenuates_two_way_and_scatters_back_at_half_power_range():
    fog = Fog(mor=100.0)
    ranges = np.repeat(np.linspace(2.0, 100.0, 400), 10)
    out = fog(targets(0.5, ranges), np.random.default_rng(1))
    kept = out.label == TARGET
    np.testing.assert_allclose(out.intensity[kept], 0.5 * np.exp(-2 * fog.beta * out.ranges[kept]), rtol=1e-5)
    back = out.ranges[out.label == FOG]
    assert len(back) > 0
    assert np.isclose(back, -math.log(0.5) / fog.beta, rtol=1e-5).mean() > 0.9


def test_denser_fog_sees_less():
    ranges = np.repeat(np.linspace(1.0, 150.0, 400), 5)
    kept = [int((Fog(k=k)(targets(0.3, ranges), np.random.default_rng(0)).label == TARGET).sum())
            for k in (0.0, 0.2, 0.5, 1.0)]
    assert kept[0] == len(ranges) and all(a > b for a, b in zip(kept, kept[1:]))


def ground(n: int = 20000, seed: int = 0) -> PointCloud:
    rng = np.random.default_rng(seed)
    r = rng.uniform(2.0, 40.0, n)
    xyz = np.c_[r, np.zeros(n), np.full(n, -0.3)]
    return PointCloud.from_arrays(xyz=xyz, intensity=rng.uniform(0.001, 0.2, n), ring=np.zeros(n),
                                  label=np.full(n, label_id("ground")))


def test_rain_loss_and_noise_rise_with_rate():
    pc = ground()
    far = targets(0.9, np.full(5000, 20.0))
    lost, noise = [], []
    for rate in RAIN_SEVERITIES:
        out = Rain(rate=rate)(pc, np.random.default_rng(2))
        lost.append(1.0 - (out.label != RAIN).sum() / len(pc))
        r = Rain(rate=rate)(far, np.random.default_rng(2))
        noise.append(float(r.ranges[r.label == TARGET].std()))
    assert all(a < b for a, b in zip(lost, lost[1:]))
    assert all(a < b for a, b in zip(noise, noise[1:]))


def test_rain_range_noise_follows_goodin():
    rate = 2.0
    n = 20000
    pc = PointCloud.from_arrays(xyz=np.c_[np.full(n, 20.0), np.zeros(n), np.zeros(n)], intensity=np.full(n, 0.9),
                                ring=np.zeros(n), label=np.full(n, TARGET))
    out = Rain(rate=rate, max_rate=10.0)(pc, np.random.default_rng(3))
    r = out.ranges[out.label == TARGET]
    expected = 0.02 * 20.0 * (1 - math.exp(-rate)) ** 2
    assert abs(float(r.std()) - expected) / expected < 0.05
    assert abs(float(r.mean()) - 20.0) < 0.02


def test_rain_extinction_follows_goodin():
    assert Rain(rate=5.0).alpha == pytest.approx(0.01 * 5.0 ** 0.6)
    pc = targets(0.8, np.full(10, 30.0))
    out = Rain(rate=5.0)(pc, np.random.default_rng(0))
    kept = out.label == TARGET
    np.testing.assert_allclose(out.intensity[kept], 0.8 * np.exp(-2 * 0.01 * 5.0 ** 0.6 * 30.0), rtol=1e-5)


def test_snow_returns_rise_with_rate():
    pc = ground()
    flakes = [int((Snow(rate=s)(pc, np.random.default_rng(4)).label == SNOW).sum()) for s in SNOW_SEVERITIES]
    assert flakes[0] > 0 and all(a < b for a, b in zip(flakes, flakes[1:]))
    assert Snow(rate=5.0).alpha > Snow(rate=1.0).alpha > 0


def test_wet_road_loses_ground_returns_only():
    pc = ground()
    cone = targets(0.5, np.linspace(2, 30, 50))
    both = pc.concat(cone)
    counts = [int((WetRoad(film_mm=f)(both, np.random.default_rng(0)).label == label_id("ground")).sum())
              for f in (0.0, 0.05, 0.2, 1.0)]
    assert counts[0] == len(pc) and counts[1] > counts[2] and counts[2] == counts[3]
    out = WetRoad(film_mm=0.5)(both, np.random.default_rng(0))
    assert (out.label == TARGET).sum() == len(cone)


@pytest.mark.parametrize("rho, product", [(0.1, 1.31), (0.5, 1.58), (0.9, 1.76)])
def test_fog_d_max_times_beta_matches_the_published_values(rho, product):
    # Bijelic et al. 2020's HDL-64E S3D parameters (n 0.04, g 0.45) give d_max * beta = 1.31 / 1.58 / 1.76
    for mor in (50.0, 150.0, 600.0):
        fog = Fog(mor=mor, max_beta=0.1)
        assert float(fog.d_max(np.array([rho]))[0]) * fog.beta == pytest.approx(product, abs=0.005)


@pytest.mark.parametrize("rho", [0.05, 0.5])
def test_rain_loses_a_target_beyond_goodins_detection_range(rho):
    """A target is lost where its received power rho exp(-2 alpha r) / r^2 (alpha = 0.01 R^0.6) falls below the
    threshold, a 10 % target at 100 m: the farthest target kept at each rate of the grid sits at the root of
    that equation (found here by bisection), and the root falls with the rate."""
    from scipy.optimize import brentq

    ranges = np.linspace(2.0, 100.0, 9801)  # 1 cm apart
    reach = []
    for rate in RAIN_SEVERITIES:
        alpha = 0.01 * rate ** 0.6
        root = brentq(lambda r, a=alpha: rho * math.exp(-2 * a * r) / r ** 2 - 0.1 / 100.0 ** 2, 1.0, 1000.0)
        out = Rain(rate=rate, drop_reflectivity=0.0)(targets(rho, ranges), np.random.default_rng(5))
        noise = 0.02 * ranges * (1 - math.exp(-rate)) ** 2  # Goodin's range noise moves the kept targets
        kept = out.label == TARGET
        assert int(kept.sum()) == int((ranges <= root).sum())
        assert float(out.ranges[kept].max()) == pytest.approx(min(root, 100.0), abs=5 * float(noise.max()) + 0.01)
        reach.append(root)
    assert all(a > b for a, b in zip(reach, reach[1:]))
