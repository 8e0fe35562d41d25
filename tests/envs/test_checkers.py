"""Gymnasium's and stable-baselines3's env checkers pass on every registered id, raw and wrapped
(weather, detector, ground-truth cones), headless (render_mode="human" without a display included).

``check_env`` resets and steps twice with the same seed and compares everything, info included:
wall-clock latencies are therefore not in ``info`` (``wrapper.latency_ms`` has them).
"""

from __future__ import annotations

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env

import weather_gym  # noqa: F401 - registers the ids
from weather_gym.envs.registration import register_envs

CAMERA = {"width": 160, "height": 90}
IDS = sorted(register_envs())


def _small(env_id: str) -> dict:
    return {} if env_id == "WeatherGym/ConeTrackCones-v0" else {"camera": CAMERA}


@pytest.fixture(autouse=True)
def _headless(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_on_every_registered_id(env_id):
    env = gym.make(env_id, **_small(env_id))
    try:
        with pytest.warns(RuntimeWarning, match="needs a display"):  # the "human" mode, checked headless
            check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("kwargs", [
    {"weather": "droplets@3", "perception": "detector"},
    {"weather": {"dim": 0.5, "droplets": 0.3}, "perception": "oracle", "perception_kwargs": {"miss_prob": 0.2}},
    {"perception": "gt_cones", "perception_kwargs": {"range_noise": 0.05}},
], ids=["weather+detector", "weather+oracle", "gt_cones+noise"])
def test_check_env_passes_wrapped(kwargs):
    env = gym.make("WeatherGym/ConeTrack-v0", camera=CAMERA, **kwargs)
    try:
        with pytest.warns(RuntimeWarning, match="needs a display"):
            check_env(env)
    finally:
        env.close()


@pytest.mark.parametrize("kwargs", [{"perception": "gt_cones"}, {"perception": "detector", "weather": "low_light@1"}])
def test_stable_baselines3_check_env_passes(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("WeatherGym/ConeTrack-v0", camera=CAMERA, **kwargs)
    try:
        sb3_check_env(env, warn=False)
    finally:
        env.close()
