"""The LiDAR perception: env with a LiDAR, LidarConeWrapper, the ``lidar`` mode, the lap command's option."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import weather_gym  # noqa: F401  (registers the ids)
from weather_gym.cli.lap import _perception_kwargs
from weather_gym.core.errors import InputError
from weather_gym.envs import ConeTrackEnv, EnvConfig
from weather_gym.pipeline import make_env
from weather_gym.pipeline.modes import perception_mode
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.wrappers.lidar import LidarConeWrapper


def _env(**kw):
    return ConeTrackEnv(EnvConfig(camera_images=False, ground_truth="geometry", lidar=LidarConfig(), **kw))


def test_env_observes_points_at_the_lidar_rate():
    env = _env()
    try:
        obs, info = env.reset(seed=0)
        assert obs["points"].shape == (72000, 4) and obs["points_mask"].shape == (72000,)
        assert env.observation_space.contains(obs)
        n = int(obs["points_mask"].sum())
        assert n == len(info["lidar"]) and info["lidar_new"]
        np.testing.assert_array_equal(obs["points"][:n, :3], info["lidar"].xyz)
        news = [env.step([0.0, 0.3])[4]["lidar_new"] for _ in range(6)]
        assert news == [False, False, True, False, False, True]  # 10 Hz at 30 Hz control
    finally:
        env.close()


def test_lidar_config_from_a_dict_and_checked():
    assert EnvConfig(lidar={"channels": 16}).lidar.channels == 16
    with pytest.raises(InputError, match="lidar"):
        EnvConfig(lidar={"beams": 16})
    with pytest.raises(InputError, match="LidarConfig"):
        EnvConfig(lidar="hdl32e")


def test_wrapper_is_seeded_and_changes_weather_per_episode():
    def run(options=None):
        env = LidarConeWrapper(_env(), lidar_weather="rain@4")
        try:
            out = [env.reset(seed=3, options=options)[0]]
            out += [env.step([0.0, 0.5])[0] for _ in range(7)]
            return out
        finally:
            env.close()

    a, b = run(), run()
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x["cones"], y["cones"])
    clear = run({"lidar_weather": "clear"})
    assert any(not np.array_equal(x["cones"], y["cones"]) for x, y in zip(a, clear))
    assert all(int(o["mask"].sum()) > 0 for o in clear)
    onehot = clear[0]["cones"][clear[0]["mask"] == 1, :4]  # colour from the stripes near the car, else unknown
    assert set(onehot.sum(axis=1).tolist()) <= {0.0, 1.0} and (onehot.sum(axis=1) == 0).any()


def test_between_scans_the_cones_follow_the_odometry():
    env = LidarConeWrapper(_env(odometry=weather_gym.envs.config.OdometryConfig(0, 0, 0, 0)))
    try:
        obs, info = env.reset(seed=0, options={"start_speed": 5.0})
        first = obs["cones"][obs["mask"] == 1]
        obs, *_ = env.step([0.0, 0.0])
        moved = obs["cones"][obs["mask"] == 1]
        dx = first[:, 11] - moved[:, 11]  # x_body: the car drove about 5 m/s x 1/30 s forward
        assert np.allclose(dx, dx[0], atol=1e-4) and 0.1 < dx[0] < 0.25
    finally:
        env.close()


def test_wrapper_needs_a_lidar():
    with pytest.raises(InputError, match="LiDAR"):
        LidarConeWrapper(gym.make("WeatherGym/ConeTrack-v0", camera_images=False, ground_truth="geometry"))


def test_the_lidar_mode_builds_and_refuses_camera_weather():
    mode = perception_mode("lidar")
    assert not mode.renders_frames and mode.takes_lidar_weather and mode.observation == frozenset(
        {"cones", "mask", "state"})
    env = make_env("WeatherGym/ConeTrack-v0", perception="lidar", perception_kwargs={"lidar_weather": "fog@2"},
                   max_episode_steps=5)
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs) and "fog" in info["lidar_weather"]
    finally:
        env.close()
    with pytest.raises(InputError, match="lidar_weather"):
        make_env("WeatherGym/ConeTrack-v0", perception="lidar", weather="droplets:0.5", max_episode_steps=5)


def test_lap_option_checks_mode_and_spec():
    assert _perception_kwargs(perception_mode("lidar"), False, None, "fog@1") == {"lidar_weather": "fog@1"}
    with pytest.raises(InputError, match="--perception lidar"):
        _perception_kwargs(perception_mode("gt_cones"), False, None, "fog@1")
    with pytest.raises(InputError, match="hail"):
        _perception_kwargs(perception_mode("lidar"), False, None, "hail@1")


def test_gymnasium_env_checker_passes_with_a_lidar():
    env = _env()
    try:
        check_env(env, skip_render_check=True)
    finally:
        env.close()
