"""Vector envs: gym.make_vec (sync and async) and stable-baselines3's SubprocVecEnv run 1,000 steps
with divergent seeds and actions, with weather and the detector; info stacks; no renderer changes.

Small frames (160x90) keep them affordable; episodes are short (time limit 120 steps, and random
actions leave the track), so every env resets many times at different steps.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import weather_gym  # noqa: F401 - registers the ids
from weather_gym.pipeline import make_env

CAMERA = {"width": 160, "height": 90}
STACK = {"camera": CAMERA, "weather": "droplets@2", "perception": "detector", "max_episode_steps": 120}
STEPS = 1000


def _renderer_here() -> str:
    env = make_env(camera=CAMERA, max_episode_steps=5)
    try:
        env.reset(seed=0)
        return env.unwrapped.renderer
    finally:
        env.close()


def _actions(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.uniform(-1.0, 1.0, (n, 2)).astype(np.float32)
    a[:, 1] = np.abs(a[:, 1])  # mostly forward, so the cars go somewhere different
    return a


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_gym_make_vec_runs_1000_divergent_steps_with_weather_and_detector(mode):
    venv = gym.make_vec("WeatherGym/ConeTrack-v0", num_envs=2, vectorization_mode=mode, **STACK)
    rng = np.random.default_rng(0)
    episodes = 0
    try:
        obs, info = venv.reset(seed=[11, 12])
        first = obs
        assert not np.array_equal(obs["state"][0], obs["state"][1])
        for _ in range(STEPS):
            obs, reward, term, trunc, info = venv.step(_actions(rng, 2))
            assert venv.observation_space.contains(obs) and reward.shape == (2,)
            episodes += int(np.sum(term | trunc))
        assert info["gt"].dtype == object and info["detections"].dtype == object  # one per env, any length
        assert info["renderer"].tolist() == [_renderer_here()] * 2  # workers render as this process does
    finally:
        venv.close()
    assert episodes >= 10
    # same seeds, same bytes as a single env in this process (no other renderer in the workers)
    env = make_env(**STACK)
    try:
        single, _ = env.reset(seed=12)
        assert all(np.array_equal(single[k], first[k][1]) for k in single)
    finally:
        env.close()


@pytest.mark.slow
def test_stable_baselines3_subprocvecenv_runs_1000_divergent_steps():
    from stable_baselines3.common.vec_env import SubprocVecEnv

    def maker(i):
        return lambda: make_env(**STACK)

    venv = SubprocVecEnv([maker(i) for i in range(2)])  # forkserver: a fresh process per worker
    rng = np.random.default_rng(1)
    try:
        venv.seed(21)
        obs = venv.reset()
        ends = []
        for _ in range(STEPS):
            obs, reward, done, infos = venv.step(_actions(rng, 2))
            ends += [i["episode"]["end_reason"] for i, d in zip(infos, done, strict=True) if d]
        assert obs["cones"].shape == (2, 64, 14) and reward.shape == (2,)
        assert {"off_track", "time_limit"} & set(ends) and len(ends) >= 10
        assert venv.get_attr("renderer") == [_renderer_here()] * 2
    finally:
        venv.close()
