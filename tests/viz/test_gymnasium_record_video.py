"""Gymnasium's own ``RecordVideo`` (moviepy, the ``video`` extra) records a weather-gym env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import weather_gym


def test_gymnasium_record_video_writes_an_episode(tmp_path):
    pytest.importorskip("moviepy", reason="gymnasium.wrappers.RecordVideo needs moviepy (the video extra)")
    env = weather_gym.make_env(perception="gt_cones", render_mode="rgb_array", max_episode_steps=5)
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda e: True, disable_logger=True)
    try:
        env.reset(seed=0)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(np.array([0.5, 0.0], np.float32))
            done = terminated or truncated
    finally:
        env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0
