"""``weather-gym train``: a stable-baselines3 PPO driver on the cone-list observation; logs,
checkpoints, held-out evaluation, resume, and a usable model after Ctrl-C.

**Observation.** The policy reads the cone list ``Dict(cones, mask, state)`` through
``weather_gym.agents.sb3_features.ConeListPolicy`` (``ConeListExtractor``). It trains on ``gt_cones``
by default: the cones the camera would see, computed from geometry with nothing rendered, degraded
with ``OracleNoise`` (misses, range and bearing noise, phantom cones) so that it copes with a
detector's mistakes. The detector on a weathered frame gives the same observation, so the trained
policy is evaluated through weather and the detector (``examples/evaluate_policy.py``,
``weather-gym evaluate --agent sb3``; ``docs/rl.md``). ``--perception surrogate`` trains on the
detector's fitted statistics instead (env ``i`` in ``--surrogate-weathers[i % len]``); ``detector`` /
``oracle`` render a frame per step (with ``--weather``: ``WeatherRandomizer`` fields).

**Hyper-parameters** come from a file in rl-zoo3's YAML format (``--hyperparams``, default the
shipped :data:`weather_gym.rl.HYPERPARAMS`, section ``--hyperparams-key``): ``n_envs``,
``n_timesteps``, ``policy``, ``normalize``, ``policy_kwargs`` and PPO's own keywords. The same file
trains with ``python -m rl_zoo3.train --algo ppo --env WeatherGym/ConeTrackCones-v0 --gym-packages
weather_gym -conf FILE``. Options given on the command line (``--n-envs``, ``--timesteps``,
``--learning-rate``, ...) override single values.

**Tracks.** Env ``i`` drives ``--tracks[i % len]``, each episode from a random point of its track
(drawn from the reset seed); the ``EvalCallback`` drives the held-out ``--eval-track`` (never trained
on) from the start line and logs the mean reward and lap completion (``eval/success_rate``).

**Outputs** in ``--out``: ``model.zip`` and ``model.json`` (the env it was trained on: what
``examples/evaluate_policy.py`` reads), ``checkpoints/ppo_<N>_steps.zip`` each with its
``ppo_<N>_steps.json``, ``best/best_model.zip`` with ``best/best_model.json`` (every one of them
evaluates with the same command as the final model), ``logs/<segment>/progress.csv`` and TensorBoard
event files, ``learning_curve.png``, ``run.json`` (command, settings, segments, wall time).
``--resume`` continues from the newest checkpoint up to ``--timesteps``; ``--overwrite`` replaces the
run in a non-empty folder (never without it). ``--pretrain EXPERT`` first clones a registered agent (e.g.
``gt_pure_pursuit``) with DAgger on the same envs (:mod:`weather_gym.rl.pretrain`; ``--pretrain-steps``,
``--dagger-rounds``, ``--pretrain-epochs``, ``--pretrain-log-std``), then PPO continues for
``--timesteps`` (0: the cloned policy is saved as the model). **Ctrl-C** stops the run and still
writes ``model.zip``, ``model.json``, the learning curve and ``run.json`` (exit status 130); ``--resume`` continues from the newest checkpoint.

Example:
    >>> args = build_parser().parse_args(["--out", "runs/x", "--n-envs", "2"])
    >>> hp = resolve_hyperparams(args)
    >>> hp["n_envs"], hp["n_timesteps"], hp["ppo"]["n_steps"], hp["policy"].rsplit(".", 1)[-1]
    (2, 300000, 256, 'ConeListPolicy')
"""

from __future__ import annotations

import argparse
import ast
import csv
import dataclasses
import importlib
import inspect
import json
import re
import shlex
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib
import numpy as np
from matplotlib import pyplot as plt
from tqdm.auto import tqdm

from weather_gym._io import atomic_path, atomic_write_json, save_figure
from weather_gym.errors import FileFormatError, InputError, MissingDependencyError, OutputExistsError
from weather_gym.limits import check_seed
from weather_gym.pipeline import make_env
from weather_gym.rl import HYPERPARAMS
from weather_gym.rl.pretrain import PretrainConfig, pretrain
from weather_gym.wrappers import WeatherRandomizer

