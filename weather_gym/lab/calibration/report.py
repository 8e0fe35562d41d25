"""Pictures and the Markdown report of a sweep and a calibration (matplotlib PNGs, like the study's figures).

* :func:`plot_curves` - mAP@0.5 vs k per effect: each seed's points, the mean, the +/- 1 sd band, and
  the relative scale on the right axis (the study's Figures 3 and 5); :func:`plot_recall_by_range`.
* :func:`plot_calibration` - per condition, the curve with the measured severities as horizontal lines
  and the chosen k as vertical lines (as in the study's figures), achieved values as markers.
* :func:`plot_study_comparison` - our curves beside the study's Figure-7 points and Table-2 levels.
* :func:`write_report` - ``calibration_report.md``: the presets, intervals, target vs achieved, shape fits.

Example:
    >>> from weather_gym.lab.calibration.report import study_points
    >>> study_points("no/such.csv")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: study points file no/such.csv not found
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_write
from weather_gym.core._markdown import markdown_table
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.lab.calibration.shapes import STUDY_SHAPE, ShapeFit, fit_shapes

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from weather_gym.lab.calibration.curve import Curve

__all__ = ["agreement", "plot_calibration", "plot_curves", "plot_recall_by_range", "plot_study_comparison",
           "study_points", "write_report"]

COLORS = {"droplets": "tab:blue", "dim": "tab:orange", "dim_physical": "tab:red"}
SEV_COLORS = {1: "#4c9a2a", 2: "#c9a227", 3: "#d9622b", 4: "#8e2c8e"}


def _plt():
    matplotlib.use("Agg")

    return plt


def _save(fig, out: str | os.PathLike, overwrite: bool) -> Path:
    """Save ``fig`` to ``out`` safely (its folder made if needed) and close it."""
    return save_figure(fig, out, overwrite=overwrite, metadata=None)


def _color(label: str, i: int = 0) -> str:
    return COLORS.get(label, f"C{i % 10}")


def plot_curves(curves: Mapping[str, Curve], out: str | os.PathLike, *, recall_out: str | os.PathLike | None = None,
                title: str = "", overwrite: bool = False) -> Path:
    """One panel per curve: seeds as points, mean line, +/- 1 sd band; relative mAP on the right axis."""
    plt = _plt()
    labels = list(curves)
    fig, axes = plt.subplots(1, len(labels), figsize=(4.6 * len(labels), 3.8), dpi=110, squeeze=False)
    for i, (ax, label) in enumerate(zip(axes[0], labels, strict=True)):
        c = curves[label]
        col = _color(label, i)
        for j in range(c.values.shape[1]):
            ax.plot(c.ks, c.values[:, j], ".", ms=3, color=col, alpha=0.45,
                    label=f"{len(c.seeds)} seeds" if j == 0 else None)
        ax.fill_between(c.ks, c.mean - c.sd, c.mean + c.sd, color=col, alpha=0.2, lw=0, label="mean +/- 1 sd")
        ax.plot(c.ks, c.mean, "-", color=col, lw=1.8, label="mean")
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("k")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, max(0.05, float(np.nanmax(c.values)) * 1.08))
        ax.grid(alpha=0.3)
        if i == 0:
            ax.set_ylabel(f"{c.metric} (mAP@0.5)" if c.metric == "map50" else c.metric)
        try:
            ideal = c.ideal
        except ValueError:
            ideal = math.nan
        if ideal > 0:
            sec = ax.secondary_yaxis("right", functions=(lambda y, d=ideal: y / d, lambda r, d=ideal: r * d))
            sec.set_ylabel("relative to k = 0", fontsize=8)
        ax.legend(fontsize=7, loc="lower left")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out = _save(fig, out, overwrite)
    if recall_out is not None:
        plot_recall_by_range(curves, recall_out, overwrite=overwrite)
    return out


def plot_recall_by_range(curves: Mapping[str, Curve], out: str | os.PathLike, *,
                         overwrite: bool = False) -> Path | None:
    """Recall at the detector's operating threshold by cone range, mean over seeds, vs k; None without data."""
    plt = _plt()
    labels = [lb for lb in curves if any(c.startswith("recall_") for c in curves[lb].extra)]
    if not labels:
        return None
    fig, axes = plt.subplots(1, len(labels), figsize=(4.6 * len(labels), 3.6), dpi=110, squeeze=False)
    for ax, label in zip(axes[0], labels, strict=True):
        c = curves[label]
        cols = [k for k in c.extra if k.startswith("recall_")] + (["recall"] if "recall" in c.extra else [])
        for col in cols:
            y = c.extra[col]
            if np.all(np.isnan(y)):
                continue
            name = "all ranges" if col == "recall" else col[len("recall_"):].replace("_", "-").replace("plus-m", "+ m")
            if col == "recall":
                ax.plot(c.ks, y, "--", lw=1.4, label=name, color="k")
            else:
                ax.plot(c.ks, y, "-", lw=1.4, label=name)
        ax.set_title(f"{label}: recall by range", fontsize=10)
        ax.set_xlabel("k")
        ax.set_ylabel("recall (IoU 0.5, operating threshold)")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, out, overwrite)


