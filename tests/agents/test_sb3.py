"""The ``sb3`` adapter: a stable-baselines3 policy behind the Agent protocol."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from weather_gym.agents import AGENTS, Agent
from weather_gym.perception.cones import cone_list_space


class ConeListEnv(gym.Env):
    """A stand-in with the perception agents' observation and the car's action space."""

    def __init__(self):
        space = dict(cone_list_space(8).spaces)
        space["state"] = gym.spaces.Box(-np.inf, np.inf, (5,), np.float32)
        self.observation_space = gym.spaces.Dict(space)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


def test_sb3_model_and_saved_zip_drive_through_the_protocol(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    env = ConeListEnv()
    model = sb3.PPO("MultiInputPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu")
    obs, _ = env.reset(seed=0)
    agent = AGENTS.get("sb3")(None, None, model=model)
    assert isinstance(agent, Agent)
    agent.reset(seed=0)
    a = agent.act(obs, {})
    assert a.dtype == np.float32 and a.shape == (2,) and np.all(np.abs(a) <= 1)
    model.save(tmp_path / "policy")
    loaded = AGENTS.get("sb3")(None, None, path=str(tmp_path / "policy"), algo="PPO")
    assert np.array_equal(loaded.act(obs), a)  # deterministic: same weights, same action


@pytest.mark.parametrize(("key", "attr", "field", "recorded", "default"),
                         [("cone_memory", "memory", "max_age", 7, 30), ("cone_shield", "shield", "margin", 0.25, 0.15)])
def test_a_saved_model_drives_with_what_its_sidecar_records(tmp_path, key, attr, field, recorded, default):
    """The cone memory and the cone shield: read from the model's JSON, overridden by the keyword."""
    sb3 = pytest.importorskip("stable_baselines3")
    env = ConeListEnv()
    sb3.PPO("MultiInputPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu").save(tmp_path / "m")
    model = tmp_path / "m.zip"
    assert getattr(AGENTS.get("sb3")(None, None, path=model), attr) is None  # no sidecar: none
    (tmp_path / "m.json").write_text(json.dumps({"env_id": "x", key: {field: recorded}}))
    agent = AGENTS.get("sb3")(None, None, path=model)
    assert getattr(getattr(agent, attr).config, field) == recorded
    obs, _ = env.reset(seed=0)
    agent.reset(seed=0)
    assert agent.act(obs).shape == (2,)
    assert getattr(AGENTS.get("sb3")(None, None, path=model, **{key: False}), attr) is None
    assert getattr(getattr(AGENTS.get("sb3")(None, None, path=model, **{key: True}), attr).config, field) == default
    (tmp_path / "m.json").write_text("{")
    with pytest.raises(ValueError, match=r"m\.json"):
        AGENTS.get("sb3")(None, None, path=model)
    (tmp_path / "m.json").write_text(json.dumps({key: {field + "x": recorded}}))
    with pytest.raises(ValueError, match=rf"m\.json: {key}: unknown .*{field}x"):
        AGENTS.get("sb3")(None, None, path=model)
    (tmp_path / "m.json").write_text(json.dumps({key: "yes"}))
    with pytest.raises(ValueError, match=rf"m\.json: {key} must be a table"):
        AGENTS.get("sb3")(None, None, path=model)
    with pytest.raises(ValueError, match=f"{key} must be"):
        AGENTS.get("sb3")(None, None, path=model, **{key: "yes"})


def test_sb3_adapter_errors(tmp_path):
    with pytest.raises(ValueError, match="exactly one"):
        AGENTS.get("sb3")(None, None)
    with pytest.raises(FileNotFoundError, match="not found"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "nope.zip")
    (tmp_path / "m.zip").write_bytes(b"")
    with pytest.raises(ValueError, match="unknown algo"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", algo="DQN")

    class Wrong:
        def predict(self, obs, state=None, deterministic=True):
            return np.zeros(3), None

    with pytest.raises(ValueError, match="shape"):
        AGENTS.get("sb3")(None, None, model=Wrong()).act({})
