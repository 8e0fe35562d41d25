"""``report.md`` and the plots of a gap run (matplotlib, Agg, PNG).

Plots written next to ``report.json``:

* ``gap_before_after.png``: the held-out image-signal gap and the detector's mAP@0.5 (simulated,
  with the measured value as a line) at each stage: input model, after each added effect, final;
* ``perception.png``: AP@0.5 per class and recall by range and by box size, measured against
  simulated before and after;
* ``disagreements.png``: the standardised bias of every signal that disagreed, before and after;
* ``screening_step<N>.png``: the fitting-frame gap against k for every candidate of step N;
* ``frames.png``: one held-out frame as measured, as simulated by the input model and by the final one.

Example:
    >>> from weather_gym.lab.gap.report import markdown
    >>> print(markdown({"mode": "paired", "steps": [], "gap_before": 1.0, "gap_after": 1.0}).splitlines()[0])
    # Sim-versus-measured gap report
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from weather_gym.core._figures import save_figure
from weather_gym.core._io import atomic_write
from weather_gym.core._markdown import markdown_table

__all__ = ["write_plots", "write_markdown", "markdown"]


def _f(v: Any, fmt: str = ".3f") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return format(v, fmt) if isinstance(v, int | float) else str(v)


def _ci(ci: Any, fmt: str = ".3f") -> str:
    if not ci or any(c is None for c in ci):
        return ""
    return f" [{_f(ci[0], fmt)}, {_f(ci[1], fmt)}]"


PLOT_NAMES = ("gap_before_after.png", "perception.png", "disagreements.png", "frames.png")
"""The plots :func:`write_plots` may write."""


def write_plots(report: dict[str, Any], session: Any, out: str | os.PathLike, *, overwrite: bool = False) -> list[str]:
    """Write the plots (see module doc); returns their file names."""

    matplotlib.use("Agg")

    out = Path(out)
    names = []

    def save(fig, name: str) -> None:
        fig.tight_layout()
        save_figure(fig, out / name, overwrite=overwrite, dpi=110)
        names.append(name)

    # 1. gap trajectory
    stages = report.get("stages") or [{"label": "input model", "gap": report.get("gap_before")},
                                      {"label": "final model", "gap": report.get("gap_after")}]
    labels = [s["label"] for s in stages]
    x = np.arange(len(stages))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    gaps = np.array([np.nan if s.get("gap") is None else s["gap"] for s in stages], dtype=float)
    colors = ["#b54"] + ["#58a"] * (len(stages) - 1)
    axes[0].bar(x, gaps, color=colors)
    finite = gaps[np.isfinite(gaps) & (gaps > 0)]
    if finite.size and finite.max() > 20 * finite.min():
        axes[0].set_yscale("log")
    for xi, g in zip(x, gaps):
        axes[0].annotate(_f(float(g)), (xi, g), ha="center", va="bottom", fontsize=8)
    axes[0].set_xticks(x, labels, rotation=20, ha="right")
    axes[0].set_ylabel("image-signal gap (held-out)")
    axes[0].set_title("image signals (lower is better)")
    maps = np.array([np.nan if s.get("map50_sim") is None else s["map50_sim"] for s in stages], dtype=float)
    cis = [s.get("map50_diff_ci95") for s in stages]
    meas = stages[0].get("map50_measured")
    err = np.array([[0.0, 0.0] if not c or None in c else [abs(c[1] - c[0]) / 2] * 2 for c in cis]).T
    axes[1].bar(x, maps, color=colors, yerr=err, capsize=4, label="simulated")
    if meas is not None:
        axes[1].axhline(meas, color="k", ls="--", label="measured")
    axes[1].set_xticks(x, labels, rotation=20, ha="right")
    axes[1].set_ylim(0, 1)
    axes[1].set_ylabel("mAP@0.5 (held-out)")
    axes[1].set_title("perception (error bar: half the 95 % interval of the difference)", fontsize=9)
    axes[1].legend(loc="lower right")
    save(fig, "gap_before_after.png")

    # 2. perception detail
    pb, pa = report.get("perception_before"), report.get("perception_after")
    if pb and pa:
        save(_perception_figure(pb, pa), "perception.png")

    # 3. disagreements before / after
    before = {r["signal"]: r for r in report.get("disagreements", []) if r.get("level") == "image"}
    after = {r["signal"]: r for r in report.get("disagreements_after", []) if r.get("level") == "image"}
    sig = [n for n, r in before.items() if r.get("significant")] + [
        n for n, r in after.items() if r.get("significant") and not before.get(n, {}).get("significant")]
    if sig:
        sig = sig[:24]
        fig, ax = plt.subplots(figsize=(8, 0.3 * len(sig) + 1.4))
        y = np.arange(len(sig))
        b0 = [before[n].get("standardized") or 0.0 for n in sig]
        b1 = [after.get(n, {}).get("standardized") or 0.0 for n in sig]
        ax.barh(y + 0.2, b0, 0.4, color="#b54", label="input model")
        ax.barh(y - 0.2, b1, 0.4, color="#58a", label="final model")
        ax.set_yticks(y, sig)
        ax.invert_yaxis()
        ax.set_xscale("symlog", linthresh=1.0)
        ax.axvline(0, color="k", lw=0.8)
        ax.set_xlabel("standardised bias (sim - measured) / sigma, held-out")
        ax.set_title("signals that disagreed")
        ax.legend(loc="best", fontsize=8)
        save(fig, "disagreements.png")

    # 4. screening curves
    for i, s in enumerate(report.get("steps", []), 1):
        if not s.get("screening"):
            continue
        save(_screening_figure(i, s), f"screening_step{i}.png")

    # 5. one frame
    if session is not None:
        try:
            frames = _frame_panel(session)
        except Exception:  # a plot must never fail the run
            frames = None
        if frames is not None:
            fig, axes = plt.subplots(2, 3, figsize=(12, 5.2), gridspec_kw={"height_ratios": [1.4, 1]})
            for j, (title, img, crop) in enumerate(frames):
                axes[0, j].imshow(img)
                axes[0, j].set_title(title, fontsize=9)
                axes[1, j].imshow(crop, interpolation="nearest")
                for ax in (axes[0, j], axes[1, j]):
                    ax.set_axis_off()
            save(fig, "frames.png")
    return names


def _perception_figure(pb: dict[str, Any], pa: dict[str, Any]) -> plt.Figure:
    """``perception.png``: AP@0.5 per class, recall by range and by box height; measured, and simulated by
    the input model (``pb``, the report's ``perception_before``) and the final one (``pa``)."""
    groups = [("per_class", "AP@0.5 per class"), ("recall_by_range", "recall by range"),
              ("recall_by_size", "recall by box height")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, (key, title) in zip(axes, groups):
        cats = [c for c in pb[key] if pb[key][c]["measured"] is not None or pb[key][c]["sim"] is not None]
        xx = np.arange(len(cats))
        for j, (lab, vals, col) in enumerate((("measured", [pb[key][c]["measured"] for c in cats], "#333"),
                                              ("sim, input model", [pb[key][c]["sim"] for c in cats], "#b54"),
                                              ("sim, final model", [pa[key][c]["sim"] for c in cats], "#58a"))):
            ax.bar(xx + (j - 1) * 0.27, [np.nan if v is None else v for v in vals], 0.27, label=lab, color=col)
        ax.set_xticks(xx, cats, rotation=20, ha="right")
        ax.set_ylim(0, 1.05)
        ax.set_title(title)
    axes[0].legend(loc="lower left", fontsize=8)
    return fig


def _screening_figure(i: int, s: dict[str, Any]) -> plt.Figure:
    """``screening_step<i>.png``: the fitting-frame gap against k of every candidate screened in step ``s``
    (the chosen one in bold black)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    chosen = s["added"]["name"]
    for c in s["screening"]:
        ks, gs = zip(*c["curve"])
        hl = c["candidate"].split("(")[0] == chosen and c["candidate"] == s["fit"]["candidate"]
        ax.plot(ks, gs, "-o" if hl else "-", lw=2.5 if hl else 1, ms=4, label=c["candidate"],
                color=None if not hl else "k", zorder=3 if hl else 2)
    if s.get("fit_gap_before") is not None:
        ax.axhline(s["fit_gap_before"], color="gray", ls=":", lw=1, label="model before this step")
    ax.set_yscale("log")
    ax.set_xlabel("k")
    ax.set_ylabel("gap on the fitting frames")
    ax.set_title(f"step {i}: every candidate on a k grid (chosen: {s['added']['describe']})", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    return fig


def _frame_panel(session: Any) -> list[tuple[str, np.ndarray, np.ndarray]] | None:
    d = session.data
    if not len(d.held):
        return None
    held_ev = session.held_ev
    j = 0
    best = -1.0
    for i, idx in enumerate(d.held if d.paired else d.held[:1]):
        g = d.measured.gts[idx]
        h = (g["boxes"][:, 3] - g["boxes"][:, 1]) if len(g["boxes"]) else np.zeros(0)
        if h.size and float(h.max()) > best:
            best, j = float(h.max()), i
    meas = d.measured.images[d.held[j]]
    first = held_ev.frames(session.input_model)[j] if d.paired else held_ev.frames(session.input_model)[0]
    last = held_ev.frames(session.model)[j] if d.paired else held_ev.frames(session.model)[0]
    g = d.measured.gts[d.held[j]]
    h, w = meas.shape[:2]
    if len(g["boxes"]):
        k = int(np.argmax(g["boxes"][:, 3] - g["boxes"][:, 1]))
        x1, y1, x2, y2 = g["boxes"][k]
        cx, cy, half = (x1 + x2) / 2, (y1 + y2) / 2, max(x2 - x1, y2 - y1) * 0.9 + 8
    else:
        cx, cy, half = w / 2, h / 2, h / 6
    xa, xb = int(max(cx - half, 0)), int(min(cx + half, w))
    ya, yb = int(max(cy - half, 0)), int(min(cy + half, h))
    return [("measured", meas, meas[ya:yb, xa:xb]), ("simulated, input model", first, first[ya:yb, xa:xb]),
            ("simulated, final model", last, last[ya:yb, xa:xb])]


def markdown(report: dict[str, Any]) -> str:  # noqa: C901 (one section per finding kind, in order)
    """The text of ``report.md``."""
    r = report
    lines = ["# Sim-versus-measured gap report", ""]
    fr = r.get("frames", {})
    lines += [f"- measured data: `{r.get('measured', '?')}` ({fr.get('measured', '?')} frames, "
              f"{'x'.join(str(v) for v in fr.get('size', []))}, tracks {', '.join(fr.get('tracks', []))})",
              f"- input model: `{r.get('model_input') or 'clean simulator'}`; updated model: `{r.get('model', '?')}`",
              f"- mode: **{r.get('mode')}** ({r.get('mode_reason', '')})",
              f"- frames: {fr.get('fit', '?')} for fitting (of which {fr.get('fit_used', '?')} used by the search), "
              f"{fr.get('held_out', '?')} held out; every gap below is on the held-out frames"]
    if r.get("reference"):
        lines.insert(3, f"- measured clear reference: `{r['reference']}` ({fr.get('reference', '?')} frames)")
    for n in r.get("notes", []):
        lines.append(f"- note: {n}")
    missing = r.get("missing_effects", [])
    lines += ["", f"**Verdict:** {r.get('verdict', '')}", "",
              f"**Missing effects:** {', '.join(missing) if missing else 'none'}", ""]
    if r.get("confounded"):
        lines += [f"**Confounded.** {r.get('confounded_reason', '')}", ""]
    if r.get("perception_warning"):
        lines += [f"**Perception:** {r['perception_warning']}", ""]
    dom = r.get("domain")
    if dom:
        lines += ["## Domain differences (not weather, never fitted)" if not r.get("confounded") else
                  "## Differences from the clean simulator (domain or weather: cannot tell)", "",
                  f"Compared: {dom.get('compared', '')}.", ""]
        if dom.get("differences"):
            lines += markdown_table(["difference", "signals", "detail"],
                                    [[d["name"], ", ".join(d.get("signals", [])[:6]), d["detail"]]
                                     for d in dom["differences"]])
        else:
            lines.append("None significant.")
        if dom.get("perception"):
            lines += ["", "Detector mAP@0.5 (held-out): " + ", ".join(f"{k.replace('map50_', '')} {_f(v)}"
                                                                      for k, v in dom["perception"].items())]
        lines.append("")
    if r.get("flagged"):
        lines += ["## Flagged (fit on a bound, not added)", ""]
        for f in r["flagged"]:
            lines.append(f"- step {f['step']}: `{f['describe']}` ends on {', '.join(f['bounds'])}; held-out gap "
                         f"{_f(f['gap_before'])} -> {_f(f['gap_after'])}. {f['why']}")
        lines.append("")
    if r.get("beyond_range"):
        lines += ["## Beyond the family's range (added, flagged)", ""]
        for b in r["beyond_range"]:
            lines.append(f"- `{b['name']}`: {b['flag']}; clipped: {', '.join(b['clipped'])}")
        lines.append("")
    measured = [s_ for s_ in r.get("steps", []) if s_.get("measured")]
    if measured:
        lines += ["## Measured members (the parametric effects fell short)", ""]
        for s_ in measured:
            m = s_["measured"]
            close = m.get("closest_parametric")
            lines.append(f"- `{s_['added']['name']}` ({m['kind']}): {m['shape']}; closest parametric effect: "
                         + (f"`{close['describe']}` (held-out gap {_f(close['held_gap'])})" if close and
                            close.get("held_gap") is not None else f"`{close['describe']}` (fitting-frame gap "
                            f"{_f(close.get('fit_gap'))})" if close else "none")
                         + f"; {m['why']}")
        lines.append("")
    u = r.get("unexplained")
    if u:
        lines += ["## Unexplained", "", f"Held-out gap {_f(u['gap'])} with the final model; disagreeing: "
                  + ", ".join(f"{x['signal']} ({x['family']})" for x in u["signals"][:8]), ""]
        for a in u.get("closest", []):
            lines.append(f"- closest: `{a['describe']}`: {_f(a['gap_before'])} -> {_f(a['gap_after'])}, stopped: {a['why']}")
        lines.append("")
    if r.get("pruned"):
        lines += ["## Dropped by the parsimony check", ""]
        for p_ in r["pruned"]:
            lines.append(f"- `{p_['name']}`: held-out gap {_f(p_['gap_without'])} without it, {_f(p_['gap_with'])} "
                         f"with it (p = {_f(p_['p_value'], '.4f')}): not significantly better with it")
        lines.append("")

    pb, pa = r.get("perception_before"), r.get("perception_after")
    lines += ["## Perception gap", ""]
    if pb and pa:
        table = [["mAP@0.5", _f(pb["map50_measured"]), _f(pb["map50_sim"]), _f(pa["map50_sim"])],
                 ["sim - measured", "", f"{_f(pb['diff'], '+.3f')}{_ci(pb['diff_ci95'])}",
                  f"{_f(pa['diff'], '+.3f')}{_ci(pa['diff_ci95'])}"]]
        for key, title in (("per_class", "AP@0.5"), ("recall_by_range", "recall"), ("recall_by_size", "recall")):
            for c, v in pb[key].items():
                if v["measured"] is None and v["sim"] is None:
                    continue
                table.append([f"{title} {c}", _f(v["measured"]), _f(v["sim"]), _f(pa[key][c]["sim"])])
        for k, v in pb["scores"].items():
            table.append([k, _f(v["measured"]), _f(v["sim"]), _f(pa["scores"][k]["sim"])])
        lines += markdown_table(["", "measured", "simulated, input model", "simulated, final model"], table)
        lines += ["", f"Perception gap |mAP_sim - mAP_measured|: **{_f(r.get('perception_gap_before'))} -> "
                      f"{_f(r.get('perception_gap_after'))}** (95 % bootstrap intervals over frames in brackets).", ""]
    else:
        lines += ["(perception not run)", ""]

    gb, ga = r.get("gap_before"), r.get("gap_after")
    ratio = (ga / gb) if isinstance(gb, float) and isinstance(ga, float) and gb > 0 else None
    lines += ["## Image-signal gap", "",
              f"Gap (weighted RMS of standardised signal biases, lower is better): **{_f(gb)} -> {_f(ga)}**"
              + (f" ({_f(ratio, '.1%')} of before)" if ratio is not None else ""), ""]

    steps = r.get("steps", [])
    if steps:
        lines += ["## Steps", "", *markdown_table(
            ["step", "added", "gap before -> after", "reduction (95 % CI)", "p", "\\|mAP gap\\|", "evidence"],
            [[i, f"`{s['added']['describe']}`", f"{_f(s['gap_before'])} -> {_f(s['gap_after'])}",
              _ci(s["reduction_ci95"]).strip(), _f(s["p_value"], ".4f"),
              f"{_f(s['perception_gap_before'])} -> {_f(s['perception_gap_after'])}", s["evidence"]["summary"]]
             for i, s in enumerate(steps, 1)])]
        lines.append("")
        for i, s in enumerate(steps, 1):
            alts = ", ".join(f"`{a['describe']}` {_f(a['held_gap'])}" for a in s.get("alternatives", [])[1:])
            screened = sorted(s.get("screening", []), key=lambda c: c["fit_gap"])[:5]
            lines.append(f"Step {i}: fully fitted runner-up(s): {alts or 'none'}; best of the k-grid screening: "
                         + ", ".join(f"{c['candidate']} (k={_f(c['k'], '.2f')}: {_f(c['fit_gap'])})" for c in screened))
        lines.append("")
    if r.get("refits"):
        lines += ["## Re-fitted parameters", "", *markdown_table(
            ["effect", "changed", "gap before -> after"],
            [[f["name"], ", ".join(f"{p} {_f(a, '.4g')} -> {_f(b, '.4g')}" for p, (a, b) in f["changed"].items()),
              f"{_f(f['gap_before'])} -> {_f(f['gap_after'])}"] for f in r["refits"]])]
        lines.append("")

    lines += ["## Disagreements", "",
              "Held-out frames; effect size = difference / bootstrap std; significant = Holm-corrected "
              f"at alpha = {r.get('settings', {}).get('alpha', 0.01)} and |standardised bias| >= "
              f"{r.get('settings', {}).get('min_effect', 0.5)}.", ""]
    for title, key in (("input model", "disagreements"), ("final model", "disagreements_after")):
        rows = [d for d in r.get(key, []) if d.get("significant")]
        lines += [f"**{title}:** {len(rows)} significant", ""]
        if rows:
            lines += markdown_table(
                ["signal", "level", "sim", "measured", "difference (95 % CI)", "effect size"],
                [[d["signal"], d["level"], _f(d["sim"], ".4g"), _f(d["measured"], ".4g"),
                  f"{_f(d['difference'], '+.4g')}{_ci(d['ci95'], '.3g')}", _f(d["effect_size"], ".1f")]
                 for d in rows[:30]])
            lines.append("")

    lines += ["## Updated model", "", "```toml"]
    model_path = r.get("model")
    if model_path and Path(model_path).is_file():
        lines += Path(model_path).read_text().rstrip().splitlines()
    lines += ["```", ""]
    if r.get("plots"):
        lines += ["## Figures", ""] + [f"![{p}]({p})" for p in r["plots"]] + [""]
    if r.get("timings"):
        lines += ["## Timings (s)", "", ", ".join(f"{k} {v}" for k, v in r["timings"].items()), ""]
    return "\n".join(lines)


def write_markdown(report: dict[str, Any], path: str | os.PathLike, *, overwrite: bool = False) -> None:
    atomic_write(path, markdown(report), overwrite=overwrite)
