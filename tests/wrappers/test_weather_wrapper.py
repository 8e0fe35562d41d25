"""WeatherWrapper on Gymnasium envs that are not weather-gym's: image Box and Dict observations."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from weather_gym.weather import Ramp, make, preset_spec
from weather_gym.wrappers import WeatherWrapper

H, W = 64, 96


class PixelEnv(gym.Env):
    """A minimal third-party env: the observation is a camera image that changes every step."""

    metadata = {"render_modes": []}

    def __init__(self):
        self.observation_space = spaces.Box(0, 255, (H, W, 3), np.uint8)
        self.action_space = spaces.Discrete(2)
        self.options_seen = None

    def _frame(self):
        img = np.zeros((H, W, 3), np.uint8)
        img[:, :, 1] = 100 + self.t
        img[H // 3:, : W // 2] = (200, 120, 30)
        return img

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = int(self.np_random.integers(0, 20))
        self.options_seen = options
        return self._frame(), {"t": self.t}

    def step(self, action):
        self.t += 1
        return self._frame(), 1.0, self.t > 60, False, {"t": self.t}


class DictEnv(PixelEnv):
    """Image, depth and a state vector, like ConeTrackEnv but without weather-gym."""

    def __init__(self, image_key="image"):
        super().__init__()
        self.key = image_key
        self.observation_space = spaces.Dict({
            image_key: spaces.Box(0, 255, (H, W, 3), np.uint8),
            "depth": spaces.Box(0, 100, (H, W), np.float32),
            "state": spaces.Box(-np.inf, np.inf, (5,), np.float32),
        })

    def _obs(self, img):
        depth = np.tile(np.linspace(2, 90, H, dtype=np.float32)[::-1, None], (1, W))
        return {self.key: img, "depth": depth, "state": np.array([8.0, 0.2, 0, 0, 0], np.float32)}

    def reset(self, *, seed=None, options=None):
        img, info = super().reset(seed=seed, options=options)
        return self._obs(img), info

    def step(self, action):
        img, r, term, trunc, info = super().step(action)
        return self._obs(img), r, term, trunc, info


def test_box_image_env_gets_weather_and_keeps_its_space():
    base = PixelEnv()
    env = WeatherWrapper(PixelEnv(), weather={"dim": 0.5})
    assert env.observation_space == base.observation_space
    clean, _ = base.reset(seed=3)
    obs, info = env.reset(seed=3)
    np.testing.assert_array_equal(obs, make("dim", k=0.5)(clean))
    assert info["t"] == base.t and info["weather"] == [{"name": "dim", **make("dim", k=0.5).params()}]
    assert env.latency_ms >= 0.0 and "weather_latency_ms" not in info  # wall-clock times stay out of info
    obs, reward, term, trunc, info = env.step(0)
    assert reward == 1.0 and obs.dtype == np.uint8


def test_latency_goes_into_info_only_when_asked():
    env = WeatherWrapper(PixelEnv(), weather={"dim": 0.5}, latency_in_info=True)
    _, info = env.reset(seed=3)
    assert info["weather_latency_ms"] == env.latency_ms >= 0.0


def test_observations_stay_in_the_observation_space():
    for env in (WeatherWrapper(PixelEnv(), weather="droplets:0.55,noise:0.3"),
                WeatherWrapper(DictEnv(), weather="fog:0.5,motion_blur:0.5")):
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        for _ in range(3):
            assert env.observation_space.contains(env.step(env.action_space.sample())[0])


def test_dict_env_uses_depth_and_state():
    env = WeatherWrapper(DictEnv(), weather={"fog": 0.8})
    obs, _ = env.reset(seed=0)
    clean, _ = DictEnv().reset(seed=0)
    expected = make("fog", k=0.8)(clean["image"], depth=clean["depth"], state={"speed": 8.0, "yaw_rate": 0.2})
    np.testing.assert_array_equal(obs["image"], expected)
    np.testing.assert_array_equal(obs["depth"], clean["depth"])
    no_depth = make("fog", k=0.8)(clean["image"])
    assert not np.array_equal(obs["image"], no_depth)


def test_configurable_image_key_and_bad_spaces():
    env = WeatherWrapper(DictEnv(image_key="rgb"), weather="dim:0.3", image_key="rgb", depth_key=None,
                         state_key=None)
    obs, _ = env.reset(seed=1)
    assert obs["rgb"].shape == (H, W, 3)
    with pytest.raises(ValueError, match="no image key 'image'"):
        WeatherWrapper(DictEnv(image_key="rgb"))
    bad = PixelEnv()
    bad.observation_space = spaces.Box(0, 1, (H, W), np.float32)
    with pytest.raises(ValueError, match=r"image Box\(0, 255, \(H, W, 3\), uint8\)"):
        WeatherWrapper(bad)
    with pytest.raises(ValueError, match="unknown weather effect"):
        WeatherWrapper(PixelEnv(), weather="sleet:0.3")


def _episode(env, seed, steps=5):
    obs, _ = env.reset(seed=seed)
    frames = [obs]
    for _ in range(steps):
        frames.append(env.step(0)[0])
    return frames


def test_same_seed_same_bytes_different_seed_different_noise():
    a = WeatherWrapper(PixelEnv(), weather={"noise": 0.8, "droplets": 0.5})
    b = WeatherWrapper(PixelEnv(), weather={"noise": 0.8, "droplets": 0.5})
    for x, y in zip(_episode(a, 7), _episode(b, 7), strict=True):
        np.testing.assert_array_equal(x, y)
    first, second = _episode(a, 7), _episode(a, 8)
    assert not np.array_equal(first[1], second[1])
    # unseeded resets continue the sequence deterministically
    c = WeatherWrapper(PixelEnv(), weather={"noise": 0.8})
    d = WeatherWrapper(PixelEnv(), weather={"noise": 0.8})
    c.reset(seed=5)
    d.reset(seed=5)
    for x, y in zip(_episode(c, None), _episode(d, None), strict=True):
        np.testing.assert_array_equal(x, y)


def test_weather_changes_between_episodes_through_reset_options():
    inner = PixelEnv()
    env = WeatherWrapper(inner, weather="clear")
    clean, info = env.reset(seed=0, options={"other": 1})
    assert inner.options_seen == {"other": 1} and info["weather"] == []
    wet, info = env.reset(seed=0, options={"weather": "low_light@3"})
    assert inner.options_seen is None  # the weather option is the wrapper's, not the env's
    (preset,) = preset_spec("low_light", 3)
    assert info["weather"][0]["name"] == "dim" and info["weather"][0]["k"] == preset["k"]
    assert info["weather"][0]["mode"] == preset["mode"] and wet.mean() < 0.5 * clean.mean()  # night falls
    again, _ = env.reset(seed=0)  # the weather stays until changed
    np.testing.assert_array_equal(again, wet)


def test_weather_worsens_during_an_episode_with_a_ramp():
    env = WeatherWrapper(PixelEnv(), weather=Ramp("dim", k_start=0.0, k_end=0.9, steps=10))
    obs, info = env.reset(seed=0)
    ks, means = [info["weather"][0]["k"]], [obs.mean()]
    for _ in range(12):
        obs, _, _, _, info = env.step(0)
        ks.append(info["weather"][0]["k"])
        means.append(obs.mean())
    assert ks[0] == 0.0 and ks[-1] == pytest.approx(0.9) and ks == sorted(ks)
    assert means[-1] < 0.3 * means[0]
    env.reset(seed=0)  # a new episode starts the ramp again
    assert env.weather.k == 0.0


def test_persistent_droplets_are_reset_each_episode():
    env = WeatherWrapper(PixelEnv(), weather={"droplets": {"k": 0.7, "persistent": True}})
    env.reset(seed=1)
    env.step(0)
    drops = env.weather.drops.copy()
    env.reset(seed=1)
    env.step(0)
    np.testing.assert_array_equal(env.weather.drops, drops)
