"""The time limit is simulated seconds (``max_episode_s``), so it follows the control rate."""

from __future__ import annotations

import gymnasium as gym
import pytest

import weather_gym
from weather_gym.envs.scenario import load_scenario, scenario_files


def test_registered_limits_are_100_s_at_the_scenario_rate():
    for path in scenario_files():
        sc = load_scenario(path)
        assert sc.max_episode_s == 100.0 and sc.max_episode_steps == round(100.0 * sc.control_hz)
        assert gym.spec(sc.env_id).max_episode_steps == sc.max_episode_steps
    assert gym.spec("WeatherGym/ConeTrack-v0").max_episode_steps == 3000  # 30 Hz: as before


@pytest.mark.parametrize(("kwargs", "steps"), [
    ({}, 3000),
    ({"sim": {"control_hz": 60}}, 6000),
    ({"sim": {"control_hz": 15}}, 1500),
    ({"max_episode_s": 10}, 300),
    ({"max_episode_s": 10, "sim": {"control_hz": 60}}, 600),
    ({"max_episode_steps": 77, "sim": {"control_hz": 60}}, 77),
])
def test_make_env_time_limit_follows_the_control_rate(kwargs, steps):
    env = weather_gym.make_env(perception="gt_cones", **kwargs)
    try:
        assert env.spec.max_episode_steps == steps
    finally:
        env.close()


def test_the_limit_truncates_at_the_simulated_time():
    env = weather_gym.make_env(perception="gt_cones", max_episode_s=0.1, sim={"control_hz": 60})
    try:
        env.reset(seed=0)
        flags = [env.step(env.action_space.sample() * 0)[3] for _ in range(6)]
        assert flags == [False] * 5 + [True]
    finally:
        env.close()


def test_bad_time_limits_are_refused(tmp_path):
    with pytest.raises(ValueError, match="max_episode_steps or max_episode_s, not both"):
        weather_gym.make_env(perception="gt_cones", max_episode_steps=5, max_episode_s=1.0)
    with pytest.raises(ValueError, match="max_episode_s must be a number of seconds > 0"):
        weather_gym.make_env(perception="gt_cones", max_episode_s=0)
    both = tmp_path / "both.toml"
    both.write_text('id = "WeatherGym/Both-v0"\n[env]\nmax_episode_s = 10\nmax_episode_steps = 300\n')
    with pytest.raises(ValueError, match="give max_episode_s or max_episode_steps, not both"):
        load_scenario(both)
    bad = tmp_path / "bad.toml"
    bad.write_text('id = "WeatherGym/Bad-v0"\n[env]\nmax_episode_s = -1\n')
    with pytest.raises(ValueError, match=r"bad.toml \[env\]: max_episode_s must be a number of seconds > 0"):
        load_scenario(bad)
    steps = tmp_path / "steps.toml"  # steps at the scenario's rate: the same seconds at any other
    steps.write_text('id = "WeatherGym/Steps-v0"\n[env]\nmax_episode_steps = 900\n[sim]\ncontrol_hz = 60\n'
                     'physics_hz = 240\n')
    sc = load_scenario(steps)
    assert sc.max_episode_s == 15.0 and sc.max_episode_steps == 900
