"""Shared fixtures for the weather-gym test suite."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera import CameraConfig

SMALL_CAMERA = CameraConfig(width=96, height=54)
"""A tiny camera that keeps env tests fast (rendering dominates the step time)."""


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def small_camera() -> CameraConfig:
    return SMALL_CAMERA


@pytest.fixture
def make_env():
    """Factory for ``ConeTrackEnv`` (registered id by default) that closes every env it made."""
    import gymnasium as gym

    import weather_gym  # noqa: F401  (registers the ids)

    made = []

    def _make(env_id: str = "WeatherGym/ConeTrack-v0", **kwargs):
        kwargs.setdefault("camera", SMALL_CAMERA)
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()


def drive_gt(env, seed: int = 0, max_steps: int = 100_000, options: dict | None = None):
    """Run the ground-truth pure-pursuit driver for one episode; returns (steps, last info, actions)."""
    from weather_gym.agents import AGENTS

    obs, info = env.reset(seed=seed, options=options)
    u = env.unwrapped
    agent = AGENTS.get("gt_pure_pursuit")(u.track, u.config.camera)
    agent.reset(seed=seed, info=info)
    actions = []
    for step in range(1, max_steps + 1):
        a = agent.act(obs, info)
        actions.append(np.asarray(a, np.float32))
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            return step, info, actions
    return max_steps, info, actions
