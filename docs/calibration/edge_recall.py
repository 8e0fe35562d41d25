"""Which cones low light takes first: recall by where a cone is in the frame and how far, per set.

For every ``--set NAME=DIR`` the shipped detector scores the set clean and at each calibrated
low-light preset (weather seed ``--seed``: the frames of the transfer check's cells of that seed),
and the blue and yellow cones' recall at the detector's operating score (pycocotools' matching at IoU
0.5, as in every recall the project reports) is split by where the cone's box is: cut by the frame
(a side within ``CUT_PX`` of the frame's border), else by whether its centre lies beyond
``EDGE_RADIUS`` (:mod:`weather_gym.lab.datasets.frame_position`) of the frame's half-diagonal ellipse
("edge") or inside it ("centre"), and by the cone's distance (``RANGE_EDGES_M``); and each of those
by its surroundings in the clean frame: grass when the mean colour of the strips beside and below its
box (half its height wide) is green by more than ``GREEN_MARGIN`` code values over red and blue, else
asphalt (the track, a kerb). The split rides on ``score_dataset``'s recall by range, with each cone's
range replaced by its category.

The composition check asks how much of the sets' spread is *where their cones are*: each set's
recall if every category had the recall of all sets pooled, against its actual recall; first with
the categories of place and distance, then with their surroundings too.

Writes ``OUT/edge_recall.csv`` (centre / edge, each cut cone counted where its box centre is),
``OUT/edge_recall_split.csv`` (every category and surroundings) and ``OUT/edge_recall.md`` (the
tables and the checks).

    python docs/calibration/edge_recall.py --set b_shape=scratch/calib/held240_b_shape --out /tmp/edge
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from tqdm import tqdm

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.frame_position import EDGE_RADIUS, edge_radius
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.labels import xyxy_to_xywh
from weather_gym.perception.scoring import score_dataset
from weather_gym.weather.presets import load_presets
from weather_gym.weather.tables import effect_from_table

BLUE_YELLOW = [CONE_CLASSES.index("blue"), CONE_CLASSES.index("yellow")]
RANGE_EDGES_M = (6.0, 12.0)
CUT_PX = 1.0
CATEGORIES = ("centre < 6 m", "centre 6-12 m", "centre > 12 m", "edge < 6 m", "edge 6-12 m", "edge > 12 m",
              "cut by the frame, centre", "cut by the frame, edge")
SURROUNDINGS = ("asphalt", "grass")
GREEN_MARGIN = 10.0
BINS = tuple(np.arange(2 * len(CATEGORIES) + 1) - 0.5)  # "range" 2 i + g: category i, surroundings g
REGIONS = {region: [c for c in CATEGORIES if c.startswith(region) or c.endswith(f", {region}")]
           for region in ("centre", "edge")}
FULL = [(c, s) for c in CATEGORIES for s in SURROUNDINGS]  # in the order of BINS
UNCUT = {region: [c for c in cats if not c.startswith("cut")] for region, cats in REGIONS.items()}


def _on_grass(img: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Per ``[x0, y0, x1, y1]`` box: are the strips beside and below it, half its height wide, green?"""
    h, w = img.shape[:2]
    out = np.zeros(len(boxes), bool)
    for j, (x0, y0, x1, y1) in enumerate(boxes):
        m = max(2, int(0.5 * (y1 - y0)))
        a0, a1, b0, b1 = int(max(0, x0 - m)), int(min(w, x1 + m)), int(max(0, y0)), int(min(h, y1 + m))
        keep = np.ones((b1 - b0, a1 - a0), bool)
        keep[max(0, int(y0) - b0):max(0, int(y1) - b0), max(0, int(x0) - a0):max(0, int(x1) - a0)] = False  # not the box
        px = img[b0:b1, a0:a1][keep].astype(np.float64)
        if len(px):
            r, g, b = px.mean(0)
            out[j] = g > r + GREEN_MARGIN and g > b + GREEN_MARGIN
    return out


class _ByCategory:
    """A ``CocoDataset`` whose blue and yellow cones carry ``2 * category + surroundings`` as their
    range; the other classes are out of every bin (range -1)."""

    def __init__(self, ds) -> None:
        self._ds = ds
        self._ranges: dict[int, np.ndarray] = {}  # per frame: the categories, the same for every condition

    def __getattr__(self, name):
        return getattr(self._ds, name)

    def __len__(self) -> int:
        return len(self._ds)

    def gt(self, i: int) -> dict[str, np.ndarray]:
        g = dict(self._ds.gt(i))
        if i not in self._ranges:
            rec = self._ds.record(i)
            w, h = rec["width"], rec["height"]
            b = np.asarray(g["boxes"], np.float64).reshape(-1, 4)
            edge = edge_radius(xyxy_to_xywh(b), w, h) > EDGE_RADIUS
            cut = (b[:, 0] <= CUT_PX) | (b[:, 1] <= CUT_PX) | (b[:, 2] >= w - CUT_PX) | (b[:, 3] >= h - CUT_PX)
            far = np.digitize(np.asarray(g["ranges"], np.float64), RANGE_EDGES_M)
            cat = 2 * np.where(cut, 6 + edge, 3 * edge + far) + _on_grass(self._ds.image(i), b)
            self._ranges[i] = np.where(np.isin(g["classes"], BLUE_YELLOW), cat, -1).astype(np.float32)
        g["ranges"] = self._ranges[i]
        return g


