"""Timing helpers shared by the benchmarks: warm-up, then the median of many runs.

Example:
    >>> from weather_gym.lab.bench._timing import median_ms
    >>> median_ms(lambda: sum(range(100)), repeats=20) >= 0
    True
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable, Sequence

from weather_gym.core._markdown import markdown_table as table_lines


def median_ms(fn: Callable[[], object], repeats: int = 50, warmup: int = 5) -> float:
    """Median wall time of ``fn()`` in milliseconds."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times)


def interleaved_ms(fns: dict[str, Callable[[], object]], repeats: int, warmup: int, budget_s: float, run: int = 4,
                   clock: Callable[[], float] = time.perf_counter) -> dict[str, float]:
    """Median milliseconds per call of each function, the functions taking turns.

    Each round gives every function, in turn, one untimed call (its data back in the caches) and
    ``run`` timed calls back to back; ``run=0``: one timed call per round and no untimed one
    (caches as the other functions left them). ``repeats`` timed calls per function at most, fewer
    when that takes much longer than ``budget_s`` (but at least 15 when ``repeats`` allows).
    ``clock``: what a call's time is read from (``time.thread_time``: the CPU time of this thread,
    which leaves out the time other processes hold the core, on a loaded machine).
    """
    t0 = time.perf_counter()
    for _ in range(max(warmup, 1)):
        for fn in fns.values():
            fn()
    per_call = (time.perf_counter() - t0) / max(warmup, 1)  # one call of each
    calls = min(repeats, max(15, int(budget_s / max(per_call * (1 + 1 / max(run, 1)), 1e-9))))
    times: dict[str, list[float]] = {k: [] for k in fns}
    while len(next(iter(times.values()))) < calls:
        for k, fn in fns.items():
            if run:
                fn()
            for _ in range(max(run, 1)):
                t = clock()
                fn()
                times[k].append(clock() - t)
    return {k: 1000.0 * statistics.median(v) for k, v in times.items()}


def machine_line() -> str:
    """One line describing the machine the numbers were taken on."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, {platform.system()}"


def markdown_table(header: list[str], rows: Sequence[Sequence[object]]) -> str:
    """``rows`` under ``header`` as a Markdown table (tabulate), floats to 3 decimals."""
    def fmt(v: object) -> str:
        return f"{v:.3f}" if isinstance(v, float) else str(v)

    return "\n".join(table_lines(header, [[fmt(v) for v in r] for r in rows]))
