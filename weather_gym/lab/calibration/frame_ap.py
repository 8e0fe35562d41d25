"""mAP@0.5 of any multiset of frames from one matching pass: the bootstrap behind resolved presets.

pycocotools matches detections to ground truth image by image (``COCOeval.evaluateImg``); only its
``accumulate`` step mixes images. :func:`frame_matches` runs pycocotools' own matching once
(IoU 0.5, all areas, 100 detections per image, the set's too-small rule) and keeps, per class and
per *group* of frames (an episode: frames of one episode are not independent), the detection scores,
which are true or false positives and how many cones count. :meth:`FrameMatches.map50` then does
``accumulate``'s 101-point interpolated AP for any weights of the groups: weight 1 each is the set's
own mAP (equal to pycocotools' to rounding), a multinomial draw is one bootstrap replicate.

Example:
    >>> import numpy as np
    >>> gt = [{"boxes": np.array([[0, 0, 10, 40.]]), "classes": np.array([0])}] * 2
    >>> dt = [{"boxes": np.array([[0, 0, 10, 40.]]), "scores": np.array([0.9]), "classes": np.array([0])},
    ...       {"boxes": np.zeros((0, 4)), "scores": np.zeros(0), "classes": np.zeros(0, int)}]
    >>> m = frame_matches(gt, dt, groups=[0, 1], classes=("blue",), min_box_height=5.0)
    >>> round(m.map50(), 3), round(m.map50(np.array([1.0, 0.0])), 3)
    (0.505, 1.0)
    >>> m.map50_many(np.array([[1.0, 1.0], [1.0, 0.0]])).round(3).tolist()
    [0.505, 1.0]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.perception.scoring import coco_eval, coco_lists

__all__ = ["FrameMatches", "frame_matches", "STUDY_CLASSES"]

STUDY_CLASSES = ("blue", "yellow")
"""The classes the study's Table 2 scored (``map50_blue_yellow``)."""

_REC_THRS = np.linspace(0.0, 1.0, 101)


