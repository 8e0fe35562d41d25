"""One state reaches the camera, the LiDAR and the tyres through make_env(conditions=...)."""

import math

import numpy as np
import pytest

from weather_gym.core.errors import InputError, LimitError
from weather_gym.pipeline import make_env

SMALL = {"width": 96, "height": 64}


def test_camera_gets_the_states_effects_and_the_tyres_its_film():
    env = make_env(perception="camera", conditions="rain:8mm/h+dusk:20lux", camera=SMALL, max_episode_steps=20)
    try:
        obs, info = env.reset(seed=0)
        names = [t["name"] for t in info["weather"]]
        assert names == ["fog", "rain", "droplets", "dim"]  # the lens ramp, at its current k
        assert env.unwrapped.water_film_mm == 1.0
        assert info["friction"] == pytest.approx(0.55 / 0.85)  # 1 mm at rest: the 50 km/h column
        for _ in range(30):  # one second of rain on the lens: 1/60 of the way to 8/13
            env.step(np.zeros(2, np.float32))
        env.get_wrapper_attr("set_conditions")("clear")
        _, _, _, _, info = env.step(np.zeros(2, np.float32))
        assert info["conditions"] == f"lens:{round(8 / 13 * 30 / 1800, 9):g}"  # the rain stops, the lens stays wet
        assert env.unwrapped.water_film_mm == 0.0 and info["weather"][0]["name"] == "droplets"
    finally:
        env.close()


def test_lidar_gets_the_states_effects_and_ramps_between_states():
    env = make_env(perception="lidar", conditions="fog:60m", max_episode_steps=100)
    try:
        _, info = env.reset(seed=0)
        assert info["lidar_weather"].startswith("fog:") and "0.0499" in info["lidar_weather"]
        env.get_wrapper_attr("ramp_to")("fog:60m+rain:4mm/h", 2.0)
        for _ in range(30):
            _, _, _, _, info = env.step(np.zeros(2, np.float32))
        state = env.get_wrapper_attr("state")
        assert state.rain_mm_h == pytest.approx(2.0) and state.mor_m == pytest.approx(60.0)
        for _ in range(30):
            env.step(np.zeros(2, np.float32))
        assert env.get_wrapper_attr("state").rain_mm_h == pytest.approx(4.0)
        assert env.unwrapped.water_film_mm == pytest.approx(0.2 + 0.8 * 1.5 / 5.1)
        _, info = env.reset(seed=0, options={"conditions": "snow:1mm/h"})
        assert info["lidar_weather"].startswith("snow:") and env.unwrapped.water_film_mm == 0.0
    finally:
        env.close()


def test_bad_conditions_are_refused_before_anything_runs():
    with pytest.raises(LimitError, match="5 m"):
        make_env(perception="lidar", conditions="fog:5m")
    with pytest.raises(InputError, match="once"):
        make_env(perception="detector", conditions="fog:60m", weather="droplets@2")
    with pytest.raises(InputError, match="surrogate"):
        make_env(perception="surrogate", conditions="rain:2mm/h")
    env = make_env(perception="gt_cones", conditions="rain:2mm/h", max_episode_steps=5)
    try:
        with pytest.raises(InputError, match="clash"):
            env.reset(seed=0, options={"water_film_mm": 1.0})
        _, info = env.reset(seed=0)
        assert info["conditions"] == "rain:2mm/h" and not math.isnan(info["friction"])
    finally:
        env.close()


def test_lap_takes_conditions():
    from weather_gym.cli.lap import run_laps

    result = run_laps(track="small_track", agent="mapper_pure_pursuit", perception="lidar",
                      conditions="fog:60m+film:0.2mm", max_steps=10)
    assert result["weather"] == "fog:60m+film:0.2mm"
    with pytest.raises(InputError, match="once"):
        run_laps(track="small_track", agent="mapper_pure_pursuit", perception="lidar", conditions="fog:60m",
                 lidar_weather="rain@2", max_steps=10)
