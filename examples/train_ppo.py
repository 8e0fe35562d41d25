"""Train a stable-baselines3 PPO policy on the cone-list observation, in randomized weather.

Pipeline per env (the same one ``weather-gym evaluate`` drives, via
``weather_gym.evaluation.evaluate.make_eval_env``):

    ConeTrackEnv -> WeatherWrapper -> DetectorWrapper (or the ground-truth cone list) -> RandomPresetWeather

``RandomPresetWeather`` draws a weather preset (condition x severity) for every episode from its own
generator, seeded by ``reset(seed=...)``, and hands it to the ``WeatherWrapper`` through
``reset(options={"weather": ...})``; the vectorized envs (``make_vec_env``, ``SubprocVecEnv`` by
default) seed env ``i`` with ``seed + i``, so a run is repeatable.

The policy is ``MultiInputPolicy`` on ``Dict(cones, mask, state)``. Next to the model zip a JSON
sidecar records the env settings, which ``examples/evaluate_policy.py`` reads to evaluate the
policy on the same observation.

Usage:
    python examples/train_ppo.py --timesteps 200000 --n-envs 4 --out runs/ppo_cones.zip
    python examples/train_ppo.py --timesteps 4096 --n-envs 2 --perception oracle --camera 128x72 \\
        --vec dummy --out runs/ppo_smoke.zip          # a quick smoke run
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from weather_gym._io import atomic_path, atomic_write, check_output
from weather_gym.cli import run_command
from weather_gym.cli._output_args import add_overwrite_arg
from weather_gym.errors import InputError
from weather_gym.evaluation.evaluate import DEFAULT_ENV_ID, DEFAULT_TRACK, PERCEPTIONS, make_eval_env

_SPAWN_KEY = (0x9E7A,)  # separates the preset draw from the env's own streams for the same seed


class RandomPresetWeather(gym.Wrapper):
    """Pick a weather preset per episode: ``condition`` uniformly from ``conditions``, ``severity``
    from ``severities``; passed down as ``reset(options={"weather": (condition, severity)})``.

    ``info["preset"]`` is the ``(condition, severity)`` of the episode.
    """

    def __init__(self, env: gym.Env, conditions=("droplets", "low_light"), severities=(0, 1, 2, 3, 4)) -> None:
        super().__init__(env)
        from weather_gym.weather.presets import canonical_condition, preset_spec

        if not conditions or not severities:
            raise ValueError("RandomPresetWeather needs at least one condition and one severity")
        for c in conditions:
            for s in severities:
                preset_spec(c, s)  # ValueError names an unknown condition or severity
        self.conditions = tuple(canonical_condition(c) for c in conditions)
        self.severities = tuple(int(s) for s in severities)
        self._rng: np.random.Generator | None = None
        self.preset: tuple[str, int] | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY))
        cond = self.conditions[int(self._rng.integers(len(self.conditions)))]
        sev = self.severities[int(self._rng.integers(len(self.severities)))]
        self.preset = (cond, sev)
        obs, info = self.env.reset(seed=seed, options={**(options or {}), "weather": self.preset})
        return obs, {**info, "preset": self.preset}


def _progress_callback(total: int):
    """A tqdm bar over environment steps (stable-baselines3's own needs ``rich``)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TqdmCallback(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, desc="PPO", unit="step", dynamic_ncols=True)

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmCallback()


def make_training_env(env_id: str, track: str, perception: str, camera: dict | None, max_steps: int,
                      conditions: tuple[str, ...], severities: tuple[int, ...]) -> gym.Env:
    """One training env (module-level so vectorized workers can build it)."""
    env_kwargs = {"camera": camera} if camera else {}
    env = make_eval_env(env_id, track=track, max_steps=max_steps, perception=perception, env_kwargs=env_kwargs)
    return RandomPresetWeather(env, conditions, severities)


def _camera(text: str | None) -> dict | None:
    if not text:
        return None
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--camera must look like 336x188, got {text!r}") from None
    return {"width": w, "height": h}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--timesteps", type=int, default=200_000, help="total environment steps")
    p.add_argument("--n-envs", type=int, default=4, help="parallel envs")
    p.add_argument("--vec", choices=("subproc", "dummy"), default="subproc",
                   help="SubprocVecEnv (one process per env) or DummyVecEnv (in this process)")
    p.add_argument("--out", type=Path, required=True, help="model zip to write (never overwritten without --overwrite)")
    add_overwrite_arg(p, help="replace --out (and its .json sidecar)")
    p.add_argument("--env-id", default=DEFAULT_ENV_ID)
    p.add_argument("--track", default=DEFAULT_TRACK)
    p.add_argument("--perception", choices=PERCEPTIONS[:2], default="detector",
                   help="detector: the ONNX detector's cone list; oracle: ground-truth cone list")
    p.add_argument("--camera", default=None, help="camera resolution WxH (default: the scenario's)")
    p.add_argument("--conditions", default="droplets,low_light", help="weather conditions drawn per episode")
    p.add_argument("--severities", default="0,1,2,3,4", help="severities drawn per episode")
    p.add_argument("--max-steps", type=int, default=900, help="episode step limit while training (30 = 1 s)")
    p.add_argument("--n-steps", type=int, default=512, help="PPO rollout length per env")
    p.add_argument("--batch-size", type=int, default=128)
    p.add_argument("--n-epochs", type=int, default=10, help="PPO epochs per update")
    p.add_argument("--seed", type=int, default=0)
    return run_command(_train, p.parse_args(argv))


def _train(args) -> int:
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    out = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    check_output(out, overwrite=args.overwrite, what="--out")
    check_output(out.with_suffix(".json"), overwrite=args.overwrite, what="model sidecar")
    if args.timesteps < 1 or args.n_envs < 1:
        raise InputError("--timesteps and --n-envs must be >= 1")
    conditions = tuple(c.strip() for c in args.conditions.split(",") if c.strip())
    severities = tuple(int(s) for s in args.severities.split(",") if s.strip())
    settings = {"env_id": args.env_id, "track": args.track, "perception": args.perception,
                "camera": _camera(args.camera), "max_steps": args.max_steps,
                "conditions": conditions, "severities": severities}
    make_training_env(**settings).close()  # fail fast on a bad setting, in this process

    vec = make_vec_env(make_training_env, n_envs=args.n_envs, seed=args.seed, env_kwargs=settings,
                       vec_env_cls=SubprocVecEnv if args.vec == "subproc" else DummyVecEnv)
    try:
        model = PPO("MultiInputPolicy", vec, n_steps=args.n_steps, batch_size=args.batch_size,
                    n_epochs=args.n_epochs, seed=args.seed,
                    device="cpu", verbose=0)
        model.learn(total_timesteps=args.timesteps, callback=_progress_callback(args.timesteps))
    finally:
        vec.close()
    with atomic_path(out, overwrite=args.overwrite) as tmp:
        model.save(str(tmp))
    sidecar = out.with_suffix(".json")
    env_kwargs = {"camera": settings["camera"]} if settings["camera"] else {}
    atomic_write(sidecar, json.dumps({
        "algo": "PPO", "timesteps": args.timesteps, "n_envs": args.n_envs, "seed": args.seed,
        "env_id": args.env_id, "track": args.track, "perception": args.perception, "env_kwargs": env_kwargs,
        "train_conditions": list(conditions), "train_severities": list(severities), "train_max_steps": args.max_steps,
    }, indent=2) + "\n", overwrite=args.overwrite)
    print(f"saved {out} and {sidecar}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
