"""Gymnasium's and stable-baselines3's env checkers pass on every registered id, raw and wrapped
(weather, detector, ground-truth cones), headless (render_mode="human" without a display included).

``check_env`` resets and steps twice with the same seed and compares everything, info included:
wall-clock latencies are therefore not in ``info`` (``wrapper.latency_ms`` has them).
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import weather_gym
from weather_gym.envs.registration import register_envs

CAMERA = {"width": 160, "height": 90}
IDS = sorted(register_envs())


def _small(env_id: str) -> dict:
    return {} if env_id == "WeatherGym/ConeTrackCones-v0" else {"camera": CAMERA}


@pytest.fixture(autouse=True)
def _headless(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_on_every_registered_id(env_id):
    env = gym.make(env_id, **_small(env_id))
    try:
        with pytest.warns(RuntimeWarning, match="needs a display"):  # the "human" mode, checked headless
            check_env(env.unwrapped)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            check_env(env)  # as gym.make returns it: the spec rebuilds the stack
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("kwargs", [
    {"weather": "droplets@3", "perception": "detector"},
    {"weather": {"dim": 0.5, "droplets": 0.3}, "perception": "oracle", "perception_kwargs": {"miss_prob": 0.2}},
    {"perception": "gt_cones", "perception_kwargs": {"range_noise": 0.05}},
], ids=["weather+detector", "weather+oracle", "gt_cones+noise"])
def test_check_env_passes_wrapped(kwargs):
    env = gym.make("WeatherGym/ConeTrack-v0", camera=CAMERA, **kwargs)
    try:
        with pytest.warns(RuntimeWarning, match="needs a display"):
            check_env(env)
    finally:
        env.close()


@pytest.mark.parametrize("kwargs", [{"perception": "gt_cones"}, {"perception": "detector", "weather": "low_light@1"}])
def test_stable_baselines3_check_env_passes(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("WeatherGym/ConeTrack-v0", camera=CAMERA, **kwargs)
    try:
        sb3_check_env(env, warn=False)
    finally:
        env.close()


# -- Gymnasium conventions: every stack records its wrappers, so check_env and gym.make(env.spec) work --

STACKS = {
    "gt_cones": {"perception": "gt_cones"},
    "surrogate": {"perception": "surrogate", "weather": "droplets@1"},
    "camera": {"camera": CAMERA},
    "camera+weather": {"camera": CAMERA, "weather": "rain@2"},
    "oracle+noise": {"camera": CAMERA, "perception": "oracle", "perception_kwargs": {"miss_prob": 0.2}},
    "detector": {"camera": CAMERA, "perception": "detector"},
}


def _same_observations(env_a, env_b, steps: int = 3) -> bool:
    from gymnasium.utils.env_checker import data_equivalence

    action = np.full(env_a.action_space.shape, 0.3, np.float32)
    obs_a, _ = env_a.reset(seed=5)
    obs_b, _ = env_b.reset(seed=5)
    same = data_equivalence(obs_a, obs_b, exact=True)
    for _ in range(steps):
        same = same and data_equivalence(env_a.step(action)[0], env_b.step(action)[0], exact=True)
    return same


@pytest.mark.slow
@pytest.mark.parametrize("kwargs", list(STACKS.values()), ids=list(STACKS))
def test_check_env_and_spec_rebuild_on_every_make_env_stack(kwargs):
    env = weather_gym.make_env(**kwargs)
    rebuilt = None
    try:
        assert all(w.kwargs is not None for w in env.spec.additional_wrappers)  # every wrapper recorded
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "not the unwrapped env", "needs a display" (human mode, headless)
            check_env(env)
        rebuilt = gym.make(env.spec)
        assert rebuilt.spec.additional_wrappers == env.spec.additional_wrappers
        assert _same_observations(env, rebuilt)
    finally:
        env.close()
        if rebuilt is not None:
            rebuilt.close()


def test_hand_applied_wrappers_rebuild_from_the_spec(tmp_path):
    from weather_gym.wrappers import EpisodeStatistics, RecordVideo, WeatherRandomizer

    env = WeatherRandomizer(weather_gym.make_env(camera=CAMERA, perception="detector", render_mode="rgb_array"),
                            presets=("rain", "fog"), severities=(1, 2))
    env = RecordVideo(EpisodeStatistics(env, info_key="ep"), tmp_path, episode_trigger=lambda e: False)
    env2 = gym.make("WeatherGym/ConeTrackCones-v0", render_mode="rgb_array")
    env2 = RecordVideo(env2, tmp_path, episode_trigger=lambda e: False)
    names = [w.name for w in env.spec.additional_wrappers]
    assert names == ["WeatherWrapper", "DetectorWrapper", "EpisodeStatistics", "WeatherRandomizer",
                     "EpisodeStatistics", "RecordVideo"]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for e in (env, env2):  # RecordVideo takes rgb_array only: no render-mode round
                check_env(e, skip_render_check=True)
        for e in (env, env2):
            rebuilt = gym.make(e.spec)
            try:
                assert _same_observations(e, rebuilt)
            finally:
                rebuilt.close()
    finally:
        env.close()
        env2.close()


def test_weather_wrapper_on_gymnasium_car_racing():
    pytest.importorskip("Box2D", reason="CarRacing needs box2d (the dev extra)")
    pytest.importorskip("pygame", reason="CarRacing needs pygame (the dev extra)")
    from weather_gym.wrappers import WeatherWrapper

    env = WeatherWrapper(gym.make("CarRacing-v3"), "droplets:0.5")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            check_env(env, skip_render_check=True)
        rebuilt = gym.make(env.spec)
        assert _same_observations(env, rebuilt, steps=2)
        rebuilt.close()
    finally:
        env.close()


def test_a_detector_or_surrogate_model_object_rebuilds_from_the_spec():
    from weather_gym.perception import load_detector
    from weather_gym.surrogate.model import load_model

    for kwargs in ({"camera": CAMERA, "perception": "detector", "detector": load_detector(None)},
                   {"perception": "surrogate", "weather": "low_light@1", "perception_kwargs": {"model": load_model(None)}}):
        env = weather_gym.make_env(**kwargs)
        rebuilt = gym.make(env.spec)  # the recorded object equals its copy (weather_gym.wrappers._recorded)
        try:
            assert _same_observations(env, rebuilt, steps=1)
        finally:
            env.close()
            rebuilt.close()


@pytest.mark.parametrize(("kwargs", "bad"), [
    ({}, {"bogus": 1}),
    ({}, {"friction": -1}),
    ({"weather": "droplets:0.3"}, {"weather": "droplets:0.5:k=0.7"}),
])
def test_a_refused_first_reset_leaves_the_env_usable_and_checked(kwargs, bad):
    """Gymnasium's checker marks its reset check done before the reset runs; a refused first reset then
    broke the first step after a valid reset (TypeError inside Gymnasium). The ids' checker does not."""
    from weather_gym.core.errors import InputError
    from weather_gym.envs.checker import PassiveEnvCheckerSafeReset

    env = gym.make("WeatherGym/ConeTrackSmall-v0", camera=CAMERA, **kwargs)
    try:
        checker = env
        while not isinstance(checker, gym.wrappers.PassiveEnvChecker):
            checker = checker.env
        assert isinstance(checker, PassiveEnvCheckerSafeReset)
        with pytest.raises(InputError):
            env.reset(seed=0, options=bad)
        assert not checker.checked_reset  # the next reset is checked instead
        obs, _ = env.reset(seed=0)
        assert checker.checked_reset
        for _ in range(2):
            env.step(env.action_space.sample())
        assert checker.checked_step
        with pytest.raises(InputError):  # a refused later reset: usable too
            env.reset(seed=1, options=bad)
        env.reset(seed=1)
        env.step(env.action_space.sample())
    finally:
        env.close()
