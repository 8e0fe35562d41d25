"""Reports of an evaluation: aggregated Markdown table and metric-vs-severity plots (matplotlib, Agg).

``write_report(rows, out_dir)`` writes ``out_dir/report.md`` and ``out_dir/plots/<metric>.png``
(one line per effect and agent, mean over seeds with the spread over seeds shaded: min to max, and
each seed as a dot). ``aggregate`` is the mean / std / count over seeds behind both.

Example:
    >>> from weather_gym.evaluation.report import aggregate
    >>> rows = [{"effect": "dim", "severity": 0, "seed": s, "status": "ok", "progress": p}
    ...         for s, p in enumerate([1.0, 0.8])]
    >>> agg = aggregate(rows, ("effect", "severity"), ("progress",))
    >>> agg[0]["progress_mean"], round(agg[0]["progress_std"], 3), agg[0]["n"]
    (0.9, 0.141, 2)
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from weather_gym._io import atomic_write, save_figure
from weather_gym.evaluation.metrics import METRICS
from weather_gym.weather.presets import DEFAULT_PRESETS, preset_entry

__all__ = ["PLOT_METRICS", "TABLE_METRICS", "aggregate", "plot_metric", "report_paths", "write_report"]

TABLE_METRICS: tuple[str, ...] = (
    "completed", "progress", "lap_time_s", "cones_hit", "off_track_events", "cte_mean_m", "cte_max_m",
    "map_precision", "map_recall", "det_map50", "added_latency_ms",
)
"""Columns of the report's table (mean ± std over seeds)."""

PLOT_METRICS: tuple[str, ...] = (
    "progress", "completed", "lap_time_s", "cones_hit", "off_track_events", "cte_mean_m",
    "map_precision", "map_recall", "det_map50", "added_latency_ms",
)
"""One plot each (metrics with no value in any row are skipped)."""

LABELS = {
    "completed": "lap completion (share of seeds)",
    "progress": "progress along the lap (0..1)",
    "lap_time_s": "lap time (s)",
    "cones_hit": "cones hit",
    "off_track_events": "off-track events",
    "cte_mean_m": "mean cross-track error (m)",
    "cte_max_m": "max cross-track error (m)",
    "map_precision": "map precision (0.5 m)",
    "map_recall": "map recall (0.5 m)",
    "det_map50": "detector mAP@0.5 on frames seen",
    "added_latency_ms": "added latency per step (ms)",
}


def _num(v: Any) -> float:
    if v is None:
        return math.nan
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _hashable(v: Any) -> Any:
    """Group-by value: lists/dicts (parsed JSON columns) as their canonical JSON text."""
    return json.dumps(v, sort_keys=True) if isinstance(v, (list, dict)) else v


def aggregate(rows: Iterable[Mapping[str, Any]], group_by: Sequence[str], metrics: Sequence[str]) -> list[dict]:
    """Mean, std (ddof 1; 0 for one value) and count over the ``ok`` rows of each group, per metric.

    Groups appear in order of first appearance; ``n`` counts ok rows, ``n_failed`` failed ones.
    A metric with no finite value in a group has mean/std NaN.
    """
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    failed: dict[tuple, int] = {}
    for r in rows:
        key = tuple(_hashable(r.get(g)) for g in group_by)
        groups.setdefault(key, [])
        failed.setdefault(key, 0)
        if r.get("status") == "ok":
            groups[key].append(r)
        else:
            failed[key] += 1
    out = []
    for key, members in groups.items():
        rec: dict[str, Any] = dict(zip(group_by, key, strict=True))
        rec["n"] = len(members)
        rec["n_failed"] = failed[key]
        for m in metrics:
            vals = np.array([_num(r.get(m)) for r in members], dtype=np.float64)
            vals = vals[np.isfinite(vals)]
            rec[f"{m}_mean"] = float(vals.mean()) if vals.size else math.nan
            rec[f"{m}_std"] = float(vals.std(ddof=1)) if vals.size > 1 else (0.0 if vals.size else math.nan)
            rec[f"{m}_min"] = float(vals.min()) if vals.size else math.nan
            rec[f"{m}_max"] = float(vals.max()) if vals.size else math.nan
            rec[f"{m}_count"] = int(vals.size)
        out.append(rec)
    return out