@dataclass
class FrameMatches:
    """Per class: per group, ``(scores, tp, fp)`` of its detections and ``npos`` (cones that count)."""

    classes: tuple[str, ...]
    scores: list[list[np.ndarray]]  # [class][group]
    tp: list[list[np.ndarray]]
    npos: np.ndarray  # (classes, groups)
    n_groups: int

    def ap50(self, c: int, weights: np.ndarray | None = None) -> float:
        """AP@0.5 of class index ``c`` with group ``g`` counted ``weights[g]`` times (NaN: no cone)."""
        w = np.ones(self.n_groups) if weights is None else np.asarray(weights, dtype=np.float64)
        npos = float(np.dot(self.npos[c], w))
        if npos <= 0:
            return math.nan
        use = [g for g in range(self.n_groups) if w[g] > 0 and self.scores[c][g].size]
        if not use:
            return 0.0
        sc = np.concatenate([self.scores[c][g] for g in use])
        tp = np.concatenate([self.tp[c][g] for g in use])
        ww = np.concatenate([np.full(self.scores[c][g].size, w[g]) for g in use])
        order = np.argsort(-sc, kind="mergesort")
        tp, ww = tp[order], ww[order]
        tps = np.cumsum(ww * tp)
        fps = np.cumsum(ww * (1.0 - tp))
        rc = tps / npos
        pr = tps / (tps + fps + np.spacing(1))
        pr = np.maximum.accumulate(pr[::-1])[::-1]
        idx = np.searchsorted(rc, _REC_THRS, side="left")
        q = np.where(idx < pr.size, pr[np.minimum(idx, pr.size - 1)], 0.0)
        return float(q.mean())

    def ap50_many(self, c: int, weights: np.ndarray) -> np.ndarray:
        """:meth:`ap50` of class index ``c`` for each row of ``weights`` ``(B, n_groups)`` at once (one sort;
        a group of weight 0 adds nothing to the running sums, so the AP equals :meth:`ap50`'s)."""
        w = np.asarray(weights, dtype=np.float64)
        npos = w @ self.npos[c]
        out = np.full(w.shape[0], math.nan)
        has = npos > 0
        groups = [g for g in range(self.n_groups) if self.scores[c][g].size]
        if not groups:
            out[has] = 0.0
            return out
        sc = np.concatenate([self.scores[c][g] for g in groups])
        tp = np.concatenate([self.tp[c][g] for g in groups])
        grp = np.concatenate([np.full(self.scores[c][g].size, g) for g in groups])
        order = np.argsort(-sc, kind="mergesort")
        tp, grp = tp[order], grp[order]
        wd = w[:, grp]
        tps = np.cumsum(wd * tp, axis=1)
        fps = np.cumsum(wd * (1.0 - tp), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            rc = tps / npos[:, None]
        pr = tps / (tps + fps + np.spacing(1))
        pr = np.maximum.accumulate(pr[:, ::-1], axis=1)[:, ::-1]
        for b in np.flatnonzero(has):
            if not np.any(wd[b]):
                out[b] = 0.0
                continue
            idx = np.searchsorted(rc[b], _REC_THRS, side="left")
            out[b] = np.where(idx < pr.shape[1], pr[b, np.minimum(idx, pr.shape[1] - 1)], 0.0).mean()
        return out

    def map50_many(self, weights: np.ndarray) -> np.ndarray:
        """:meth:`map50` for each row of ``weights`` ``(B, n_groups)``: a bootstrap's replicates in one pass."""
        aps = np.stack([self.ap50_many(c, weights) for c in range(len(self.classes))])
        cnt = np.sum(~np.isnan(aps), axis=0)
        tot = np.nansum(aps, axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(cnt > 0, tot / np.maximum(cnt, 1), math.nan)

    def map50(self, weights: np.ndarray | None = None) -> float:
        """Mean AP@0.5 over the classes that have cones (NaN when none has)."""
        aps = [self.ap50(c, weights) for c in range(len(self.classes))]
        aps = [a for a in aps if not math.isnan(a)]
        return float(np.mean(aps)) if aps else math.nan


def frame_matches(gts: Sequence[Any], dets: Sequence[Any], *, groups: Sequence[int],
                  classes: Sequence[str] = STUDY_CLASSES, min_box_height: float | None = None) -> FrameMatches:
    """pycocotools' matching of ``dets`` to ``gts`` (per-frame dicts, as ``score_detections`` takes),
    kept per class and per group (``groups[i]``: frame ``i``'s group, e.g. its episode)."""
    if len(groups) != len(gts):
        raise InputError(f"got {len(gts)} frames but {len(groups)} group labels")
    gid = {g: i for i, g in enumerate(dict.fromkeys(groups))}
    n = len(gid)
    cls_idx = [CONE_CLASSES.index(c) for c in classes]
    images, gt_anns, dt_anns = coco_lists(list(gts), list(dets), min_box_height=min_box_height)
    ev = coco_eval(images, gt_anns, dt_anns, iou_50_only=True, accumulate=False)
    parts: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    npos = np.zeros((len(classes), n))
    for e in ev.evalImgs:
        if e is None or (e["category_id"] - 1) not in cls_idx:
            continue
        c = cls_idx.index(e["category_id"] - 1)
        g = gid[groups[int(e["image_id"])]]
        npos[c, g] += int(np.count_nonzero(np.asarray(e["gtIgnore"]) == 0))
        sc = np.asarray(e["dtScores"], dtype=np.float64)[:100]
        if not sc.size:
            continue
        m = np.asarray(e["dtMatches"])[0, :100] > 0
        ig = np.asarray(e["dtIgnore"])[0, :100].astype(bool)
        parts.setdefault((c, g), []).append((sc[~ig], m[~ig].astype(np.float64)))
    scores = [[np.concatenate([p[0] for p in parts.get((c, g), [])]) if (c, g) in parts else np.zeros(0)
               for g in range(n)] for c in range(len(classes))]
    tp = [[np.concatenate([p[1] for p in parts.get((c, g), [])]) if (c, g) in parts else np.zeros(0)
           for g in range(n)] for c in range(len(classes))]
    return FrameMatches(tuple(classes), scores, tp, npos, n)
