"""``weather-gym bench surrogate``: env-steps/s of the perception surrogate vs the full pipeline.

One env (one process, so one core) driving the ground-truth lap of ``--track`` in ``--weather``:
the full pipeline (render -> weather -> ONNX detector, the baseline, same run), ``gt_cones`` (the
render-free ground truth the surrogate builds on) and ``surrogate``; each the median of
``--repeats`` blocks of ``--block`` steps after a warm-up block, the agent's time not counted
(its actions are recorded first and replayed). gt_cones and the surrogate run in interleaved blocks,
and the surrogate's time per step relative to gt_cones is the median over block pairs, so that the
machine's changing speed does not fall on one of them. Then Gymnasium vector envs of the surrogate
(``--num-envs``, async: one process per env; a constant action, with the vector env's automatic
resets): env-steps/s summed over the envs. The machine's load average is printed with the
tables: other processes on the same cores lower every number; the single-env rows also give
env-steps per second of the process's own CPU time, what one unloaded core would come close to
(the full pipeline's renderer and onnxruntime may use more than one thread, so its CPU-time rate is
per CPU-second of all its threads).

Example:
    $ weather-gym bench surrogate --weather droplets@3 --num-envs 1,2,4

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'surrogate', '--weather', 'droplets@3', '--num-envs', '1,2,4'])
    >>> args.target, args.weather, args.num_envs
    ('surrogate', 'droplets@3', '1,2,4')
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from weather_gym.agents import make_agent
from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.pipeline import make_env, make_vec_env
from weather_gym.surrogate.model import load_model
from weather_gym.tracks import load_track


def register(targets) -> None:
    p = targets.add_parser("surrogate", help="perception surrogate vs full pipeline: env-steps/s, vector envs",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--track", default="small_track", help="track (default %(default)s)")
    p.add_argument("--weather", default="droplets@3", help="weather (default %(default)s)")
    p.add_argument("--block", type=int, default=500, help="steps per timed block (default %(default)s)")
    p.add_argument("--repeats", type=int, default=7, help="timed blocks per row (default %(default)s)")
    p.add_argument("--full-block", type=int, default=30, help="steps per block of the full pipeline (default %(default)s)")
    p.add_argument("--full-repeats", type=int, default=3, help="blocks of the full pipeline (default %(default)s)")
    p.add_argument("--num-envs", default="1,2,4", help="vector env sizes (default %(default)s; empty: none)")
    p.set_defaults(func=run)


class _TimedLap:
    """One env of ``perception`` driving the ground-truth lap of ``track``, its actions recorded first
    (the agent is not timed); :meth:`block` times block ``r`` of ``block`` steps."""

    def __init__(self, perception: str, track: str, weather: str | None, block: int, repeats: int) -> None:
        self.perception = perception
        self.block_steps = block
        self.env = make_env(perception=perception, weather=weather, track=track, laps=0, max_episode_steps=10**9,
                            episode_statistics=False)
        try:
            u = self.env.unwrapped
            agent = make_agent("gt_pure_pursuit", u.track, u.config.camera)  # type: ignore[attr-defined]  # a ConeTrackEnv
            obs, info = self.env.reset(seed=0)
            agent.reset(seed=0, info=info)
            self.actions = []
            for _ in range(block * (repeats + 1)):
                a = agent.act(obs, info)
                self.actions.append(a)
                obs, _, term, trunc, info = self.env.step(a)
                if term or trunc:
                    obs, info = self.env.reset(seed=0)
                    agent.reset(seed=0, info=info)
            self.env.reset(seed=0)
        except BaseException:
            self.env.close()
            raise

    def block(self, r: int) -> tuple[float, float]:
        """Env-steps per second of wall time and of this process's CPU time over block ``r``."""
        chunk = self.actions[r * self.block_steps:(r + 1) * self.block_steps]
        t0, c0 = time.perf_counter(), time.process_time()
        for a in chunk:
            self.env.step(a)
        return len(chunk) / (time.perf_counter() - t0), len(chunk) / max(time.process_time() - c0, 1e-9)

    def close(self) -> None:
        self.env.close()


def steps_per_s(perception: str, track: str, weather: str | None, block: int, repeats: int) -> tuple[float, float]:
    """Median env-steps/s of one env of ``perception`` driving the ground-truth lap of ``track``: per
    second of wall time and per second of this process's CPU time (what one unloaded core would give)."""
    return paired_steps_per_s([(perception, weather)], track, block, repeats)[0][:2]