def _fmt(mean: float, std: float, count: int) -> str:
    if not math.isfinite(mean):
        return "–"
    digits = 3 if abs(mean) < 10 else 1
    return f"{mean:.{digits}f}" if count < 2 else f"{mean:.{digits}f} ± {std:.{digits}f}"


def _has_values(rows: Sequence[Mapping[str, Any]], metric: str) -> bool:
    return any(r.get("status") == "ok" and math.isfinite(_num(r.get(metric))) for r in rows)


def plot_metric(rows: Sequence[Mapping[str, Any]], metric: str, path: str | Path, *, x: str = "severity",
                line: Sequence[str] = ("agent", "effect"), panel: str = "track", title: str | None = None,
                overwrite: bool = False) -> Path:
    """``metric`` against ``x``: one panel per ``panel`` value, one line per ``line`` combination.

    Each line is the mean over the ok rows (seeds) at each x; the band spans their min..max, dots are
    the individual rows. Lines whose ``line`` fields are constant over all rows are labelled by the
    varying fields only.
    """

    matplotlib.use("Agg")

    ok = [r for r in rows if r.get("status") == "ok"]
    panels = list(dict.fromkeys(_hashable(r.get(panel)) for r in rows))
    varying = [f for f in line if len({_hashable(r.get(f)) for r in rows}) > 1] or list(line[-1:])
    fig, axes = plt.subplots(1, len(panels), figsize=(5.6 * len(panels), 4.0), squeeze=False, sharey=True)
    for ax, pv in zip(axes[0], panels, strict=True):
        sub = [r for r in ok if _hashable(r.get(panel)) == pv]
        keys = list(dict.fromkeys(tuple(_hashable(r.get(f)) for f in varying) for r in sub))
        for i, key in enumerate(keys):
            members = [r for r in sub if tuple(_hashable(r.get(f)) for f in varying) == key]
            agg = aggregate(members, (x,), (metric,))
            agg = [a for a in agg if math.isfinite(a[f"{metric}_mean"])]
            agg.sort(key=lambda a: a[x])
            if not agg:
                continue
            color = f"C{i % 10}"
            xs = np.array([a[x] for a in agg], dtype=float)
            label = " / ".join(str(k) for k in key)
            ax.plot(xs, [a[f"{metric}_mean"] for a in agg], "-o", color=color, label=label, lw=2, ms=4)
            ax.fill_between(xs, [a[f"{metric}_min"] for a in agg], [a[f"{metric}_max"] for a in agg],
                            color=color, alpha=0.18, lw=0)
            pts = [(_num(r.get(x)), _num(r.get(metric))) for r in members]
            pts = [(a, b) for a, b in pts if math.isfinite(a) and math.isfinite(b)]
            if pts:
                px, py = np.array(pts).T
                ax.scatter(px + 0.06 * (i - (len(keys) - 1) / 2), py, s=10, color=color, alpha=0.55, lw=0)
        ax.set_title(f"{panel} {pv}" if len(panels) > 1 or pv is not None else "")
        ax.set_xlabel(x)
        xs_all = sorted({r.get(x) for r in rows if r.get(x) is not None})
        if xs_all and all(isinstance(v, (int, np.integer)) for v in xs_all):
            ax.set_xticks(xs_all)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, title=" / ".join(varying), title_fontsize=8)
    axes[0][0].set_ylabel(LABELS.get(metric, metric))
    fig.suptitle(title or f"{LABELS.get(metric, metric)} vs {x}\nline: mean over seeds, band: min..max, dots: seeds",
                 fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite, dpi=110)


def _severity_table(rows: Sequence[Mapping[str, Any]], presets: str | None) -> list[str]:
    seen = list(dict.fromkeys((r.get("effect"), r.get("severity"), _hashable(r.get("weather"))) for r in rows))
    lines = ["| effect | severity | weather (preset effect list) | k |", "|---|---|---|---|"]
    try:
        def status(e: Any, s: Any) -> str:
            try:
                return "calibrated" if preset_entry(str(e), int(s), presets)["calibrated"] else "nominal"
            except (ValueError, TypeError):
                return "?"

        source = presets or str(DEFAULT_PRESETS.name)
        lines.insert(0, f"Severities resolve through the presets file `{source}` (calibrated: k read off a "
                        f"measured perception drop; nominal: a documented choice of k, not measured):\n")
    except Exception:  # noqa: BLE001 - the report still lists the specs the cells used
        def status(e: Any, s: Any) -> str:
            return "?"
    for e, s, w in sorted(seen, key=lambda t: (str(t[0]), _num(t[1]))):
        spec = w if isinstance(w, str) else json.dumps(w)
        lines.append(f"| {e} | {s} | `{spec}` | {status(e, s)} |")
    return lines


