"""Before and after: the shipped pool presets and the presets resolved per scenario, on held-out scenarios.

For each scenario: resolve the presets (``weather_gym.lab.calibration.resolve.resolve_presets``; its own
reference set, cached), render a *different* set of the same scenario (``--frames``, default 320; render seed
4242, one frame per episode as the reference set draws them: ``--frames-per-episode``), and score the detector there at the pool k and at the resolved k of every study
row, 5 weather seeds each (relative mAP@0.5 over blue and yellow: mean and sd over the seeds, and the check
set's own standard error: a bootstrap over its episodes of the 5-seed mean, 200 replicates). Writes
``OUT/resolved_check.csv`` and ``.md``, and each scenario's resolved presets and curve plot
(``OUT/<scenario>.toml``, ``.png``). One scenario per process keeps a run short enough to repeat:

    python docs/calibration/resolved_check.py --out docs/calibration/resolved/skidpad skidpad

With a user's detector (``--detector yolov8:FILE``: the second detector of ``second_detector.py``), the
presets are resolved for that detector and the check set is scored with it:

    python docs/calibration/resolved_check.py --out docs/calibration/resolved_yolov8/skidpad \
        --detector yolov8:docs/calibration/second_detector/yolov8_conenet_s4.onnx skidpad

The check set's frames go through the detector one at a time, shared by the resolver's helper processes; a degraded frame whose
bytes equal its clear frame (droplets at k = 0) reuses the clear detections, and a row whose pool and
resolved k are equal is scored once. The weather seeds are those of ``score_dataset(..., seed=s)``.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.lab.calibration._resolve_worker import FrameBlock
from weather_gym.lab.calibration.frame_ap import FrameMatches, frame_matches
from weather_gym.lab.calibration.resolve import (
    Helper,
    Scenario,
    default_workers,
    resolve_presets,
    write_resolved,
)
from weather_gym.lab.calibration.resolve_plot import plot_resolution
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.render import render_dataset
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.scoring import small_rule

BOOTSTRAP = 200


def scenario_of(text: str, detector: str | None) -> Scenario:
    scene, _, track = text.rpartition(":") if text.startswith("realistic:") else ("plain", "", text)
    return Scenario(tracks=(track,), scene=scene or "plain", detector=detector)


class CheckSet:
    """A rendered check set in memory with the detector's clear detections; ``workers`` processes share its
    frames (the resolver's helper processes: every detection is the same as in one process)."""

    def __init__(self, folder: Path, spec: str | None, workers: int) -> None:
        ds = load_coco(folder)
        self.n = len(ds)
        self.gts = [ds.gt(j) for j in range(self.n)]
        self.groups = [ds.record(j).get("episode", j) for j in range(self.n)]
        self.det = load_detector(spec)
        rule = small_rule(ds, self.det)
        self.min_h = None if rule is None else rule.min_height_px
        frames = [(str(folder), j) for j in range(self.n)]
        self.helpers = [Helper(spec, 1) for _ in range(workers - 1)]
        self.cuts = np.linspace(0, self.n, workers + 1).round().astype(int)
        zero = np.zeros(self.n, np.uint32)
        for b, h in enumerate(self.helpers, start=1):
            h.send("frames", 0, frames[self.cuts[b]:self.cuts[b + 1]], zero[self.cuts[b]:self.cuts[b + 1]])
        self.own = FrameBlock.load(frames[:self.cuts[1]], zero[:self.cuts[1]])
        for h in self.helpers:
            h.recv()
        self.clear = self.matches(self._detect(None, zero))

    def close(self) -> None:
        for h in self.helpers:
            h.close()

    def _detect(self, table: dict[str, Any] | None, seeds: np.ndarray) -> list[Any]:
        for b, h in enumerate(self.helpers, start=1):
            h.send("detect", 0, table, seeds[self.cuts[b]:self.cuts[b + 1]])
        out = list(self.own.detect(self.det.detect_batch, table, seeds[:self.cuts[1]]))
        for h in self.helpers:
            out += h.recv()
        return out

    def matches(self, dets: list[Any]) -> FrameMatches:
        return frame_matches(self.gts, dets, groups=self.groups, min_box_height=self.min_h)

    def score(self, table: dict[str, Any], seeds: int) -> dict[str, float]:
        """Relative mAP per seed (mean, sd) and the bootstrap se (over episodes) of the seeds' mean; the
        weather seeds of ``score_dataset(..., seed=s)``."""
        ms = [self.matches(self._detect(table, np.random.SeedSequence(s).generate_state(self.n, dtype=np.uint32)))
              for s in range(seeds)]
        cm = self.clear.map50()
        vals = [m.map50() / cm for m in ms]
        rng = np.random.default_rng(12345)
        g = self.clear.n_groups
        w = rng.multinomial(g, np.full(g, 1.0 / g), size=BOOTSTRAP).astype(np.float64)
        c = self.clear.map50_many(w)
        ok = c > 0
        boot = np.mean([m.map50_many(w[ok]) / c[ok] for m in ms], axis=0)
        return {"mean": round(float(np.mean(vals)), 4),
                "sd": round(float(np.std(vals, ddof=1)), 4) if len(vals) > 1 else 0.0,
                "se": round(float(np.std(boot, ddof=1)), 4)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenarios", nargs="+", help="TRACK or realistic:TRACK")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--detector", default=None)
    ap.add_argument("--frames", type=int, default=320, help="check-set frames (default %(default)s)")
    ap.add_argument("--seeds", type=int, default=5, help="weather seeds at the resolved k (default %(default)s)")
    ap.add_argument("--pool-seeds", type=int, default=5, help="weather seeds at the pool k (default %(default)s)")
    ap.add_argument("--workers", type=int, default=None, help="processes (default: as resolve_presets)")
    ap.add_argument("--frames-per-episode", type=int, default=1, help="frames per episode of the check set")
    ap.add_argument("--sets", type=Path, default=Path("scratch/resolved_check_sets"),
                    help="where the check sets are rendered (large; not in the repository)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for text in args.scenarios:
        sc = scenario_of(text, args.detector)
        t0 = time.perf_counter()
        res = resolve_presets(sc, progress=False, workers=args.workers)
        t_res = time.perf_counter() - t0
        stem = args.out / text.replace(":", "_")
        write_resolved(res, stem.with_suffix(".toml"), scenario=sc, overwrite=True)
        plot_resolution(res, stem.with_suffix(".png"), overwrite=True)
        check = args.sets / f"{text.replace(':', '_')}_{args.frames}x{args.frames_per_episode}"
        if not (check / "annotations.json").is_file():
            render_dataset(check, tracks=list(sc.tracks), frames=args.frames, seed=4242, scene=sc.scene,
                           frames_per_episode=args.frames_per_episode, progress=False, overwrite=True)
        cs = CheckSet(check, sc.detector, args.workers or default_workers())
        for r in res.rows:
            if r.severity == 0:
                continue
            out = {"scenario": text, "preset": f"{r.condition}@{r.severity}", "target": r.target,
                   "k_pool": r.k_pool, "k_resolved": r.k, "resolve_s": round(t_res, 1), "cached": res.cached,
                   "ref_frames": res.n_frames, "ref_achieved": round(r.achieved, 4), "ref_se": r.se,
                   "check_frames": cs.n}
            done: dict[tuple[float, int], dict[str, float]] = {}
            for which, k, n in (("pool", r.k_pool, args.pool_seeds), ("resolved", r.k, args.seeds)):
                if (k, n) not in done:
                    done[k, n] = cs.score(dict(r.effect, k=k), n)
                for q, v in done[k, n].items():
                    out[f"{which}_{q}"] = v
            rows.append(out)
            print(out, flush=True)
        cs.close()
        with open(args.out / "resolved_check.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    md = ["| scenario | preset | target | k pool | pool presets | k resolved | resolved (check se) | "
          "reference set (se) | resolved within 0.03 |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = abs(r["resolved_mean"] - r["target"]) <= 0.03
        md.append(f"| {r['scenario']} | {r['preset']} | {r['target']:.3f} | {r['k_pool']:.3f} | {r['pool_mean']:.3f} ± "
                  f"{r['pool_sd']:.3f} | {r['k_resolved']:.3f} | {r['resolved_mean']:.3f} ± {r['resolved_sd']:.3f} "
                  f"({r['resolved_se']:.3f}) | {r['ref_achieved']:.3f} ({r['ref_se']:.3f}) | {'yes' if ok else 'no'} |")
    (args.out / "resolved_check.md").write_text("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
