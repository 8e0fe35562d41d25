"""``weather-gym bench sensors``: the full pipeline with camera, LiDAR and fusion, beside camera-only.

One env (no vectorization) per stack: ``detector`` (camera-only: render -> camera weather -> detector,
the baseline in the same run), ``lidar`` (scan -> LiDAR weather -> cones; nothing rendered) and ``fused``
(both, and the fusion rule), all under the same physical weather (``--conditions``, one state for the
camera, the LiDAR and the tyres) with the mapping and planning agent driving. Each row is the median
over ``--repeats`` blocks of ``--steps`` steps after a warm-up, as ms per control step (agent included)
and steps/s; the 1-minute load average is printed with the table (other processes on the same cores
slow every row).

Example:
    weather-gym bench sensors --conditions rain:8mm/h+fog:60m --repeats 10 --out bench_sensors.md

The command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'sensors', '--conditions', 'rain:8mm/h+fog:60m'])
    >>> args.target, args.stacks, args.conditions
    ('sensors', 'detector,lidar,fused', 'rain:8mm/h+fog:60m')
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from weather_gym.agents import make_agent
from weather_gym.conditions import parse_state
from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.pipeline import make_env
from weather_gym.pipeline.modes import perception_mode

STACKS = ("detector", "lidar", "fused")


def register(targets) -> None:
    p = targets.add_parser("sensors", help="ms per step of the camera, LiDAR and fused pipelines, single env",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--stacks", default=",".join(STACKS), help="perception modes (default %(default)s; the first "
                                                             "is the baseline)")
    p.add_argument("--conditions", default="rain:8mm/h+fog:60m", help="the physical weather (default %(default)s)")
    p.add_argument("--track", default="small_track")
    p.add_argument("--agent", default="mapper_pure_pursuit")
    p.add_argument("--steps", type=int, default=30, help="steps per timed block (default %(default)s)")
    p.add_argument("--repeats", type=int, default=10, help="timed blocks per row; the median is reported")
    p.add_argument("--warmup", type=int, default=15, help="untimed steps first (default %(default)s)")
    p.add_argument("--out", type=Path, help="also write the markdown table to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def time_stack(stack: str, conditions: str, track: str, agent_name: str, *, steps: int, repeats: int,
               warmup: int) -> list[float]:
    """Milliseconds per control step (env + weather + perception + agent) of each timed block."""
    env = make_env(perception=stack, conditions=conditions, track=track, laps=0, terminate_off_track=False,
                   max_episode_steps=10**7)
    try:
        base = env.unwrapped
        agent = make_agent(agent_name, base.track, base.config.camera)  # type: ignore[attr-defined]  # a ConeTrackEnv
        obs, info = env.reset(seed=0)
        agent.reset(seed=0, info=info)

        def run(n: int) -> None:
            nonlocal obs, info
            for _ in range(n):
                obs, _, terminated, truncated, info = env.step(np.asarray(agent.act(obs, info), np.float32))
                if terminated or truncated:
                    obs, info = env.reset()
                    agent.reset(info=info)

        run(warmup)
        out = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            run(steps)
            out.append(1000.0 * (time.perf_counter() - t0) / steps)
        return out
    finally:
        env.close()


def _run(args: argparse.Namespace) -> int:
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, what="--out")
    stacks = [s.strip() for s in args.stacks.split(",") if s.strip()]
    if not stacks:
        raise InputError("--stacks is empty; give perception modes such as detector,lidar,fused")
    for s in stacks:
        perception_mode(s)
    state = parse_state(args.conditions)
    if args.steps < 1 or args.repeats < 1 or args.warmup < 0:
        raise InputError("--steps and --repeats must be >= 1, --warmup >= 0")
    load_before = os.getloadavg()
    rows, base = [], None
    for stack in tqdm(stacks, desc="bench sensors", unit="stack"):
        ms = time_stack(stack, state.spec(), args.track, args.agent, steps=args.steps, repeats=args.repeats,
                        warmup=args.warmup)
        med = statistics.median(ms)
        q1, _, q3 = statistics.quantiles(ms, n=4) if len(ms) > 1 else (med, med, med)
        base = med if base is None else base
        rows.append([stack + (" (baseline)" if med is base else ""), f"{med:.1f}", f"{q1:.1f}-{q3:.1f}",
                     f"{1000.0 / med:.1f}", f"{med / base:.2f}"])
    load_after = os.getloadavg()
    table = markdown_table(["stack", "ms per step (median)", "interquartile range", "steps/s", "x baseline"], rows)
    note = (f"{machine_line()}; one env, agent {args.agent}, track {args.track}, conditions {state.spec()}; median "
            f"of {args.repeats} blocks of {args.steps} steps after {args.warmup} warm-up steps; 1-minute load "
            f"average {load_before[0]:.2f} before, {load_after[0]:.2f} after")
    text = table + "\n\n" + note + "\n"
    print(text)
    if args.out is not None:
        atomic_write(args.out, text, overwrite=args.overwrite)
    return 0
