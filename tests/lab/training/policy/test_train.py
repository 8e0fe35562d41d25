"""``weather-gym train``: the rl-zoo3 hyper-parameter file, a tiny run, Ctrl-C, resume, and every saved
model (final, best, checkpoints) evaluating with the same command."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from weather_gym.agents import AGENTS
from weather_gym.agents.cone_memory import ConeMemoryConfig
from weather_gym.cli import main
from weather_gym.lab.training.policy import HYPERPARAMS
from weather_gym.lab.training.policy.train import DEFAULT_HYPERPARAMS_KEY, load_hyperparams

pytest.importorskip("stable_baselines3")
ROOT = Path(__file__).resolve().parents[4]


def _evaluate_policy():
    spec = importlib.util.spec_from_file_location("example_evaluate_policy", ROOT / "examples" / "evaluate_policy.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_shipped_file_is_rl_zoo3_format_and_builds_ppo():
    from stable_baselines3 import PPO

    from weather_gym.agents.sb3_features import ConeListPolicy
    from weather_gym.pipeline import make_env

    hp = load_hyperparams(HYPERPARAMS, DEFAULT_HYPERPARAMS_KEY)
    assert hp["n_envs"] == 16 and hp["n_timesteps"] == 100_000 and hp["ppo"]["learning_rate"] == 1e-4
    assert hp["normalize"] == {"norm_obs": False, "norm_reward": True}
    assert hp["policy_kwargs"] == {"net_arch": {"pi": [128, 128], "vf": [128, 128]}, "log_std_init": -0.5}
    env = make_env(perception="gt_cones", max_episode_steps=10)
    try:
        model = PPO(ConeListPolicy, env, policy_kwargs=hp["policy_kwargs"], device="cpu", **hp["ppo"])
        assert type(model.policy).__name__ == "ConeListPolicy" and model.n_steps == 256
    finally:
        env.close()


@pytest.mark.parametrize(("text", "message"), [
    ("X:\n  n_envs: 2\n", r"no section 'WeatherGym/ConeTrackCones-v0' \(sections: \['X'\]\)"),
    ("WeatherGym/ConeTrackCones-v0:\n  n_stepz: 2\n", r"unknown key\(s\) \['n_stepz'\]"),
    ("WeatherGym/ConeTrackCones-v0:\n  policy_kwargs: \"dict(activation_fn=nn.ReLU)\"\n", "only literals and dict"),
    ("WeatherGym/ConeTrackCones-v0:\n  n_envs: 0\n", r"n_envs must be an integer in \[1, 64\], got 0"),
])
def test_bad_hyperparameter_files_are_refused(tmp_path, text, message):
    path = tmp_path / "hp.yml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_hyperparams(path, DEFAULT_HYPERPARAMS_KEY)


@pytest.mark.slow
def test_rl_zoo3_trains_with_the_shipped_file(tmp_path):
    pytest.importorskip("rl_zoo3")
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "WeatherGym/ConeTrackCones-v0",
           "--gym-packages", "weather_gym", "-conf", str(HYPERPARAMS), "-n", "64", "--eval-freq", "-1",
           "-f", str(tmp_path), "-params", "n_envs:1", "n_steps:64", "batch_size:64", "n_epochs:1"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert list(tmp_path.glob("ppo/WeatherGym-ConeTrackCones-v0_1/*.zip"))


@pytest.mark.slow
def test_tiny_run_ctrl_c_resume_and_every_saved_model_evaluates(tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    out = tmp_path / "run"
    args = ["train", "--out", str(out), "--n-envs", "1", "--track", "hairpin", "--n-steps", "64",
            "--batch-size", "64", "--n-epochs", "1", "--max-steps", "60", "--eval-freq", "64",
            "--eval-episodes", "1", "--checkpoint-freq", "64", "--cone-memory", "--pretrain", "none",
            "--perception", "gt_cones", "--eval-track", "small_track", "--eval-weathers", "clear",
            "--eval-max-steps", "30"]
    updates = {"n": 0}
    real_train = PPO.train

    def interrupted_train(self):  # Ctrl-C in the 3rd update (after 192 steps)
        updates["n"] += 1
        if updates["n"] == 3:
            raise KeyboardInterrupt
        return real_train(self)

    monkeypatch.setattr(PPO, "train", interrupted_train)
    assert main([*args, "--timesteps", "256"]) == 130
    monkeypatch.setattr(PPO, "train", real_train)
    meta = json.loads((out / "model.json").read_text())
    assert meta["timesteps"] == 192 and meta["env_id"] == "WeatherGym/ConeTrack-v0"
    memory = ConeMemoryConfig(detection_range=30.0)
    assert meta["cone_memory"] == memory.to_dict()  # the tuning it trained with, for the driver
    assert (out / "model.zip").is_file() and (out / "learning_curve.png").stat().st_size > 0
    run = json.loads((out / "run.json").read_text())
    assert run["segments"][0]["interrupted"] is True and run["segments"][0]["to_steps"] == 192
    assert PPO.load(str(out / "model.zip"), device="cpu").num_timesteps == 192  # a usable model

    assert main([*args, "--timesteps", "256", "--resume"]) == 0
    meta = json.loads((out / "model.json").read_text())  # the best policy on the held-out drives
    best = json.loads((out / "best" / "best_model.json").read_text())
    assert meta["last_timesteps"] == 256 and meta["held_out"] == best["held_out"]
    assert meta["timesteps"] == best["timesteps"] and meta["held_out"]["episodes"] == 1
    log = (out / "train.log").read_text()  # progress and statistics in a file, both segments
    assert log.count("PPO 64/256 steps") == 1 and "PPO 256/256 steps" in log and "resuming from" in log
    assert "held-out drives at 256 PPO steps" in log
    checkpoints = sorted((out / "checkpoints").glob("ppo_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    assert [p.name for p in checkpoints][-1] == "ppo_256_steps.zip"
    assert all(p.with_suffix(".json").is_file() for p in checkpoints)
    assert (out / "best" / "best_model.zip").is_file() and (out / "best" / "best_model.json").is_file()
    assert list((out / "logs").glob("*/events.out.tfevents*")) and len(list((out / "logs").glob("*/progress.csv"))) == 2

    from weather_gym.lab.evaluation.evaluate import evaluate

    evaluate_policy = _evaluate_policy()
    for i, model in enumerate((out / "model.zip", out / "best" / "best_model.zip", checkpoints[0])):
        config = evaluate_policy.config_for_model(model, effects=["dim"], severities=[0], seeds=[0], max_steps=10,
                                                  perception="gt_cones")
        assert config.env_id == "WeatherGym/ConeTrack-v0" and config.tracks == ("small_track",)
        rows = evaluate(config, tmp_path / f"eval{i}", backend="serial", progress=False)
        assert [r["status"] for r in rows] == ["ok"]
        assert AGENTS.get("sb3")(None, None, path=model).memory.config == memory  # drives as trained
    (checkpoints[0].with_suffix(".json")).unlink()  # no sidecar: the run folder's model.json is found
    assert evaluate_policy.find_sidecar(checkpoints[0]) == out / "model.json"

    assert main([*args, "--timesteps", "64"]) == 2  # a run folder is never replaced without --overwrite
    assert main([*args, "--timesteps", "64", "--resume", "--overwrite"]) == 2
    assert main([*args, "--timesteps", "64", "--overwrite"]) == 0
    assert [p.name for p in (out / "checkpoints").glob("*.zip")] == ["ppo_64_steps.zip"]
    assert len(json.loads((out / "run.json").read_text())["segments"]) == 1


def test_random_starts_keep_a_share_at_the_start_line():
    """A quarter of training episodes start at the line from rest: a policy must learn to leave it."""
    from weather_gym.core.errors import InputError
    from weather_gym.lab.training.policy.train import RandomStart
    from weather_gym.pipeline import make_env

    env = RandomStart(make_env("WeatherGym/ConeTrackCones-v0", track="small_track", perception="gt_cones",
                               episode_statistics=False))
    try:
        starts = [env.reset(seed=s)[1]["start_s"] for s in range(40)]
        again = [env.reset(seed=s)[1]["start_s"] for s in range(40)]
    finally:
        env.close()
    at_line = sum(s == 0.0 for s in starts)
    assert 4 <= at_line <= 18 and starts == again  # ~25 %, and the same seeds give the same starts
    with pytest.raises(InputError, match="line_share"):
        RandomStart(env, line_share=1.5)


def test_ppo_steps_render_free_envs_in_two_processes_with_lean_infos(tmp_path, monkeypatch):
    """The default vector env for render-free perception on 2 cores: SplitVecEnv (half the envs in a
    second process, stepped at the same time), each env's info cut to INFO_KEYS (DummyVecEnv deep-copies the infos every step)."""
    from stable_baselines3 import PPO

    from weather_gym.lab.training.policy import train as train_module
    from weather_gym.lab.training.policy.split_vec_env import SplitVecEnv
    from weather_gym.lab.training.policy.training_env import LeanInfo

    seen = {}

    def no_learning(self, total_timesteps, **kwargs):  # the envs as PPO would step them, nothing learnt
        seen["vec"] = self.env
        seen["wrapped"] = self.env.env_is_wrapped(LeanInfo)
        return self

    monkeypatch.setattr(PPO, "learn", no_learning)
    monkeypatch.setattr(train_module.os, "sched_getaffinity", lambda pid: {0, 1})
    assert main(["train", "--out", str(tmp_path / "run"), "--n-envs", "2", "--track", "hairpin,oval",
                 "--perception", "surrogate", "--timesteps", "64", "--n-steps", "32", "--batch-size", "32",
                 "--pretrain", "none", "--eval-freq", "0"]) == 0
    assert seen["wrapped"] == [True, True]
    vec = seen["vec"]
    while not isinstance(vec, SplitVecEnv):  # VecNormalize -> VecMonitor -> SplitVecEnv
        vec = vec.venv
    assert vec.num_envs == 2 and all(isinstance(env, LeanInfo) for env in vec._local.envs)