def paired_steps_per_s(rows: list[tuple[str, str | None]], track: str, block: int,
                       repeats: int) -> list[tuple[float, float, list[float]]]:
    """:func:`steps_per_s` of several ``(perception, weather)`` envs, their blocks interleaved (block 1
    of each, then block 2 of each in reverse order, ...) so that a change of the machine's speed during
    the run falls on all of them alike. Per env: median wall and CPU rates, and the wall rate of each
    block (to pair with the other envs' blocks of the same round)."""
    laps: list[_TimedLap] = []
    try:
        for perception, weather in rows:
            laps.append(_TimedLap(perception, track, weather, block, repeats))
        rates: list[list[tuple[float, float]]] = [[] for _ in laps]
        for r in range(repeats + 1):
            order = range(len(laps)) if r % 2 == 0 else reversed(range(len(laps)))
            for i in order:
                rate = laps[i].block(r)
                if r:  # the first block is the warm-up
                    rates[i].append(rate)
        return [(statistics.median(w for w, _ in rr), statistics.median(c for _, c in rr), [w for w, _ in rr])
                for rr in rates]
    finally:
        for lap in laps:
            lap.close()


def vector_steps_per_s(num_envs: int, track: str, weather: str | None, block: int, repeats: int) -> float:
    """Median env-steps/s (summed over the envs) of an async vector env of ``num_envs`` surrogate envs."""

    venv = make_vec_env(num_envs=num_envs, perception="surrogate", weather=weather, track=track,
                        max_episode_steps=400, episode_statistics=False)
    try:
        venv.reset(seed=0)
        action = np.tile(np.array([0.3, 0.02], np.float32), (num_envs, 1))
        rates = []
        for r in range(repeats + 1):
            t0 = time.perf_counter()
            for _ in range(block):
                venv.step(action)
            if r:
                rates.append(num_envs * block / (time.perf_counter() - t0))
        return statistics.median(rates)
    finally:
        venv.close()


def run(args: argparse.Namespace) -> int:
    for name in ("block", "repeats", "full_block", "full_repeats"):
        if getattr(args, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    try:
        sizes = [int(x) for x in args.num_envs.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--num-envs: expected comma-separated integers, got {args.num_envs!r}") from None
    if any(n < 1 for n in sizes):
        raise InputError(f"--num-envs: sizes must be >= 1, got {args.num_envs!r}")

    load_track(args.track)

    load_model().point(args.weather)  # an unmodelled weather fails here
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f}")
    full = steps_per_s("detector", args.track, args.weather, args.full_block, args.full_repeats)
    gt, sur = paired_steps_per_s([("gt_cones", None), ("surrogate", args.weather)], args.track, args.block,
                                 args.repeats)
    slower = statistics.median(g / s for g, s in zip(gt[2], sur[2], strict=True))  # block by block
    rows = [[f"detector (full pipeline, {args.weather})", f"{full[0]:.1f}", f"{full[1]:.1f}", "1.0x", "",
             f"{args.full_repeats} x {args.full_block}"],
            ["gt_cones (ground truth, no errors)", f"{gt[0]:.0f}", f"{gt[1]:.0f}", f"{gt[0] / full[0]:.0f}x", "1.00",
             f"{args.repeats} x {args.block}"],
            [f"surrogate ({args.weather})", f"{sur[0]:.0f}", f"{sur[1]:.0f}", f"{sur[0] / full[0]:.0f}x",
             f"{slower:.2f}", f"{args.repeats} x {args.block}"]]
    print(f"\nOne env (one process), {args.track}, ground-truth lap, median of the blocks; gt_cones and the "
          f"surrogate in interleaved blocks (load average {os.getloadavg()[0]:.1f}):")
    print(markdown_table(["perception", "env-steps/s (wall)", "env-steps per CPU-second", "vs full pipeline (wall)",
                          "time per step vs gt_cones (paired blocks)", "blocks x steps"], rows))
    if sizes:
        vrows = []
        for n in sizes:
            rate = vector_steps_per_s(n, args.track, args.weather, max(args.block // 5, 20), args.repeats)
            vrows.append([n, f"{rate:.0f}", f"{rate / n:.0f}"])
        print(f"\nAsync vector envs of the surrogate ({args.weather}), constant action, automatic resets "
              f"(load average {os.getloadavg()[0]:.1f}):")
        print(markdown_table(["envs", "env-steps/s (all envs)", "per env"], vrows))
    return 0
