"""The training examples: per-episode random presets, and a PPO smoke run through ``evaluate``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _Recorder(gym.Env):
    """Records the options of every reset."""

    observation_space = gym.spaces.Box(0, 1, (1,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (2,), np.float32)

    def __init__(self):
        self.options = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.options.append(options)
        return np.zeros(1, np.float32), {}


def test_random_preset_weather_is_seeded_and_varies_per_episode():
    train = _load("train_ppo")

    def presets(seed):
        env = train.RandomPresetWeather(_Recorder(), ("droplets", "dim"), (0, 2, 4))
        out = [env.reset(seed=seed)[1]["preset"]] + [env.reset()[1]["preset"] for _ in range(11)]
        assert [o["weather"] for o in env.env.options] == out
        return out

    a, b = presets(3), presets(3)
    assert a == b  # same seed, same sequence of presets
    assert presets(4) != a
    assert {c for c, _ in a} == {"droplets", "low_light"} and len({s for _, s in a}) > 1
    with pytest.raises(ValueError, match="invalid severity 9"):
        train.RandomPresetWeather(_Recorder(), ("dim",), (9,))


@pytest.mark.slow
def test_ppo_smoke_train_then_evaluate(tmp_path):
    pytest.importorskip("stable_baselines3")
    train, evaluate_policy = _load("train_ppo"), _load("evaluate_policy")
    model = tmp_path / "ppo.zip"
    assert train.main(["--timesteps", "2048", "--n-envs", "2", "--vec", "dummy", "--perception", "oracle",
                       "--camera", "96x54", "--n-steps", "256", "--batch-size", "128", "--n-epochs", "2",
                       "--max-steps", "150", "--out", str(model)]) == 0
    meta = json.loads(model.with_suffix(".json").read_text())
    assert meta["perception"] == "oracle" and meta["env_kwargs"] == {"camera": {"width": 96, "height": 54}}

    from weather_gym.evaluation.evaluate import evaluate

    config = evaluate_policy.config_for_model(model, effects=["dim"], severities=[0, 4], seeds=[0], max_steps=40)
    rows = evaluate(config, tmp_path / "eval", backend="serial", progress=False)
    assert [(r["agent"], r["severity"], r["status"], r["steps"]) for r in rows] == [
        ("sb3", 0, "ok", 40), ("sb3", 4, "ok", 40)]
    assert (tmp_path / "eval" / "report.md").exists()
