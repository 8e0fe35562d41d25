"""Which cones low light takes first: recall near the frame's edge and in its centre, per set.

For every ``--set NAME=DIR`` the shipped detector scores the set clean and at each calibrated
low-light preset (weather seed ``--seed``: the frames of the transfer check's cells of that seed),
and the blue and yellow cones' recall at the detector's operating score (pycocotools' matching at IoU
0.5, as in every recall the project reports) is split by where the cone's box centre is: beyond
``EDGE_RADIUS`` (:mod:`weather_gym.datasets.frame_position`) of the frame's half-diagonal ellipse
("edge") or inside it ("centre"). The split rides on ``score_dataset``'s recall by range, with each
cone's range replaced by its region.
Writes ``OUT/edge_recall.csv`` and ``OUT/edge_recall.md``.

    python docs/calibration/edge_recall.py --set b_shape=scratch/calib/held240_b_shape --out /tmp/edge
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from tqdm import tqdm

from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.datasets.coco import load_coco
from weather_gym.datasets.frame_position import EDGE_RADIUS, edge_radius
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.labels import xyxy_to_xywh
from weather_gym.perception.scoring import score_dataset
from weather_gym.weather.presets import load_presets
from weather_gym.weather.tables import effect_from_table

BLUE_YELLOW = [CONE_CLASSES.index("blue"), CONE_CLASSES.index("yellow")]
REGIONS = (0.0, 0.5, 1.5)  # "range" 0: centre, 1: edge


class _ByRegion:
    """A ``CocoDataset`` whose blue and yellow cones carry their region (0 centre, 1 edge) as their
    range; the other classes are out of every bin (range -1)."""

    def __init__(self, ds) -> None:
        self._ds = ds

    def __getattr__(self, name):
        return getattr(self._ds, name)

    def __len__(self) -> int:
        return len(self._ds)

    def gt(self, i: int) -> dict[str, np.ndarray]:
        g = dict(self._ds.gt(i))
        rec = self._ds.record(i)
        region = (edge_radius(xyxy_to_xywh(g["boxes"]), rec["width"], rec["height"]) > EDGE_RADIUS).astype(np.float32)
        g["ranges"] = np.where(np.isin(g["classes"], BLUE_YELLOW), region, -1.0).astype(np.float32)
        return g


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", required=True, metavar="NAME=DIR")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)
    sets = {}
    for text in args.set:
        name, sep, path = text.partition("=")
        if not sep or not name or not path:
            raise SystemExit(f"--set must be NAME=DIR, got {text!r}")
        sets[name] = path
    data = load_presets()
    conditions = [("clear", None)] + [(f"low_light@{sev}", e["effects"][0])
                                      for sev, e in sorted(data["presets"]["low_light"].items())
                                      if e.get("calibrated") and sev in (1, 2)]
    det = load_detector(None)
    rows = []
    for name, path in tqdm(sets.items(), desc="sets", unit="set"):
        ds = _ByRegion(load_coco(path))
        row = {"set": name}
        for label, table in conditions:
            effect = None if table is None else effect_from_table(table)
            r = score_dataset(ds, det, effect, seed=args.seed, range_bins=REGIONS)
            (centre, n_centre), (edge, n_edge) = r.recall_by_range.values()
            row.update({f"{label} centre": centre, f"{label} edge": edge, "cones centre": n_centre,
                        "cones edge": n_edge})
        rows.append(row)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "edge_recall.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    labels = [c for c, _ in conditions]
    lines = [f"Blue and yellow cones found at the detector's operating score (IoU 0.5), weather seed {args.seed}; "
             f"edge: box centre beyond {EDGE_RADIUS} of the frame's half-diagonal ellipse.", "",
             "| set | cones: centre / edge | " + " | ".join(f"{c}: centre / edge" for c in labels) + " |",
             "|---|---|" + "---|" * len(labels)]
    for r in rows:
        cells = " | ".join(f"{r[f'{c} centre']:.3f} / {r[f'{c} edge']:.3f}" for c in labels)
        lines.append(f"| {r['set']} | {r['cones centre']} / {r['cones edge']} | {cells} |")
    (args.out / "edge_recall.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
