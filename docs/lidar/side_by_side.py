"""Camera and LiDAR evaluations side by side: one Markdown table per track, a column per weather.

    PYTHONPATH=. python docs/lidar/side_by_side.py docs/lidar/eval_camera.csv docs/lidar/eval_lidar.csv

Each cell: the lap time and cones hit, or how the episode ended (``off_track``) with the share of the
lap driven; the two files are ``weather-gym evaluate`` results (see docs/lidar.md for the commands).
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict


def cell(r: dict) -> str:
    if r["completed"] in ("1", "True", "true"):
        return f"{float(r['lap_time_s']):.2f} s, {r['cones_hit']} hit"
    return f"{r['end_reason']} at {int(100 * float(r['progress']))} % of the lap"


def main(paths: list[str]) -> None:
    rows = [r for p in paths for r in csv.DictReader(open(p, encoding="utf-8"))]
    cols = sorted({(r["perception"], r["effect"]) for r in rows}, key=lambda c: (c[0] == "lidar", c[1]))
    table: dict = defaultdict(dict)
    for r in rows:
        table[(r["track"], int(r["severity"]))][(r["perception"], r["effect"])] = cell(r)
    for track in sorted({t for t, _ in table}):
        print(f"\n{track} (seed 0, agent mapper_pure_pursuit)\n")
        print("| severity | " + " | ".join(f"{p}: {e}" for p, e in cols) + " |")
        print("|---" * (len(cols) + 1) + "|")
        for sev in sorted({s for t, s in table if t == track}):
            print(f"| {sev} | " + " | ".join(table[track, sev].get(c, "-") for c in cols) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