def write_report(rows: Sequence[Mapping[str, Any]], out_dir: str | Path, *, config: Any = None,
                 wall_s: float | None = None, command: str | None = None,
                 group_by: Sequence[str] = ("agent", "track", "effect", "severity"),
                 table_metrics: Sequence[str] = TABLE_METRICS,
                 plot_metrics: Sequence[str] = PLOT_METRICS, overwrite: bool = False) -> Path:
    """Write ``out_dir/report.md`` and ``out_dir/plots/*.png`` from evaluation rows; return the report path.

    Existing files are replaced only with ``overwrite`` (see :func:`report_paths`)."""
    out = Path(out_dir)
    plots = out / "plots"
    rows = list(rows)
    n_ok = sum(r.get("status") == "ok" for r in rows)
    failed = [r for r in rows if r.get("status") != "ok"]
    metrics = [m for m in table_metrics if _has_values(rows, m)]
    agg = aggregate(rows, group_by, metrics)

    md: list[str] = ["# Robustness evaluation", ""]
    if command:
        md += ["Command:", "", f"```\n{command}\n```", ""]
    summary = f"{len(rows)} cells: {n_ok} ok, {len(failed)} failed"
    if wall_s is not None:
        summary += f"; this invocation took {wall_s:.0f} s (cells already in results.csv were not re-run)"
    md += [summary + ". Raw rows: [results.csv](results.csv).", ""]
    if config is not None:
        cfg = asdict(config) if is_dataclass(config) else dict(config)
        md += ["| setting | value |", "|---|---|"]
        for k, v in cfg.items():
            text = ", ".join(map(str, v)) if isinstance(v, (list, tuple)) else json.dumps(v, default=str)
            md.append(f"| {k} | {text.replace('|', '/')} |")
        md.append("")

    md += ["## Results (mean ± std over seeds)", ""]
    header = [*group_by, "ok/failed", *metrics]
    md.append("| " + " | ".join(header) + " |")
    md.append("|" + "---|" * len(header))
    for a in agg:
        cells = [str(a[g]) for g in group_by] + [f"{a['n']}/{a['n_failed']}"]
        cells += [_fmt(a[f"{m}_mean"], a[f"{m}_std"], a[f"{m}_count"]) for m in metrics]
        md.append("| " + " | ".join(cells) + " |")
    md.append("")

    written = []
    for m in plot_metrics:
        if _has_values(rows, m):
            written.append(plot_metric(rows, m, plots / f"{m}.png", overwrite=overwrite))
    if written:
        md += ["## Plots", ""]
        for p in written:
            md += [f"![{p.stem}](plots/{p.name})", ""]

    md += ["## Severity table", ""]
    md += _severity_table(rows, getattr(config, "presets", None))
    md.append("")
    if failed:
        md += ["## Failed cells", "", "| " + " | ".join([*group_by, "seed", "error"]) + " |",
               "|" + "---|" * (len(group_by) + 2)]
        for r in failed:
            err = str(r.get("error") or "").replace("|", "\\|")
            md.append("| " + " | ".join([*(str(r.get(g)) for g in group_by), str(r.get("seed")), err]) + " |")
        md.append("")

    md += ["## Metrics", ""] + [f"- `{k}`: {v}" for k, v in METRICS.items()] + [""]
    return atomic_write(out / "report.md", "\n".join(md), overwrite=overwrite)


def report_paths(out_dir: str | Path, plot_metrics: Sequence[str] = PLOT_METRICS) -> list[Path]:
    """The files :func:`write_report` may write in ``out_dir`` (report.md and one plot per metric)."""
    out = Path(out_dir)
    return [out / "report.md", *(out / "plots" / f"{m}.png" for m in plot_metrics)]
