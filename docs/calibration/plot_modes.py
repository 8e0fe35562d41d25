"""Relative mAP against k for every mode of droplets and dim, with the study's points and Table 2 levels.

The default metric is mAP@0.5 over blue and yellow cones, the study's two classes and the presets' metric.

    python docs/calibration/plot_modes.py docs/calibration/curves.csv --dataset-id POOL_ID --dataset-id MIX_ID \
        --out docs/calibration/modes.png

A curve file may hold a mode's curve on several sets (rows keyed by ``dataset_id``): ``--dataset-id``
(repeatable) picks the sets in order of preference, each mode drawn from the first set that has it.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from weather_gym.lab.calibration.curve import load_curves  # noqa: E402

PANELS = {
    "droplets": (("droplets", "faithful (the study's white discs)"), ("droplets_refractive", "refractive (shipped)")),
    "low_light": (("dim", "faithful (the study's brightness factor)"), ("dim_physical", "physical"),
                  ("dim_night", "night (shipped)")),
}
STUDY_FIG7 = {"droplets": (0.55, 0.490 / 0.715), "low_light": (0.78, 0.273 / 0.715)}  # its simulated runs


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("curves", nargs="+", type=Path)
    ap.add_argument("--table2", type=Path, default=Path("docs/calibration/study_table2.csv"))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--metric", default="map50_blue_yellow", help="curve column (default: the presets' metric)")
    ap.add_argument("--dataset-id", action="append", default=None,
                    help="evaluation set(s) to draw from, in order of preference (default: the file's only set)")
    args = ap.parse_args(argv)
    curves = {}
    for ds_id in args.dataset_id or [None]:
        for path in args.curves:
            for label, c in load_curves(path, metric=args.metric, dataset_id=ds_id).items():
                curves.setdefault(label, c)
    rows = [r for r in csv.DictReader(line for line in args.table2.open() if not line.startswith("#"))
            if r["domain"] == "real" and r["condition"] in PANELS]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), dpi=110)
    for ax, (cond, modes) in zip(axes, PANELS.items(), strict=True):
        for label, name in modes:
            if label not in curves:
                continue
            c = curves[label]
            mean, sd = c.scaled(relative=True)
            ax.plot(c.ks, mean, "-o", ms=2.5, lw=1.6, label=f"{name}, {len(c.seeds)} seeds")
            ax.fill_between(c.ks, mean - sd, mean + sd, alpha=0.2, lw=0)
        for r in rows:
            if r["condition"] == cond:
                ax.axhline(float(r["relative_to_ideal"]), color="k", lw=0.7, ls=":")
                ax.text(1.005, float(r["relative_to_ideal"]), f"S{r['severity']}", fontsize=7, va="center")
        k, rel = STUDY_FIG7[cond]
        ax.plot([k], [rel], "k*", ms=10, label="the study's Figure 7 point (its simulator)")
        ax.set_title(cond.replace("_", " "))
        ax.set_xlabel("k")
        ax.set_xlim(0, 1)
        ax.set_ylim(-0.03, 1.08)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    axes[0].set_ylabel(f"relative {args.metric} (mean ± 1 sd over seeds)")
    fig.suptitle("Each mode's damage to the shipped detector; dotted: the study's measured severities (Table 2)",
                 fontsize=9)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