__all__ = ["DEFAULT_TRACKS", "LapSuccess", "RandomStart", "build_parser", "latest_checkpoint", "load_hyperparams",
           "make_training_env", "model_metadata", "plot_learning_curve", "plot_pretrain_curve", "resolve_hyperparams", "train"]

DEFAULT_TRACKS = ("peanut", "fsds_training", "b_shape", "jellybean", "hairpin", "oval", "random:1", "random:2")
DEFAULT_EVAL_TRACK = "small_track"
DEFAULT_HYPERPARAMS_KEY = "WeatherGym/ConeTrackCones-v0"
DEFAULT_NOISE = {"miss_prob": 0.15, "range_noise": 0.05, "bearing_noise": 0.01, "false_positives": 0.3,
                 "swap_prob": 0.02, "max_range": 22.0}
"""OracleNoise of training: roughly what the detector does wrong on clean frames (see docs/rl.md)."""
PERCEPTIONS = ("gt_cones", "oracle", "detector", "surrogate")
EVAL_MAX_STEPS = 1800
"""Step limit of a held-out evaluation episode (60 s: a lap of small_track takes about 20 s)."""
INTERRUPTED = 130
"""Exit status after Ctrl-C (the model so far is saved)."""
_SPAWN_KEY = (0x57A27,)  # the start-point draw, apart from the env's own streams for the same seed
_RUN_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "policy_kwargs")
"""Keys of a hyper-parameter section that are not PPO keywords."""
_CLI_PPO = {"n_steps": "n_steps", "batch_size": "batch_size", "n_epochs": "n_epochs",
            "learning_rate": "learning_rate", "gamma": "gamma", "ent_coef": "ent_coef"}


class RandomStart(gym.Wrapper):
    """Start an episode at a random arc length of the track (from the reset seed); ``info["start_s"]``.

    A share ``line_share`` of the episodes starts at the start line from rest instead: a policy trained
    only on rolling starts anywhere never learns to leave the line (docs/rl.md, "The start line").
    """

    def __init__(self, env: gym.Env, line_share: float = 0.25) -> None:
        if not 0.0 <= float(line_share) <= 1.0:
            raise InputError(f"RandomStart: line_share={line_share!r} must be in [0, 1]")
        super().__init__(env)
        self.line_share = float(line_share)
        self._rng: np.random.Generator | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY))
        options = dict(options or {})
        track = self.env.unwrapped.track
        at_line = self._rng.uniform() < self.line_share
        if track.closed and not at_line and "start_s" not in options and "start_pose" not in options:
            options["start_s"] = float(self._rng.uniform(0.0, track.length))
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {**info, "start_s": options.get("start_s", 0.0)}


class LapSuccess(gym.Wrapper):
    """``info["is_success"]`` at the end of an episode: the requested laps were driven (for EvalCallback)."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info = {**info, "is_success": bool(info.get("lap", 0) >= max(1, self.env.unwrapped.config.laps)
                                               or info.get("finished", False))}
        return obs, reward, terminated, truncated, info


def make_training_env(env_id: str, track: str, perception: str, noise: dict[str, Any], max_steps: int,
                      env_kwargs: dict[str, Any], weather: dict[str, Any] | None = None,
                      random_start: bool = True, surrogate_weather: str = "clear") -> gym.Env:
    """One env of the run (module level, so vector-env workers can build it)."""
    pk = dict(noise) if perception in ("gt_cones", "oracle") else {}
    env = make_env(env_id, track=track, perception=perception, perception_kwargs=pk or None,
                   max_episode_steps=max_steps, episode_statistics=False,
                   weather=surrogate_weather if perception == "surrogate" else
                   "clear" if perception != "gt_cones" else None, **dict(env_kwargs))
    if weather and perception not in ("gt_cones", "surrogate"):
        env = WeatherRandomizer(env, **weather)
    if random_start:
        env = RandomStart(env)
    return LapSuccess(env)


# ------------------------------------------------------------------ hyper-parameters
def _literal(text: Any, where: str) -> Any:
    """A value of rl-zoo3's string-encoded keys: Python literals and ``dict(...)`` calls of them."""
    if not isinstance(text, str):
        return text

    def ev(node: ast.AST) -> Any:
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args:
            return {kw.arg: ev(kw.value) for kw in node.keywords}
        if isinstance(node, ast.Dict):
            return {ev(k): ev(v) for k, v in zip(node.keys, node.values)}
        if isinstance(node, ast.List | ast.Tuple):
            vals = [ev(e) for e in node.elts]
            return vals if isinstance(node, ast.List) else tuple(vals)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -ev(node.operand)
        if isinstance(node, ast.Constant):
            return node.value
        raise InputError(f"{where}: only literals and dict(...) are read here, got {ast.unparse(node)!r}")

    try:
        return ev(ast.parse(text, mode="eval").body)
    except SyntaxError:
        raise InputError(f"{where}: not a Python expression: {text!r}") from None


