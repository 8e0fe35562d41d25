"""Is the low-light spread over tracks the work of one stage of the night camera?

The night camera (``dim`` in ``mode="night"``) damages the detector with four ISP stages on top of the
physical camera: the denoiser's smear, colour noise, a raised black level and chroma suppression. This
script sweeps the shipped model and variants of it with stages switched off (and the physical camera,
no ISP at all) over k on every ``--set``, with ``--seeds`` weather realisations, on the evaluation
runner (parallel, resumable: ``OUT/cells.csv``). For each of the study's low-light targets it then
puts each variant's k where the mean relative mAP over the ``--set`` sets meets the target (linear
between the grid's k) and gives every set's relative mAP there: does any variant spread less over
the tracks at the same mean damage? ``--extra`` sets (e.g. the realistic world) are reported at that
k but not matched on; ``--match NAME`` (repeatable) matches on the named sets instead (e.g. an
``--extra`` calibration pool, as the presets are). ``--variant NAME=JSON`` (repeatable) sweeps other
night-camera variants instead of the stages (``dim`` parameters as JSON), e.g. bigger colour blotches.
Writes ``OUT/STEM.csv``, ``OUT/STEM.md`` and ``OUT/STEM.png`` (``--stem``, default ``isp_stages``).

    python docs/calibration/isp_stages.py --set oval=scratch/calib/held_oval --set hairpin=scratch/calib/held_hairpin \
        --extra realistic=scratch/calib/held_realistic --out /tmp/isp_stages
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from weather_gym.lab.calibration.sweep import (
    KEY_FIELDS,
    SweepEffect,
    make_sweep_cells,
    metric_by_cell,
    run_sweep_cell,
)
from weather_gym.lab.evaluation.runner import run_cells
from weather_gym.weather import make
from weather_gym.weather.presets import load_presets

TOLERANCE = 0.05
#: The variants: the shipped night camera, the same with stages off, and the physical camera.
VARIANTS = {
    "night (shipped)": {"mode": "night"},
    "no colour noise": {"mode": "night", "chroma_noise": 0.0},
    "no chroma suppression": {"mode": "night", "desaturate": 0.0},
    "chroma suppression only": {"mode": "night", "chroma_noise": 0.0, "black_level": 0.0, "denoise_px": 0.0},
    "colour noise only": {"mode": "night", "desaturate": 0.0, "black_level": 0.0, "denoise_px": 0.0},
    "physical (no ISP)": {"mode": "physical"},
}
#: k grids: the night variants lose every cone by about k = 0.95, the physical camera never does.
NIGHT_KS = np.round(np.arange(0.70, 0.9501, 0.025), 3).tolist()
PHYSICAL_KS = np.round(np.arange(0.75, 1.0001, 0.025), 3).tolist()


def matched(curves: dict[str, dict[float, float]], names: list[str], target: float) -> float | None:
    """The k where the mean over ``names`` of the relative curves first falls to ``target`` (None: not reached)."""
    ks = sorted(set.intersection(*(set(curves[n]) for n in names)))
    mean = np.array([np.mean([curves[n][k] for n in names]) for k in ks])
    for i in range(len(ks) - 1):
        if mean[i] >= target >= mean[i + 1] and mean[i] > mean[i + 1]:
            return float(ks[i] + (mean[i] - target) / (mean[i] - mean[i + 1]) * (ks[i + 1] - ks[i]))
    return None


def parse_variants(ap: argparse.ArgumentParser, items: list[str]) -> dict[str, dict]:
    """``NAME=JSON`` items -> {name: dim parameters}, each checked by building the effect."""
    variants = {}
    for item in items:
        name, sep, spec = item.partition("=")
        try:
            params = json.loads(spec) if sep else None
        except json.JSONDecodeError as exc:
            ap.error(f"--variant {item!r}: the parameters after '=' are not JSON ({exc})")
        if not isinstance(params, dict):
            ap.error(f"--variant {item!r}: expected NAME={{...}}, dim parameters as a JSON object")
        try:
            make("dim", k=0.5, **params)
        except (TypeError, ValueError) as exc:
            ap.error(f"--variant {item!r}: {exc}")
        variants[name] = params
    return variants


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", required=True, metavar="NAME=DIR", help="a set matched on")
    ap.add_argument("--extra", action="append", default=[], metavar="NAME=DIR", help="a set only reported")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=JSON",
                    help="a variant to sweep instead of the stage variants: dim parameters as JSON")
    ap.add_argument("--match", action="append", default=[], metavar="NAME",
                    help="match k on the mean of these sets (--set or --extra names; default: every --set)")
    ap.add_argument("--stem", default="isp_stages", help="name of the result files")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    variants = parse_variants(ap, args.variant) if args.variant else VARIANTS

    sets = dict(s.split("=", 1) for s in args.set)
    extra = dict(s.split("=", 1) for s in args.extra)
    both = {**sets, **extra}
    unknown = [n for n in args.match if n not in both]
    if unknown:
        ap.error(f"--match {unknown[0]!r}: not the name of a --set or --extra ({', '.join(both)})")
    match = args.match or list(sets)
    data = load_presets(None)
    targets = [(sev, float(e["measured_relative"])) for sev, e in data["presets"]["low_light"].items()
               if e.get("calibrated") and 0 < sev < 4]
    metric = str(data.get("metric", "map50")).split()[0]
    seeds = list(range(args.seeds))
    out = Path(args.out)
    effects = {v: SweepEffect("dim", p) for v, p in variants.items()}
    cells = []
    for path in both.values():
        for eff in effects.values():
            cells += make_sweep_cells([eff], [0.0], [0], path)
            cells += make_sweep_cells([eff], PHYSICAL_KS if eff.params.get("mode") == "physical" else NIGHT_KS, seeds,
                                      path)
    rows = run_cells(cells, run_sweep_cell, out / "cells.csv", key_fields=KEY_FIELDS, workers=args.workers,
                     desc="isp stages")
    by = metric_by_cell(cells, rows, metric)

    table = []
    for v, eff in effects.items():
        curves = {}
        for name, path in both.items():
            ds = str(Path(path).resolve())
            clean = float(np.mean(by[(ds, eff.label, 0.0)]))
            curves[name] = {k: float(np.mean(m)) / clean for (d, label, k), m in by.items()
                            if d == ds and label == eff.label and k > 0}
        for sev, target in targets:
            k = matched(curves, match, target)
            row = {"variant": v, "severity": sev, "target": target, "k": k}
            for name in both:
                c = curves[name]
                row[name] = float(np.interp(k, sorted(c), [c[x] for x in sorted(c)])) if k is not None else None
            table.append(row)

    with open(out / f"{args.stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    names = list(both)
    lines = ["| variant | low light | target | k | " + " | ".join(names) + " | spread | within 0.05 |",
             "|---|---|---|---|" + "---|" * len(names) + "---|---|"]
    for row in table:
        if row["k"] is None:
            lines.append(f"| {row['variant']} | S{row['severity']} | {row['target']:.3f} | out of reach |"
                         + " |" * len(names) + " | |")
            continue
        vals = [row[n] for n in sets]
        ok = sum(abs(x - row["target"]) <= TOLERANCE for x in vals)
        lines.append(f"| {row['variant']} | S{row['severity']} | {row['target']:.3f} | {row['k']:.3f} | "
                     + " | ".join(f"{row[n]:.3f}" for n in names)
                     + f" | {max(vals) - min(vals):.3f} | {ok} of {len(vals)} |")
    (out / f"{args.stem}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(targets), figsize=(4 * len(targets), 4), sharey=False)
    for ax, (sev, target) in zip(np.atleast_1d(axes), targets, strict=True):
        rows_s = [r for r in table if r["severity"] == sev]
        for i, r in enumerate(rows_s):
            if r["k"] is None:
                continue
            ax.scatter([i] * len(sets), [r[n] for n in sets], s=14, c="tab:blue",
                       label=("sets matched on" if not args.match else "--set sets") if i == 0 else None)
            if extra:
                ax.scatter([i] * len(extra), [r[n] for n in extra], s=22, marker="x", c="tab:red",
                           label=("sets only reported (--extra)" if not args.match else "--extra sets") if i == 0 else None)
        ax.axhspan(target - TOLERANCE, target + TOLERANCE, color="0.9", zorder=0)
        ax.axhline(target, c="k", lw=1)
        ax.set_xticks(range(len(rows_s)), [r["variant"] for r in rows_s], rotation=35, ha="right", fontsize=7)
        ax.set_title(f"low light S{sev} (target {target:.3f})", fontsize=9)
        ax.set_ylabel(f"relative {metric}")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    if args.match:
        fig.suptitle(f"each variant at the k where the mean of {', '.join(match)} meets the target", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / f"{args.stem}.png", dpi=110)


if __name__ == "__main__":
    main()
