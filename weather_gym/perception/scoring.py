"""Detector scoring with pycocotools: mAP@0.5, COCO mAP@[.5:.95], per-class AP and recall by range.

``score_detections(gt, detections)`` (also importable as ``evaluate``) takes either a ``CocoDataset`` (plus one ``Detections`` per image, in
dataset order) or in-memory per-frame lists: ``gt[i]`` a dict of arrays ``boxes`` (K, 4 xyxy pixels),
``classes`` and optionally ``iscrowd``, ``ranges`` (e.g. ``info["gt"]`` of the env), and
``detections[i]`` a ``Detections`` or a dict with ``boxes``, ``scores``, ``classes``.

Conventions: cones too small for the detector (``weather_gym.perception.labels.SmallRule``: shorter
than 6.1 px at its input scale, 8 px in the default camera image), cones in ignore regions (classes
a dataset import did not map) and cones inside the frame's ignore mask are ``iscrowd`` (ignored: a
detection on one is neither a hit nor a false positive); detections inside the ignore mask are
dropped. ``map50`` is pycocotools' AP at IoU 0.5 (101-point
interpolated precision, area "all", 100 detections per image) averaged over the classes present in
the ground truth - the single-threshold "VOC-style" mAP the reference study reports
(``map50_blue_yellow``: the same over blue and yellow only, the two classes the study scored); ``map`` is
COCO's AP averaged over IoU 0.50:0.05:0.95. Recall by range counts ground-truth cones matched at
IoU 0.5 by a detection scoring at least ``score_threshold``.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.scoring import score_detections
    >>> gt = [{"boxes": np.array([[10, 10, 30, 50.]]), "classes": np.array([1]), "ranges": np.array([6.0])}]
    >>> det = [{"boxes": np.array([[11, 10, 30, 49.]]), "scores": np.array([0.9]), "classes": np.array([1])}]
    >>> r = score_detections(gt, det)
    >>> round(r.map50, 3), r.recall_by_range["5-10 m"]
    (1.0, (1.0, 1))
"""

from __future__ import annotations

import contextlib
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
from tqdm import tqdm

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.perception.ignore import inside_mask
from weather_gym.perception.labels import CATEGORIES, MIN_BOX_HEIGHT_PX, SmallRule, tiny_mask, xyxy_to_xywh
from weather_gym.weather import parse_weather

__all__ = ["EvalResult", "evaluate", "score_dataset", "score_detections", "small_rule", "coco_lists", "coco_eval", "DEFAULT_RANGE_BINS"]

DEFAULT_RANGE_BINS: tuple[float, ...] = (0.0, 5.0, 10.0, 15.0, 20.0, math.inf)


