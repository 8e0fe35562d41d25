"""``weather-gym bench resolve``: what presets resolved per scenario cost, first use and cached.

First use: :func:`weather_gym.lab.calibration.resolve.resolve_presets` of one scenario into an empty cache
(``--cache``, default a fresh temporary folder): render the reference set, the clear detections, the
search on k, the bootstrap, the presets file. One run (minutes) with ``--workers`` processes (default: the
usable cores, at most 4) beside the baseline in the same run: one process (``--baseline-workers``, 0 to
skip it), into its own empty cache; wall and CPU seconds (this process and its helpers) both: on a shared
machine the wall time is what others' processes leave. Cached use: the same call again, the median of
``--repeats`` calls (key: the detector file's and the code's hashes; reading the entry), beside the
baseline in the same run: a ``CONDITION@SEVERITY`` read from the shipped pool presets.

Example:
    $ weather-gym bench resolve --track small_track

The command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'resolve', '--track', 'small_track'])
    >>> args.target, args.track, args.repeats, args.baseline_workers
    ('resolve', 'small_track', 200, 1)
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.lab.calibration import resolve as rs
from weather_gym.lab.calibration.resolve import Scenario, resolve_presets
from weather_gym.weather import parse_weather


def register(targets) -> None:
    p = targets.add_parser("resolve", help="presets resolved per scenario: first-use and cached cost",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--track", default="small_track", help="track of the scenario (default %(default)s)")
    p.add_argument("--world", default="plain", choices=("plain", "realistic"), help="world (default %(default)s)")
    p.add_argument("--frames", type=int, default=Scenario.frames, help="reference frames (default %(default)s)")
    p.add_argument("--max-frames", type=int, default=Scenario.max_frames, help="widening limit (default %(default)s)")
    p.add_argument("--tolerance", type=float, default=0.02, help="half-width of the damage's 95 %% interval accepted (default %(default)s)")
    p.add_argument("--cache", type=Path, default=None,
                   help="cache folder (default: a fresh temporary one, so the first call is a first use)")
    p.add_argument("--repeats", type=int, default=200, help="cached calls timed (default %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="processes of the first use (default: the usable cores, at most 4)")
    p.add_argument("--baseline-workers", type=int, default=1,
                   help="processes of the baseline first use (default %(default)s; 0: no baseline run)")
    p.set_defaults(func=run)


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000.0)
    return statistics.median(times)


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished child processes (the resolution's helpers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _first_use(sc: Scenario, tolerance: float, workers: int, cache: Path) -> tuple[Any, str]:
    os.environ[rs.CACHE_ENV] = str(cache)
    load = os.getloadavg()[0]
    w0, c0 = time.perf_counter(), _cpu_s()
    res = resolve_presets(sc, tolerance=tolerance, progress=False, workers=workers)
    wall, cpu = time.perf_counter() - w0, _cpu_s() - c0
    if res.cached:
        return res, "(already cached)"
    return res, (f"{wall:.1f} s wall, {cpu:.1f} s CPU ({workers} process{'es' if workers > 1 else ''}, "
                 f"load average {load:.1f} at the start)")


def run(args) -> int:
    if args.repeats < 1:
        raise InputError(f"--repeats must be >= 1, got {args.repeats}")
    workers = rs.default_workers() if args.workers is None else args.workers
    if workers < 1 or args.baseline_workers < 0:
        raise InputError(f"--workers must be >= 1 and --baseline-workers >= 0, got {workers}, {args.baseline_workers}")
    tmp = None
    if args.cache is None:
        tmp = tempfile.TemporaryDirectory(prefix="weather-gym-bench-resolve-")
        args.cache = Path(tmp.name)
    saved = os.environ.get(rs.CACHE_ENV)
    os.environ[rs.CACHE_ENV] = str(args.cache)
    try:
        sc = Scenario(tracks=(args.track,), scene=args.world, frames=args.frames, max_frames=args.max_frames)
        print(machine_line())
        print(f"load average {os.getloadavg()[0]:.2f} (other processes on the same cores slow every number)")
        base = None
        if args.baseline_workers:
            with tempfile.TemporaryDirectory(prefix="weather-gym-bench-resolve-base-") as tmp_base:
                base_res, base = _first_use(sc, args.tolerance, args.baseline_workers, Path(tmp_base))
        res, first = _first_use(sc, args.tolerance, workers, args.cache)
        if base is not None and [r.k for r in base_res.rows] != [r.k for r in res.rows]:
            raise RuntimeError("the baseline and the timed first use resolved different k's")  # they must not
        cached = _median_ms(lambda: resolve_presets(sc, tolerance=args.tolerance, progress=False), args.repeats)
        rs.code_version.cache_clear()
        rs._sha_cached.cache_clear()
        def cold_call() -> Any:
            rs.code_version.cache_clear()
            rs._sha_cached.cache_clear()
            return resolve_presets(sc, tolerance=args.tolerance, progress=False)

        cold = _median_ms(cold_call, max(args.repeats // 10, 3))
        pool = _median_ms(lambda: parse_weather("low_light@2"), args.repeats)
        resolved = _median_ms(lambda: parse_weather("low_light@2", res.path), args.repeats)
        rows = [["first use (render, search, bootstrap, write)", first],
                *([["baseline: first use in one process" if args.baseline_workers == 1 else
                    f"baseline: first use in {args.baseline_workers} processes", base]] if base else []),
                ["cached use, median (key + read)", f"{cached:.2f} ms"],
                ["cached use, median, hashes recomputed (a new process)", f"{cold:.2f} ms"],
                ["parse 'low_light@2' from the resolved presets file, median", f"{resolved:.3f} ms"],
                ["baseline: parse 'low_light@2' from the shipped pool presets, median", f"{pool:.3f} ms"]]
        print(f"scenario: {res.scenario}; {res.n_frames} reference frames, {sum(r.evals for r in res.rows)} k values measured")
        print(markdown_table(["what", "cost"], rows))
    finally:
        if saved is None:
            os.environ.pop(rs.CACHE_ENV, None)
        else:
            os.environ[rs.CACHE_ENV] = saved
        if tmp is not None:
            tmp.cleanup()
    return 0
