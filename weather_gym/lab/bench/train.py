"""``weather-gym bench train``: PPO training throughput, each vector env kind against one process.

Runs ``weather-gym train`` as a user does (a fresh process per run, in a temporary folder) with each
``--vecs`` kind in turn, ``--pairs`` times, the kinds alternating so that the machine's drift falls
on all of them; the first kind is the baseline. Each run's speed is SB3's own ``time/fps`` at the end
(env steps per second of wall time since the start of learning: rollouts and updates; the runs
skip the warm start and the held-out drives, ``--pretrain none --eval-freq 0``) and its wall time the whole command's. The table has one row per round, the
median of each kind and the speed-up of each over the baseline, round by round.

Example:
    weather-gym bench train --perception surrogate --timesteps 40960 --n-envs 8 --pairs 5

The command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'train', '--perception', 'surrogate', '--pairs', '5'])
    >>> args.target, args.vecs, args.pairs
    ('train', 'dummy,auto', 5)
"""

from __future__ import annotations

import csv
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.lab.training.policy.train import PERCEPTIONS, VEC_KINDS


def register(targets) -> None:
    p = targets.add_parser("train", help="time PPO training with each vector env kind (alternating runs)",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--vecs", default="dummy,auto",
                   help=f"--vec kinds to time, comma-separated, the first the baseline ({', '.join(VEC_KINDS)}; "
                        "default %(default)s)")
    p.add_argument("--pairs", type=int, default=3, help="rounds; each runs every kind once (default %(default)s)")
    p.add_argument("--perception", choices=PERCEPTIONS, default="surrogate", help="default %(default)s")
    p.add_argument("--timesteps", type=int, default=40960, help="env steps per run (default %(default)s)")
    p.add_argument("--n-envs", type=int, default=8, help="envs per run (default %(default)s)")
    p.add_argument("--train-args", default="",
                   help="more options of weather-gym train for every run, in one string (e.g. '--n-steps 64')")
    p.add_argument("--out", type=Path, help="also write the markdown table to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def parse_vecs(text: str) -> list[str]:
    """``--vecs``: distinct known kinds, at least one.

    Example:
        >>> parse_vecs("dummy, split")
        ['dummy', 'split']
    """
    kinds = [k.strip() for k in text.split(",") if k.strip()]
    bad = [k for k in kinds if k not in VEC_KINDS]
    if not kinds or bad or len(set(kinds)) != len(kinds):
        raise InputError(f"--vecs must be distinct kinds among {', '.join(VEC_KINDS)}, comma-separated, got {text!r}")
    return kinds


def final_fps(run: Path) -> float:
    """SB3's last ``time/fps`` in the run folder's ``progress.csv``."""
    logs = sorted(run.glob("logs/*/progress.csv"))
    if not logs:
        raise InputError(f"{run}: no logs/*/progress.csv (did the training run finish?)")
    with logs[-1].open(newline="") as f:
        values = [row["time/fps"] for row in csv.DictReader(f) if row.get("time/fps")]
    if not values:
        raise InputError(f"{logs[-1]}: no time/fps value")
    return float(values[-1])


def time_run(folder: Path, vec: str, args) -> tuple[float, float]:
    """``(fps, wall s)`` of one ``weather-gym train`` run with ``--vec vec``."""
    cmd = [sys.executable, "-m", "weather_gym.cli", "train", "--out", str(folder), "--perception", args.perception,
           "--timesteps", str(args.timesteps), "--n-envs", str(args.n_envs), "--vec", vec,
           "--pretrain", "none", "--eval-freq", "0", *args.train_args.split()]  # PPO's env steps alone
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise InputError(f"weather-gym train --vec {vec} failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return final_fps(folder), wall


def _run(args) -> int:
    kinds = parse_vecs(args.vecs)
    if args.pairs < 1 or args.timesteps < 1 or args.n_envs < 1:
        raise InputError(f"--pairs, --timesteps and --n-envs must be >= 1, got {args.pairs}, {args.timesteps}, "
                         f"{args.n_envs}")
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, suffixes=(".md", ".txt"), what="--out")
    fps: dict[str, list[float]] = {k: [] for k in kinds}
    rows = []
    with tempfile.TemporaryDirectory(prefix="wg_bench_train_") as tmp:
        for r in range(args.pairs):
            row: list[object] = [r + 1]
            for k in kinds:
                f, wall = time_run(Path(tmp) / f"{k}_{r}", k, args)
                fps[k].append(f)
                row.append(f"{f:,.0f} ({wall:.1f})")
                print(f"round {r + 1}: --vec {k}: {f:,.0f} env-steps/s, {wall:.1f} s", flush=True)
            row += [f"{fps[k][-1] / fps[kinds[0]][-1]:.2f}" for k in kinds[1:]]
            rows.append(row)
    rows.append(["median", *(f"{statistics.median(fps[k]):,.0f}" for k in kinds),
                 *(f"{statistics.median(a / b for a, b in zip(fps[k], fps[kinds[0]], strict=True)):.2f}"
                   for k in kinds[1:])])
    header = ["round", *(f"--vec {k} env-steps/s (wall s)" for k in kinds), *(f"{k} vs {kinds[0]}" for k in kinds[1:])]
    text = (f"PPO training, --perception {args.perception}, {args.n_envs} envs, {args.timesteps} steps per run, "
            f"SB3 time/fps, kinds alternating, baseline --vec {kinds[0]}\n{machine_line()}\n\n"
            f"{markdown_table(header, rows)}\n")
    print(text)
    if args.out is not None:
        atomic_write(args.out, text, overwrite=args.overwrite)
    return 0
