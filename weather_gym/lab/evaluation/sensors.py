"""Which sensor carries the stack: camera-only, LiDAR-only and fused stacks side by side per weather.

``weather-gym evaluate --stacks detector,lidar,fused --conditions clear,rain:8mm/h,fog:60m,dusk:20lux``
runs every stack through the same physical weathers (:mod:`weather_gym.conditions`), tracks and seeds in
one results file; :func:`write_sensor_report` writes ``OUT/sensors.md`` (per track: a row per weather, a
column per stack, each cell ``lap time / cones hit / cone recall``, and the stack that carries it: the
one that completes the lap with the fewest cones hit, then the fastest) and the plots
``OUT/plots/sensors_<metric>.png`` (grouped bars: weather x stack) and ``OUT/plots/sensors_recall_by_range.png``
(the cone list's recall against range, one panel per weather, one line per stack).

Example:
    >>> from weather_gym.lab.evaluation.sensors import carrier
    >>> rows = [{"perception": p, "status": "ok", "completed": c, "cones_hit": h, "lap_time_s": t}
    ...         for p, c, h, t in (("detector", 0, 0, None), ("lidar", 1, 2, 20.0), ("fused", 1, 0, 21.0))]
    >>> carrier(rows)
    'fused'
    >>> carrier(rows[:1] + [{**rows[0], "perception": "lidar"}])
    'tie: camera, LiDAR'
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_write
from weather_gym.core._markdown import markdown_table
from weather_gym.lab.evaluation.metrics import cone_list_bins

__all__ = ["BAR_METRICS", "carrier", "plot_recall_by_range", "plot_sensor_bars", "write_sensor_report"]

BAR_METRICS: tuple[str, ...] = ("completed", "lap_time_s", "cones_hit", "off_track_events", "cone_recall",
                                "cone_precision", "det_map50")
"""Metrics drawn as grouped bars (weather x stack)."""
STACK_NAMES = {"detector": "camera", "lidar": "LiDAR", "fused": "fused"}


def _num(v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return math.nan
    return f


def _mean(rows: Sequence[Mapping[str, Any]], metric: str) -> float:
    vals = [_num(r.get(metric)) for r in rows if r.get("status") == "ok"]
    vals = [v for v in vals if math.isfinite(v)]
    return float(np.mean(vals)) if vals else math.nan


def carrier(rows: Sequence[Mapping[str, Any]]) -> str:
    """The stack (``perception``) that does best in ``rows`` (one weather): the most laps completed,
    then the fewest cones hit, then the shortest lap, then the farthest progress; ``tie: a, b`` when
    several are equal on all four; ``-`` when none ran."""
    keys: dict[str, tuple[float, ...]] = {}
    for p in dict.fromkeys(r.get("perception") for r in rows):
        sub = [r for r in rows if r.get("perception") == p]
        if not any(r.get("status") == "ok" for r in sub):
            continue
        done, hit, lap, prog = (_mean(sub, m) for m in ("completed", "cones_hit", "lap_time_s", "progress"))
        keys[str(p)] = (-(done if math.isfinite(done) else 0.0), hit if math.isfinite(hit) else math.inf,
                        lap if math.isfinite(lap) else math.inf, -(round(prog, 3) if math.isfinite(prog) else 0.0))
    if not keys:
        return "-"
    best = min(keys.values())
    who = [p for p, k in keys.items() if k == best]
    return who[0] if len(who) == 1 else "tie: " + ", ".join(STACK_NAMES.get(p, p) for p in who)


def _cell(rows: Sequence[Mapping[str, Any]]) -> str:
    ok = [r for r in rows if r.get("status") == "ok"]
    if not ok:
        return "failed" if rows else "-"
    done, lap, hit, rec = (_mean(ok, m) for m in ("completed", "lap_time_s", "cones_hit", "cone_recall"))
    if done >= 1 and math.isfinite(lap):
        head = f"{lap:.2f} s"
    else:
        reasons = sorted({str(r.get("end_reason")) for r in ok})
        head = f"{'/'.join(reasons)} at {100 * _mean(ok, 'progress'):.0f} %"
    return f"{head}, {hit:.0f} hit, recall {rec:.2f}" if math.isfinite(rec) else f"{head}, {hit:.0f} hit"


def plot_sensor_bars(rows: Sequence[Mapping[str, Any]], metric: str, path: str | Path, *,
                     overwrite: bool = False) -> Path:
    """Grouped bars of ``metric`` (mean over tracks and seeds): a group per weather, a bar per stack."""
    matplotlib.use("Agg")
    weathers = list(dict.fromkeys(r["effect"] for r in rows))
    stacks = list(dict.fromkeys(r["perception"] for r in rows))
    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(weathers), 3.6))
    w = 0.8 / max(1, len(stacks))
    for i, p in enumerate(stacks):
        vals = [_mean([r for r in rows if r["effect"] == e and r["perception"] == p], metric) for e in weathers]
        xs = np.arange(len(weathers)) + (i - (len(stacks) - 1) / 2) * w
        ax.bar(xs, np.nan_to_num(vals, nan=0.0), w, label=STACK_NAMES.get(p, p), color=f"C{i}")
        for x, v in zip(xs, vals):
            ax.text(x, 0 if not math.isfinite(v) else v, "n/a" if not math.isfinite(v) else f"{v:.2g}",
                    ha="center", va="bottom", fontsize=7)
    ax.set_xticks(np.arange(len(weathers)), weathers, rotation=15, fontsize=8)
    ax.set_ylabel(metric)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8, title="stack", title_fontsize=8)
    ax.set_title(f"{metric} per weather and stack (mean over tracks and seeds)", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite, dpi=110)


def plot_recall_by_range(rows: Sequence[Mapping[str, Any]], path: str | Path, *, overwrite: bool = False) -> Path:
    """The cone list's recall against range: one panel per weather, one line per stack."""
    matplotlib.use("Agg")
    weathers = list(dict.fromkeys(r["effect"] for r in rows))
    stacks = list(dict.fromkeys(r["perception"] for r in rows))
    bins = cone_list_bins()
    fig, axes = plt.subplots(1, len(weathers), figsize=(3.2 * len(weathers), 3.2), squeeze=False, sharey=True)
    for ax, e in zip(axes[0], weathers):
        for i, p in enumerate(stacks):
            sub = [r for r in rows if r["effect"] == e and r["perception"] == p]
            ys = [_mean(sub, f"cone_recall_{suffix}") for suffix, _ in bins]
            ax.plot(range(len(bins)), ys, "-o", color=f"C{i}", label=STACK_NAMES.get(p, p), ms=4)
        ax.set_xticks(range(len(bins)), [label for _, label in bins], fontsize=7)
        ax.set_title(e, fontsize=9)
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("cone list recall (ahead)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("recall of the cones ahead by range from the camera, per weather and stack", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite, dpi=110)


def write_sensor_report(rows: Sequence[Mapping[str, Any]], out_dir: str | Path, *, command: str | None = None,
                        overwrite: bool = False) -> Path:
    """``out_dir/sensors.md`` and its plots (module doc); returns the report's path."""
    out = Path(out_dir)
    rows = [r for r in rows if r.get("effect") is not None]
    stacks = list(dict.fromkeys(r["perception"] for r in rows))
    md = ["# Which sensor carries the stack", ""]
    if command:
        md += ["Command:", "", f"```\n{command}\n```", ""]
    md += ["Each cell: lap time (or why the episode ended, and how far it got), cones hit, the recall of the "
           "cones ahead in the cone list the agent read; mean over seeds. Stacks: "
           + ", ".join(f"`{p}` ({STACK_NAMES.get(p, p)})" for p in stacks) + ".", ""]
    for t in dict.fromkeys(r["track"] for r in rows):
        sub = [r for r in rows if r["track"] == t]
        md += [f"## {t}", ""]
        table = []
        for e in dict.fromkeys(r["effect"] for r in sub):
            cells = [r for r in sub if r["effect"] == e]
            table.append([e, *(_cell([r for r in cells if r["perception"] == p]) for p in stacks),
                          STACK_NAMES.get(carrier(cells), carrier(cells))])
        md += markdown_table(["weather", *(STACK_NAMES.get(p, p) for p in stacks), "carries"], table) + [""]
    md += ["## Plots", ""]
    for m in BAR_METRICS:
        if any(math.isfinite(_num(r.get(m))) for r in rows if r.get("status") == "ok"):
            p = plot_sensor_bars(rows, m, out / "plots" / f"sensors_{m}.png", overwrite=overwrite)
            md += [f"![{m}](plots/{p.name})", ""]
    p = plot_recall_by_range(rows, out / "plots" / "sensors_recall_by_range.png", overwrite=overwrite)
    md += [f"![recall by range](plots/{p.name})", ""]
    path = out / "sensors.md"
    atomic_write(path, "\n".join(md), overwrite=overwrite)
    return path
