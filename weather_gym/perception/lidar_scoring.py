"""Scoring LiDAR cones: recall and precision by range and the position error, per frame and over frames.

A LiDAR's cones carry no boxes, so they are matched by position, as the map is scored
(:func:`weather_gym.lab.evaluation.metrics.map_precision_recall`): a detected cone and a true one within
``radius`` (0.5 m) of each other in the car frame, one to one (``scipy.optimize.linear_sum_assignment``
on the distances). The truth of a frame is the cones the clear-air scan hit with at least
``min_points`` returns (what the sensor could see); ranges are from the sensor; the bins are the camera
scoring's (:data:`weather_gym.perception.scoring.DEFAULT_RANGE_BINS`).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.lidar_scoring import LidarScoring
    >>> s = LidarScoring()
    >>> s.add(det_xy=np.array([[5.1, 1.0], [9.0, -4.0]]), gt_xy=np.array([[5.0, 1.0], [12.0, 2.0]]),
    ...       gt_ranges=np.array([5.0, 12.2]), det_ranges=np.array([5.2, 9.8]))
    >>> r = s.result()
    >>> r.recall, r.precision, round(r.position_error_m, 2), r.recall_by_range["5-10 m"]
    (0.5, 0.5, 0.1, (1.0, 1))
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from weather_gym.perception.scoring import DEFAULT_RANGE_BINS

__all__ = ["LidarScores", "LidarScoring", "match_cones"]

MATCH_RADIUS_M = 0.5


def match_cones(det_xy: np.ndarray, gt_xy: np.ndarray, radius: float = MATCH_RADIUS_M):
    """``(det_index, gt_index, distance)`` of the one-to-one matches within ``radius``."""
    det_xy, gt_xy = np.asarray(det_xy, float).reshape(-1, 2), np.asarray(gt_xy, float).reshape(-1, 2)
    if not len(det_xy) or not len(gt_xy):
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0)
    d = np.hypot(*(det_xy[:, None, :] - gt_xy[None, :, :]).transpose(2, 0, 1))
    rows, cols = linear_sum_assignment(np.where(d <= radius, d, 1e6))
    ok = d[rows, cols] <= radius
    return rows[ok], cols[ok], d[rows[ok], cols[ok]]


def _label(lo: float, hi: float) -> str:
    return f"{lo:g}-{hi:g} m" if math.isfinite(hi) else f">{lo:g} m"


@dataclass(frozen=True)
class LidarScores:
    """Over the frames scored: ``recall``, ``precision``, the median ``position_error_m`` of the matches,
    and per range bin ``(share, count)`` for recall (true cones) and precision (detections)."""

    recall: float
    precision: float
    position_error_m: float
    recall_by_range: dict[str, tuple[float, int]]
    precision_by_range: dict[str, tuple[float, int]]
    frames: int

    def as_dict(self) -> dict:
        return {"recall": self.recall, "precision": self.precision, "position_error_m": self.position_error_m,
                "frames": self.frames,
                "recall_by_range": {k: {"recall": v, "n": n} for k, (v, n) in self.recall_by_range.items()},
                "precision_by_range": {k: {"precision": v, "n": n} for k, (v, n) in self.precision_by_range.items()}}


@dataclass
class LidarScoring:
    """Collects frames (:meth:`add`) and scores them (:meth:`result`)."""

    radius: float = MATCH_RADIUS_M
    range_bins: Sequence[float] = DEFAULT_RANGE_BINS
    _gt_r: list = field(default_factory=list)
    _gt_hit: list = field(default_factory=list)
    _det_r: list = field(default_factory=list)
    _det_hit: list = field(default_factory=list)
    _err: list = field(default_factory=list)
    frames: int = 0

    def add(self, *, det_xy: np.ndarray, gt_xy: np.ndarray, gt_ranges: np.ndarray, det_ranges: np.ndarray) -> None:
        """One frame: detected and true cones (car frame, m) and their ranges from the sensor."""
        di, gi, dist = match_cones(det_xy, gt_xy, self.radius)
        gt_hit = np.zeros(len(np.asarray(gt_ranges).reshape(-1)), bool)
        det_hit = np.zeros(len(np.asarray(det_ranges).reshape(-1)), bool)
        gt_hit[gi], det_hit[di] = True, True
        self._gt_r.append(np.asarray(gt_ranges, float).reshape(-1))
        self._gt_hit.append(gt_hit)
        self._det_r.append(np.asarray(det_ranges, float).reshape(-1))
        self._det_hit.append(det_hit)
        self._err.append(dist)
        self.frames += 1

    def result(self) -> LidarScores:
        cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0)  # noqa: E731
        gr, gh, dr, dh, err = (cat(x) for x in (self._gt_r, self._gt_hit, self._det_r, self._det_hit, self._err))
        share = lambda h: float(np.mean(h)) if len(h) else math.nan  # noqa: E731
        bins = list(self.range_bins)
        rbr, pbr = {}, {}
        for lo, hi in zip(bins[:-1], bins[1:]):
            g, d = (gr >= lo) & (gr < hi), (dr >= lo) & (dr < hi)
            rbr[_label(lo, hi)] = (share(gh[g]), int(g.sum()))
            pbr[_label(lo, hi)] = (share(dh[d]), int(d.sum()))
        return LidarScores(recall=share(gh), precision=share(dh),
                           position_error_m=float(np.median(err)) if len(err) else math.nan,
                           recall_by_range=rbr, precision_by_range=pbr, frames=self.frames)
