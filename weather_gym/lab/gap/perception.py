"""The perception level of the gap: detector scores that can be bootstrapped over frames.

Detections are matched to ground truth once, by pycocotools (IoU 0.5, 100 detections per image,
tiny cones ignored: exactly what :func:`weather_gym.perception.evaluate` does). Matching is per
frame, so it does not change when frames are resampled; :func:`perception_stats` then recomputes
AP@0.5 the way ``COCOeval.accumulate`` does (101-point interpolated precision, per class, averaged
over the classes present) for any frame weights, which makes a bootstrap of mAP cheap. With all
weights 1 it equals ``evaluate(...).map50`` (checked in the tests).

Statistics (all pooled over the weighted frames):

* ``map50``, ``ap50.<class>``;
* ``recall`` and ``recall.range.<bin>`` / ``recall.size.<bin>`` at the detector's operating score
  threshold (IoU 0.5), by cone range and by box height;
* ``fp_per_frame`` (unmatched detections at the operating threshold), ``score_tp_mean`` /
  ``score_fp_mean`` (mean score of matched / unmatched detections above the operating threshold).

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.gap.perception import match_frames, perception_stats
    >>> gt = [{"boxes": np.array([[10, 10, 30, 50.]]), "classes": np.array([1]), "ranges": np.array([6.0])}]
    >>> det = [{"boxes": np.array([[11, 10, 30, 49.]]), "scores": np.array([0.9]), "classes": np.array([1])}]
    >>> m = match_frames(gt, det)
    >>> round(perception_stats(m)["map50"], 6), perception_stats(m)["recall.range.5-10 m"]
    (1.0, 1.0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX
from weather_gym.perception.scoring import coco_eval, coco_lists

__all__ = ["FrameMatches", "match_frames", "perception_stats", "detect_frames", "RANGE_BINS", "SIZE_BINS"]

RANGE_BINS: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0, math.inf)
SIZE_BINS: tuple[float, ...] = (MIN_BOX_HEIGHT_PX, 16.0, 32.0, 64.0, math.inf)
_REC_THRS = np.linspace(0.0, 1.0, 101)


def _bin_labels(bins: Sequence[float], unit: str) -> list[str]:
    return [f"{lo:g}+ {unit}" if math.isinf(hi) else f"{lo:g}-{hi:g} {unit}" for lo, hi in zip(bins[:-1], bins[1:])]


RANGE_LABELS = _bin_labels(RANGE_BINS, "m")
SIZE_LABELS = _bin_labels(SIZE_BINS, "px")


@dataclass
class FrameMatches:
    """Matched detections of one detector run over ``n_frames`` frames (flat arrays).

    Detections (``det_*``, top 100 per frame and class): frame, class, score, true positive at IoU
    0.5, ignored (matched to a tiny cone). Scored ground truth (``gt_*``, tiny cones left out):
    frame, class, range (m, NaN unknown), box height (px), score of the matching detection (-1 when
    unmatched).
    """

    n_frames: int
    score_threshold: float
    det_frame: np.ndarray
    det_class: np.ndarray
    det_score: np.ndarray
    det_tp: np.ndarray
    det_ignore: np.ndarray
    gt_frame: np.ndarray
    gt_class: np.ndarray
    gt_range: np.ndarray
    gt_height: np.ndarray
    gt_match_score: np.ndarray


def match_frames(gts: Sequence[dict], detections: Sequence[Any], *, score_threshold: float = 0.3,
                 min_box_height: float = MIN_BOX_HEIGHT_PX) -> FrameMatches:
    """Match ``detections[i]`` to ``gts[i]`` with pycocotools at IoU 0.5 (see module doc)."""
    images, gt_anns, dt_anns = coco_lists(gts, detections, min_box_height=min_box_height)
    gt_info = {a["id"]: (a["image_id"], a["category_id"] - 1, a["range"], a["height"]) for a in gt_anns}
    dt_info = {a["id"]: (a["image_id"], a["category_id"] - 1, a["score"]) for a in dt_anns}
    det: dict[str, list[Any]] = {k: [] for k in ("frame", "class", "score", "tp", "ignore")}
    gtr: dict[str, list[Any]] = {k: [] for k in ("frame", "class", "range", "height", "match")}
    if images:
        ev = coco_eval(images, gt_anns, dt_anns, iou_50_only=True, accumulate=False)
        for e in ev.evalImgs:
            if e is None:
                continue
            for did, m, ig in zip(e["dtIds"], e["dtMatches"][0], e["dtIgnore"][0]):
                f, c, s = dt_info[did]
                det["frame"].append(f), det["class"].append(c), det["score"].append(s)  # type: ignore[func-returns-value]  # appends, one line
                det["tp"].append(bool(m > 0) and not bool(ig)), det["ignore"].append(bool(ig))  # type: ignore[func-returns-value]  # appends, one line
            for gid, m, ig in zip(e["gtIds"], e["gtMatches"][0], e["gtIgnore"]):
                if ig:
                    continue
                f, c, r, hgt = gt_info[gid]
                gtr["frame"].append(f), gtr["class"].append(c), gtr["range"].append(r), gtr["height"].append(hgt)  # type: ignore[func-returns-value]  # appends, one line
                gtr["match"].append(dt_info[int(m)][2] if m > 0 else -1.0)
    return FrameMatches(
        n_frames=len(images), score_threshold=float(score_threshold),
        det_frame=np.asarray(det["frame"], np.int64), det_class=np.asarray(det["class"], np.int64),
        det_score=np.asarray(det["score"], np.float64), det_tp=np.asarray(det["tp"], bool),
        det_ignore=np.asarray(det["ignore"], bool),
        gt_frame=np.asarray(gtr["frame"], np.int64), gt_class=np.asarray(gtr["class"], np.int64),
        gt_range=np.asarray(gtr["range"], np.float64), gt_height=np.asarray(gtr["height"], np.float64),
        gt_match_score=np.asarray(gtr["match"], np.float64))


def _ap(scores: np.ndarray, tp: np.ndarray, valid: np.ndarray, w: np.ndarray, n_pos: float) -> float:
    """COCOeval.accumulate's 101-point AP of one class for detection weights ``w`` (frames' counts)."""
    order = np.argsort(-scores, kind="mergesort")
    keep = valid[order] & (w[order] > 0)
    order = order[keep]
    if order.size == 0:
        return 0.0
    ww, t = w[order], tp[order]
    tps = np.cumsum(ww * t)
    fps = np.cumsum(ww * ~t)
    rc = tps / n_pos
    pr = tps / (fps + tps + np.spacing(1))
    pr = np.maximum.accumulate(pr[::-1])[::-1]
    idx = np.searchsorted(rc, _REC_THRS, side="left")
    q = np.zeros(_REC_THRS.size)
    ok = idx < pr.size
    q[ok] = pr[idx[ok]]
    return float(q.mean())


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


def perception_stats(m: FrameMatches, weights: np.ndarray | None = None) -> dict[str, float]:
    """Detector statistics of the frames of ``m`` weighted by ``weights`` (frame counts; default 1)."""
    w = np.ones(m.n_frames) if weights is None else np.asarray(weights, np.float64)
    dw, gw = w[m.det_frame], w[m.gt_frame]
    out: dict[str, float] = {}
    aps = {}
    for k, name in enumerate(CONE_CLASSES):
        n_pos = float(gw[m.gt_class == k].sum())
        if n_pos <= 0:
            aps[name] = math.nan
            continue
        sel = m.det_class == k
        aps[name] = _ap(m.det_score[sel], m.det_tp[sel], ~m.det_ignore[sel], dw[sel], n_pos)
    present = [v for v in aps.values() if not math.isnan(v)]
    out["map50"] = float(np.mean(present)) if present else math.nan
    for name, v in aps.items():
        out[f"ap50.{name}"] = v
    hit = m.gt_match_score >= m.score_threshold
    out["recall"] = _ratio(float((gw * hit).sum()), float(gw.sum()))
    for bins, labels, key, vals in ((RANGE_BINS, RANGE_LABELS, "range", m.gt_range),
                                    (SIZE_BINS, SIZE_LABELS, "size", m.gt_height)):
        for lo, hi, label in zip(bins[:-1], bins[1:], labels):
            sel = (vals >= lo) & (vals < hi)
            out[f"recall.{key}.{label}"] = _ratio(float((gw * hit)[sel].sum()), float(gw[sel].sum()))
    above = (m.det_score >= m.score_threshold) & ~m.det_ignore
    fp = above & ~m.det_tp
    tp = above & m.det_tp
    out["fp_per_frame"] = _ratio(float(dw[fp].sum()), float(w.sum()))
    out["score_tp_mean"] = _ratio(float((dw * m.det_score)[tp].sum()), float(dw[tp].sum()))
    out["score_fp_mean"] = _ratio(float((dw * m.det_score)[fp].sum()), float(dw[fp].sum()))
    return out


def detect_frames(detector: Any, images: Sequence[np.ndarray], *, batch_size: int = 8,
                  keep_threshold: float = 0.05) -> list:
    """Detections of every frame (kept down to ``keep_threshold`` so the AP curve is complete)."""
    out: list = []
    for start in range(0, len(images), batch_size):
        out += detector.detect_batch(list(images[start:start + batch_size]), score_threshold=keep_threshold)
    return out
