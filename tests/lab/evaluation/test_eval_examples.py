"""The training examples: per-episode random presets, and a PPO smoke run through ``evaluate``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _Track:
    closed, length = True, 100.0


class _Recorder(gym.Env):
    """Records the options of every reset."""

    observation_space = gym.spaces.Box(0, 1, (1,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (2,), np.float32)
    track = _Track()

    def __init__(self):
        self.options = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.options.append(options)
        return np.zeros(1, np.float32), {}


def test_random_start_is_seeded_and_varies_per_episode():
    train = _load("train_ppo")

    def starts(seed):
        env = train.RandomStart(_Recorder(), line_share=0.0)  # every episode from a random point
        out = [env.reset(seed=seed)[1]["start_s"]] + [env.reset()[1]["start_s"] for _ in range(9)]
        assert [o["start_s"] for o in env.env.options] == out
        return out

    a = starts(3)
    assert a == starts(3) and a != starts(4)  # same seed, same starts
    assert all(0 <= s < 100 for s in a) and len(set(a)) == 10


@pytest.mark.slow
def test_ppo_trains_on_gt_cones_resumes_and_drives_through_the_detector(tmp_path):
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("weather_gym.pipeline", reason="the render-free gt_cones mode comes with the pipeline builder")
    train, evaluate_policy = _load("train_ppo"), _load("evaluate_policy")
    out = tmp_path / "run"
    common = ["--n-envs", "2", "--track", "hairpin,oval", "--n-steps", "128", "--batch-size", "64",
              "--n-epochs", "1", "--max-steps", "150", "--eval-freq", "256", "--eval-episodes", "1",
              "--checkpoint-freq", "256", "--pretrain", "none", "--perception", "gt_cones",
              "--eval-track", "small_track", "--eval-weathers", "clear", "--eval-perception", "gt_cones",
              "--out", str(out)]
    assert train.main(["--timesteps", "512", *common]) == 0
    assert train.main(["--timesteps", "512", *common]) == 2  # never overwrites a run
    assert sorted(p.name for p in (out / "checkpoints").glob("*.zip")) == ["ppo_256_steps.zip", "ppo_512_steps.zip"]
    (out / "checkpoints" / "ppo_512_steps.zip").unlink()  # as if it had stopped after 256 steps
    assert train.main(["--timesteps", "768", "--resume", *common]) == 0
    run = json.loads((out / "run.json").read_text())
    assert [(s["from_steps"], s["to_steps"]) for s in run["segments"]] == [(0, 512), (256, 768)]
    assert len(list((out / "logs").glob("*/progress.csv"))) == 2
    assert list((out / "logs").glob("*/events.out.tfevents*"))  # TensorBoard
    assert (out / "best" / "best_model.zip").is_file() and (out / "learning_curve.png").stat().st_size > 0
    meta = json.loads((out / "model.json").read_text())
    assert meta["perception"] == "gt_cones" and meta["last_timesteps"] == 768 and meta["track"] == "small_track"
    assert meta["timesteps"] in (0, 256, 512, 768)  # model.zip: the best of the held-out drives
    assert train.main(["--timesteps", "512", *common[:-2], "--eval-track", "hairpin", "--out", str(tmp_path / "x")]) == 2

    from weather_gym.lab.evaluation.evaluate import evaluate
    from weather_gym.lab.evaluation.report import write_report

    config = evaluate_policy.config_for_model(out / "model.zip", effects=["droplets"], severities=[0, 3], seeds=[0],
                                              max_steps=30)
    assert config.perception == "detector"
    rows = evaluate(config, tmp_path / "eval", backend="serial", progress=False)
    assert [(r["agent"], r["severity"], r["status"]) for r in rows] == [("sb3", 0, "ok"), ("sb3", 3, "ok")]
    assert all(0 < r["steps"] <= 30 for r in rows) and rows[0]["det_frames"] > 0
    assert not (tmp_path / "eval" / "report.md").exists()  # evaluate() writes results only; its caller the report
    assert write_report(rows, tmp_path / "eval", config=config).is_file()
