"""The perception-only stack (mapper + planner + pure pursuit) closed loop on synthetic cone lists."""

from __future__ import annotations

import numpy as np
import pytest
from agent_sim import SyntheticCones, drive

from weather_gym.agents import AGENTS, Agent
from weather_gym.camera.config import CameraConfig
from weather_gym.tracks import load_track

DRIFT = {"scale_error": 0.005, "gyro_bias": 0.002}  # about the env's odometry errors


class NoPeeking(dict):
    """An info dict that fails the test if the agent reads anything from it."""

    def _fail(self, *args, **kwargs):
        raise AssertionError("a perception agent read ground truth from info")

    __getitem__ = get = __contains__ = keys = items = values = __iter__ = _fail


def _drive_stack(track_name, laps, perception_kwargs=None, seed=1, odometry=DRIFT):
    track = load_track(track_name)
    agent = AGENTS.get("mapper_pure_pursuit")(track, CameraConfig())
    assert isinstance(agent, Agent)
    per = SyntheticCones(track, seed=seed, **(perception_kwargs or {}))
    blind = _Blindfold(agent)
    return drive(track, blind, laps=laps, perception=per, odometry=odometry, max_t=120.0), agent


class _Blindfold:
    """Hands the agent a poisoned info so any ground-truth read fails."""

    def __init__(self, agent):
        self.agent = agent

    def reset(self, seed=None, info=None):
        self.agent.reset(seed=seed, info=NoPeeking())

    def act(self, obs, info=None):
        return self.agent.act(obs, NoPeeking())


@pytest.mark.parametrize("track_name,laps", [("small_track", 1), ("hairpin", 2), ("random:3", 1)])
def test_stack_completes_laps_with_perfect_perception(track_name, laps):
    r, agent = _drive_stack(track_name, laps)
    assert r["completed"], f"{track_name}: not completed in {r['time']:.0f} s"
    assert r["min_margin"] > 0.2, f"{track_name}: car within {r['min_margin']:.2f} m of the cone line"
    summary = agent.last_map.summary()
    assert summary["confirmed"] > 10 and summary["mean_class_confidence"] == 1.0


def test_stack_survives_noisy_perception():
    """5 % range noise, 0.01 rad bearing noise, 20 % missed cones and a phantom cone every 2 frames."""
    noise = {"range_noise": 0.05, "bearing_noise": 0.01, "miss_prob": 0.2, "false_per_frame": 0.5}
    r, agent = _drive_stack("small_track", 1, noise, odometry={})  # exact odometry: map frame = track frame
    assert r["completed"] and r["min_margin"] > 0.2, r
    # about 300 phantom detections were made, yet every confirmed cone is a real one
    track = load_track("small_track")
    m = agent.mapper.map(confirmed_only=True)
    d = np.hypot(*(m.xy[:, None, :] - track.cones_xy[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    # nearly all within 0.5 m of a real cone, none beyond the association gate (1.5 m): a real cone seen
    # only from 15-20 m, where the 5 % range noise is 0.75-1 m, may be mapped a metre off (the last cones
    # of the lap are mapped afresh after assoc_max_age; one was 1.06 m off with the 20 m range limit)
    assert len(m) > 40 and d.max() < 1.5, f"{np.sum(d >= 1.5)} confirmed cones are not real"
    assert np.mean(d < 0.5) > 0.95, f"only {np.mean(d < 0.5):.0%} of the confirmed cones within 0.5 m"


def test_stack_waits_when_nothing_is_mapped_and_validates_obs():
    agent = AGENTS.get("mapper_pure_pursuit")(None, CameraConfig())
    agent.reset()
    empty = {"cones": np.zeros((64, 14), np.float32), "mask": np.zeros(64, np.int8),
             "state": np.array([3.0, 0, 0, 0, 0], np.float32)}
    assert agent.act(empty).tolist() == [0.0, -1.0]  # rolling and blind: brake
    with pytest.raises(ValueError, match="cones"):
        agent.act({"state": empty["state"]})
    with pytest.raises(ValueError, match="unknown option"):
        AGENTS.get("mapper_pure_pursuit")(None, CameraConfig(), speed=3)
    with pytest.raises(ValueError, match="unknown mission 'autox'"):
        AGENTS.get("mapper_pure_pursuit")(None, CameraConfig(), mission="autox")


def test_stack_is_deterministic():
    a, _ = _drive_stack("hairpin", 1, {"miss_prob": 0.3}, seed=7)
    b, _ = _drive_stack("hairpin", 1, {"miss_prob": 0.3}, seed=7)
    assert a == b
