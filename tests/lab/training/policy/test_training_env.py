"""The envs of a PPO run: ``LeanInfo`` passes on only the info entries SB3 reads, nothing else changes."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.lab.training.policy.training_env import INFO_KEYS, LeanInfo, make_training_env


def _run(env, steps: int = 120):
    obs, info = env.reset(seed=3)
    out = [(obs, 0.0, False, False, info)]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        out.append(env.step(rng.uniform(-1, 1, 2).astype(np.float32)))
        if out[-1][2] or out[-1][3]:
            break
    env.close()
    return out


def test_lean_info_keeps_the_observations_and_only_the_keys_sb3_reads():
    args = ("WeatherGym/ConeTrack-v0", "hairpin", "surrogate", {}, 120, {})
    full = _run(make_training_env(*args, surrogate_weather="droplets@2"))
    lean = _run(make_training_env(*args, surrogate_weather="droplets@2", lean_info=True))
    assert len(full) == len(lean) > 1
    for (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) in zip(full, lean, strict=True):
        assert sorted(o1) == sorted(o2) and all(o1[k].tobytes() == o2[k].tobytes() for k in o1)
        assert (r1, te1, tr1) == (r2, te2, tr2)
        assert set(i2) <= set(INFO_KEYS) and i2 == {k: i1[k] for k in INFO_KEYS if k in i1}
    assert "gt" in full[-1][4] and "is_success" in lean[-1][4]  # the episode ended: LapSuccess's flag kept


def test_lean_info_records_its_arguments_and_refuses_bad_keys():
    env = LeanInfo(make_training_env("WeatherGym/ConeTrack-v0", "hairpin", "gt_cones", {}, 10, {}), keys=("lap",))
    try:
        assert env._saved_kwargs == {"keys": ("lap",)}
        assert env.reset(seed=0)[1] == {"lap": 0}
    finally:
        env.close()
    with pytest.raises(InputError, match="keys"):
        LeanInfo(env, keys="lap")


def test_remembered_cones_is_the_cone_memory_an_agent_applies_and_passes_the_checker():
    from gymnasium.utils.env_checker import check_env

    from weather_gym.agents.cone_memory import ConeMemory, ConeMemoryConfig
    from weather_gym.lab.training.policy.training_env import RememberedCones

    args = ("WeatherGym/ConeTrack-v0", "peanut", "surrogate", {}, 90, {})
    plain = _run(make_training_env(*args, surrogate_weather="droplets@3"), steps=90)
    remembered = _run(make_training_env(*args, surrogate_weather="droplets@3", cone_memory={"max_age": 20}),
                      steps=90)
    memory = ConeMemory(ConeMemoryConfig(max_age=20))
    added = 0
    for (o1, *_), (o2, *_) in zip(plain, remembered, strict=True):  # the same episode: only the list differs
        expected = memory(o1)
        assert all(expected[k].tobytes() == o2[k].tobytes() for k in o2)
        added += int(o2["mask"].sum() - o1["mask"].sum())
    assert added > 0  # a drive of 3 s at droplets S3 misses cones the memory still holds
    again = _run(make_training_env(*args, surrogate_weather="droplets@3", cone_memory={"max_age": 20}), steps=90)
    assert all(a[0][k].tobytes() == b[0][k].tobytes() for a, b in zip(remembered, again, strict=True) for k in a[0])

    env = make_training_env(*args, cone_memory={}, random_start=False)
    try:
        wrapper = env
        while not isinstance(wrapper, RememberedCones):
            wrapper = wrapper.env
        assert wrapper._saved_kwargs == {"config": ConeMemoryConfig()}  # gym.make(env.spec) rebuilds it
        check_env(env)  # resets forget: the same seed gives the same observations
    finally:
        env.close()
    with pytest.raises(InputError, match="max_ages"):
        make_training_env(*args, cone_memory={"max_ages": 3})
