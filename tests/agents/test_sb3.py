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


def test_a_saved_model_drives_with_the_cone_memory_its_sidecar_records(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    env = ConeListEnv()
    sb3.PPO("MultiInputPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu").save(tmp_path / "m")
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip").memory is None  # no sidecar: none
    (tmp_path / "m.json").write_text(json.dumps({"env_id": "x", "cone_memory": {"max_age": 7}}))
    agent = AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    assert agent.memory.config.max_age == 7
    obs, _ = env.reset(seed=0)
    agent.reset(seed=0)
    assert agent.act(obs).shape == (2,)
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_memory=False).memory is None
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_memory=True).memory.config.max_age == 30
    (tmp_path / "m.json").write_text("{")
    with pytest.raises(ValueError, match=r"m\.json"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    (tmp_path / "m.json").write_text(json.dumps({"cone_memory": {"max_agee": 7}}))
    with pytest.raises(ValueError, match=r"m\.json: cone_memory: unknown .*max_agee"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    (tmp_path / "m.json").write_text(json.dumps({"cone_memory": "yes"}))
    with pytest.raises(ValueError, match=r"m\.json: cone_memory must be a table"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    with pytest.raises(ValueError, match="cone_memory must be"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_memory="yes")


def test_a_saved_model_drives_with_the_cone_shield_its_sidecar_records(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    env = ConeListEnv()
    sb3.PPO("MultiInputPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu").save(tmp_path / "m")
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip").shield is None  # no sidecar: none
    (tmp_path / "m.json").write_text(json.dumps({"env_id": "x", "cone_shield": {"margin": 0.25}}))
    agent = AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    assert agent.shield.config.margin == 0.25
    obs, _ = env.reset(seed=0)
    agent.reset(seed=0)
    assert agent.act(obs).shape == (2,) and agent.shield.interventions >= 0
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_shield=False).shield is None
    assert AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_shield=True).shield.config.margin == 0.15
    (tmp_path / "m.json").write_text(json.dumps({"cone_shield": {"marginn": 0.2}}))
    with pytest.raises(ValueError, match=r"m\.json: cone_shield: unknown .*marginn"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip")
    with pytest.raises(ValueError, match="cone_shield must be"):
        AGENTS.get("sb3")(None, None, path=tmp_path / "m.zip", cone_shield="yes")


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
