"""pycocotools scoring: mAP@0.5, COCO mAP, per-class AP, recall by range, ignored tiny cones."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.perception.scoring import score_detections


def _gt(boxes, classes, ranges=None, iscrowd=None):
    g = {"boxes": np.array(boxes, float).reshape(-1, 4), "classes": np.array(classes, int)}
    if ranges is not None:
        g["ranges"] = np.array(ranges, float)
    if iscrowd is not None:
        g["iscrowd"] = np.array(iscrowd, int)
    return g


def _det(boxes, scores, classes):
    return {"boxes": np.array(boxes, float).reshape(-1, 4), "scores": np.array(scores, float),
            "classes": np.array(classes, int)}


GT = [_gt([[10, 10, 30, 50], [100, 20, 120, 60]], [0, 1], [4.0, 12.0]),
      _gt([[200, 30, 216, 60]], [0], [7.0])]


def test_perfect_detections_score_one():
    dets = [_det(g["boxes"], np.full(len(g["boxes"]), 0.9), g["classes"]) for g in GT]
    r = score_detections(GT, dets)
    assert r.map50 == pytest.approx(1.0) and r.map == pytest.approx(1.0)
    assert r.ap50_per_class["blue"] == pytest.approx(1.0) and math.isnan(r.ap50_per_class["orange"])
    assert r.recall == 1.0 and r.n_gt == 3 and r.n_images == 2 and r.map50_blue_yellow == pytest.approx(1.0)


def test_missed_cone_lowers_map_and_recall_by_range():
    dets = [_det([[10, 10, 30, 50]], [0.9], [0]), _det([[200, 30, 216, 60]], [0.8], [0])]
    r = score_detections(GT, dets)
    assert r.ap50_per_class["blue"] == pytest.approx(1.0)
    assert r.ap50_per_class["yellow"] == 0.0
    assert r.map50 == pytest.approx(0.5) and r.map50_blue_yellow == pytest.approx(0.5)
    assert r.recall_by_range["0-5 m"] == (1.0, 1)
    assert r.recall_by_range["10-15 m"] == (0.0, 1)
    assert math.isnan(r.recall_by_range["20+ m"][0])


def test_wrong_class_and_false_positive_cost_precision():
    good = [_det(g["boxes"], [0.9] * len(g["boxes"]), g["classes"]) for g in GT]
    worse = [_det(np.r_[GT[0]["boxes"], [[300, 30, 320, 70]]], [0.9, 0.9, 0.95], [0, 1, 0]), good[1]]
    assert score_detections(GT, worse).map50 < score_detections(GT, good).map50


def test_loose_box_passes_iou_half_but_not_coco_map():
    dets = [_det([[10, 14, 30, 54], [100, 24, 120, 64]], [0.9, 0.9], [0, 1]), _det([[200, 33, 216, 63]], [0.9], [0])]
    r = score_detections(GT, dets)
    assert r.map50 == pytest.approx(1.0)
    assert r.map < 0.8


def test_tiny_cones_are_ignored_not_false_positives():
    gt = [_gt([[10, 10, 30, 50], [300, 100, 305, 106]], [0, 0], [4.0, 25.0])]  # second cone: 6 px tall
    hit_tiny = [_det([[10, 10, 30, 50], [300, 100, 305, 106]], [0.9, 0.95], [0, 0])]
    r = score_detections(gt, hit_tiny)
    assert r.map50 == pytest.approx(1.0) and r.n_gt == 1 and r.n_ignored == 1
    # the dataset's own iscrowd flags win over the size rule
    r2 = score_detections([_gt([[300, 100, 305, 106]], [0], [25.0], iscrowd=[0])], [_det([], [], [])])
    assert r2.n_gt == 1 and r2.map50 == 0.0


def test_recall_uses_the_operating_threshold():
    dets = [_det(g["boxes"], [0.2] * len(g["boxes"]), g["classes"]) for g in GT]
    assert score_detections(GT, dets, score_threshold=0.3).recall == 0.0
    assert score_detections(GT, dets, score_threshold=0.1).recall == 1.0
    assert score_detections(GT, dets).map50 == pytest.approx(1.0)  # AP does not depend on it


def test_no_detections_and_no_cones():
    r = score_detections(GT, [_det([], [], []), _det([], [], [])])
    assert r.map50 == 0.0 and r.n_detections == 0
    empty = score_detections([_gt([], [])], [_det([], [], [])])
    assert math.isnan(empty.map50) and empty.n_gt == 0
    assert "mAP@0.5" in empty.table()


def test_detections_objects_and_bad_input():
    from weather_gym.perception import Detections

    d = Detections(np.array([[10, 10, 30, 50]], np.float32), np.array([0.9], np.float32), np.array([0]))
    assert score_detections([GT[0]], [d]).ap50_per_class["blue"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="2 ground-truth frames but 1"):
        score_detections(GT, [d])
    with pytest.raises(ValueError, match="missing key"):
        score_detections([GT[0]], [{"boxes": np.zeros((0, 4))}])


def test_coco_dataset_input(tmp_path):
    from cone_synth import write_synth_dataset

    from weather_gym.lab.datasets.coco import load_coco

    ds = load_coco(write_synth_dataset(tmp_path / "d", 3))
    dets = [_det(ds.gt(i)["boxes"], [0.9] * len(ds.gt(i)["boxes"]), ds.gt(i)["classes"]) for i in range(len(ds))]
    assert score_detections(ds, dets).map50 == pytest.approx(1.0)


def test_the_former_name_still_imports():
    import weather_gym.perception as perception

    assert perception.evaluate is perception.score_detections is score_detections
