import math

import pytest

from weather_gym.conditions import camera_tables, dim_k, friction, lidar_weather, lux_of_dim_k, parse_state
from weather_gym.conditions.mapping import study_severity_states
from weather_gym.weather import parse_weather
from weather_gym.weather.fog import KOSCHMIEDER


def test_camera_fog_has_the_states_extinction():
    s = parse_state("fog:60m")
    (fog,) = camera_tables(s)
    effect = parse_weather([fog])
    beta_camera = effect.k * KOSCHMIEDER / effect.min_visibility_m
    assert beta_camera == pytest.approx(math.log(20) / 60, rel=1e-5)


def test_rain_reaches_the_camera_as_extinction_streaks_and_a_wetting_lens():
    tables = camera_tables(parse_state("rain:8mm/h"), control_hz=30)
    by = {t["name"]: t for t in tables}
    assert by["fog"]["k"] == pytest.approx(0.312 * 8 ** 0.67 / 1000 * 15 / KOSCHMIEDER, rel=1e-4)
    assert by["rain"]["k"] == pytest.approx(8 / 50)
    ramp = by["ramp"]
    assert (ramp["effect"], ramp["k_start"], ramp["steps"], ramp["mode"]) == ("droplets", 0.0, 1800, "refractive")
    assert ramp["k_end"] == pytest.approx(8 / 13, rel=1e-5)
    parse_weather(tables)  # every table is a valid camera effect


def test_dusk_maps_to_the_dim_scale_and_back():
    assert dim_k(10_000) == 0.0 and dim_k(10_000 * 2 ** -12) == pytest.approx(1.0)
    for lux in (2.5, 20.0, 400.0):
        assert lux_of_dim_k(dim_k(lux)) == pytest.approx(lux)
    (dim,) = camera_tables(parse_state("dusk:20lux"))
    assert dim["mode"] == "night" and dim["k"] == pytest.approx(math.log2(500) / 12, rel=1e-5)
    assert camera_tables(parse_state("clear")) == []


def test_lidar_weather_in_the_states_units():
    w = lidar_weather(parse_state("fog:30m+rain:20mm/h+snow:1mm/h+film:0.5mm"))
    fog, rain, snow, wet = w.effects
    assert fog.beta == pytest.approx(math.log(20) / 30)  # beyond the grid's 50 m: its top raised
    assert rain.physical == pytest.approx(20.0) and snow.physical == pytest.approx(1.0)
    assert wet.physical == pytest.approx(0.5)
    assert lidar_weather(parse_state("dusk:5lux")).effects == ()  # the LiDAR does not see the light
    (only_wet,) = lidar_weather(parse_state("rain:1mm/h")).effects[1:]
    assert only_wet.physical == pytest.approx(0.2)  # the film derived from the rain reaches the ground returns


def test_friction_and_the_study_severities():
    assert friction(parse_state("clear"), 1.3, 10.0) == 1.3
    assert friction(parse_state("film:0.2mm"), 1.0, 10.0) == pytest.approx(0.65 / 0.85)
    states = study_severity_states({"droplets": {3: 0.331}, "low_light": {1: 0.755}})
    assert states["droplets"][3]["rain_mm_h"] == pytest.approx(5 * 0.331 / 0.669, abs=0.01)
    assert states["low_light"][1]["illuminance_lux"] == pytest.approx(10_000 * 2 ** (-12 * 0.755), abs=0.1)
