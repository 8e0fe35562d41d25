"""Is the low-light spread over tracks the car's motion blur? The presets scored as if the car stood still.

The night camera lengthens its exposure as the light fades, and the longer exposure smears the frame by
the car's motion (each frame's recorded speed and yaw rate; the twisty tracks turn more). For every
``--set`` and every calibrated low-light preset of ``--presets`` (default: the shipped one), the shipped
detector scores the set clean and under the preset twice, with ``--seeds`` weather realisations: with
the state as recorded, and with the car standing still (speed 0, yaw rate 0: the same exposure, gain,
noise and ISP, no smear). Cells run on the evaluation runner (parallel, resumable: ``OUT/cells.csv``).
Writes ``OUT/still_camera.csv`` (one row per set, preset and state) and ``OUT/still_camera.md`` (both
tables, with the spread over the sets and how many land within 0.05 of the study's target).

    python docs/calibration/still_camera.py --set oval=scratch/calib/held_oval \\
        --set hairpin=scratch/calib/held_hairpin --out /tmp/still
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
from transfer import _preset_effect, parse_set_args  # docs/calibration/transfer.py, beside this script

from weather_gym.lab.calibration.sweep import (
    KEY_FIELDS,
    SweepCell,
    SweepEffect,
    make_sweep_cells,
    metric_by_cell,
    run_sweep_cell,
    score_cell,
)
from weather_gym.lab.evaluation.runner import run_cells
from weather_gym.weather import make

TOLERANCE = 0.05
#: Marks the still variant of an effect in its (key) spec; taken out before the effect is made.
STILL = "still_car"


class _Still:
    """``effect`` with the state's speed and yaw rate set to 0 (no motion smear)."""

    def __init__(self, effect: Any) -> None:
        self.effect = effect

    def reset(self, seed: int) -> None:
        self.effect.reset(seed)

    def __call__(self, image, *, depth=None, state=None, rng=None):
        return self.effect(image, depth=depth, state={**(state or {}), "speed": 0.0, "yaw_rate": 0.0}, rng=rng)


def still_or_recorded_cell(cell: SweepCell) -> dict[str, Any]:
    """:func:`run_sweep_cell`, or with the car standing still when the spec carries :data:`STILL`."""
    spec = json.loads(cell.spec)
    if not spec.pop(STILL, False):
        return run_sweep_cell(cell)
    return score_cell(cell, _Still(make(cell.name, k=float(cell.k), **spec)))


def main(argv: list[str] | None = None) -> None:
    args, sets, data, metric = parse_set_args(argv, __doc__.split("\n\n")[0])
    presets = []
    for sev, entry in sorted(data["presets"].get("low_light", {}).items()):
        got = _preset_effect({**entry, "condition": "low_light", "severity": sev}) if entry.get("calibrated") else None
        if got is not None:
            presets.append((sev, float(entry["measured_relative"]), got[0].name, got[0].params, got[1]))
    if not presets:
        raise SystemExit("no calibrated low-light presets in the presets file")
    seeds = list(range(args.seeds))
    variants = {"as recorded": False, "car standing still": True}
    cells = []
    for path in sets.values():
        for _, _, name, table, k in presets:
            for still in variants.values():
                eff = SweepEffect(name, {**table, STILL: True} if still else table)
                cells += make_sweep_cells([eff], [k], seeds, path)
        name, table = presets[0][2], presets[0][3]
        cells += make_sweep_cells([SweepEffect(name, table)], [0.0], [0], path)
    cells = list({(c.effect, c.k, c.seed, c.dataset): c for c in cells}.values())
    out = Path(args.out)
    rows = run_cells(cells, still_or_recorded_cell, out / "cells.csv", key_fields=KEY_FIELDS,
                     workers=args.workers, desc="still camera")
    by = metric_by_cell(cells, rows, metric)

    table_rows, lines = [], []
    for variant, still in variants.items():
        lines += [f"**{variant}**", "", "| preset | target | " + " | ".join(sets) + " | spread | within 0.05 |",
                  "|---|---|" + "---|" * len(sets) + "---|---|"]
        for sev, target, name, table, k in presets:
            label = SweepEffect(name, {**table, STILL: True} if still else table).label
            clean_label = SweepEffect(name, table).label
            vals = []
            for set_name, path in sets.items():
                ds = str(Path(path).resolve())
                rel = float(np.mean(by[(ds, label, k)]) / np.mean(by[(ds, clean_label, 0.0)]))
                vals.append(rel)
                table_rows.append({"variant": variant, "preset": f"low_light@{sev}", "target": target,
                                   "set": set_name, "relative": rel})
            ok = sum(abs(v - target) <= TOLERANCE for v in vals)
            lines.append(f"| low_light@{sev} | {target:.3f} | " + " | ".join(f"{v:.3f}" for v in vals)
                         + f" | {max(vals) - min(vals):.3f} | {ok} of {len(vals)} |")
        lines.append("")
    with open(out / "still_camera.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table_rows[0]))
        w.writeheader()
        w.writerows(table_rows)
    (out / "still_camera.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
