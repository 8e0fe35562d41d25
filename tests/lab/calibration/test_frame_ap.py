"""frame_ap: the AP of any weighted multiset of frames equals pycocotools' on those frames."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.lab.calibration.frame_ap import frame_matches
from weather_gym.perception.scoring import score_detections


def _frames(rng, n):
    gts, dets = [], []
    for _ in range(n):
        k = int(rng.integers(1, 6))
        xy = rng.uniform(0, 300, (k, 2))
        wh = rng.uniform(8, 40, (k, 2))
        boxes = np.hstack([xy, xy + wh])
        classes = rng.integers(0, 2, k)
        gts.append({"boxes": boxes, "classes": classes})
        keep = rng.random(k) < 0.7
        jitter = rng.normal(0, 2.0, (k, 4))
        fp = rng.uniform(0, 300, (2, 2))
        dboxes = np.vstack([boxes[keep] + jitter[keep], np.hstack([fp, fp + 20])])
        dets.append({"boxes": dboxes, "scores": rng.uniform(0.05, 1, len(dboxes)),
                     "classes": np.concatenate([classes[keep], rng.integers(0, 2, 2)])})
    return gts, dets


def test_equals_pycocotools_and_weights_are_copies():
    rng = np.random.default_rng(3)
    gts, dets = _frames(rng, 24)
    groups = [i // 4 for i in range(24)]
    m = frame_matches(gts, dets, groups=groups, min_box_height=5.0)
    ref = score_detections(gts, dets, min_box_height=5.0).map50_blue_yellow
    assert m.map50() == pytest.approx(ref, abs=1e-12)
    # weight 2 on group 0 and 0 on group 5 == the frames of group 0 twice and group 5 left out
    w = np.ones(6)
    w[0], w[5] = 2.0, 0.0
    idx = [i for i in range(24) if groups[i] != 5] + [0, 1, 2, 3]
    ref2 = score_detections([gts[i] for i in idx], [dets[i] for i in idx], min_box_height=5.0).map50_blue_yellow
    assert m.map50(w) == pytest.approx(ref2, abs=1e-9)


def test_group_labels_must_match_frames():
    rng = np.random.default_rng(0)
    gts, dets = _frames(rng, 3)
    with pytest.raises(ValueError, match="3 frames but 2 group labels"):
        frame_matches(gts, dets, groups=[0, 1])
