"""``weather-gym bench env``: training throughput, env-steps/s of vectorized envs.

For every pipeline (``clean``: the camera env; ``weather+detector``: env -> weather -> detector)
and resolution, it times a plain single env (the baseline, in the same run) and Gymnasium vector
envs of 1, 2 and 4 copies, ``sync`` (one process) and ``async`` (one worker process per env).
Each row is the median over ``--repeats`` blocks of ``--steps`` vector steps after a warm-up,
reported as env-steps/s (copies x steps / block time); the car drives a steady circle that never
ends an episode, so resets are not timed. The machine's load average is printed with the table:
other processes on the same cores lower every number.

Example:
    weather-gym bench env --envs 1,2,4 --modes sync,async --resolutions 672x376,336x188 --out bench_env.md

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'env', '--envs', '1,2,4', '--modes', 'sync,async'])
    >>> args.target, args.envs, args.modes
    ('env', '1,2,4', 'sync,async')
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.core.limits import parse_sizes
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.weather import parse_weather

PIPELINES = ("clean", "weather+detector")
MODES = ("sync", "async")
ACTION = (0.35, 0.15)
"""Steering and throttle of the steady circle driven while timing (stays on the track's asphalt)."""


def register(targets) -> None:
    p = targets.add_parser("env", help="env-steps/s of vector envs: 1/2/4 envs, sync/async, two resolutions",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--env-id", default="WeatherGym/ConeTrack-v0")
    p.add_argument("--track", default="small_track")
    p.add_argument("--envs", default="1,2,4", help="vector sizes (default %(default)s)")
    p.add_argument("--modes", default="sync,async", help="vector modes (default %(default)s)")
    p.add_argument("--resolutions", default="672x376,336x188", help="camera sizes WxH (default %(default)s)")
    p.add_argument("--pipelines", default=",".join(PIPELINES), help=f"of {', '.join(PIPELINES)} (default: all)")
    p.add_argument("--weather", default="droplets@3", help="weather of the weather+detector pipeline")
    p.add_argument("--steps", type=int, default=20, help="vector steps per timed block (default %(default)s)")
    p.add_argument("--repeats", type=int, default=15, help="timed blocks per row; the median is reported")
    p.add_argument("--warmup", type=int, default=10, help="untimed vector steps first (default %(default)s)")
    p.add_argument("--out", type=Path, help="also write the markdown table to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def _ints(text: str, what: str) -> list[int]:
    try:
        vals = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--{what} must be comma-separated integers, got {text!r}") from None
    if not vals or min(vals) < 1:
        raise InputError(f"--{what} must list integers >= 1, got {text!r}")
    return vals


def _resolutions(text: str) -> list[tuple[int, int]]:
    out = parse_sizes(text, what="--resolutions", example="672x376,336x188")
    for w, h in out:
        if w < 16 or h < 16:
            raise InputError(f"--resolutions: {w}x{h} is too small (at least 16x16)")
    return out


def _names(text: str, valid: Sequence[str], what: str) -> list[str]:
    vals = [v.strip() for v in text.split(",") if v.strip()]
    bad = [v for v in vals if v not in valid]
    if bad or not vals:
        raise InputError(f"--{what}: unknown {', '.join(bad) or 'empty list'}; valid: {', '.join(valid)}")
    return vals


def env_factory(env_id: str, track: str, size: tuple[int, int], pipeline: str, weather: str) -> Callable[[], Any]:
    """A picklable ``() -> env`` for one pipeline (so async workers can build it)."""
    return _Factory(env_id, track, size, pipeline, weather)


class _Factory:
    def __init__(self, env_id: str, track: str, size: tuple[int, int], pipeline: str, weather: str) -> None:
        self.args = (env_id, track, size, pipeline, weather)

    def __call__(self):
        env_id, track, (w, h), pipeline, weather = self.args
        kwargs: dict[str, Any] = {"track": track, "camera": {"width": w, "height": h}, "laps": 0,
                                  "terminate_off_track": False, "max_episode_steps": 10**7}
        if pipeline == "weather+detector":
            kwargs.update(weather=weather, detector={"threads": 1})
        return gym.make(env_id, **kwargs)


def time_vector(make_env: Callable[[], Any], num_envs: int, mode: str | None, *, steps: int, repeats: int,
                warmup: int) -> tuple[list[float], str]:
    """Env-steps/s of each timed block, and the renderer(s) in use: ``mode`` None = one plain env,
    else a gymnasium vector env."""

    if mode is None:
        env = make_env()
        step = env.step
        action: Any = np.asarray(ACTION, np.float32)
        env.reset(seed=0)
        renderers = {env.unwrapped.renderer}
    else:
        if mode == "sync":
            env = gym.vector.SyncVectorEnv([make_env] * num_envs)
        else:  # spawned workers keep the EGL renderer (a forked child of an EGL process cannot use it)
            env = gym.vector.AsyncVectorEnv([make_env] * num_envs, context="spawn")
        step = env.step
        action = np.tile(np.asarray(ACTION, np.float32), (num_envs, 1))
        env.reset(seed=list(range(num_envs)))
        renderers = set(env.get_attr("renderer"))
    try:
        for _ in range(warmup):
            step(action)
        rates = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(steps):
                step(action)
            rates.append(num_envs * steps / (time.perf_counter() - t0))
        return rates, "+".join(sorted(renderers))
    finally:
        env.close()


def _run(args: argparse.Namespace) -> int:
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, what="--out")

    envs = _ints(args.envs, "envs")
    modes = _names(args.modes, MODES, "modes")
    sizes = _resolutions(args.resolutions)
    pipelines = _names(args.pipelines, PIPELINES, "pipelines")
    if args.steps < 1 or args.repeats < 1 or args.warmup < 0:
        raise InputError("--steps and --repeats must be >= 1, --warmup >= 0")
    if pipelines.count("weather+detector"):
        parse_weather(args.weather)
    plan = [(p, s, n, m) for p in pipelines for s in sizes for n, m in [(1, None)] + [(n, m) for m in modes for n in envs]]
    load_before = os.getloadavg()
    rows = []
    base: dict[tuple[str, tuple[int, int]], float] = {}
    for pipeline, size, n, mode in tqdm(plan, desc="bench env", unit="row"):
        rates, renderer = time_vector(env_factory(args.env_id, args.track, size, pipeline, args.weather), n, mode,
                            steps=args.steps, repeats=args.repeats, warmup=args.warmup)
        med = statistics.median(rates)
        q1, _, q3 = statistics.quantiles(rates, n=4) if len(rates) > 1 else (med, med, med)
        if mode is None:
            base[pipeline, size] = med
        rows.append([pipeline, f"{size[0]}x{size[1]}", n, mode or "plain env (baseline)", renderer, f"{med:.1f}",
                     f"{q1:.1f}-{q3:.1f}", f"{med / base[pipeline, size]:.2f}"])
    load_after = os.getloadavg()
    table = markdown_table(["pipeline", "camera", "envs", "vectorization", "renderer", "env-steps/s (median)",
                            "interquartile range", "x plain env"], rows)
    note = (f"{machine_line()}; median of {args.repeats} blocks of {args.steps} vector steps after {args.warmup} "
            f"warm-up steps; track {args.track}; weather+detector = {args.weather} + the shipped detector "
            f"(1 thread); 1-minute load average {load_before[0]:.2f} before, {load_after[0]:.2f} after")
    text = table + "\n\n" + note + "\n"
    print(text)
    if args.out is not None:
        atomic_write(args.out, text, overwrite=args.overwrite)
    return 0
