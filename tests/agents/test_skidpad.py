"""Skidpad mission: the rule figure eight fitted to cones, and the stack driving the shipped skidpad."""

from __future__ import annotations

import numpy as np
import pytest
from agent_sim import SyntheticCones, drive

from weather_gym.agents import AGENTS
from weather_gym.agents.skidpad import SkidpadConfig, SkidpadPlanner, skidpad_cones
from weather_gym.camera.config import CameraConfig
from weather_gym.tracks import load_track


def test_fit_finds_the_circles_from_part_of_the_rings():
    xy, cls = skidpad_cones(junction=(3.0, 1.0), heading=0.3)
    rng = np.random.default_rng(0)
    # only the cones a car approaching the junction sees: the near halves, with 10 cm of noise
    start = np.array([3.0, 1.0]) - 15.0 * np.array([np.cos(0.3), np.sin(0.3)])
    near = np.hypot(*(xy - start).T) < 22.0
    noisy = xy[near] + rng.normal(0, 0.1, (int(near.sum()), 2))
    planner = SkidpadPlanner(start_pose=(*start, 0.3))
    path = planner.plan(noisy, cls[near])
    n = np.array([-np.sin(0.3), np.cos(0.3)])
    expected = np.array([[3.0, 1.0] - 9.125 * n, [3.0, 1.0] + 9.125 * n])
    assert np.abs(planner.centres - expected).max() < 0.15
    # the path: approach to the junction, then the right circle clockwise (first quarter turns right)
    app = planner.lengths["approach"]
    k = int(round((app + 2 * np.pi * 9.125 / 4) / planner.config.step))
    quarter = path[k]
    assert np.hypot(*(quarter - expected[0])) == pytest.approx(9.125, abs=0.2)
    assert (quarter - np.array([3.0, 1.0])) @ np.array([np.cos(0.3), np.sin(0.3)]) > 8.0  # ahead, to the right
    total = app + planner.lengths["circles"] + planner.lengths["exit"]
    assert len(path) * planner.config.step == pytest.approx(total, abs=1.0)


def test_before_any_fit_the_path_is_the_starting_axis():
    planner = SkidpadPlanner(start_pose=(0.0, 0.0, np.pi / 2))
    path = planner.plan(np.zeros((0, 2)), np.zeros(0, int))
    assert planner.centres is None and np.allclose(path[:, 0], 0.0) and path[-1, 1] > 15.0
    with pytest.raises(ValueError, match="inner_radius"):
        SkidpadConfig(inner_radius=12.0)


@pytest.mark.slow
@pytest.mark.parametrize("noise", [{}, {"range_noise": 0.05, "bearing_noise": 0.01, "miss_prob": 0.2}])
def test_stack_drives_the_shipped_skidpad(noise):
    track = load_track("skidpad")
    agent = AGENTS.get("mapper_pure_pursuit")(track, CameraConfig())
    assert agent.mission == "skidpad"  # from track.event
    r = drive(track, agent, perception=SyntheticCones(track, seed=2, **noise),
              odometry={"scale_error": 0.005, "gyro_bias": 0.002}, max_t=90.0)
    assert r["completed"] and r["min_margin"] > 0.0, r


def test_stack_drives_the_acceleration_event():
    track = load_track("acceleration")
    agent = AGENTS.get("mapper_pure_pursuit")(track, CameraConfig())
    r = drive(track, agent, perception=SyntheticCones(track, seed=2), max_t=30.0)
    assert r["completed"] and r["min_margin"] > 0.5, r
