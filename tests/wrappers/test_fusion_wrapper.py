"""The fused mode: detector cones and LiDAR cones in one list; a team's own rule through the hook."""

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.perception.cones import unpack_cones
from weather_gym.perception.fusion import SensorCones
from weather_gym.pipeline import make_env

SMALL = {"width": 160, "height": 96}


def test_fused_cones_carry_lidar_positions_and_camera_colours():
    env = make_env(perception="fused", camera=SMALL, max_episode_steps=10)
    try:
        obs, info = env.reset(seed=0)
        d = unpack_cones(obs["cones"], obs["mask"])
        src = info["fusion_sources"]
        assert src["lidar"] + src["both"] > 0 and len(d["x_body"]) == sum(src.values())
        assert "boxes" in info["detections"] and "x_body" in info["lidar_detections"]  # camera's for mAP
        lid = info["lidar_detections"]
        both = d["classes"] >= 0
        # every coloured cone near a LiDAR cone sits exactly on it
        for x, y in zip(d["x_body"][both], d["y_body"][both]):
            dist = np.hypot(np.asarray(lid["x_body"]) - x, np.asarray(lid["y_body"]) - y)
            assert dist.min() < 1e-5 or dist.min() > 0.5
    finally:
        env.close()


def test_a_teams_own_rule_is_used():
    calls = []
    given = []

    def lidar_only(camera: SensorCones, lidar: SensorCones) -> SensorCones:
        calls.append((len(camera), len(lidar)))
        given.append(lidar)
        return lidar

    env = make_env(perception="fused", camera=SMALL, max_episode_steps=10,
                   perception_kwargs={"fusion": lidar_only, "lidar_weather": "fog:mor=60"})
    try:
        obs, info = env.reset(seed=0)
        env.step(np.zeros(2, np.float32))
        assert len(calls) == 2 and info["fusion_sources"]["camera"] == 0
        onehot = obs["cones"][obs["mask"].astype(bool), :4]  # the colours are the LiDAR's (its stripes) only
        lidar = given[-1]
        assert len(onehot) == len(lidar)
        expected = np.zeros_like(onehot)
        known = lidar.classes >= 0
        expected[np.flatnonzero(known), lidar.classes[known]] = 1.0
        assert sorted(map(tuple, onehot)) == sorted(map(tuple, expected))
    finally:
        env.close()
    with pytest.raises(InputError, match="callable"):
        make_env(perception="fused", camera=SMALL, perception_kwargs={"fusion": 3})
