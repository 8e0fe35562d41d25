"""Colour from the stripes, by range: the share of the found cones whose colour is read right and wrong.

    PYTHONPATH=. python docs/lidar/colour.py [--tracks small_track,peanut] [--every 15] [--overwrite]

The scans of docs/lidar/figures.py (a ground-truth lap of each track, every ``--every``-th step, the
HDL-32E), each through a few weathers, ``cones_from_points``; each found cone within 0.5 m of a cone the
clear scan hit with 2 returns or more takes that cone's true colour. Writes ``colour_by_range.json`` here.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import numpy as np

from weather_gym.core._io import atomic_file
from weather_gym.lidar_weather import parse_lidar_weather
from weather_gym.perception.lidar_cones import cones_from_points
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.tracks import load_track

HERE = Path(__file__).resolve().parent
BINS = (0, 2, 4, 6, 8, 10, 15, 30)
WEATHERS = ("clear", "fog@3", "fog@5", "rain@3", "rain@5", "snow@3")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracks", default="small_track,peanut")
    ap.add_argument("--every", type=int, default=15)
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    spec = importlib.util.spec_from_file_location("lidar_figures", HERE / "figures.py")
    assert spec is not None and spec.loader is not None
    figs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(figs)
    cfg = LidarConfig()
    frames = []  # (pose, clear scan, true cone xy, true classes)
    for name in args.tracks.split(","):
        track = load_track(name.strip())
        xy_all, cls_all = np.asarray(track.cones_xy, float), np.asarray(track.cone_classes)
        for pose, clouds, truth in figs.scans(name.strip(), args.every):
            t = truth["HDL-32E"]
            idx = [int(np.hypot(*(xy_all - p).T).argmin()) for p in t]
            frames.append((pose, clouds["HDL-32E"], t, cls_all[idx]))
    out: dict = {"tracks": args.tracks, "every": args.every, "scans": len(frames), "by_weather": {}}
    for spec_w in WEATHERS:
        weather = parse_lidar_weather(spec_w)
        st = np.zeros((len(BINS) - 1, 3), int)  # found and matched, colour right, colour wrong
        for i, (pose, clear, truth, cls) in enumerate(frames):
            cones = cones_from_points(weather(clear, np.random.default_rng([0, i, len(spec_w)])), cfg)
            gt = figs._body(truth, pose)
            for x, y, c, r in zip(cones["x_body"], cones["y_body"], cones["classes"], cones["ranges"]):
                d = np.hypot(gt[:, 0] - x, gt[:, 1] - y) if len(gt) else np.zeros(0)
                if not len(d) or d.min() > 0.5:
                    continue
                b = min(int(np.searchsorted(BINS, r, side="right")) - 1, len(BINS) - 2)
                st[b] += (1, int(c == cls[d.argmin()]), int(c >= 0 and c != cls[d.argmin()]))
        out["by_weather"][spec_w] = {f"{BINS[b]}-{BINS[b + 1]} m": {"matched": int(st[b, 0]),
                                                                  "right": round(st[b, 1] / max(st[b, 0], 1), 3),
                                                                  "wrong": round(st[b, 2] / max(st[b, 0], 1), 3)}
                                     for b in range(len(BINS) - 1)}
    with atomic_file(HERE / "colour_by_range.json", "w", overwrite=args.overwrite) as f:
        json.dump(out, f, indent=1)
    print(f"{len(frames)} scans; wrote {HERE / 'colour_by_range.json'}")


if __name__ == "__main__":
    main()