def load_hyperparams(path: str | Path, key: str) -> dict[str, Any]:
    """Section ``key`` of an rl-zoo3 hyper-parameter YAML file, checked: ``{"n_envs", "n_timesteps",
    "policy", "normalize" (VecNormalize keywords), "policy_kwargs", "ppo" (PPO keywords)}``."""
    try:
        import yaml
    except ImportError:
        raise MissingDependencyError("reading a hyper-parameter file needs PyYAML (pip install pyyaml)") from None
    path = Path(path)
    if not path.is_file():
        raise InputError(f"hyper-parameter file {path} not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise FileFormatError(f"{path}: not YAML ({exc})") from None
    if not isinstance(data, dict) or key not in data or not isinstance(data[key], dict):
        keys = sorted(data) if isinstance(data, dict) else []
        raise FileFormatError(f"{path}: no section {key!r} (sections: {keys})")
    from stable_baselines3 import PPO

    sec = dict(data[key])
    where = f"{path} [{key}]"
    valid_ppo = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env", "_init_setup_model"}
    unknown = sorted(set(sec) - set(_RUN_KEYS) - valid_ppo)
    if unknown:
        raise FileFormatError(f"{where}: unknown key(s) {unknown}; valid: {sorted(set(_RUN_KEYS) | valid_ppo)}")
    normalize = _literal(sec.pop("normalize", False), f"{where} normalize")
    if normalize is True:
        normalize = {}
    if normalize is not False and not isinstance(normalize, dict):
        raise FileFormatError(f"{where}: normalize must be true/false or a dict of VecNormalize keywords")
    policy_kwargs = _literal(sec.pop("policy_kwargs", {}), f"{where} policy_kwargs")
    if not isinstance(policy_kwargs, dict):
        raise FileFormatError(f"{where}: policy_kwargs must be a dict")
    out = {"n_envs": sec.pop("n_envs", 1), "n_timesteps": sec.pop("n_timesteps", None),
           "policy": sec.pop("policy", "MultiInputPolicy"), "normalize": normalize, "policy_kwargs": policy_kwargs}
    for name in ("n_envs", "n_timesteps"):
        v = out[name]
        if isinstance(v, float) and v.is_integer():
            v = out[name] = int(v)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise FileFormatError(f"{where}: {name} must be an integer >= 1, got {v!r}")
    out["ppo"] = sec
    return out


def resolve_hyperparams(args: argparse.Namespace) -> dict[str, Any]:
    """The run's hyper-parameters: the file's section, with the options given on the command line."""
    hp = load_hyperparams(args.hyperparams, args.hyperparams_key)
    if args.n_envs is not None:
        hp["n_envs"] = args.n_envs
    if args.timesteps is not None:
        hp["n_timesteps"] = args.timesteps
    if hp["n_timesteps"] is None:
        raise InputError(f"{args.hyperparams} [{args.hyperparams_key}] has no n_timesteps; give --timesteps")
    for opt, key in _CLI_PPO.items():
        if getattr(args, opt) is not None:
            hp["ppo"][key] = getattr(args, opt)
    if args.log_std_init is not None:
        hp["policy_kwargs"]["log_std_init"] = args.log_std_init
    return hp


# ------------------------------------------------------------------ outputs
def _tqdm_callback(total: int):
    """A tqdm bar over env steps, with the latest mean episode reward (SB3's own bar needs ``rich``)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class TqdmCallback(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, initial=self.model.num_timesteps, desc="PPO", unit="step",
                            dynamic_ncols=True)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.ep_info_buffer
            if buf:
                self.bar.set_postfix(ep_rew=f"{np.mean([e['r'] for e in buf]):.1f}",
                                     ep_len=f"{np.mean([e['l'] for e in buf]):.0f}")

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmCallback()


def _metadata_callbacks(meta, checkpoints: Path, checkpoint_freq: int, best: Path):
    """SB3's ``CheckpointCallback`` writing ``ppo_<N>_steps.json`` beside each checkpoint, and the
    callback that writes ``best/best_model.json`` whenever ``EvalCallback`` saves a new best model."""
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback

    class CheckpointWithMetadata(CheckpointCallback):
        def _on_step(self) -> bool:
            go_on = super()._on_step()
            if self.n_calls % self.save_freq == 0:
                zip_path = Path(self._checkpoint_path(extension="zip"))
                atomic_write_json(zip_path.with_suffix(".json"), meta(self.num_timesteps), indent=2, overwrite=True)
            return go_on

    class BestMetadata(BaseCallback):
        def _on_step(self) -> bool:
            atomic_write_json(best / "best_model.json", meta(self.num_timesteps), indent=2, overwrite=True)
            return True

    return (CheckpointWithMetadata(checkpoint_freq, str(checkpoints), name_prefix="ppo", save_vecnormalize=True),
            BestMetadata())


def _checkpoint_steps(path: Path | None) -> int:
    m = re.fullmatch(r"ppo_(\d+)_steps\.zip", path.name) if path is not None else None
    return int(m.group(1)) if m else 0


def latest_checkpoint(folder: Path) -> Path | None:
    """The checkpoint with the most steps in ``folder`` (``ppo_<steps>_steps.zip``), or None."""
    found = sorted(folder.glob("ppo_*_steps.zip"), key=_checkpoint_steps)
    return found[-1] if found else None


def plot_learning_curve(out: Path) -> Path | None:
    """``out/learning_curve.png`` from every segment's ``progress.csv``: training and held-out reward,
    held-out lap completion."""
    matplotlib.use("Agg")
    rows: list[dict[str, str]] = []
    for f in sorted((out / "logs").glob("*/progress.csv")):
        with f.open(newline="") as fh:
            rows += list(csv.DictReader(fh))
    if not rows:
        return None

    def series(key: str) -> tuple[np.ndarray, np.ndarray]:
        pts = sorted((float(r["time/total_timesteps"]), float(r[key])) for r in rows
                     if r.get(key) not in (None, "") and r.get("time/total_timesteps") not in (None, ""))
        return (np.array([p[0] for p in pts]), np.array([p[1] for p in pts])) if pts else (np.zeros(0), np.zeros(0))

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for key, label in (("rollout/ep_rew_mean", "training tracks (mean of the last 100 episodes)"),
                       ("eval/mean_reward", "held-out track (EvalCallback)")):
        x, y = series(key)
        if len(x):
            ax1.plot(x, y, marker="." if key.startswith("eval") else None, label=label)
    ax1.set_xlabel("environment steps")
    ax1.set_ylabel("episode reward (m of progress, penalties)")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    x, y = series("eval/success_rate")
    if len(x):
        ax2.plot(x, y, marker=".", color="tab:green")
    ax2.set_xlabel("environment steps")
    ax2.set_ylabel("lap completion on the held-out track")
    ax2.set_ylim(-0.05, 1.05)
    ax2.grid(alpha=0.3)
    fig.suptitle(f"PPO on the cone list ({out.name})")
    fig.tight_layout()
    return save_figure(fig, out / "learning_curve.png", overwrite=True, dpi=110)


def plot_pretrain_curve(out: Path, record: dict[str, Any] | None) -> Path | None:
    """``out/pretrain_curve.png`` from a warm start's record (``run.json["pretrain"]``): the behaviour-cloning
    loss before and after each DAgger round's fit, and per round the share of the steps the expert drove and
    the share of ended episodes that were laps."""
    rounds = (record or {}).get("rounds_log") or []
    if not rounds:
        return None
    matplotlib.use("Agg")
    r = np.array([x["round"] for x in rounds])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    ax1.semilogy(r, [x["loss_before"] for x in rounds], "o--", label="before the round's fit (new data included)")
    ax1.semilogy(r, [x["loss"] for x in rounds], "o-", label="after the fit")
    ax1.set_xlabel("DAgger round")
    ax1.set_ylabel("BC loss (MSE of the policy mean to the expert's action)")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(r, [x["expert_share"] for x in rounds], "o-", label="steps driven by the expert")
    ax2.plot(r, [x["laps"] / max(x["episodes"], 1) for x in rounds], "o-", label="ended episodes that were laps")
    ax2.set_xlabel("DAgger round")
    ax2.set_ylim(-0.05, 1.05)
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    fig.suptitle(f"warm start: behaviour cloning of {record.get('expert')} with DAgger ({out.name})")
    fig.tight_layout()
    return save_figure(fig, out / "pretrain_curve.png", overwrite=True, dpi=110)


def model_metadata(settings: dict[str, Any], hp: dict[str, Any], seed: int, eval_track: str,
                   timesteps: int, pretrain: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON written beside every saved model (final, checkpoint, best): the env it was trained on
    (and, after ``--pretrain``, the warm start's record: expert, steps, rounds, BC loss per round)."""
    extra = {"pretrain": pretrain} if pretrain is not None else {}
    return {**extra, "algo": "PPO", "timesteps": int(timesteps), "n_envs": hp["n_envs"], "seed": seed,
            "env_id": settings["env_id"], "track": eval_track, "train_tracks": settings["tracks"],
            "perception": settings["perception"], "train_noise": settings["noise"],
            "env_kwargs": settings["env_kwargs"], "train_weather": settings["weather"],
            "train_max_steps": settings["max_steps"], "policy": hp["policy"],
            "features": "weather_gym.agents.sb3_features.ConeListExtractor"}


# ------------------------------------------------------------------ command line
def build_parser(p: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    """The options of ``weather-gym train`` (and ``examples/train_ppo.py``), added to ``p``."""
    p = p or argparse.ArgumentParser(prog="weather-gym train", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="run folder (see --resume, --overwrite)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    p.add_argument("--overwrite", action="store_true",
                   help="start a new run in a non-empty --out: its run files (model, checkpoints/, best/, logs/, "
                        "run.json, learning curve) are removed first")
    p.add_argument("--hyperparams", type=Path, default=HYPERPARAMS,
                   help="hyper-parameter file in rl-zoo3's YAML format (default: the shipped ppo.yml)")
    p.add_argument("--hyperparams-key", default=DEFAULT_HYPERPARAMS_KEY, help="its section")
    p.add_argument("--timesteps", type=int, default=None, help="total environment steps (default: n_timesteps)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs, env i drives tracks[i %% len] "
                   "(default: n_envs)")
    p.add_argument("--vec", choices=("dummy", "subproc"), default="dummy",
                   help="DummyVecEnv (one process; best for gt_cones/surrogate) or SubprocVecEnv (rendered perception)")
    p.add_argument("--env-id", default="WeatherGym/ConeTrack-v0",
                   help="the scenario (an id with camera images, so the policy evaluates through the detector)")
    p.add_argument("--tracks", default=",".join(DEFAULT_TRACKS), help="training tracks, comma-separated")
    p.add_argument("--eval-track", default=DEFAULT_EVAL_TRACK, help="held-out track of the EvalCallback")
    p.add_argument("--perception", choices=PERCEPTIONS, default="gt_cones",
                   help="gt_cones: geometry, nothing rendered (fast); surrogate: the detector's statistics, "
                        "nothing rendered; oracle: rendered ground truth; detector")
    p.add_argument("--noise", default=json.dumps(DEFAULT_NOISE),
                   help="OracleNoise fields (JSON) for gt_cones/oracle; '{}' for perfect cones")
    p.add_argument("--weather", default=None,
                   help="WeatherRandomizer fields (JSON) for rendered perception, e.g. "
                        "'{\"presets\": [\"droplets\", \"low_light\", \"rain\"], \"severities\": [0, 1, 2, 3]}'")
    p.add_argument("--camera", default=None, help="camera resolution WxH (default: the scenario's)")
    p.add_argument("--max-steps", type=int, default=1200, help="episode step limit while training (30 = 1 s)")
    for opt, typ in (("n-steps", int), ("batch-size", int), ("n-epochs", int), ("learning-rate", float),
                     ("gamma", float), ("ent-coef", float)):
        p.add_argument(f"--{opt}", type=typ, default=None, help="PPO's, overriding the file's")
    p.add_argument("--log-std-init", type=float, default=None,
                   help="initial log std of the actions (policy_kwargs; the file's -0.5: std 0.61 of [-1, 1])")
    p.add_argument("--eval-freq", type=int, default=25_000, help="env steps between held-out evaluations")
    p.add_argument("--eval-episodes", type=int, default=2, help="held-out episodes per evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=25_000, help="env steps between checkpoints")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--surrogate-weathers", default="clear,droplets@2,droplets@4,low_light@1,low_light@2",
                   help="--perception surrogate: weathers, env i drives the i-th (cycled); the eval env the first")
    p.add_argument("--init", type=Path, default=None,
                   help="start from this saved PPO model (e.g. weather_gym/agents/models/ppo_cones.zip): fine-tuning")
    p.add_argument("--torch-threads", type=int, default=1, help="torch threads (1: the envs share the cores)")
    g = p.add_argument_group("warm start (behaviour cloning with DAgger before PPO; weather_gym.rl.pretrain)")
    g.add_argument("--pretrain", default=None, metavar="EXPERT",
                   help="a registered agent that labels the training envs' observations, e.g. gt_pure_pursuit "
                        "(the true pose) or mapper_pure_pursuit; the policy is cloned from it before PPO")
    g.add_argument("--pretrain-steps", type=int, default=60_000, help="env steps of expert-labelled data, all rounds")
    g.add_argument("--dagger-rounds", type=int, default=4,
                   help="round 0 drives with the expert, round r with the student but for a share beta**r")
    g.add_argument("--dagger-beta", type=float, default=0.5, help="expert-driven share base (see --dagger-rounds)")
    g.add_argument("--pretrain-epochs", type=int, default=20, help="passes over all the data after each round")
    g.add_argument("--pretrain-log-std", type=float, default=-1.6,
                   help="the policy's log std after pretraining, PPO's exploration from there (-1.6: std 0.2)")
    return p


def _check_args(args: argparse.Namespace) -> None:
    least = 0 if getattr(args, "pretrain", None) is not None else 1  # 0: the cloned policy is the model
    if args.timesteps is not None and args.timesteps < least:
        raise InputError(f"--timesteps must be >= 1 (0 only with --pretrain), got {args.timesteps}")
    for name in ("n_envs", "max_steps", "n_steps", "batch_size", "n_epochs", "eval_freq",
                 "eval_episodes", "checkpoint_freq", "torch_threads"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise InputError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    check_seed(args.seed, what="--seed")


def _settings(args: argparse.Namespace, hp: dict[str, Any]) -> dict[str, Any]:
    env_kwargs: dict[str, Any] = {}
    if args.camera:
        try:
            w, h = (int(v) for v in args.camera.lower().split("x"))
        except ValueError:
            raise InputError(f"--camera must look like 336x188, got {args.camera!r}") from None
        env_kwargs["camera"] = {"width": w, "height": h}
    try:
        noise = json.loads(args.noise)
        weather = json.loads(args.weather) if args.weather else None
    except json.JSONDecodeError as exc:
        raise InputError(f"--noise / --weather must be JSON objects: {exc}") from None
    tracks = [t.strip() for t in args.tracks.split(",") if t.strip()]
    if not tracks:
        raise InputError("--tracks is empty")
    if args.eval_track in tracks:
        raise InputError(f"--eval-track {args.eval_track} is also a training track: it would not be held out")
    if weather and args.perception in ("gt_cones", "surrogate"):
        raise InputError(f"--weather acts on camera images; {args.perception} renders none (use --perception detector, "
                         "or --surrogate-weathers)")
    sw = [w.strip() for w in args.surrogate_weathers.split(",") if w.strip()] if args.perception == "surrogate" else []
    out = {"env_id": args.env_id, "perception": args.perception,
           "noise": noise if args.perception in ("gt_cones", "oracle") else {},
           "max_steps": args.max_steps, "env_kwargs": env_kwargs, "weather": weather, "tracks": tracks,
           "hyperparams": {k: v for k, v in hp.items() if k != "n_timesteps"}}
    if sw:
        out["surrogate_weathers"] = sw
    if args.init is not None:
        out["init"] = str(args.init)
    if getattr(args, "pretrain", None) is not None:
        out["pretrain"] = dataclasses.asdict(_pretrain_config(args))
    return out


def _pretrain_config(args: argparse.Namespace) -> PretrainConfig:
    return PretrainConfig(expert=args.pretrain, steps=args.pretrain_steps, rounds=args.dagger_rounds,
                          epochs=args.pretrain_epochs, beta=args.dagger_beta, log_std=args.pretrain_log_std)


def _close(env: Any) -> None:
    try:
        env.close()
    except (EOFError, OSError):  # SubprocVecEnv workers already gone (Ctrl-C reaches them too)
        pass


def train(args: argparse.Namespace) -> int:
    """Run (or resume) the training of ``args``; 0 when done, :data:`INTERRUPTED` after Ctrl-C."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CallbackList, EvalCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor, VecNormalize

    _check_args(args)
    torch.set_num_threads(args.torch_threads)
    hp = resolve_hyperparams(args)
    out: Path = args.out
    s = _settings(args, hp)
    checkpoints = out / "checkpoints"
    run_file = out / "run.json"
    if args.resume and args.overwrite:
        raise InputError("--resume continues the run in --out and --overwrite replaces it: give one")
    if args.resume:
        ckpt = latest_checkpoint(checkpoints)
        if ckpt is None or not run_file.is_file():
            raise InputError(f"--resume: no checkpoint in {checkpoints} (or no {run_file}); start a new run instead")
        run = json.loads(run_file.read_text())
        if run["settings"] != json.loads(json.dumps(s)):
            raise InputError(f"--resume with other settings than the run in {out}: {run['settings']} vs {s}")
    else:
        if out.exists() and any(out.iterdir()):
            if not args.overwrite:
                raise OutputExistsError(f"{out} exists and is not empty; pass --resume to continue that run, "
                                        "--overwrite to start a new one there, or give another --out")
            _remove_run(out)
        ckpt, run = None, {"settings": s, "segments": []}

    def meta(steps: int) -> dict[str, Any]:
        return model_metadata(s, hp, args.seed, args.eval_track, steps, run.get("pretrain"))

    n_envs, total = hp["n_envs"], hp["n_timesteps"]
    tracks = s["tracks"]
    sw = s.get("surrogate_weathers") or ["clear"]
    make = [lambda i=i: make_training_env(s["env_id"], tracks[i % len(tracks)], s["perception"], s["noise"],
                                          s["max_steps"], s["env_kwargs"], s["weather"],
                                          surrogate_weather=sw[i % len(sw)])
            for i in range(n_envs)]
    make[0]().close()  # a bad setting fails here, in this process, with its message
    vec = VecMonitor((SubprocVecEnv if args.vec == "subproc" else DummyVecEnv)(make))
    normalize = hp["normalize"]
    if normalize is not False:  # rl-zoo3's `normalize`: VecNormalize keywords; its state is saved with each checkpoint
        vec = VecNormalize(vec, **{"gamma": hp["ppo"].get("gamma", 0.99), **normalize})
    eval_env = VecMonitor(DummyVecEnv([lambda: make_training_env(
        s["env_id"], args.eval_track, s["perception"], s["noise"], EVAL_MAX_STEPS, s["env_kwargs"], s["weather"],
        random_start=False, surrogate_weather=sw[0])]))
    if normalize is not False:
        eval_env = VecNormalize(eval_env, **{**normalize, "norm_reward": False, "training": False})
    segment = f"steps{_checkpoint_steps(ckpt):09d}"
    logger = configure(str(out / "logs" / segment), ["csv", "tensorboard"])
    started = time.time()
    model = None
    start_steps = 0
    interrupted = False
    try:
        out.mkdir(parents=True, exist_ok=True)
        if ckpt is None and args.init is not None:
            vec.seed(args.seed)
            model = PPO.load(str(args.init), env=vec, device="cpu")
            model.num_timesteps = 0
        elif ckpt is None:
            vec.seed(args.seed)
            model = PPO(hp["policy"] if "." not in hp["policy"] else _class(hp["policy"]), vec, seed=args.seed,
                        device="cpu", verbose=0, policy_kwargs=dict(hp["policy_kwargs"]), **hp["ppo"])
        else:
            print(f"resuming from {ckpt}")
            stats = ckpt.with_name(ckpt.name.replace("ppo_", "ppo_vecnormalize_").replace(".zip", ".pkl"))
            if normalize is not False and stats.is_file():
                vec = VecNormalize.load(str(stats), vec.venv)
            model = PPO.load(str(ckpt), env=vec, device="cpu")
            vec.seed(args.seed + model.num_timesteps)
        if ckpt is None and "pretrain" in s:
            teach = [m() for m in make]  # plain envs of the same settings, stepped in this process
            try:
                run["pretrain"] = pretrain(model.policy, teach, _pretrain_config(args), args.seed)
            except KeyboardInterrupt:
                interrupted = True
                print("interrupted while pretraining: saving the policy so far", file=sys.stderr)
            finally:
                for env in teach:
                    env.close()
        model.set_logger(logger)
        eval_env.seed(10_000 + args.seed)
        checkpoint_cb, best_cb = _metadata_callbacks(meta, checkpoints, max(args.checkpoint_freq // n_envs, 1),
                                                     out / "best")
        callbacks = CallbackList([
            _tqdm_callback(total),
            checkpoint_cb,
            EvalCallback(eval_env, n_eval_episodes=args.eval_episodes, eval_freq=max(args.eval_freq // n_envs, 1),
                         best_model_save_path=str(out / "best"), log_path=str(out / "logs" / segment),
                         deterministic=True, verbose=0, callback_on_new_best=best_cb),
        ])
        start_steps = model.num_timesteps
        remaining = total - start_steps
        if remaining > 0 and not interrupted:
            try:
                model.learn(total_timesteps=remaining, callback=callbacks, reset_num_timesteps=False)
            except KeyboardInterrupt:
                interrupted = True
                print(f"interrupted after {model.num_timesteps} steps: saving the model so far", file=sys.stderr)
        with atomic_path(out / "model.zip", overwrite=True) as tmp:  # this run's own file
            model.save(str(tmp))
        atomic_write_json(out / "model.json", meta(model.num_timesteps), indent=2, overwrite=True)
    finally:
        logger.close()
        _close(vec)
        _close(eval_env)
        run["segments"].append({"from_steps": int(start_steps),
                                "to_steps": int(model.num_timesteps) if model is not None else None,
                                "wall_s": round(time.time() - started, 1), "interrupted": interrupted,
                                "command": shlex.join([sys.executable, *sys.argv])})
        run["wall_s_total"] = round(sum(seg["wall_s"] for seg in run["segments"]), 1)
        if out.is_dir():
            atomic_write_json(run_file, run, indent=2, overwrite=True)
    curve = plot_learning_curve(out)
    warm = plot_pretrain_curve(out, run.get("pretrain"))
    print(f"saved {out / 'model.zip'} after {model.num_timesteps} steps; {run['wall_s_total']:.0f} s of training "
          f"in {len(run['segments'])} segment(s); learning curve: {curve}" + (f"; warm start: {warm}" if warm else ""))
    if interrupted:
        print(f"stopped early: continue with the same command and --resume (from the newest checkpoint in "
              f"{checkpoints}), or evaluate {out / 'model.zip'} as it is", file=sys.stderr)
        return INTERRUPTED
    return 0


RUN_FILES = ("model.zip", "model.json", "run.json", "learning_curve.png", "pretrain_curve.png", "checkpoints", "best",
             "logs")
"""What a run writes in its folder (``--overwrite`` removes these, nothing else)."""


def _remove_run(out: Path) -> None:
    for name in RUN_FILES:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()


def _class(path: str) -> type:
    """The class at an import path (``module.Class``), as rl-zoo3 reads ``policy``."""
    module, _, name = path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        raise InputError(f"policy {path!r}: no such class (expected an import path like "
                         "weather_gym.agents.sb3_features.ConeListPolicy, or MultiInputPolicy)") from None