@dataclass
class EvalResult:
    """Scores of a detector on a set of frames (NaN where undefined, e.g. no ground truth)."""

    map50: float
    map: float
    ap50_per_class: dict[str, float]
    ap_per_class: dict[str, float]
    recall_by_range: dict[str, tuple[float, int]]  # bin label -> (recall, number of cones)
    recall: float
    n_images: int
    n_gt: int
    n_ignored: int
    n_detections: int
    score_threshold: float
    map50_blue_yellow: float = math.nan  # mean AP@0.5 of the two colour classes the study scored
    ignored: dict[str, int] = field(default_factory=dict)  # reason (small, ignore, masked) -> cones
    too_small: str = f"box height < {MIN_BOX_HEIGHT_PX:g} px"  # the too-small rule that was applied
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "map50": self.map50, "map": self.map, "map50_blue_yellow": self.map50_blue_yellow, "ap50_per_class": dict(self.ap50_per_class),
            "ap_per_class": dict(self.ap_per_class),
            "recall_by_range": {k: {"recall": r, "n": n} for k, (r, n) in self.recall_by_range.items()},
            "recall": self.recall, "n_images": self.n_images, "n_gt": self.n_gt, "n_ignored": self.n_ignored,
            "n_detections": self.n_detections, "score_threshold": self.score_threshold,
            "ignored": dict(self.ignored), "too_small": self.too_small, **self.extra,
        }

    def ignored_text(self) -> str:
        """``"12 too small (box height < 16.3 px (...)), 3 in ignore regions, 40 in the ignore mask"``."""
        ig = self.ignored
        parts = [f"{ig.get('small', 0)} too small ({self.too_small})"]
        if ig.get("ignore"):
            parts.append(f"{ig['ignore']} in ignore regions (unmapped classes, projected 3D-only cones)")
        if ig.get("masked"):
            parts.append(f"{ig['masked']} in the ignore mask")
        return ", ".join(parts)

    def table(self) -> str:
        """A plain-text table (what ``weather-gym detector eval`` prints)."""
        def f(v: float) -> str:
            return "  n/a" if not np.isfinite(v) else f"{v:.3f}"

        lines = [f"images {self.n_images}, cones {self.n_gt} scored + {self.n_ignored} ignored, "
                 f"detections {self.n_detections}", f"ignored: {self.ignored_text()}"]
        lines += [
            f"mAP@0.5      {f(self.map50)}",
            f"mAP@.5:.95   {f(self.map)}",
            f"mAP@0.5 blue+yellow (the study's two classes) {f(self.map50_blue_yellow)}",
            "",
            "class        AP@0.5  AP@.5:.95",
        ]
        for name in self.ap50_per_class:
            lines.append(f"{name:<12} {f(self.ap50_per_class[name]):>6}  {f(self.ap_per_class[name]):>9}")
        lines += ["", f"recall at score >= {self.score_threshold:g}, IoU 0.5: {f(self.recall)}", "range        recall  cones"]
        for label, (r, n) in self.recall_by_range.items():
            lines.append(f"{label:<12} {f(r):>6}  {n:>5}")
        return "\n".join(lines)


def _as_arrays(d: Any, keys: Sequence[str], where: str) -> dict[str, np.ndarray]:
    if hasattr(d, "to_dict") and not isinstance(d, dict):
        d = d.to_dict()
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected a dict of arrays or Detections, got {type(d).__name__}")
    missing = [k for k in keys if k not in d]
    if missing:
        raise InputError(f"{where}: missing key(s) {missing}; expected {list(keys)}")
    return d


def _label(lo: float, hi: float) -> str:
    return f"{lo:g}+ m" if math.isinf(hi) else f"{lo:g}-{hi:g} m"


def _flags(g: dict, key: str, n: int) -> np.ndarray:
    return np.asarray(g[key], dtype=bool).reshape(-1) if key in g else np.zeros(n, bool)


