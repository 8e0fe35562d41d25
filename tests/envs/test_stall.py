"""Episode starts and the stall rule: ``random_start`` puts a share of the starts beside the start line;
``stall_s`` ends an episode in which the car stands (with a penalty), never one in which it drives."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import drive_gt
from weather_gym.core.errors import InputError
from weather_gym.envs import END_REASONS, EnvConfig
from weather_gym.envs.config import RewardConfig

CONES = "WeatherGym/ConeTrackCones-v0"
STALL = {"stall_s": 3.0}
STEPS_3S = 90  # stall_s = 3 s at 30 Hz


def _run(env, action, steps: int, seed: int = 0):
    env.reset(seed=seed)
    total = 0.0
    for n in range(1, steps + 1):
        _, r, terminated, truncated, info = env.step(np.asarray(action, np.float32))
        total += r
        if terminated or truncated:
            return n, total, terminated, info
    return steps, total, False, info


@pytest.mark.parametrize("pedal", [0.0, -1.0])
def test_a_car_that_stands_at_the_start_line_stalls_after_3_s_with_the_penalty(make_env, pedal):
    env = make_env(CONES, **STALL)
    n, total, terminated, info = _run(env, [0.0, pedal], 300)
    assert (n, terminated, info["end_reason"]) == (STEPS_3S, True, "stalled")
    assert total == pytest.approx(-10.0)  # no progress, the stall penalty
    assert "stalled" in END_REASONS


def test_a_constant_forward_action_leaves_the_start_line_without_stalling(make_env):
    env = make_env(CONES, **STALL)
    n, total, terminated, info = _run(env, [0.0, 0.3], 2 * STEPS_3S)
    assert info["progress"] > 5.0, f"{info['progress']:.2f} m in {n} steps"
    assert info.get("end_reason") != "stalled"
    assert total > 0


def test_a_car_that_stops_mid_episode_stalls(make_env):
    env = make_env(CONES, **STALL)
    env.reset(seed=0)
    for _ in range(30):  # 1 s of throttle, then full brake
        env.step(np.array([0.0, 0.5], np.float32))
    braking = 0
    while braking < 300:
        _, r, terminated, _, info = env.step(np.array([0.0, -1.0], np.float32))
        braking += 1
        if terminated:
            break
    assert info["end_reason"] == "stalled" and info["speed"] == 0.0
    assert STEPS_3S - 30 < braking < 2 * STEPS_3S
    assert r < -9.0


def test_by_default_an_episode_never_stalls(make_env):
    env = make_env(CONES)
    n, total, terminated, info = _run(env, [0.0, 0.0], 2 * STEPS_3S)
    assert (n, total, terminated) == (2 * STEPS_3S, 0.0, False)


def test_the_ground_truth_driver_laps_without_stalling(make_env):
    env = make_env(CONES, **STALL)
    steps, info, _ = drive_gt(env, seed=0, max_steps=3000)
    assert info["lap"] == 1 and info["end_reason"] == "laps", (steps, info.get("end_reason"))


@pytest.mark.parametrize("field, value", [("stall_s", -1.0), ("stall_s", float("nan")), ("stall_m", "1"),
                                          ("stall_s", True)])
def test_bad_stall_settings_are_input_errors(field, value):
    with pytest.raises(InputError, match=f"EnvConfig.{field}"):
        EnvConfig(**{field: value})
    with pytest.raises(InputError, match="RewardConfig.stall"):
        RewardConfig(stall=float("inf"))


def _start_s(env, seed: int, options: dict | None = None) -> float:
    return float(env.reset(seed=seed, options=options)[1]["s"])


def test_random_start_share_of_start_line_episodes(make_env):
    env = make_env(CONES, random_start=0.75)
    line = _start_s(make_env(CONES), 0)
    starts = [_start_s(env, seed) for seed in range(40)]
    at_line = sum(s == pytest.approx(line, abs=1e-6) for s in starts)
    assert 4 <= at_line <= 18  # about a quarter start where an evaluation starts (10 expected)
    length = env.unwrapped.track.length
    others = [s for s in starts if s > 1.0]
    assert min(others) < 0.25 * length and max(others) > 0.75 * length  # the rest anywhere on the track
    assert starts[:5] == [_start_s(env, seed) for seed in range(5)]  # the seed decides


def test_random_start_defaults_off_and_yields_to_explicit_options(make_env):
    env = make_env(CONES)
    assert {_start_s(env, seed) for seed in range(10)} == {_start_s(env, 0)}
    env = make_env(CONES, random_start=1.0)
    assert _start_s(env, 3, {"start_s": 40.0}) == pytest.approx(40.0, abs=0.05)


def test_random_start_on_an_open_track_keeps_the_start_line(make_env):
    env = make_env(CONES, track="acceleration", random_start=1.0)
    assert {_start_s(env, seed) for seed in range(5)} == {_start_s(env, 0)}


@pytest.mark.parametrize("value", [-0.1, 1.5, True, "0.5"])
def test_bad_random_start_is_an_input_error(value):
    with pytest.raises(InputError, match="EnvConfig.random_start"):
        EnvConfig(random_start=value)
