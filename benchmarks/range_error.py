"""Range error of the cone list's depth ranging, by true range, for several depth quantiles.

Every detection of the shipped (or given) detector (score >= 0.3) that matches a labelled cone of its
class (COCO's greedy one-to-one matching at IoU >= 0.5, ``weather_gym.surrogate.log.match_detections``) is ranged from the set's depth map as ``DetectorWrapper`` ranges it, once per
quantile, and compared with the label's range. Rear cones (box touching a nearer cone's) are
reported apart: a low quantile can pick up the front cone's depth.

    python benchmarks/range_error.py DATASET [--model M.onnx] [--quantiles 0.5,0.25,0.1]

DATASET is a rendered set with depth maps (``weather-gym dataset render ...``).
"""

from __future__ import annotations

import argparse

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel, CameraPipeline
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.perception import ConeDetector
from weather_gym.perception.labels import hidden_mask
from weather_gym.perception.ranging import range_from_depth
from weather_gym.surrogate.log import match_detections

BANDS = ((0, 10), (10, 15), (15, 20), (20, 30))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("--model", default=None)
    ap.add_argument("--quantiles", default="0.5,0.25,0.1")
    args = ap.parse_args()
    qs = [float(q) for q in args.quantiles.split(",")]
    ds, det = load_coco(args.dataset), ConeDetector(args.model)
    rows = []  # true range, rear, error per quantile
    for i in range(len(ds)):
        rec, gt, depth = ds.record(i), ds.gt(i), ds.depth(i)
        if depth is None:
            raise SystemExit(f"{args.dataset}: frame {i} has no depth map; render the set with depth")
        cam = CameraConfig(**rec["camera"])
        lens = CameraPipeline(CameraModel.from_dict(rec.get("camera_model", {"enabled": False})), cam.width,
                              cam.height, fx=cam.fx).undistort_points
        gb, gc, gr = (np.asarray(gt[k], float) for k in ("boxes", "classes", "ranges"))
        d = det.detect(ds.image(i))
        db, dc, sc = np.asarray(d.boxes, float).reshape(-1, 4), np.asarray(d.classes), np.asarray(d.scores)
        keep = sc >= 0.3
        db, dc = db[keep], dc[keep]
        if not len(gb) or not len(db):
            continue
        rear, match = hidden_mask(gb.reshape(-1, 4), gr), match_detections(gb, db, sc[keep])
        for k, j in enumerate(match):
            if j >= 0 and dc[k] == gc[j]:
                errs = [range_from_depth(db[k:k + 1], dc[k:k + 1], depth, cam, lens, q)[0] - gr[j] for q in qs]
                rows.append([gr[j], rear[j], *errs])
    a = np.array(rows, float)
    print(f"{args.dataset}: {len(a)} matched detections; share more than 1 m off (median error, m)")
    print("cones | true range | n | " + " | ".join(f"q {q:g}" for q in qs))
    for sel, name in ((a[:, 1] == 0, "standing clear"), (a[:, 1] == 1, "rear (box touches a nearer cone)")):
        for lo, hi in BANDS:
            s = a[sel & (a[:, 0] >= lo) & (a[:, 0] < hi)]
            if len(s):
                cells = [f"{np.mean(np.abs(s[:, 2 + c]) > 1):.2f} ({np.median(s[:, 2 + c]):+.2f})" for c in range(len(qs))]
                print(f"{name} | {lo}-{hi} m | {len(s)} | " + " | ".join(cells))


if __name__ == "__main__":
    main()
