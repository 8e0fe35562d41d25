"""``weather-gym bench gap``: the gap workflow's wall time on large frames, scaled once vs not scaled.

Builds ``--frames`` clean frames at ``--size`` (the simulator with random looks: a stand-in for a
camera's clear recording) and an "adverse" copy with hidden weather (``--weather SPEC``), then times the
whole same-camera run ``weather-gym gap ADVERSE --reference CLEAR`` (loading, signals, the search,
the detector on the held-out frames, the report; plots off) as a user runs it:

* frames scaled once to the comparison size (the default, ``--compare-width 672``);
* baseline in the same run (``--baseline``): the same run at the frames' own size (no scaling).

A run takes minutes, so each row is the median of ``--repeats`` runs (default 1). The frames are
kept in ``--workdir`` (a temporary folder by default) and reused.

Example:
    weather-gym bench gap --frames 200 --size 1024x768 --baseline --out bench_gap.md

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'gap', '--frames', '200', '--size', '1024x768', '--baseline'])
    >>> args.target, args.frames, args.size, args.baseline
    ('gap', 200, '1024x768', True)
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from weather_gym.camera.config import CameraConfig
from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.core.limits import parse_size
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.lab.datasets import render_dataset
from weather_gym.lab.datasets.coco import ANNOTATIONS
from weather_gym.lab.gap.synthetic import degrade_dataset
from weather_gym.lab.gap.workflow import GapConfig, run_gap
from weather_gym.weather.option import add_weather_arg, weather_from_arg


def register(targets) -> None:
    p = targets.add_parser("gap", help="time the gap workflow on large frames (scaled once vs not)",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--frames", type=int, default=200, help="frames per set (default %(default)s)")
    p.add_argument("--size", default="1024x768", help="frame size WxH (default %(default)s)")
    add_weather_arg(p, default="blur:0.5", help="hidden weather of the adverse set (default %(default)s)")
    p.add_argument("--repeats", type=int, default=1, help="timed runs per row (default %(default)s)")
    p.add_argument("--baseline", action="store_true", help="also time the run without scaling (slow)")
    p.add_argument("--workdir", type=Path, default=None, help="keep the frames here (default: a temporary folder)")
    p.add_argument("--out", type=Path, help="also write the markdown table to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def make_sets(root: Path, frames: int, size: tuple[int, int], weather: str) -> tuple[Path, Path, float]:
    """``(clear, adverse, seconds)``: rendered clear frames and a copy with ``weather`` (a spec; reused when present)."""

    t0 = time.perf_counter()
    clear, adverse = root / "clear", root / f"adverse_{weather.replace(':', '_').replace(',', '_')}"
    if not (clear / ANNOTATIONS).is_file():
        render_dataset(clear, tracks=["small_track"], frames=frames, seed=3, randomize=True, frames_per_episode=10,
                       camera=CameraConfig().scaled(*size), progress=True, overwrite=True)
    if not (adverse / ANNOTATIONS).is_file():
        degrade_dataset(clear, adverse, weather_from_arg(weather), seed=4242, progress=True, overwrite=True)
    return clear, adverse, time.perf_counter() - t0


def time_run(clear: Path, adverse: Path, out: Path, compare_width: int | None) -> tuple[float, dict[str, Any]]:
    """Wall time (s) of one same-camera gap run, and its report."""

    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    report = run_gap(adverse, None, out, GapConfig(compare_width=compare_width), reference=clear, plots=False)
    return time.perf_counter() - t0, report


def _run(args) -> int:
    w, h = parse_size(args.size, what="--size", example="1024x768")
    if args.frames < 8 or args.repeats < 1:
        raise InputError("--frames must be >= 8 and --repeats >= 1")
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, suffixes=(".md", ".txt"), what="--out")
    tmp = None
    root = args.workdir
    if root is None:
        tmp = tempfile.TemporaryDirectory(prefix="wg_bench_gap_")
        root = Path(tmp.name)
    try:
        clear, adverse, t_make = make_sets(root, args.frames, (w, h), args.weather)
        print(f"sets ready in {t_make:.0f} s: {clear}, {adverse}")
        rows = []
        cases = [("scaled once (--compare-width 672)", 672)] + ([("baseline: not scaled", None)] if args.baseline else [])
        for label, cw in cases:
            times, report = [], None
            for r in range(args.repeats):
                t, report = time_run(clear, adverse, root / f"out_{cw}_{r}", cw)
                times.append(t)
                print(f"{label}: {t:.1f} s ({', '.join(report['missing_effects']) or 'nothing'} named)")
            assert report is not None  # one run at least (--repeats >= 1)
            size = "x".join(str(v) for v in report["frames"]["size"])
            tm = report["timings"]
            rows.append([label, size, f"{statistics.median(times):.1f}", f"{statistics.median(times) / 60:.2f}",
                         ", ".join(report["missing_effects"]) or "none", f"{report['gap_before']:.2f} -> "
                         f"{report['gap_after']:.3f}", tm.get("simulate_s"), tm.get("diagnose_s"), tm.get("compare_s")])
        table = markdown_table(["run", "compared at", "wall s", "wall min", "named", "held-out gap", "load s",
                                "search s", "compare s"], rows)
        text = (f"gap workflow, same-camera mode, {args.frames} frames at {w}x{h} per set, hidden {args.weather}, "
                f"median of {args.repeats}\n{machine_line()}\n\n{table}\n")
        print(text)
        if args.out is not None:
            atomic_write(args.out, text, overwrite=args.overwrite)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0
