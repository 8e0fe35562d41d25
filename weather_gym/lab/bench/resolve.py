"""``weather-gym bench resolve``: what presets resolved per scenario cost, first use and cached.

First use: :func:`weather_gym.lab.calibration.resolve.resolve_presets` of one scenario into an empty cache
(``--cache``, default a fresh temporary folder): render the reference set, the clear detections, the
search on k, the bootstrap, the presets file. One run (minutes), wall and CPU seconds both: on a shared
machine the wall time is what others' processes leave. Cached use: the same call again, the median of
``--repeats`` calls (key: the detector file's and the code's hashes; reading the entry), beside the
baseline in the same run: a ``CONDITION@SEVERITY`` read from the shipped pool presets.

Example:
    $ weather-gym bench resolve --track small_track

The command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'resolve', '--track', 'small_track'])
    >>> args.target, args.track, args.repeats
    ('resolve', 'small_track', 200)
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
    p.add_argument("--tolerance", type=float, default=0.02, help="bootstrap standard error accepted (default %(default)s)")
    p.add_argument("--cache", type=Path, default=None,
                   help="cache folder (default: a fresh temporary one, so the first call is a first use)")
    p.add_argument("--repeats", type=int, default=200, help="cached calls timed (default %(default)s)")
    p.set_defaults(func=run)


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000.0)
    return statistics.median(times)


def run(args) -> int:
    if args.repeats < 1:
        raise InputError(f"--repeats must be >= 1, got {args.repeats}")
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
        w0, c0 = time.perf_counter(), time.process_time()
        res = resolve_presets(sc, tolerance=args.tolerance, progress=False)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        first = "(already cached)" if res.cached else f"{wall:.1f} s wall, {cpu:.1f} s CPU (this process)"
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