def coco_lists(frames: Sequence[Any], detections: Sequence[Any], *,
               min_box_height: float | None = None) -> tuple[list[dict], list[dict], list[dict]]:
    """``(images, gt_anns, dt_anns)`` in COCO form for per-frame ground truth and detections.

    Image ``i`` has id ``i``; annotation ids count from 1. A ground-truth annotation also carries
    its cone's ``range`` (m, NaN unknown), box ``height`` (px) and, when it is ignored, ``reason``
    (``small``, ``ignore`` region, ``masked``), which pycocotools ignores.

    Which cones are ignored (``iscrowd``): boxes flagged ``ignore`` (ignore regions, e.g. unmapped
    classes; ``any_class`` ones ignore detections of every class), boxes at least half inside the
    frame's ``ignore_mask`` (detections there are dropped), and boxes too small: shorter than
    ``min_box_height`` when it is given (the rule at the detector's input scale), else the frame's
    stored ``iscrowd`` flags, else shorter than ``MIN_BOX_HEIGHT_PX``.
    """

    if len(frames) != len(detections):
        raise InputError(f"got {len(frames)} ground-truth frames but {len(detections)} detection lists")
    images: list[dict[str, Any]] = []
    gt_anns: list[dict[str, Any]] = []
    dt_anns: list[dict[str, Any]] = []
    for i, (g, d) in enumerate(zip(frames, detections, strict=True)):
        g = _as_arrays(g, ("boxes", "classes"), f"ground truth of frame {i}")
        d = _as_arrays(d, ("boxes", "scores", "classes"), f"detections of frame {i}")
        images.append({"id": i})
        gb = np.asarray(g["boxes"], dtype=np.float64).reshape(-1, 4)
        gc = np.asarray(g["classes"], dtype=np.int64).reshape(-1)
        n = len(gb)
        ignore, any_class = _flags(g, "ignore", n), _flags(g, "any_class", n)
        if min_box_height is not None:
            small = tiny_mask(gb, min_box_height)
        elif "iscrowd" in g:
            small = _flags(g, "iscrowd", n) & ~ignore
        else:
            small = tiny_mask(gb, MIN_BOX_HEIGHT_PX)
        mask = g.get("ignore_mask")
        masked = inside_mask(mask, gb)
        gr = np.asarray(g["ranges"], dtype=np.float64).reshape(-1) if "ranges" in g else np.full(n, np.nan)
        for k, (b, c, r) in enumerate(zip(xyxy_to_xywh(gb), gc, gr, strict=True)):
            reason = "ignore" if ignore[k] else "masked" if masked[k] else "small" if small[k] else None
            ann = {"id": len(gt_anns) + 1, "image_id": i, "category_id": int(c) + 1, "bbox": b.tolist(),
                   "area": float(b[2] * b[3]), "iscrowd": int(reason is not None), "range": float(r),
                   "height": float(b[3])}
            if reason is not None:
                ann["reason"] = reason
            gt_anns.append(ann)
            if reason is not None and any_class[k]:  # an ignore region for every class
                for other in range(len(CONE_CLASSES)):
                    if other != int(c):
                        gt_anns.append({**ann, "id": len(gt_anns) + 1, "category_id": other + 1, "copy": True})
        keep = ~inside_mask(mask, np.asarray(d["boxes"], dtype=np.float64).reshape(-1, 4))
        for r in coco_results(d, i, keep=keep):
            w, h = r["bbox"][2:]
            dt_anns.append({"id": len(dt_anns) + 1, **r, "area": float(w * h), "iscrowd": 0})
    return images, gt_anns, dt_anns


def coco_results(detections: Any, image_id: int, *, keep: np.ndarray | None = None) -> list[dict]:
    """One frame's detections (``boxes`` xyxy pixels, ``scores``, ``classes``) in COCO's results format:
    ``{"image_id", "category_id" (class index + 1), "bbox" [x, y, w, h], "score"}`` per detection
    (``keep``: a boolean mask of the detections to write).

    Example:
        >>> coco_results({"boxes": [[10, 20, 30, 60]], "scores": [0.9], "classes": [1]}, 7)
        [{'image_id': 7, 'category_id': 2, 'bbox': [10.0, 20.0, 20.0, 40.0], 'score': 0.9}]
    """
    d = detections
    boxes = np.asarray(d["boxes"], dtype=np.float64).reshape(-1, 4)
    scores, classes = np.asarray(d["scores"]).reshape(-1), np.asarray(d["classes"]).reshape(-1)
    if keep is not None:
        boxes, scores, classes = boxes[keep], scores[keep], classes[keep]
    return [{"image_id": int(image_id), "category_id": int(c) + 1, "bbox": b.tolist(), "score": float(sc)}
            for b, sc, c in zip(xyxy_to_xywh(boxes), scores, classes, strict=True)]


