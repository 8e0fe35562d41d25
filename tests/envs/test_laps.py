"""The ground-truth driver completes every shipped track (and 20 generated ones) without leaving it."""

from __future__ import annotations

import pytest

from tests.conftest import drive_gt
from weather_gym.camera.config import CameraConfig
from weather_gym.tracks import SHIPPED

TINY = CameraConfig(width=64, height=36)  # the camera is not what is tested here
FAST = {"renderer": "tiny"}  # TinyRenderer is the cheaper one for tiny frames


@pytest.mark.slow
@pytest.mark.parametrize("track", [*sorted(SHIPPED), "oval"])
def test_gt_driver_completes_every_shipped_track(make_env, track):
    env = make_env(track=track, camera=TINY, sim=FAST, max_episode_steps=6000)
    steps, info, _ = drive_gt(env, seed=0)
    assert info["lap"] == 1, f"{track}: no lap after {steps} steps"
    assert info["off_track_events"] == 0
    assert info["cones_hit"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(20))
def test_gt_driver_completes_random_tracks(make_env, seed):
    env = make_env(track=f"random:{seed}", camera=TINY, sim=FAST, max_episode_steps=6000)
    steps, info, _ = drive_gt(env, seed=seed)
    assert info["lap"] == 1, f"random:{seed}: no lap after {steps} steps"
    assert info["off_track_events"] == 0
    assert info["cones_hit"] == 0
