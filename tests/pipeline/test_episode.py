"""The one episode driver: run_episode -> EpisodeResult, one set of end reasons, TimeLimit owns truncation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import SMALL_CAMERA
from weather_gym.agents import make_agent
from weather_gym.envs import END_REASONS
from weather_gym.pipeline import make_env
from weather_gym.pipeline.episode import EpisodeResult, run_episode


class Constant:
    def __init__(self, action):
        self.action = np.asarray(action, np.float32)

    def reset(self, seed=None, info=None):
        pass

    def act(self, obs, info=None):
        return self.action


def test_a_lap_ends_with_laps_and_its_statistics():
    env = make_env(perception="gt_cones", track="hairpin", max_episode_steps=2000)
    seen = []
    try:
        agent = make_agent("gt_pure_pursuit", env.unwrapped.track, env.unwrapped.config.camera)
        r = run_episode(env, agent, seed=0, on_step=lambda step, obs, info, done: seen.append((step, done)))
    finally:
        env.close()
    assert isinstance(r, EpisodeResult) and r.end_reason == "laps" and r.completed
    assert r.laps_completed == 1 and len(r.lap_times_s) == 1 and 5.0 < r.lap_times_s[0] < 60.0
    assert r.progress == pytest.approx(1.0, abs=0.02) and r.cones_hit == 0 and r.off_track_events == 0
    assert r.steps == len(seen) - 1 and seen[0] == (0, False) and seen[-1] == (r.steps, True)
    assert r.sim_time_s == pytest.approx(r.steps / 30.0) and r.episode_return > 0
    assert r.weather_latency_ms == 0.0 and r.detector_latency_ms == 0.0
    assert set(r.to_dict()) >= {"end_reason", "lap_times_s", "wall_time_s"}


def test_time_limit_and_off_track_end_reasons():
    env = make_env(perception="gt_cones", track="acceleration", max_episode_steps=20)
    try:
        r = run_episode(env, Constant([0.0, 0.2]), seed=0)
        assert (r.end_reason, r.steps, r.completed) == ("time_limit", 20, False)
    finally:
        env.close()
    env = make_env(perception="gt_cones", track="acceleration", max_episode_steps=600)
    try:
        r = run_episode(env, Constant([1.0, 0.6]), seed=0)
        assert r.end_reason == "off_track" and r.off_track_events == 1 and not r.completed
    finally:
        env.close()
    assert {"laps", "off_track", "stalled", "time_limit"} == set(END_REASONS)


def test_the_time_limit_belongs_to_gymnasium_and_can_be_longer_than_the_scenario():
    env = make_env(perception="gt_cones", track="acceleration", laps=0, terminate_off_track=False,
                   max_episode_steps=3100)
    try:
        assert env.spec.max_episode_steps == 3100  # the scenario registers 3000
        r = run_episode(env, Constant([0.3, -1.0]), seed=0)
        assert (r.end_reason, r.steps) == ("time_limit", 3100)
    finally:
        env.close()


def test_the_driver_needs_a_time_limit_and_reports_the_weather_latency():
    from weather_gym.envs import ConeTrackEnv, EnvConfig

    raw = ConeTrackEnv(EnvConfig(camera=SMALL_CAMERA))
    try:
        with pytest.raises(ValueError, match="time limit"):
            run_episode(raw, Constant([0.0, 0.0]))
    finally:
        raw.close()
    env = make_env(weather="droplets@3", camera=SMALL_CAMERA, max_episode_steps=5)
    try:
        r = run_episode(env, Constant([0.0, 0.3]), seed=1)
        assert r.weather_latency_ms > 0 and r.detector_latency_ms == 0
    finally:
        env.close()


def test_a_bad_action_names_the_agent():
    env = make_env(perception="gt_cones", max_episode_steps=5)
    try:
        with pytest.raises(ValueError, match="agent 'wobbly' returned"):
            run_episode(env, Constant([2.0, 0.0]), agent_name="wobbly")
    finally:
        env.close()