def coco_eval(images: list[dict], gt_anns: list[dict], dt_anns: list[dict], *,
              iou_50_only: bool = False, accumulate: bool = True):
    """pycocotools' ``COCOeval`` (bbox) over these lists, evaluated (and accumulated), quietly.

    ``iou_50_only``: match at IoU 0.5 only, one area range ("all") and 100 detections per image,
    the matching the gap workflow bootstraps.
    """

    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO()
        coco_gt.dataset = {"images": images, "annotations": gt_anns, "categories": CATEGORIES}
        coco_gt.createIndex()
        coco_dt = COCO()
        coco_dt.dataset = {"images": images, "annotations": dt_anns, "categories": CATEGORIES}
        coco_dt.createIndex()
        ev = COCOeval(coco_gt, coco_dt, "bbox")
        if iou_50_only:
            ev.params.iouThrs = np.array([0.5])
            ev.params.areaRng = [[0.0, 1e10]]
            ev.params.areaRngLbl = ["all"]
            ev.params.maxDets = [100]
        ev.evaluate()
        if accumulate:
            ev.accumulate()
    return ev


def score_detections(
    gt: Any,
    detections: Sequence[Any],
    *,
    score_threshold: float = 0.3,
    range_bins: Sequence[float] = DEFAULT_RANGE_BINS,
    min_box_height: float | None = None,
    too_small: str | None = None,
) -> EvalResult:
    """Score ``detections`` against ``gt`` (a ``CocoDataset`` or a list of per-frame dicts).

    ``min_box_height``: the too-small rule in image pixels (see :func:`coco_lists`; default: the
    frames' stored flags); ``too_small``: its description for the report.
    """
    if hasattr(gt, "gt") and hasattr(gt, "images"):  # a CocoDataset
        frames = [gt.gt(i) for i in range(len(gt))]
    else:
        frames = list(gt)
    images, gt_anns, dt_anns = coco_lists(frames, list(detections), min_box_height=min_box_height)
    ranges = {a["id"]: a["range"] for a in gt_anns}
    originals = [a for a in gt_anns if not a.get("copy")]
    n_ignored = sum(a["iscrowd"] for a in originals)
    ignored = {r: sum(a.get("reason") == r for a in originals) for r in ("small", "ignore", "masked")}
    ev = coco_eval(images, gt_anns, dt_anns)
    n_gt = len(originals) - n_ignored
    # precision: [T iou, R recall, K class, A area, M maxDets]; area 0 = all, maxDets -1 = 100
    prec = ev.eval["precision"][:, :, :, 0, -1] if images else np.full((10, 101, len(CONE_CLASSES)), -1.0)

    def ap(p: np.ndarray) -> float:
        v = p[p > -1]
        return float(v.mean()) if v.size else math.nan

    ap50 = {name: ap(prec[0, :, k]) for k, name in enumerate(CONE_CLASSES)}
    apall = {name: ap(prec[:, :, k]) for k, name in enumerate(CONE_CLASSES)}
    present = [k for k in range(len(CONE_CLASSES)) if (prec[0, :, k] > -1).any()]
    map50 = float(np.mean([ap50[CONE_CLASSES[k]] for k in present])) if present else math.nan
    mapall = float(np.mean([apall[CONE_CLASSES[k]] for k in present])) if present else math.nan
    by = [ap50[c] for c in ("blue", "yellow") if CONE_CLASSES.index(c) in present]
    map50_by = float(np.mean(by)) if by else math.nan

    # recall by range at the operating threshold, from pycocotools' own matching at IoU 0.5
    dt_score = {a["id"]: a["score"] for a in dt_anns}
    matched: dict[int, bool] = {}
    for e in ev.evalImgs if images else []:
        if e is None or e["aRng"] != ev.params.areaRng[0]:
            continue
        for gid, m, ig in zip(e["gtIds"], e["gtMatches"][0], e["gtIgnore"], strict=True):
            if ig:
                continue
            matched[gid] = bool(m > 0 and dt_score[int(m)] >= score_threshold)
    bins = list(range_bins)
    rbr: dict[str, tuple[float, int]] = {}
    for lo, hi in zip(bins[:-1], bins[1:], strict=True):
        ids = [gid for gid in matched if lo <= ranges[gid] < hi]
        rbr[_label(lo, hi)] = (float(np.mean([matched[g] for g in ids])) if ids else math.nan, len(ids))
    recall = float(np.mean(list(matched.values()))) if matched else math.nan
    return EvalResult(map50=map50, map=mapall, ap50_per_class=ap50, ap_per_class=apall, recall_by_range=rbr,
                      recall=recall, n_images=len(images), n_gt=n_gt, n_ignored=n_ignored, ignored=ignored,
                      too_small=too_small or (f"box height < {min_box_height:.3g} px" if min_box_height is not None
                                              else f"box height < {MIN_BOX_HEIGHT_PX:g} px, as stored"),
                      n_detections=len(dt_anns), score_threshold=float(score_threshold), map50_blue_yellow=map50_by)


