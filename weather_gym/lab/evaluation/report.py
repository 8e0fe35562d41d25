"""Reports of an evaluation: aggregated Markdown table and metric-vs-severity plots (matplotlib, Agg).

``write_report(rows, out_dir)`` writes ``out_dir/report.md`` (Markdown tables by tabulate) and
``out_dir/plots/<metric>.png`` (one line per effect and agent, mean over seeds with the spread over
seeds shaded: min to max, and each seed as a dot): the table's columns and the plots are the metrics
of :data:`weather_gym.lab.evaluation.metrics.METRICS` marked ``table`` / ``plot``. ``aggregate`` is the
mean / std / count over seeds behind both. ``weather-gym evaluate`` writes the report after the grid
ran (:func:`report_replaceable` first, so a report someone else wrote is refused before any cell runs).

Example:
    >>> from weather_gym.lab.evaluation.report import aggregate
    >>> rows = [{"effect": "dim", "severity": 0, "seed": s, "status": "ok", "progress": p}
    ...         for s, p in enumerate([1.0, 0.8])]
    >>> agg = aggregate(rows, ("effect", "severity"), ("progress",))
    >>> agg[0]["progress_mean"], round(agg[0]["progress_std"], 3), agg[0]["n"]
    (0.9, 0.141, 2)
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_write, derived_outputs_replaceable
from weather_gym.core._markdown import markdown_table
from weather_gym.lab.evaluation import metrics as registry
from weather_gym.lab.evaluation.metrics import METRICS
from weather_gym.weather.presets import DEFAULT_PRESETS, preset_entry, preset_source

__all__ = ["aggregate", "plot_metric", "report_paths", "report_replaceable", "write_report"]

def _label(metric: str) -> str:
    m = METRICS.get(metric)
    return (m.label or m.name) if m is not None else metric


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
        xs_all = sorted({r.get(x) for r in rows if r.get(x) is not None})  # type: ignore[type-var]  # Nones left out
        if xs_all and all(isinstance(v, (int, np.integer)) for v in xs_all):
            ax.set_xticks(xs_all)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, title=" / ".join(varying), title_fontsize=8)
    axes[0][0].set_ylabel(_label(metric))
    fig.suptitle(title or f"{_label(metric)} vs {x}\nline: mean over seeds, band: min..max, dots: seeds",
                 fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite, dpi=110)


def _severity_table(rows: Sequence[Mapping[str, Any]], presets: Any) -> list[str]:
    if isinstance(presets, Mapping):  # one presets file per track (e.g. each resolved for its track)
        head = [f"Severities resolve per track: {', '.join(f'{t}: `{p}` ({preset_source(p)})' for t, p in presets.items())}; "
                "results.csv has each cell's k in `weather` and its source in `k_source`.", ""]
        return head + _severity_table(rows, next(iter(presets.values()), None))[1:]
    seen = list(dict.fromkeys((r.get("effect"), r.get("severity"), _hashable(r.get("weather"))) for r in rows))
    lines: list[str] = []
    try:
        def status(e: Any, s: Any) -> str:
            try:
                return "calibrated" if preset_entry(str(e), int(s), presets)["calibrated"] else "nominal"
            except (ValueError, TypeError):
                return "?"

        source = f"{presets or DEFAULT_PRESETS.name}` ({preset_source(presets)}"
        lines.insert(0, f"Severities resolve through the presets file `{source}` (calibrated: k read off a "
                        f"measured perception drop; nominal: a documented choice of k, not measured):\n")
    except Exception:  # noqa: BLE001 - the report still lists the specs the cells used
        def status(e: Any, s: Any) -> str:
            return "?"
    table = [(e, s, f"`{w if isinstance(w, str) else json.dumps(w)}`", status(e, s))
             for e, s, w in sorted(seen, key=lambda t: (str(t[0]), _num(t[1])))]
    return lines + markdown_table(["effect", "severity", "weather (preset effect list)", "k"], table)


PAIR_KEYS = ("track", "effect", "severity", "seed")
"""What two cells share to be compared against each other: the same track, weather and seed."""


def baseline_rows(rows: Sequence[Mapping[str, Any]], baseline: str) -> list[dict[str, Any]]:
    """Each other agent's cell beside the ``baseline`` agent's cell of the same track, weather and seed:
    ``lap_time_ratio`` (its lap time over the baseline's, where both completed the lap), ``cones_hit_diff``
    and ``both_completed``; cells without a baseline cell are left out.

    Example:
        >>> cell = lambda agent, t, hits: {"agent": agent, "track": "a", "effect": "dim", "severity": 1,
        ...                                "seed": 0, "status": "ok", "completed": 1, "lap_time_s": t, "cones_hit": hits}
        >>> [(r["agent"], r["lap_time_ratio"], r["cones_hit_diff"]) for r in baseline_rows(
        ...     [cell("ppo", 22.0, 1), cell("mapper", 20.0, 0)], "mapper")]
        [('ppo', 1.1, 1.0)]
    """
    base = {tuple(_hashable(r.get(k)) for k in PAIR_KEYS): r for r in rows
            if r.get("agent") == baseline and r.get("status") == "ok"}
    out = []
    for r in rows:
        b = base.get(tuple(_hashable(r.get(k)) for k in PAIR_KEYS))
        if r.get("agent") == baseline or r.get("status") != "ok" or b is None:
            continue
        both = bool(_num(r.get("completed")) == 1 and _num(b.get("completed")) == 1)
        t, tb = _num(r.get("lap_time_s")), _num(b.get("lap_time_s"))
        out.append({**{k: r.get(k) for k in ("agent", *PAIR_KEYS)}, "status": "ok", "both_completed": int(both),
                    "lap_time_ratio": t / tb if both and tb > 0 else math.nan,
                    "cones_hit_diff": _num(r.get("cones_hit")) - _num(b.get("cones_hit"))})
    return out


def _baseline_section(rows: Sequence[Mapping[str, Any]], baseline: str, group_by: Sequence[str], plots: Path,
                      overwrite: bool) -> list[str]:
    paired = baseline_rows(rows, baseline)
    md = [f"## Against the baseline agent `{baseline}`", ""]
    if not paired:
        return md + [f"No cell of another agent has a `{baseline}` cell of the same track, weather and seed.", ""]
    md += [f"Each agent's cells beside `{baseline}`'s of the same track, weather and seed: its lap time over "
           f"`{baseline}`'s (where both completed the lap; below 1 is faster), and cones hit minus `{baseline}`'s.", ""]
    keys = [g for g in group_by if g != "seed"]
    agg = aggregate(paired, keys, ("lap_time_ratio", "cones_hit_diff", "both_completed"))
    md += markdown_table([*keys, "pairs", "lap time ratio", "cones hit difference", "both completed"],
                         [[*(a[k] for k in keys), a["n"], _fmt(a["lap_time_ratio_mean"], a["lap_time_ratio_std"],
                                                               a["lap_time_ratio_count"]),
                           _fmt(a["cones_hit_diff_mean"], a["cones_hit_diff_std"], a["cones_hit_diff_count"]),
                           f"{int(round(a['both_completed_mean'] * a['n']))}/{a['n']}"] for a in agg])
    md.append("")
    if _has_values(paired, "lap_time_ratio"):
        p = plot_metric(paired, "lap_time_ratio", plots / "lap_time_ratio.png", overwrite=overwrite,
                        title=f"lap time over {baseline}'s vs severity\nline: mean over seeds, band: min..max, dots: seeds")
        md += [f"![lap time ratio](plots/{p.name})", ""]
    return md


def write_report(rows: Sequence[Mapping[str, Any]], out_dir: str | Path, *, config: Any = None,
                 wall_s: float | None = None, command: str | None = None,
                 group_by: Sequence[str] = ("agent", "track", "effect", "severity"),
                 table_metrics: Sequence[str] | None = None, plot_metrics: Sequence[str] | None = None,
                 baseline: str | None = None, overwrite: bool = False) -> Path:
    """Write ``out_dir/report.md`` and ``out_dir/plots/*.png`` from evaluation rows; return the report path.

    ``table_metrics`` / ``plot_metrics``: default the registry's (``Metric.table`` / ``Metric.plot``).
    ``baseline``: an agent of the grid the others are compared against, cell by cell
    (:func:`baseline_rows`: lap time ratio, cones hit difference; a table and a plot).
    Existing files are replaced only with ``overwrite`` (see :func:`report_paths`)."""
    table_metrics = registry.table_metrics() if table_metrics is None else table_metrics
    plot_metrics = registry.plot_metrics() if plot_metrics is None else plot_metrics
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
        cfg = asdict(config) if is_dataclass(config) else dict(config)  # type: ignore[arg-type]  # an EvalConfig instance or a mapping
        if isinstance(cfg.get("presets"), (str, os.PathLike)) and preset_source(cfg["presets"]) == "pool":
            cfg["presets"] = "pool"  # the shipped presets: their name, not this machine's install path
        settings = [(k, (", ".join(map(str, v)) if isinstance(v, (list, tuple)) else json.dumps(v, default=str))
                     .replace("|", "/")) for k, v in cfg.items()]
        md += [*markdown_table(["setting", "value"], settings), ""]

    md += ["## Results (mean ± std over seeds)", ""]
    md += markdown_table([*group_by, "ok/failed", *metrics],
                         [[*(a[g] for g in group_by), f"{a['n']}/{a['n_failed']}",
                           *(_fmt(a[f"{m}_mean"], a[f"{m}_std"], a[f"{m}_count"]) for m in metrics)] for a in agg])
    md.append("")

    written = []
    for m in plot_metrics:
        if _has_values(rows, m):
            written.append(plot_metric(rows, m, plots / f"{m}.png", overwrite=overwrite))
    if written:
        md += ["## Plots", ""]
        for p in written:
            md += [f"![{p.stem}](plots/{p.name})", ""]

    if baseline is not None:
        md += _baseline_section(rows, baseline, group_by, plots, overwrite)

    md += ["## Severity table", ""]
    md += _severity_table(rows, getattr(config, "presets", None))
    md.append("")
    if failed:
        md += ["## Failed cells", "", *markdown_table(
            [*group_by, "seed", "error"],
            [[*(r.get(g) for g in group_by), r.get("seed"), str(r.get("error") or "").replace("|", "\\|")]
             for r in failed]), ""]

    md += ["## Metrics", ""] + [f"- `{m.name}`: {m.doc}" for m in METRICS.values()] + [""]
    return atomic_write(out / "report.md", "\n".join(md), overwrite=overwrite)


def report_paths(out_dir: str | Path, plot_metrics: Sequence[str] | None = None) -> list[Path]:
    """The files :func:`write_report` may write in ``out_dir`` (report.md and one plot per metric)."""
    out = Path(out_dir)
    names = registry.plot_metrics() if plot_metrics is None else plot_metrics
    return [out / "report.md", *(out / "plots" / f"{m}.png" for m in names), out / "plots" / "lap_time_ratio.png"]


def report_replaceable(out_dir: str | Path, *, overwrite: bool = False) -> bool:
    """May the report of the results in ``out_dir/results.csv`` replace the files there? Call it
    before the grid runs: an existing report or plot in a folder without results.csv is refused
    (``OutputExistsError``) unless ``overwrite``. Returns the ``overwrite`` flag for :func:`write_report`."""
    return derived_outputs_replaceable(Path(out_dir) / "results.csv", report_paths(out_dir), overwrite=overwrite)

