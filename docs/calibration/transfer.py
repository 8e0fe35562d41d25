"""Do the calibrated presets transfer? Each preset's relative mAP on evaluation sets it was not calibrated on.

For every set given with ``--set NAME=DIR`` (a COCO folder: a rendered held-out track, the realistic
world, imported real frames with their ignore mask) and every calibrated preset of ``--presets``
(default: the shipped ``weather_gym/weather/presets.toml``), the shipped detector scores the set clean and
under the preset's effect with ``--seeds`` weather realisations; the relative mAP is the mean over seeds
divided by the clean mAP of the same set (the study's "relative to ideal"), in the metric the presets
were calibrated on (their ``metric`` field, e.g. ``map50_blue_yellow``). Cells run on the evaluation
runner (parallel, resumable: ``OUT/cells.csv``). Writes ``OUT/transfer.csv`` (one row per set and
preset), ``OUT/transfer.md`` (the table: target, achieved per set, the spread across sets) and
``OUT/transfer.png``.

    python docs/calibration/transfer.py --set peanut=scratch/calib/held_peanut --seeds 2 --out /tmp/tr
"""

from __future__ import annotations

import argparse
import csv
import math
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
from weather_gym.weather.presets import load_presets

TOLERANCE = 0.05


def _preset_effect(entry: dict) -> tuple[SweepEffect, float] | None:
    """The one effect of a calibrated preset as (sweep effect, k); None for the clear severity."""
    effects = entry.get("effects") or []
    if not effects:
        return None
    if len(effects) != 1:
        raise SystemExit(f"preset {entry['condition']}@{entry['severity']}: transfer checks one effect per preset")
    table = dict(effects[0])
    name, k = table.pop("name"), float(table.pop("k"))
    return SweepEffect(name, table), k


def parse_set_args(argv: list[str] | None, description: str) -> tuple[argparse.Namespace, dict[str, str], dict, str]:
    """The arguments of a script that scores presets on ``--set NAME=DIR`` sets: ``(args, sets, presets file, metric)``."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--set", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--presets", default=None, help="presets TOML (default: the shipped one)")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    data = load_presets(args.presets)
    return args, dict(s.split("=", 1) for s in args.set), data, str(data.get("metric", "map50")).split()[0]


def main(argv: list[str] | None = None) -> None:
    args, sets, data, metric = parse_set_args(argv, __doc__.split("\n\n")[0])
    presets = [{"condition": cond, "severity": sev, **entry}
               for cond, rows in data["presets"].items()
               for sev, entry in rows.items() if entry.get("calibrated") and sev > 0]
    seeds = list(range(args.seeds))
    out = Path(args.out)
    cells = []
    for path in sets.values():
        wanted: dict[str, tuple[SweepEffect, set[float]]] = {}
        for p in presets:
            got = _preset_effect(p)
            if got is None:
                continue
            eff, k = got
            wanted.setdefault(eff.label, (eff, {0.0}))[1].add(k)
        for eff, ks in wanted.values():
            cells += make_sweep_cells([eff], [0.0], [0], path)
            cells += make_sweep_cells([eff], sorted(ks - {0.0}), seeds, path)
    rows = run_cells(cells, run_sweep_cell, out / "cells.csv", key_fields=KEY_FIELDS, workers=args.workers,
                     desc="transfer")
    by = metric_by_cell(cells, rows, metric)

    table = []
    for p in presets:
        got = _preset_effect(p)
        target = float(p["measured_relative"])
        row = {"condition": p["condition"], "severity": p["severity"], "target": target}
        for name, path in sets.items():
            ds = str(Path(path).resolve())
            if got is None:
                rel, sd = 1.0, 0.0
            else:
                eff, k = got
                clean = float(np.mean(by[(ds, eff.label, 0.0)]))
                vals = np.array(by[(ds, eff.label, k)]) / clean if clean > 0 else np.array([math.nan])
                rel, sd = float(vals.mean()), float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
            row[name], row[f"{name}_sd"] = rel, sd
        table.append(row)

    names = list(sets)
    with open(out / "transfer.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    lines = ["| preset | target | " + " | ".join(names) + " | spread | within 0.05 |",
             "|---|---|" + "---|" * len(names) + "---|---|"]
    for row in table:
        vals = [row[n] for n in names]
        ok = sum(abs(v - row["target"]) <= TOLERANCE for v in vals)
        cells_txt = " | ".join(f"{row[n]:.3f} ± {row[n + '_sd']:.3f}" for n in names)
        lines.append(f"| {row['condition']}@{row['severity']} | {row['target']:.3f} | {cells_txt} | "
                     f"{max(vals) - min(vals):.3f} | {ok} of {len(vals)} |")
    (out / "transfer.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    xs = np.arange(len(table))
    for j, n in enumerate(names):
        ax.errorbar(xs + (j - len(names) / 2) * 0.08, [r[n] for r in table], yerr=[r[n + "_sd"] for r in table],
                    fmt="o", ms=4, label=n)
    ax.scatter(xs, [r["target"] for r in table], marker="_", s=400, c="k", label="study (target)", zorder=5)
    ax.set_xticks(xs, [f"{r['condition'].replace('_', ' ')}\nS{r['severity']}" for r in table], fontsize=8)
    ax.set_ylabel(f"relative {metric}")
    ax.set_ylim(-0.05, 1.1)
    ax.legend(fontsize=7)
    ax.set_title("Shipped presets on other sets (mean ± sd over seeds)")
    fig.tight_layout()
    fig.savefig(out / "transfer.png", dpi=110)


if __name__ == "__main__":
    main()