def plot_calibration(calibs: Sequence[Any], curves: Mapping[str, Curve], out: str | os.PathLike, *,
                     overwrite: bool = False) -> Path:
    """Per condition: the curve in the matched units, measured severities (horizontal), chosen k (vertical)."""
    plt = _plt()
    conds = sorted({c.condition for c in calibs})
    fig, axes = plt.subplots(1, len(conds), figsize=(5.4 * len(conds), 4.2), dpi=110, squeeze=False)
    for i, (ax, cond) in enumerate(zip(axes[0], conds, strict=True)):
        cs = [c for c in calibs if c.condition == cond and c.severity > 0]
        if not cs:
            continue
        curve = curves[cs[0].curve]
        relative = cs[0].match == "relative"
        mean, sd = curve.scaled(relative)
        col = _color(curve.label, i)
        ax.fill_between(curve.ks, mean - sd, mean + sd, color=col, alpha=0.2, lw=0)
        ax.plot(curve.ks, mean, "-", color=col, lw=2, label=f"ours: {curve.label} (mean, +/- 1 sd)")
        for c in cs:
            sc = SEV_COLORS.get(c.severity, "k")
            ax.axhline(c.target, color=sc, ls="--", lw=1)
            ax.text(0.01, c.target, f" S{c.severity} {c.description[:22]}", color=sc, fontsize=7, va="bottom")
            ax.axvline(c.k, color=sc, ls=":" if c.reachable else "-.", lw=1.2)
            ax.axvspan(*c.k_interval, color=sc, alpha=0.08, lw=0)
            if math.isfinite(c.achieved):
                ax.errorbar([c.k], [c.achieved], yerr=[c.achieved_sd if math.isfinite(c.achieved_sd) else 0],
                            fmt="o" if c.reachable else "x", color=sc, ms=6, capsize=3,
                            label=f"S{c.severity}: k = {c.k:.3f}" + ("" if c.reachable else " (unreachable)"))
        ax.set_title(f"{cond} ({'relative' if relative else 'absolute'} matching)", fontsize=10)
        ax.set_xlabel("k")
        ax.set_ylabel("mAP@0.5 / mAP@0.5 at k = 0" if relative else "mAP@0.5")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1.08 if relative else max(0.85, float(np.nanmax(mean)) * 1.1))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    return _save(fig, out, overwrite)


