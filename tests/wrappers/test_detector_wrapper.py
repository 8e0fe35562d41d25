"""DetectorWrapper: image observation in, fixed-size cone list out."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import FIELD, unpack_cones
from weather_gym.perception.onnx_detector import Detections
from weather_gym.wrappers import DetectorWrapper


class FakeDetector:
    """Reports one yellow cone 20 px tall at the image centre, or nothing on a black frame."""

    score_threshold = 0.3

    def __call__(self, image):
        if not image.any():
            return Detections()
        return Detections(np.array([[326, 180, 346, 200]], np.float32), np.array([0.8], np.float32), np.array([1]))


class CameraEnv(gym.Env):
    def __init__(self, with_depth=True, black=False):
        spaces = {"image": gym.spaces.Box(0, 255, (376, 672, 3), np.uint8),
                  "state": gym.spaces.Box(-np.inf, np.inf, (5,), np.float32)}
        if with_depth:
            spaces["depth"] = gym.spaces.Box(0, 80, (376, 672), np.float32)
        self.observation_space = gym.spaces.Dict(spaces)
        self.action_space = gym.spaces.Box(-1, 1, (2,), np.float32)
        self.with_depth, self.black = with_depth, black

    def _obs(self):
        o = {"image": np.full((376, 672, 3), 0 if self.black else 90, np.uint8),
             "state": np.arange(5, dtype=np.float32)}
        if self.with_depth:
            o["depth"] = np.full((376, 672), 9.0, np.float32)
        return o

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self._obs(), {"gt": None}

    def step(self, action):
        return self._obs(), 0.0, False, False, {"gt": None}


def test_cone_list_observation_is_in_its_space_and_state_passes_through():
    env = DetectorWrapper(CameraEnv(), FakeDetector(), max_cones=16)
    assert set(env.observation_space.spaces) == {"cones", "mask", "state"}
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    u = unpack_cones(obs["cones"], obs["mask"])
    assert u["classes"].tolist() == [1] and u["score"][0] == pytest.approx(0.8)
    assert u["range"][0] == pytest.approx(9.0 + 0.057, abs=0.05)  # from the depth observation
    np.testing.assert_array_equal(obs["state"], np.arange(5))
    assert info["detections"]["boxes"].shape == (1, 4) and env.latency_ms >= 0
    assert "detector_latency_ms" not in info  # wall-clock times stay out of info (determinism)
    obs, r, term, trunc, info = env.step(np.zeros(2, np.float32))
    assert env.observation_space.contains(obs) and "gt" in info


def test_without_depth_range_comes_from_box_height():
    env = DetectorWrapper(CameraEnv(with_depth=False), FakeDetector(), max_cones=4)
    obs, _ = env.reset(seed=0)
    cam = CameraConfig()
    assert obs["cones"][0, FIELD["range"]] == pytest.approx(cam.fy * 0.325 / 20, rel=1e-3)
    env2 = DetectorWrapper(CameraEnv(), FakeDetector(), max_cones=4, use_depth=False)
    assert env2.reset(seed=0)[0]["cones"][0, FIELD["range"]] == pytest.approx(obs["cones"][0, FIELD["range"]])


class HalfBackgroundEnv(CameraEnv):
    """The fake cone's box: its left half at 9 m, its right half the ground 40 m behind."""

    def _obs(self):
        o = super()._obs()
        o["depth"][:, 336:] = 40.0
        return o


def test_depth_quantile_reaches_the_cone_list_and_a_bad_one_is_refused():
    med = DetectorWrapper(HalfBackgroundEnv(), FakeDetector(), max_cones=4).reset(seed=0)[0]
    low = DetectorWrapper(HalfBackgroundEnv(), FakeDetector(), max_cones=4, depth_quantile=0.25).reset(seed=0)[0]
    assert med["cones"][0, FIELD["range"]] > 20.0
    assert low["cones"][0, FIELD["range"]] == pytest.approx(9.0 + 0.057, abs=0.05)
    with pytest.raises(InputError, match="depth_quantile"):
        DetectorWrapper(CameraEnv(), FakeDetector(), depth_quantile=2.0)


def test_frame_without_cones_gives_an_empty_valid_list_with_the_real_detector():
    env = DetectorWrapper(CameraEnv(black=True), max_cones=8, keep_image=True)
    obs, info = env.reset(seed=0)
    assert obs["mask"].sum() == 0 and not obs["cones"].any()
    assert obs["image"].shape == (376, 672, 3) and env.observation_space.contains(obs)
    assert len(info["detections"]["scores"]) == 0


def test_bad_configuration_is_rejected():
    with pytest.raises(ValueError, match="image key"):
        DetectorWrapper(CameraEnv(), FakeDetector(), image_key="rgb")
    with pytest.raises(ValueError, match="max_cones"):
        DetectorWrapper(CameraEnv(), FakeDetector(), max_cones=0)
    with pytest.raises(ValueError, match="640x360"):
        DetectorWrapper(CameraEnv(), FakeDetector(), camera=CameraConfig(width=640, height=360))


@pytest.mark.slow
def test_env_weather_detector_stack_steps_and_sees_cones():
    from weather_gym.envs import ConeTrackEnv, EnvConfig
    from weather_gym.wrappers import WeatherWrapper

    env = DetectorWrapper(WeatherWrapper(ConeTrackEnv(EnvConfig(track="small_track")), weather={"dim": 0.0}))
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert obs["mask"].sum() >= 2  # the start of small_track shows several cones
        obs, *_ , info = env.step(np.array([0.0, 0.3], np.float32))
        assert env.observation_space.contains(obs) and env.latency_ms > 0
    finally:
        env.close()
