"""The LiDAR weather effects keep the effect contract: k = 0 identity, seeded, batch = loop, typed errors."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.lidar_weather import (
    FOG_SEVERITIES,
    LIDAR_EFFECTS,
    RAIN_SEVERITIES,
    Fog,
    LidarWeather,
    Rain,
    make,
    mor_of,
    parse_lidar_weather,
)

NAMES = ["fog", "rain", "snow", "wet"]


def scan(n: int = 4000, seed: int = 0) -> PointCloud:
    """A synthetic scan: ground returns 1-40 m around a sensor 0.3 m up, and a few targets."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(1.0, 40.0, n)
    az = rng.uniform(-np.pi, np.pi, n)
    z = np.where(np.arange(n) % 5 == 0, rng.uniform(-0.3, 0.0, n), -0.3)
    xyz = np.c_[r * np.cos(az), r * np.sin(az), z]
    label = np.where(z > -0.3, label_id("cone"), label_id("ground"))
    refl = np.where(label == label_id("cone"), 0.5, 0.15)
    return PointCloud.from_arrays(xyz=xyz, intensity=refl * 0.5, reflectivity=refl, ring=np.zeros(n),
                                  cone=np.where(label == label_id("cone"), 1, -1), label=label)


@pytest.mark.parametrize("name", NAMES)
def test_k0_is_the_identity(name):
    pc = scan()
    out = make(name, k=0.0)(pc, np.random.default_rng(0))
    assert out.equals(pc)


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_same_points_and_the_input_untouched(name):
    pc = scan()
    before = pc.xyz.copy()
    a = make(name, k=0.8)(pc, np.random.default_rng(7))
    b = make(name, k=0.8)(pc, np.random.default_rng(7))
    assert a.equals(b) and not a.equals(pc)
    np.testing.assert_array_equal(pc.xyz, before)


@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_loop(name):
    clouds = [scan(seed=s) for s in range(3)]
    effect = make(name, k=0.6)
    batch = effect.apply_batch(clouds, seed=11)
    children = np.random.SeedSequence(11).spawn(3)
    loop = [effect(c, np.random.default_rng(s)) for c, s in zip(clouds, children)]
    assert all(x.equals(y) for x, y in zip(batch, loop))


@pytest.mark.parametrize("name", NAMES)
def test_severities_map_onto_k_and_grow(name):
    cls = LIDAR_EFFECTS.get(name)
    ks = [cls.at_severity(s).k for s in range(6)]
    assert ks[0] == 0.0 and ks[5] == pytest.approx(1.0) and all(a < b for a, b in zip(ks, ks[1:]))
    assert [round(cls.at_severity(s).physical, 6) for s in range(1, 6)] == [round(v, 6) for v in cls.SEVERITIES]


def test_published_grids():
    assert FOG_SEVERITIES == (0.005, 0.01, 0.02, 0.03, 0.06)
    assert RAIN_SEVERITIES == (0.20, 0.73, 1.56, 3.13, 7.29)
    assert [round(mor_of(b)) for b in FOG_SEVERITIES] == [599, 300, 150, 100, 50]


@pytest.mark.parametrize("make_it, words", [
    (lambda: Fog(k=1.2), ["fog", "k = 1.2", "[0, 1]"]),
    (lambda: Fog(mor=20.0), ["mor = 20", "0.06", "max_beta"]),
    (lambda: Rain(rate=30.0), ["rate = 30", "7.29", "max_rate"]),
    (lambda: Rain(k=0.5, divergence=1.0), ["divergence = 1", "[0.0001, 0.05]"]),
    (lambda: make("snow", k=float("nan")), ["k must be a finite number"]),
])
def test_typed_errors_name_parameter_value_and_range(make_it, words):
    with pytest.raises(InputError) as err:
        make_it()
    for w in words:
        assert w in str(err.value)


def test_errors_are_limit_errors_for_values_out_of_range():
    with pytest.raises(LimitError):
        Fog(k=-0.1)
    with pytest.raises(InputError, match="unknown parameter|valid"):
        make("fog", k=0.5, visibility=30)


def test_specs_parse_and_reject():
    w = parse_lidar_weather("fog:mor=100+rain@2+snow:0.5+wet:film_mm=0.2")
    assert [e.name for e in w.effects] == ["fog", "rain", "snow", "wet"]
    assert w.effects[0].beta == pytest.approx(np.log(20) / 100)
    assert parse_lidar_weather(None) == LidarWeather() and parse_lidar_weather("clear").is_clear
    for bad in ("fog", "fog@7", "fog@1.5", "rain:rate=abc", "fog:mor"):
        with pytest.raises(InputError):
            parse_lidar_weather(bad)
    with pytest.raises(InputError, match="rng"):
        make("fog", k=0.5)(scan(), rng=3)
    with pytest.raises(InputError, match="PointCloud"):
        make("fog", k=0.5)(np.zeros((3, 3)), np.random.default_rng(0))


def test_composed_weather_is_seeded():
    w = parse_lidar_weather("fog@3+rain@3")
    a, b = w(scan(), np.random.default_rng(1)), w(scan(), np.random.default_rng(1))
    assert a.equals(b)
