"""The default world is the plain one with the study's ideal camera; the realistic world and camera model
stay one setting away (scenario TOML, gym.make keyword, reset option)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import weather_gym  # noqa: F401  (registers the ids)
from weather_gym.camera_model import CameraModel
from weather_gym.envs.config import EnvConfig
from weather_gym.envs.scenario import build_config, load_scenario
from weather_gym.sim.config import SimConfig


def test_defaults_are_the_plain_world_and_the_ideal_camera():
    assert SimConfig().scene == "plain" and not EnvConfig().camera_model.enabled
    cfg = {i: gym.make(i).unwrapped.config for i in ("WeatherGym/ConeTrack-v0", "WeatherGym/ConeTrackRealistic-v0",
                                                     "WeatherGym/ConeTrackSmall-v0", "WeatherGym/ConeTrackPlain-v0")}
    for i in ("WeatherGym/ConeTrack-v0", "WeatherGym/ConeTrackSmall-v0", "WeatherGym/ConeTrackPlain-v0"):
        assert cfg[i].sim.scene == "plain" and not cfg[i].camera_model.enabled, i
    real = cfg["WeatherGym/ConeTrackRealistic-v0"]
    assert real.sim.scene == "realistic" and real.camera_model == CameraModel.realistic()


def test_scenario_table_switches_the_camera_model_off_or_changes_one_field(tmp_path):
    path = tmp_path / "ideal.toml"
    path.write_text('id = "WeatherGym/Ideal-v0"\n[camera_model]\nenabled = false\n')
    assert not build_config(load_scenario(path)).camera_model.enabled
    path.write_text('id = "WeatherGym/NoJpeg-v0"\n[camera_model]\njpeg_quality = 0\n')
    assert build_config(load_scenario(path)).camera_model == CameraModel.realistic().with_(jpeg_quality=0)


def test_camera_model_per_episode_sees_the_same_episode_with_other_frames(make_env):
    env = make_env(camera_model={"enabled": True})  # the default id, 96x54, with the realistic camera
    ideal = make_env()  # the default: the ideal camera
    a, _ = env.reset(seed=3)
    b, _ = ideal.reset(seed=3)
    c, _ = env.reset(seed=3, options={"camera_model": {"enabled": False}})
    assert np.array_equal(b["image"], c["image"])  # the reset option = the env built with the camera off
    assert not np.array_equal(a["image"], b["image"])  # the camera model finishes the frame
    # same start, look and odometry noise with the camera on or off: only the frames differ
    act = np.array([0.1, 0.5], np.float32)
    env.reset(seed=3)
    sa = [env.step(act)[0]["state"] for _ in range(3)]
    ideal.reset(seed=3)
    sb = [ideal.step(act)[0]["state"] for _ in range(3)]
    assert np.array_equal(np.stack(sa), np.stack(sb))
    d, _ = env.reset(seed=3)  # no option: back to the env's own camera
    assert np.array_equal(d["image"], a["image"])
