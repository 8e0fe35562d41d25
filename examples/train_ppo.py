"""Train a stable-baselines3 PPO driver on the cone-list observation; log, checkpoint, evaluate, resume.

**Observation.** The policy reads the cone list ``Dict(cones, mask, state)`` through
``weather_gym.agents.sb3_features.ConeListExtractor``. It trains on ``gt_cones`` by default: the
cones the camera would see, computed from geometry with nothing rendered (thousands of steps per
second on 2 cores), degraded with ``OracleNoise`` (misses, range and bearing noise, phantom cones)
so that it copes with a detector's mistakes. The same observation comes out of the detector on a
weathered frame, so the trained policy is evaluated through weather and the detector with
``weather-gym evaluate --agent sb3 --perception detector`` (see ``docs/rl.md``). Training on
detector cones (``--perception detector``, with ``WeatherRandomizer`` weather per episode) or on
pixels costs a rendered frame and a detector pass per step: 20-40 steps/s here, days for a policy.
``--perception surrogate`` trains on the detector's fitted statistics instead of ``OracleNoise``
(``weather_gym.surrogate``; env ``i`` in ``--surrogate-weathers[i % len]``), nothing rendered;
``--init PATH`` starts from a saved policy (fine-tuning).

**Tracks.** Env ``i`` drives ``--tracks[i % len]``, each episode from a random point of its track
(``reset(options={"start_s": ...})``, drawn from the reset seed); the ``EvalCallback`` drives the
held-out ``--eval-track`` (never trained on) from the start line and logs the mean reward, the lap
completion rate (``eval/success_rate``) and keeps the best model.

**Outputs** in ``--out`` (a folder): ``model.zip`` (the final policy) and ``model.json`` (the env it
was trained on, read by ``examples/evaluate_policy.py``), ``checkpoints/``, ``best/best_model.zip``,
``logs/<segment>/progress.csv`` and TensorBoard event files (``tensorboard --logdir OUT/logs``),
``learning_curve.png``, ``run.json`` (command, segments, wall time). ``--resume`` continues from
the newest checkpoint up to ``--timesteps`` in total; an existing run folder is never overwritten.

Usage:
    python examples/train_ppo.py --timesteps 300000 --n-envs 8 --out runs/ppo_cones
    python examples/train_ppo.py --timesteps 300000 --n-envs 8 --out runs/ppo_cones --resume   # after a stop
    python examples/train_ppo.py --timesteps 4096 --n-envs 2 --out runs/ppo_smoke                # a smoke run
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

DEFAULT_TRACKS = ("peanut", "fsds_training", "b_shape", "jellybean", "hairpin", "oval", "random:1", "random:2")
DEFAULT_EVAL_TRACK = "small_track"
DEFAULT_NOISE = {"miss_prob": 0.15, "range_noise": 0.05, "bearing_noise": 0.01, "false_positives": 0.3,
                 "swap_prob": 0.02, "max_range": 22.0}
"""OracleNoise of training: roughly what the detector does wrong on clean frames (see docs/rl.md)."""
PERCEPTIONS = ("gt_cones", "oracle", "detector", "surrogate")
EVAL_MAX_STEPS = 1800
"""Step limit of a held-out evaluation episode (60 s: a lap of small_track takes about 20 s)."""
_SPAWN_KEY = (0x57A27,)  # the start-point draw, apart from the env's own streams for the same seed


class RandomStart(gym.Wrapper):
    """Start each episode at a random arc length of the track (from the reset seed); ``info["start_s"]``."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._rng: np.random.Generator | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY))
        options = dict(options or {})
        track = self.env.unwrapped.track
        if track.closed and "start_s" not in options and "start_pose" not in options:
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
    from weather_gym.pipeline import make_env

    kwargs = dict(env_kwargs)
    pk = dict(noise) if perception in ("gt_cones", "oracle") else {}
    env = make_env(env_id, track=track, perception=perception, perception_kwargs=pk or None,
                   max_episode_steps=max_steps, episode_statistics=False,
                   weather=surrogate_weather if perception == "surrogate" else
                   "clear" if perception != "gt_cones" else None, **kwargs)
    if weather and perception not in ("gt_cones", "surrogate"):
        from weather_gym.wrappers import WeatherRandomizer

        env = WeatherRandomizer(env, **weather)
    if random_start:
        env = RandomStart(env)
    return LapSuccess(env)


