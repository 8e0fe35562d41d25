"""``weather-gym train --pretrain``: behaviour cloning with DAgger before PPO (weather_gym.lab.training.policy.pretrain)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.core.errors import InputError
from weather_gym.lab.training.policy.pretrain import PretrainConfig, bc_loss, collect

pytest.importorskip("stable_baselines3")


def _args(out, *extra):
    return ["train", "--out", str(out), "--n-envs", "2", "--track", "hairpin,peanut", "--perception", "gt_cones",
            "--pretrain", "gt_pure_pursuit", "--pretrain-steps", "600", "--dagger-rounds", "2",
            "--pretrain-epochs", "4", "--timesteps", "0", "--eval-freq", "0", *extra]


def test_pretraining_clones_the_expert_and_saves_a_usable_model(tmp_path):
    from stable_baselines3 import PPO

    from weather_gym.agents import make_agent
    from weather_gym.lab.training.policy.train import DEFAULT_NOISE, make_training_env

    out = tmp_path / "run"
    assert main(_args(out)) == 0
    meta = json.loads((out / "model.json").read_text())
    pre = meta["pretrain"]
    assert pre["expert"] == "gt_pure_pursuit" and pre["steps"] == 600 and pre["rounds"] == 2
    assert [r["samples"] for r in pre["rounds_log"]] == [300, 600]
    assert pre["rounds_log"][0]["expert_share"] == 1.0 and pre["rounds_log"][1]["expert_share"] < 1.0
    assert pre["final_loss"] < pre["initial_loss"]
    assert json.loads((out / "run.json").read_text())["pretrain"] == pre
    assert (out / "pretrain_curve.png").stat().st_size > 10_000  # the loss per DAgger round, drawn
    model = PPO.load(str(out / "model.zip"), device="cpu")
    assert meta["timesteps"] == 0 and np.allclose(model.policy.log_std.detach().numpy(), -1.6)

    # on fresh expert-labelled observations the cloned policy is closer to the expert than an untrained one
    env = make_training_env("WeatherGym/ConeTrack-v0", "hairpin", "gt_cones", DEFAULT_NOISE, 1200, {})
    try:
        expert = make_agent("gt_pure_pursuit", env.unwrapped.track, env.unwrapped.config.camera)
        data, stats = collect([env], [expert], None, 200, 1.0, np.random.default_rng(7))
        untrained = PPO(model.policy_class, env, policy_kwargs=model.policy_kwargs, seed=0, device="cpu")
    finally:
        env.close()
    assert stats["expert_steps"] == 200 and data["action"].shape == (200, 2)
    assert bc_loss(model.policy, data) < 0.5 * bc_loss(untrained.policy, data)


def test_pretraining_is_repeatable(tmp_path):
    from stable_baselines3 import PPO

    logs, params = [], []
    for name in ("a", "b"):
        assert main(_args(tmp_path / name, "--dagger-rounds", "2", "--pretrain-steps", "200")) == 0
        logs.append(json.loads((tmp_path / name / "model.json").read_text())["pretrain"]["rounds_log"])
        params.append(PPO.load(str(tmp_path / name / "model.zip"), device="cpu").policy.state_dict())
    assert logs[0] == logs[1]
    assert all(np.array_equal(params[0][k].numpy(), params[1][k].numpy()) for k in params[0])


@pytest.mark.parametrize(("extra", "message"), [
    (["--pretrain", "no_such_driver"], r"unknown agent 'no_such_driver'; valid names: gt_pure_pursuit"),
    (["--pretrain-steps", "-5"], r"--pretrain-steps must be an integer >= 1, got -5"),
    (["--dagger-rounds", "0"], r"--dagger-rounds must be an integer >= 1, got 0"),
    (["--dagger-beta", "1.5"], r"--dagger-beta must be a finite number in \[0, 1\], got 1.5"),
    (["--teacher-narrow-width", "-1"], r"--teacher-narrow-width must be .*>= 0.*got -1"),
])
def test_bad_pretraining_options_are_refused(tmp_path, capsys, extra, message):
    assert main(_args(tmp_path / "run", *extra)) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not (tmp_path / "run").exists()
    with pytest.raises(InputError):
        PretrainConfig(expert="gt_pure_pursuit", steps=0)


def test_the_teacher_narrow_width_reaches_the_teacher(tmp_path, monkeypatch):
    from weather_gym.lab.training.policy import pretrain as pretrain_module

    seen: list[dict] = []
    real = pretrain_module.make_agent

    def spy(name, track, camera, **kwargs):
        seen.append(kwargs)
        return real(name, track, camera, **kwargs)

    monkeypatch.setattr(pretrain_module, "make_agent", spy)
    out = tmp_path / "run"
    assert main(_args(out, "--pretrain-steps", "200", "--teacher-narrow-width", "3.0")) == 0
    assert seen == [{"narrow_width": 3.0}] * 2  # one teacher per env
    assert json.loads((out / "model.json").read_text())["pretrain"]["teacher_narrow_width"] == 3.0
    seen.clear()
    assert main(_args(tmp_path / "off", "--pretrain-steps", "200")) == 0
    assert seen == [{}] * 2  # 0 (the default): the teacher as it always was


def test_timesteps_zero_needs_pretraining(tmp_path, capsys):
    assert main(["train", "--out", str(tmp_path / "run"), "--timesteps", "0", "--pretrain", "none"]) == 2
    assert "--timesteps must be an integer >= 1 (0 only with --pretrain), got 0" in capsys.readouterr().err


def test_a_stop_during_ppo_resumes_from_the_clone(tmp_path, monkeypatch):
    """The clone is checkpointed (``ppo_0_steps``) and driven on the held-out drives once: a resume after a
    stop in PPO continues from it, with its warm-start record and best score, not from scratch."""
    from stable_baselines3 import PPO

    out = tmp_path / "run"
    args = ["train", "--out", str(out), "--n-envs", "1", "--track", "hairpin", "--perception", "gt_cones",
            "--pretrain-steps", "200", "--dagger-rounds", "2", "--pretrain-epochs", "1", "--n-steps", "64",
            "--batch-size", "64", "--n-epochs", "1", "--max-steps", "60", "--timesteps", "128",
            "--checkpoint-freq", "1000", "--eval-freq", "1000", "--eval-track", "small_track",
            "--eval-weathers", "clear", "--eval-max-steps", "20"]
    real_train = PPO.train

    def interrupted_train(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(PPO, "train", interrupted_train)
    assert main(args) == 130
    monkeypatch.setattr(PPO, "train", real_train)
    assert (out / "checkpoints" / "ppo_0_steps.json").is_file() and (out / "best" / "best_model.json").is_file()
    pre = json.loads((out / "run.json").read_text())["pretrain"]
    assert [r["samples"] for r in pre["rounds_log"]] == [100, 200]
    assert main([*args, "--resume"]) == 0
    meta = json.loads((out / "model.json").read_text())
    assert meta["pretrain"] == pre and meta["last_timesteps"] == 128 and "held_out" in meta
    log = (out / "train.log").read_text()
    assert log.count("pretrain round 2 of 2:") == 1 and log.count("held-out drives at 0 PPO steps") == 1
    assert "resuming from ppo_0_steps.zip" in log and "held-out drives at 128 PPO steps" in log