def _found(recall: float, n: int) -> int:
    return 0 if n == 0 else round(recall * n)


def _sum(row: dict, prefix: str, pairs) -> int:
    return sum(row[f"{prefix} {c}, {s}"] for c, s in pairs)


def _pairs(c: str) -> list[tuple[str, str]]:
    """Category ``c`` on every surroundings."""
    return [(c, s) for s in SURROUNDINGS]


REGION_PAIRS = {region: [p for c in cats for p in _pairs(c)] for region, cats in REGIONS.items()}


def _composition_lines(rows: list[dict], labels: list[str], groups: list[list[tuple[str, str]]]) -> list[str]:
    """Each set's recall against the recall its composition (cones per group of ``groups``) gives with
    the pooled per-group recall."""
    lines = ["| condition | " + " | ".join(r["set"] for r in rows) + " | spread | r |",
             "|---|" + "---|" * len(rows) + "---|---|"]
    n = np.array([[_sum(r, "cones", g) for g in groups] for r in rows], np.float64)
    for label in labels:
        found = np.array([[_sum(r, f"{label} found", g) for g in groups] for r in rows], np.float64)
        pooled = found.sum(0) / np.maximum(n.sum(0), 1)
        actual, expected = found.sum(1) / n.sum(1), (n * pooled).sum(1) / n.sum(1)
        r = float(np.corrcoef(actual, expected)[0, 1])
        for name, v, corr in (("actual", actual, ""), ("from composition", expected, f"{r:.2f}")):
            cells = " | ".join(f"{x:.3f}" for x in v)
            lines.append(f"| {label}: {name} | {cells} | {np.ptp(v):.3f} | {corr} |")
    return lines


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
    labels = [c for c, _ in conditions]
    det = load_detector(None)
    coarse, fine = [], []
    for name, path in tqdm(sets.items(), desc="sets", unit="set"):
        ds = _ByCategory(load_coco(path))
        row = {"set": name}
        for label, table in conditions:
            effect = None if table is None else effect_from_table(table)
            r = score_dataset(ds, det, effect, seed=args.seed, range_bins=BINS)
            for (c, s), (rec, n) in zip(FULL, r.recall_by_range.values(), strict=True):
                row[f"{label} found {c}, {s}"], row[f"cones {c}, {s}"] = _found(rec, n), n
        fine.append(row)
        out = {"set": name}
        for label in labels:
            for region, pairs in REGION_PAIRS.items():
                n = _sum(row, "cones", pairs)
                out[f"{label} {region}"] = _sum(row, f"{label} found", pairs) / n if n else float("nan")
            if label == "clear":
                out.update({f"cones {region}": _sum(row, "cones", pairs) for region, pairs in REGION_PAIRS.items()})
        coarse.append(out)
    args.out.mkdir(parents=True, exist_ok=True)
    for fname, rows in (("edge_recall.csv", coarse), ("edge_recall_split.csv", fine)):
        with open(args.out / fname, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    lines = [f"Blue and yellow cones found at the detector's operating score (IoU 0.5), weather seed {args.seed}; "
             f"edge: box centre beyond {EDGE_RADIUS} of the frame's half-diagonal ellipse.", "",
             "| set | cones: centre / edge | " + " | ".join(f"{c}: centre / edge" for c in labels) + " |",
             "|---|---|" + "---|" * len(labels)]
    for r in coarse:
        cells = " | ".join(f"{r[f'{c} centre']:.3f} / {r[f'{c} edge']:.3f}" for c in labels)
        lines.append(f"| {r['set']} | {r['cones centre']} / {r['cones edge']} | {cells} |")
    lines += ["", f"By distance and whether the frame cuts the box (a side within {CUT_PX:g} px of the border): "
              "found / cones.", "",
              "| set | condition | " + " | ".join(CATEGORIES) + " |", "|---|---|" + "---|" * len(CATEGORIES)]
    for r in fine:
        for label in labels:
            cells = " | ".join(f"{_sum(r, f'{label} found', _pairs(c))} / {_sum(r, 'cones', _pairs(c))}"
                               for c in CATEGORIES)
            lines.append(f"| {r['set']} | {label} | {cells} |")
    heads = [f"{region}, {s}" for region in UNCUT for s in SURROUNDINGS]
    lines += ["", "The cones the frame does not cut, by where they are and what surrounds them in the clean frame "
              f"(grass: the strips beside and below the box green by more than {GREEN_MARGIN:g} code values): "
              "found / cones.", "",
              "| set | condition | " + " | ".join(heads) + " |", "|---|---|" + "---|" * len(heads)]
    for r in fine:
        for label in labels:
            cells = " | ".join(f"{_sum(r, f'{label} found', [(c, s) for c in cats])} / "
                               f"{_sum(r, 'cones', [(c, s) for c in cats])}"
                               for cats in UNCUT.values() for s in SURROUNDINGS)
            lines.append(f"| {r['set']} | {label} | {cells} |")
    lines += ["", "Composition check: each set's recall, and the recall it would have if every category of place "
              "and distance had the recall of all sets pooled (r: their correlation over the sets).", ""]
    lines += _composition_lines(fine, labels, [_pairs(c) for c in CATEGORIES])
    lines += ["", "The same with the surroundings too (every category of place and distance, on asphalt and on "
              "grass).", ""]
    lines += _composition_lines(fine, labels, [[p] for p in FULL])
    (args.out / "edge_recall.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
