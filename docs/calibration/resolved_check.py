"""Before and after: the shipped pool presets and the presets resolved per scenario, on held-out scenarios.

For each scenario: resolve the presets (``weather_gym.lab.calibration.resolve.resolve_presets``; its own
reference set, cached), render a *different* 80-frame set of the same scenario (seed 4242), and score the
detector there at the pool k and at the resolved k of every study row, 5 weather seeds each (relative
mAP@0.5 over blue and yellow, mean and sd over seeds). Writes ``OUT/resolved_check.csv`` and ``.md``, and
each scenario's resolved presets and curve plot (``OUT/<scenario>.toml``, ``.png``).

    python docs/calibration/resolved_check.py --out docs/calibration/resolved skidpad random:90 realistic:small_track

With a user's detector (``--detector yolov8:FILE``: the second detector of ``second_detector.py``), the
presets are resolved for that detector and the check set is scored with it:

    python docs/calibration/resolved_check.py --out docs/calibration/resolved_yolov8 \
        --detector yolov8:docs/calibration/second_detector/yolov8_conenet_s4.onnx skidpad realistic:small_track
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from weather_gym.lab.calibration.resolve import Scenario, resolve_presets, write_resolved
from weather_gym.lab.calibration.resolve_plot import plot_resolution
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.render import render_dataset
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.scoring import score_dataset


def scenario_of(text: str, detector: str | None) -> Scenario:
    scene, _, track = text.rpartition(":") if text.startswith("realistic:") else ("plain", "", text)
    return Scenario(tracks=(track,), scene=scene or "plain", detector=detector)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="+", help="TRACK or realistic:TRACK")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--detector", default=None)
    ap.add_argument("--frames", type=int, default=80)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--sets", type=Path, default=Path("scratch/resolved_check_sets"),
                    help="where the check sets are rendered (large; not in the repository)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for text in args.scenarios:
        sc = scenario_of(text, args.detector)
        t0 = time.perf_counter()
        res = resolve_presets(sc, progress=False)
        t_res = time.perf_counter() - t0
        stem = args.out / text.replace(":", "_")
        write_resolved(res, stem.with_suffix(".toml"), scenario=sc, overwrite=True)
        plot_resolution(res, stem.with_suffix(".png"), overwrite=True)
        check = args.sets / text.replace(":", "_")
        if not (check / "annotations.json").is_file():
            render_dataset(check, tracks=list(sc.tracks), frames=args.frames, seed=4242, scene=sc.scene,
                           frames_per_episode=4, progress=False, overwrite=True)
        ds = load_coco(check, cache_images=True)
        det = load_detector(sc.detector)
        clear = score_dataset(ds, det, None, batch_size=1, progress=False).map50_blue_yellow
        for r in res.rows:
            if r.severity == 0:
                continue
            out = {"scenario": text, "preset": f"{r.condition}@{r.severity}", "target": r.target,
                   "k_pool": r.k_pool, "k_resolved": r.k, "resolve_s": round(t_res, 1), "cached": res.cached,
                   "ref_frames": res.n_frames, "ref_achieved": round(r.achieved, 4), "ref_se": r.se}
            for which, k in (("pool", r.k_pool), ("resolved", r.k)):
                table = dict(r.effect, k=k)
                vals = [score_dataset(ds, det, [table], seed=s, batch_size=1, progress=False).map50_blue_yellow / clear
                        for s in range(args.seeds)]
                out[f"{which}_mean"], out[f"{which}_sd"] = round(float(np.mean(vals)), 4), round(float(np.std(vals, ddof=1)), 4)
            rows.append(out)
            print(out, flush=True)
        with open(args.out / "resolved_check.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    md = ["| scenario | preset | target | k pool | pool: relative mAP | k resolved | resolved: relative mAP | "
          "resolved within 0.03 |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = abs(r["resolved_mean"] - r["target"]) <= 0.03
        md.append(f"| {r['scenario']} | {r['preset']} | {r['target']:.3f} | {r['k_pool']:.3f} | {r['pool_mean']:.3f} ± "
                  f"{r['pool_sd']:.3f} | {r['k_resolved']:.3f} | {r['resolved_mean']:.3f} ± {r['resolved_sd']:.3f} | "
                  f"{'yes' if ok else 'no'} |")
    (args.out / "resolved_check.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