evaluate = score_detections
"""The name :func:`score_detections` had before; kept for code that imports it."""


def small_rule(dataset: Any, detector: Any = None) -> SmallRule | None:
    """The too-small rule for ``dataset``'s frames at ``detector``'s input scale (None when the
    frames have several sizes: then the stored flags are used)."""
    sizes = {(int(r["width"]), int(r["height"])) for r in dataset.images}
    return SmallRule.for_image(next(iter(sizes)), detector) if len(sizes) == 1 else None


def _resolve_effect(effect: Any) -> Callable | None:
    if effect is None or callable(effect):
        return effect

    return parse_weather(effect)


def score_dataset(
    dataset: Any,
    detector: Any,
    effect: Any = None,
    seed: int = 0,
    *,
    batch_size: int = 8,
    keep_threshold: float = 0.05,
    limit: int | None = None,
    progress: bool = False,
    **evaluate_kwargs: Any,
) -> EvalResult:
    """Run ``detector`` over a ``CocoDataset`` under ``effect`` and score it (batched inference).

    ``effect`` is None (clean), a weather effect (``effect(image, depth=, state=, rng=)``) or any
    spec ``weather_gym.weather.parse_weather`` accepts. Frame ``i`` gets the effect with
    ``reset(seed_i)`` and ``rng=default_rng(seed_i)``, ``seed_i`` spawned from ``seed``: the same seed
    gives the same degraded frames. Detections are kept down to ``keep_threshold`` (low, so the AP
    curve is complete); recall by range uses the detector's operating ``score_threshold``.
    """

    eff = _resolve_effect(effect)
    n = len(dataset) if limit is None else min(len(dataset), int(limit))
    seeds = np.random.SeedSequence(seed).generate_state(max(n, 1), dtype=np.uint32)
    dets = []
    for start in tqdm(range(0, n, batch_size), desc="score", unit="batch", disable=not progress):
        idx = range(start, min(n, start + batch_size))
        ims = []
        for i in idx:
            im = dataset.image(i)
            if eff is not None:
                rec = dataset.record(i)
                state = {"speed": float(rec.get("speed", 0.0)), "yaw_rate": float(rec.get("yaw_rate", 0.0))}
                cam = rec.get("camera")
                if cam:
                    c = CameraConfig(**cam)
                    state.update(exposure_s=c.exposure_s, fx=c.fx)
                if hasattr(eff, "reset"):
                    eff.reset(int(seeds[i]))
                depth = dataset.depth(i) if rec.get("depth_file") else None
                im = eff(im, depth=depth, state=state, rng=np.random.default_rng(int(seeds[i])))
            ims.append(im)
        dets += detector.detect_batch(ims, score_threshold=keep_threshold)
    gts = [dataset.gt(i) for i in range(n)]
    evaluate_kwargs.setdefault("score_threshold", float(getattr(detector, "score_threshold", 0.3)))
    rule = small_rule(dataset, detector)
    if rule is not None and "min_box_height" not in evaluate_kwargs:
        evaluate_kwargs.update(min_box_height=rule.min_height_px, too_small=rule.describe())
    result = score_detections(gts, dets, **evaluate_kwargs)
    result.extra.update(effect=None if eff is None else getattr(eff, "params", lambda: str(eff))(), seed=int(seed))
    return result
