"""The default world is the plain one seen through the realistic camera model (the default finishing stage);
the study's ideal camera (``WeatherGym/ConeTrackPlain-v0``) and the realistic world stay one setting away
(scenario TOML, gym.make keyword, reset option)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import weather_gym  # noqa: F401  (registers the ids)
from weather_gym.camera.isp import CameraModel
from weather_gym.envs.config import EnvConfig
from weather_gym.envs.scenario import build_config, load_scenario
from weather_gym.sim.config import SimConfig


def test_defaults_are_the_plain_world_and_the_realistic_camera_model():
    assert SimConfig().scene == "plain" and EnvConfig().camera_model == CameraModel.realistic()
    cfg = {i: gym.make(i).unwrapped.config for i in ("WeatherGym/ConeTrack-v0", "WeatherGym/ConeTrackRealistic-v0",
                                                     "WeatherGym/ConeTrackSmall-v0", "WeatherGym/ConeTrackPlain-v0")}
    for i in ("WeatherGym/ConeTrack-v0", "WeatherGym/ConeTrackSmall-v0"):
        assert cfg[i].sim.scene == "plain" and cfg[i].camera_model == CameraModel.realistic(), i
    plain = cfg["WeatherGym/ConeTrackPlain-v0"]  # the study's ideal camera, switched off in its scenario
    assert plain.sim.scene == "plain" and not plain.camera_model.enabled
    real = cfg["WeatherGym/ConeTrackRealistic-v0"]
    assert real.sim.scene == "realistic" and real.camera_model == CameraModel.realistic()


def test_the_ideal_camera_passes_frames_unchanged_and_the_default_finishes_them():
    ideal = gym.make("WeatherGym/ConeTrackPlain-v0", camera={"width": 96, "height": 54})
    default = gym.make("WeatherGym/ConeTrack-v0", camera={"width": 96, "height": 54})
    off = gym.make("WeatherGym/ConeTrack-v0", camera={"width": 96, "height": 54}, camera_model={"enabled": False})
    a, b, c = (e.reset(seed=5)[0]["image"] for e in (ideal, default, off))
    assert np.array_equal(a, c) and not np.array_equal(a, b)
    for e in (ideal, default, off):
        e.close()


def test_scenario_table_switches_the_camera_model_off_or_changes_one_field(tmp_path):
    path = tmp_path / "ideal.toml"
    path.write_text('id = "WeatherGym/Ideal-v0"\n[camera_model]\nenabled = false\n')
    assert not build_config(load_scenario(path)).camera_model.enabled
    path.write_text('id = "WeatherGym/NoJpeg-v0"\n[camera_model]\njpeg_quality = 0\n')
    assert build_config(load_scenario(path)).camera_model == CameraModel.realistic().with_(jpeg_quality=0)


def test_camera_model_per_episode_sees_the_same_episode_with_other_frames(make_env):
    env = make_env()  # the default id, 96x54: the realistic camera
    ideal = make_env(camera_model={"enabled": False})  # the study's ideal camera
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


def test_render_free_ground_truth_follows_the_lens_as_the_rendered_frame_does(make_env):
    """The surrogate and the cone-list envs render nothing; their geometric boxes still go through the
    default camera's lens distortion, so a box is the same size with or without frames."""
    rendered = make_env(ground_truth="geometry")
    free = make_env(camera_images=False, ground_truth="geometry")
    ideal = make_env(camera_images=False, ground_truth="geometry", camera_model={"enabled": False})
    boxes = [e.reset(seed=2)[1]["gt"]["boxes"] for e in (rendered, free, ideal)]
    assert len(boxes[0]) > 3
    np.testing.assert_array_equal(boxes[0], boxes[1])
    assert not np.allclose(boxes[1], boxes[2], atol=0.5)  # the barrel lens moves them