def study_points(path: str | os.PathLike) -> dict[str, tuple[float, float]]:
    """The study's Figure-7 points file (``effect,k,map``; ``#`` comments) -> ``{effect: (k, map)}``."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"study points file {path} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"study points file {path} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    missing = [c for c in ("effect", "k", "map") if c not in (reader.fieldnames or [])]
    if missing:
        raise InputError(f"study points file {path} lacks column(s) {', '.join(missing)}")
    out = {}
    for n, r in enumerate(reader, start=1):
        try:
            k, m = float(r["k"]), float(r["map"])
        except ValueError:
            raise InputError(f"{path}, data row {n}: k and map must be numbers, got {r['k']!r}, {r['map']!r}") from None
        if not (0 <= k <= 1 and 0 <= m <= 1):
            raise InputError(f"{path}, data row {n}: k = {k:g} and map = {m:g} must lie in [0, 1]")
        out[r["effect"].strip()] = (k, m)
    return out


def plot_study_comparison(curves: Mapping[str, Curve], points: Mapping[str, tuple[float, float]],
                          levels: Sequence[Any], out: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """2 x 2: (droplets, dim) x (absolute, relative) - our curves, the study's Figure-7 points (simulator)
    and its Table-2 real-world levels (horizontal lines)."""
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(10.5, 7.6), dpi=110)
    groups = {"droplets": ("droplets", [lb for lb in curves if lb.startswith("droplets")]),
              "dim": ("low_light", [lb for lb in curves if lb.startswith("dim")])}
    sim_clean = points.get("none", (0.0, math.nan))[1]
    real_ideal = next((m.map for m in levels if m.condition == "ideal" and m.domain == "real"), math.nan)
    for row, (effect, (cond, labels)) in enumerate(groups.items()):
        for col, relative in enumerate((False, True)):
            ax = axes[row, col]
            for i, lb in enumerate(labels):
                c = curves[lb]
                mean, sd = c.scaled(relative)
                ax.fill_between(c.ks, mean - sd, mean + sd, color=_color(lb, i), alpha=0.18, lw=0)
                ax.plot(c.ks, mean, "-", color=_color(lb, i), lw=1.8, label=f"ours: {lb}")
            if effect in points and math.isfinite(sim_clean):
                k, m = points[effect]
                ys = [1.0, m / sim_clean] if relative else [sim_clean, m]
                ax.plot([0.0, k], ys, "k*", ms=11, label=f"study, simulator (Fig. 7): k = {k:g} -> "
                        f"{ys[1]:.3f}" + (" rel." if relative else ""))
            for m in levels:
                if m.condition != cond:
                    continue
                y = m.relative if relative else m.map
                if not math.isfinite(y):
                    continue
                sc = SEV_COLORS.get(m.severity, "k")
                ax.axhline(y, color=sc, ls="--", lw=0.9)
                ax.text(0.995, y, f"S{m.severity} {m.description[:18]}", color=sc, fontsize=6.5, ha="right",
                        va="bottom")
            if not relative and math.isfinite(real_ideal):
                ax.axhline(real_ideal, color="0.4", ls="-.", lw=0.8)
                ax.text(0.995, real_ideal, "study real ideal", color="0.4", fontsize=6.5, ha="right", va="bottom")
            ax.set_xlim(0, 1)
            ax.set_ylim(0, 1.08)
            ax.grid(alpha=0.3)
            ax.set_xlabel(f"k_{effect}")
            ax.set_ylabel("mAP@0.5 relative to ideal" if relative else "mAP@0.5")
            ax.set_title(f"{effect}: {'relative' if relative else 'absolute'}", fontsize=10)
            ax.legend(fontsize=6.5, loc="lower left")
    fig.suptitle("ours (our detector, our rendered set) vs the study (YOLOv3-tiny; Table 2 real levels as dashed "
                 "lines, Figure 7 simulator points as stars)", fontsize=8.5)
    fig.tight_layout()
    return _save(fig, out, overwrite)


# ------------------------------------------------------------------------------------------- report
def agreement(effect_name: str, fits: Mapping[str, ShapeFit]) -> str:
    """Whether our curve has the study's shape: its R^2 >= 0.95 and at least the other study shape's."""
    shape = STUDY_SHAPE.get(effect_name)
    if shape is None:
        return "-"
    other = "exponential" if shape == "linear" else "linear"
    r2, r2o = fits[shape].r2, fits[other].r2
    if r2 >= 0.95 and r2 >= r2o:
        return f"yes ({shape} R² {r2:.3f} >= 0.95, and >= {other})"
    if r2 >= r2o:
        return f"partly ({shape} fits better than {other}, but R² {r2:.3f} < 0.95)"
    return f"no ({other} fits better: R² {r2o:.3f} vs {r2:.3f})"


def _f(v: float, nd: int = 3) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.{nd}f}"


def _curve_value_rows(curves: Mapping[str, Curve]) -> list[list[str]]:
    """Rows of the report's "Curve values" table: one per k swept by any curve, with each curve's
    ``mean ± sd (mean / ideal)`` there (blank where that curve did not sweep k)."""
    rows = []
    for k in sorted({float(k) for c in curves.values() for k in c.ks}):
        cells = []
        for c in curves.values():
            i = np.flatnonzero(np.isclose(c.ks, k))
            if i.size == 0:
                cells.append("")
                continue
            m, s = c.mean[i[0]], c.sd[i[0]]
            try:
                rel = f" ({m / c.ideal:.3f})"
            except ValueError:
                rel = ""
            cells.append(f"{m:.3f} ± {s:.3f}{rel}")
        rows.append([f"{k:g}", *cells])
    return rows


def write_report(calibs: Sequence[Any], curves: Mapping[str, Curve], out_dir: str | os.PathLike, *,
                 command: str | None = None, presets_path: str | os.PathLike | None = None,
                 study: Mapping[str, tuple[float, float]] | None = None, levels: Sequence[Any] = (),
                 relative_fits: bool = True, overwrite: bool = False) -> Path:
    """Write ``calibration_report.md`` and ``calibration.png`` (and ``study_comparison.png`` with ``study``);
    existing files only with ``overwrite`` (see :data:`REPORT_FILES`)."""
    out_dir = Path(out_dir)
    plot_calibration(calibs, curves, out_dir / "calibration.png", overwrite=overwrite)
    if study is not None:
        plot_study_comparison(curves, study, levels, out_dir / "study_comparison.png", overwrite=overwrite)
    match = calibs[0].match if calibs else "relative"
    md = ["# Calibration report", ""]
    if command:
        md += ["Generated by:", "", "```bash", command, "```", ""]
    if presets_path:
        md += [f"Presets written to `{presets_path}`.", ""]
    md += [f"Matching: **{match}** ({'mAP / mAP in ideal conditions of the same domain' if match == 'relative' else 'mAP itself'}); "
           "metric: mAP@0.5 (pycocotools). k interval: where mean -/+ 1 sd over seeds meets the target.", ""]
    rows = []
    for lb, c in curves.items():
        try:
            ideal = _f(c.ideal)
        except ValueError:
            ideal = "n/a"
        rows.append([lb, ideal, len(c.seeds), f"{len(c.ks)} ({c.ks[0]:g}..{c.ks[-1]:g})", f"`{c.model_id}`",
                     f"`{c.dataset_id}`"])
    md += ["## Curves", "", *markdown_table(
        ["curve", "clean mAP@0.5 (k = 0)", "seeds", "k values", "model", "eval set"], rows)]
    rows = []
    for c in calibs:
        if c.severity == 0:
            continue
        ach = c.achieved
        diff = ach - c.target if math.isfinite(ach) else math.nan
        rows.append([c.condition, c.severity, c.description, _f(c.measured_map), _f(c.target), f"{c.k:.3f}",
                     f"[{c.k_interval[0]:.3f}, {c.k_interval[1]:.3f}]", _f(c.predicted),
                     f"{_f(ach)} ± {_f(c.achieved_sd)}", _f(diff, 3), _f(c.k_other),
                     "yes" if c.reachable else "**no**", c.note])
    md += ["", "## Presets", "", "![calibration](calibration.png)", "", *markdown_table(
        ["condition", "S", "description", "measured mAP", "target", "k", "k interval", "predicted",
         "achieved (mean ± sd)", "achieved − target", f"k if {'absolute' if match == 'relative' else 'relative'}",
         "reachable", "note"], rows)]
    sources = sorted({c.achieved_source for c in calibs if c.severity > 0 and c.achieved_source})
    if sources:
        md += ["", "Achieved: " + "; ".join(sources) + "."]
    md += ["", "## Shapes", "",
           "Two-parameter least-squares fits to the mean curve (relative to k = 0) over the swept k; the study "
           "reported droplets ≈ linear and dimming ≈ exponential. Logistic (3 parameters) for diagnosis.", ""]
    all_fits = {lb: fit_shapes(c.ks, c.scaled(relative_fits)[0]) for lb, c in curves.items()}
    shapes = []
    for lb, c in curves.items():
        fits, base = all_fits[lb], c.name or lb
        shapes.append([lb, f"{fits['linear'].r2:.3f}", f"{fits['exponential'].r2:.3f}", f"{fits['logistic'].r2:.3f}",
                       STUDY_SHAPE.get(base, "-"), agreement(base, fits)])
    md += markdown_table(["curve", "R² linear", "R² exponential", "R² logistic", "study's shape", "agrees"], shapes)
    md += ["", "Fitted parameters (relative units): " + "; ".join(
        f"{lb}: linear {f['linear'].params['a']:.3f} {f['linear'].params['b']:+.3f} k, "
        f"exponential {f['exponential'].params['a']:.3f} exp(-{f['exponential'].params['b']:.3f} k), "
        f"logistic k50 = {f['logistic'].params['k50']:.3f}"
        for lb, f in all_fits.items()) + "."]
    md += ["", "## Curve values", ""]
    md += markdown_table(["k", *(f"{lb} mAP (rel.)" for lb in curves)], _curve_value_rows(curves))
    if study is not None:
        md += ["", "## Beside the study", "", "![study comparison](study_comparison.png)", ""]
        sim_clean = study.get("none", (0, math.nan))[1]
        beside = []
        for lb, c in curves.items():
            base = c.name or lb
            if base in study:
                k, m = study[base]
                beside.append([lb, f"{k:g}", f"{m:.3f} ({m / sim_clean:.3f})", f"{c.at(k):.3f} ({c.at(k, True):.3f})"])
        md += markdown_table(["effect", "study k (Fig. 7)", "study mAP (rel.)", "ours at that k: mAP (rel.)"], beside)
    return atomic_write(out_dir / "calibration_report.md", "\n".join(md) + "\n", overwrite=overwrite)


REPORT_FILES = ("calibration_report.md", "calibration.png", "study_comparison.png", "remeasured.csv")
"""The files ``weather-gym calibrate`` writes in its report folder."""