def _tqdm_callback(total: int):
    """A tqdm bar over env steps, with the latest mean episode reward (SB3's own bar needs ``rich``)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

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
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    from weather_gym._io import save_figure

    return save_figure(fig, out / "learning_curve.png", overwrite=True, dpi=110)


def _parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--out", type=Path, required=True, help="run folder (never overwritten; see --resume)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    p.add_argument("--timesteps", type=int, default=300_000, help="total environment steps of the run")
    p.add_argument("--n-envs", type=int, default=8, help="parallel envs (env i drives tracks[i %% len])")
    p.add_argument("--vec", choices=("dummy", "subproc"), default="dummy",
                   help="DummyVecEnv (one process; best for gt_cones) or SubprocVecEnv (rendered perception)")
    p.add_argument("--env-id", default="WeatherGym/ConeTrack-v0")
    p.add_argument("--tracks", default=",".join(DEFAULT_TRACKS), help="training tracks, comma-separated")
    p.add_argument("--eval-track", default=DEFAULT_EVAL_TRACK, help="held-out track of the EvalCallback")
    p.add_argument("--perception", choices=PERCEPTIONS, default="gt_cones",
                   help="gt_cones: geometry, nothing rendered (fast); oracle: rendered ground truth; detector")
    p.add_argument("--noise", default=json.dumps(DEFAULT_NOISE),
                   help="OracleNoise fields (JSON) for gt_cones/oracle; '{}' for perfect cones")
    p.add_argument("--weather", default=None,
                   help="WeatherRandomizer fields (JSON) for rendered perception, e.g. "
                        "'{\"presets\": [\"droplets\", \"low_light\", \"rain\"], \"severities\": [0, 1, 2, 3]}'")
    p.add_argument("--camera", default=None, help="camera resolution WxH (default: the scenario's)")
    p.add_argument("--max-steps", type=int, default=1200, help="episode step limit while training (30 = 1 s)")
    p.add_argument("--n-steps", type=int, default=256, help="PPO rollout length per env")
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--n-epochs", type=int, default=10, help="PPO epochs per update")
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--log-std-init", type=float, default=-0.5,
                   help="initial log standard deviation of the actions (-0.5: std 0.61 of the [-1, 1] range)")
    p.add_argument("--eval-freq", type=int, default=25_000, help="env steps between held-out evaluations")
    p.add_argument("--eval-episodes", type=int, default=2, help="held-out episodes per evaluation")
    p.add_argument("--checkpoint-freq", type=int, default=25_000, help="env steps between checkpoints")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--surrogate-weathers", default="clear,droplets@2,droplets@4,low_light@1,low_light@2",
                   help="--perception surrogate: weathers, env i drives the i-th (cycled); the eval env the first")
    p.add_argument("--init", type=Path, default=None,
                   help="start from this saved PPO model (e.g. weather_gym/agents/models/ppo_cones.zip): fine-tuning")
    p.add_argument("--torch-threads", type=int, default=1,
                   help="torch threads (1: the envs share this process's cores)")
    args = p.parse_args(argv)
    for name in ("timesteps", "n_envs", "max_steps", "n_steps", "batch_size", "n_epochs", "eval_freq",
                 "eval_episodes", "checkpoint_freq"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be >= 1")
    return args


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    from weather_gym.errors import InputError

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
           "max_steps": args.max_steps, "env_kwargs": env_kwargs, "weather": weather, "tracks": tracks}
    if sw:
        out["surrogate_weathers"] = sw
    if args.init is not None:
        out["init"] = str(args.init)
    return out


def main(argv: list[str] | None = None) -> int:
    from weather_gym.cli import run_command

    return run_command(_train, _parse(argv))


def _train(args: argparse.Namespace) -> int:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor, VecNormalize

    from weather_gym._io import atomic_path, atomic_write_json
    from weather_gym.agents.sb3_features import ConeListExtractor
    from weather_gym.errors import InputError, OutputExistsError

    torch.set_num_threads(args.torch_threads)
    out: Path = args.out
    s = _settings(args)
    checkpoints = out / "checkpoints"
    run_file = out / "run.json"
    if args.resume:
        ckpt = latest_checkpoint(checkpoints)
        if ckpt is None or not run_file.is_file():
            raise InputError(f"--resume: no checkpoint in {checkpoints} (or no {run_file}); start a new run instead")
        run = json.loads(run_file.read_text())
        if run["settings"] != s:
            raise InputError(f"--resume with other settings than the run in {out}: {run['settings']} vs {s}")
    else:
        if out.exists() and any(out.iterdir()):
            raise OutputExistsError(f"{out} exists and is not empty; pass --resume to continue that run, "
                                    "or give another --out (a run folder is never overwritten)")
        ckpt, run = None, {"settings": s, "segments": []}
    tracks = s["tracks"]
    sw = s.get("surrogate_weathers") or ["clear"]
    make = [lambda i=i: make_training_env(s["env_id"], tracks[i % len(tracks)], s["perception"], s["noise"],
                                          s["max_steps"], s["env_kwargs"], s["weather"],
                                          surrogate_weather=sw[i % len(sw)])
            for i in range(args.n_envs)]
    make[0]().close()  # a bad setting fails here, in this process, with its message
    vec = VecMonitor((SubprocVecEnv if args.vec == "subproc" else DummyVecEnv)(make))
    # rewards scaled by a running estimate of the return's spread (the policy's input is untouched, so the
    # saved policy needs no statistics to drive); its state is saved beside each checkpoint for resuming
    vec = VecNormalize(vec, norm_obs=False, norm_reward=True, gamma=args.gamma)
    eval_env = VecNormalize(VecMonitor(DummyVecEnv([lambda: make_training_env(
        s["env_id"], args.eval_track, s["perception"], s["noise"], EVAL_MAX_STEPS, s["env_kwargs"], s["weather"],
        random_start=False, surrogate_weather=sw[0])])), norm_obs=False, norm_reward=False, training=False)
    segment = f"steps{_checkpoint_steps(ckpt):09d}"
    logger = configure(str(out / "logs" / segment), ["csv", "tensorboard"])
    started = time.time()
    model = None
    start_steps = 0
    try:
        if ckpt is None and args.init is not None:
            out.mkdir(parents=True, exist_ok=True)
            vec.seed(args.seed)
            model = PPO.load(str(args.init), env=vec, device="cpu")
            model.num_timesteps = 0
        elif ckpt is None:
            out.mkdir(parents=True, exist_ok=True)
            vec.seed(args.seed)
            model = PPO("MultiInputPolicy", vec, n_steps=args.n_steps, batch_size=args.batch_size,
                        n_epochs=args.n_epochs, learning_rate=args.learning_rate, gamma=args.gamma,
                        ent_coef=args.ent_coef, seed=args.seed, device="cpu", verbose=0,
                        policy_kwargs={"features_extractor_class": ConeListExtractor,
                                       "net_arch": {"pi": [128, 128], "vf": [128, 128]},
                                       "log_std_init": args.log_std_init})
        else:
            print(f"resuming from {ckpt} ({ckpt.name})")
            stats = ckpt.with_name(ckpt.name.replace("ppo_", "ppo_vecnormalize_").replace(".zip", ".pkl"))
            if stats.is_file():
                vec = VecNormalize.load(str(stats), vec.venv)
            model = PPO.load(str(ckpt), env=vec, device="cpu")
            vec.seed(args.seed + model.num_timesteps)
        model.set_logger(logger)
        eval_env.seed(10_000 + args.seed)
        callbacks = CallbackList([
            _tqdm_callback(args.timesteps),
            CheckpointCallback(max(args.checkpoint_freq // args.n_envs, 1), str(checkpoints), name_prefix="ppo",
                               save_vecnormalize=True),
            EvalCallback(eval_env, n_eval_episodes=args.eval_episodes, eval_freq=max(args.eval_freq // args.n_envs, 1),
                         best_model_save_path=str(out / "best"), log_path=str(out / "logs" / segment),
                         deterministic=True, verbose=0),
        ])
        start_steps = model.num_timesteps
        remaining = args.timesteps - start_steps
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=callbacks, reset_num_timesteps=False)
        with atomic_path(out / "model.zip", overwrite=True) as tmp:  # this run's own file
            model.save(str(tmp))
    finally:
        vec.close()
        eval_env.close()
        run["segments"].append({"from_steps": int(start_steps),
                                "to_steps": int(model.num_timesteps) if model is not None else None,
                                "wall_s": round(time.time() - started, 1),
                                "command": shlex.join([sys.executable, *sys.argv])})
        run["wall_s_total"] = round(sum(seg["wall_s"] for seg in run["segments"]), 1)
        if out.is_dir():
            atomic_write_json(run_file, run, indent=2, overwrite=True)
    atomic_write_json(out / "model.json", {
        "algo": "PPO", "timesteps": int(model.num_timesteps), "n_envs": args.n_envs, "seed": args.seed,
        "env_id": s["env_id"], "track": args.eval_track, "train_tracks": tracks, "perception": s["perception"],
        "train_noise": s["noise"], "env_kwargs": s["env_kwargs"], "train_weather": s["weather"],
        "train_max_steps": s["max_steps"], "features": "weather_gym.agents.sb3_features.ConeListExtractor",
    }, indent=2, overwrite=True)
    curve = plot_learning_curve(out)
    print(f"saved {out / 'model.zip'} after {model.num_timesteps} steps; {run['wall_s_total']:.0f} s of training "
          f"in {len(run['segments'])} segment(s); learning curve: {curve}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
