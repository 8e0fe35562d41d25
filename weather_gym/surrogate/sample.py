"""Draw one frame's detections from a surrogate :class:`~weather_gym.surrogate.model.Point`.

:class:`FrameSampler` turns a frame's ground truth (the visible cones of ``info["gt"]``: boxes,
classes, cone ids, ranges, bearings) into what the detector would have reported: each cone is
detected with its model probability, modulated by the per-cone Markov chain (its state on the
previous frame, when it was visible then), reported in a class drawn from the confusion row (the
crowded one for a cone whose box overlaps another's), at the true range and bearing plus errors
drawn from that range bin's quantiles, with a score drawn from the score quantiles; each cone may
also carry a part detection (a logged one, placed relative to its box); then a negative-binomial
number of false positives away from the cones, drawn from the logged ones.
Everything is vectorised over the cones of the frame; the random numbers come from the caller's
generator only.

Example:
    >>> import numpy as np
    >>> from weather_gym.surrogate.model import load_model
    >>> from weather_gym.surrogate.sample import FrameSampler
    >>> s = FrameSampler(load_model().point("clear"))
    >>> gt = {"boxes": np.array([[300, 170, 330, 215.]]), "classes": np.array([1]), "cone_ids": np.array([7]),
    ...       "ranges": np.array([5.0]), "bearings": np.array([0.0])}
    >>> det = s(gt, np.random.default_rng(0), step=0)
    >>> sorted(det), det["boxes"].shape[1]
    (['bearings', 'boxes', 'classes', 'ranges', 'scores'], 4)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from weather_gym.camera import CameraConfig
from weather_gym.surrogate.log import _HEIGHTS
from weather_gym.surrogate.model import CROWDED, ERR_RANGE_EDGES, QUANTILES, Point, crowding

__all__ = ["FrameSampler"]

_NQ = len(QUANTILES) - 1


def _draw(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Inverse-CDF draws: ``q`` (N, Q) quantile rows, ``u`` (N,) uniforms -> (N,) values."""
    pos = u * _NQ
    i = np.minimum(pos.astype(np.int64), _NQ - 1)
    f = pos - i
    rows = np.arange(len(u))
    return q[rows, i] * (1.0 - f) + q[rows, i + 1] * f


class FrameSampler:
    """Per-episode sampler of detections from a fitted point (``reset()`` at each episode).

    Args:
        point: the model parameters for the current weather.
        camera: the camera (for the visibility feature); default ``CameraConfig()``.
    """

    def __init__(self, point: Point, camera: Any = None) -> None:
        self.camera = camera if camera is not None else CameraConfig()
        self.point = point
        self._fy_h = self.camera.fy * _HEIGHTS
        self._last_step = np.full(256, -10, np.int64)
        self._last_det = np.zeros(256, bool)

    def set_point(self, point: Point) -> None:
        """New parameters (new weather) from the next frame; the cones' states are kept."""
        self.point = point

    def reset(self) -> None:
        self._last_step[:] = -10
        self._last_det[:] = False

    def hold(self, gt: Any, step: int) -> None:
        """The frame of ``step`` repeats the previous one (the caller reports the previous detections):
        its cones keep their state, as seen on this frame too."""
        n = int(len(gt["classes"])) if gt is not None and "classes" in gt else 0
        if n:
            ids = np.asarray(gt["cone_ids"], np.int64).reshape(n)
            self._grow(int(ids.max()))
            self._last_step[ids] = step

    def _grow(self, max_id: int) -> None:
        if max_id >= len(self._last_step):
            n = max(2 * len(self._last_step), max_id + 1)
            self._last_step = np.concatenate([self._last_step, np.full(n - len(self._last_step), -10, np.int64)])
            self._last_det = np.concatenate([self._last_det, np.zeros(n - len(self._last_det), bool)])

    def __call__(self, gt: Any, rng: np.random.Generator, step: int) -> dict[str, np.ndarray]:
        p = self.point
        n = int(len(gt["classes"])) if gt is not None and "classes" in gt else 0
        if n:
            boxes = np.asarray(gt["boxes"], np.float64).reshape(n, 4)
            cls = np.asarray(gt["classes"], np.int64).reshape(n)
            ids = np.asarray(gt["cone_ids"], np.int64).reshape(n)
            rng_ = np.asarray(gt["ranges"], np.float64).reshape(n)
            brg = np.asarray(gt["bearings"], np.float64).reshape(n)
            box_h = boxes[:, 3] - boxes[:, 1]
            full = self._fy_h[cls] / np.maximum(rng_ * np.cos(brg), 0.1)
            vis = np.minimum(box_h / full, 1.0)  # = log.visibility, inlined (this runs every step)
            crowd = crowding(boxes) if n > 1 else None
            feats = p.features(rng_, brg, box_h, vis, crowd)
            prob = p.probability_of(feats, cls)
            self._grow(int(ids.max()))
            seen_before = self._last_step[ids] == step - 1
            before = self._last_det[ids]
            rho = p.rho
            q = np.where(seen_before, np.where(before, prob + rho * (1.0 - prob), prob * (1.0 - rho)), prob)
            u = rng.random((9, n))
            det = u[0] < q
            self._last_step[ids] = step
            self._last_det[ids] = det
            # a cone not detected may still be reported "loosely": a box a little off (a scoring miss
            # plus a false positive), near the cone's true place
            loose = ~det & (u[5] < p.probability_of(feats, cls, kind="loose"))
            rep_any = np.flatnonzero(det | loose)  # indices: cheaper than a boolean mask, used many times
            c = cls[rep_any]
            r_true = rng_[rep_any]
            b = np.minimum(np.searchsorted(ERR_RANGE_EDGES, r_true, side="right"), len(ERR_RANGE_EDGES) - 1) - 1
            lz = loose[rep_any]
            conf = p.confusion[b, c]
            if crowd is not None:
                conf = np.where(crowd[rep_any, None] > CROWDED, p.confusion_crowded[b, c], conf)
            cum = np.cumsum(np.where(lz[:, None], p.confusion_loose[b, c], conf), axis=1)
            rep = np.minimum(np.add.reduce(u[1, rep_any][:, None] > cum, axis=1), cum.shape[1] - 1)
            # range error, bearing error and score: one inverse-CDF draw over the three stacked
            # (each row from the loose or the matched quantiles)
            lz2 = lz[:, None]
            q = np.concatenate([np.where(lz2, p.loose_range_err_q[b], p.range_err_q[b]),
                                np.where(lz2, p.loose_bearing_err_q[b], p.bearing_err_q[b]),
                                np.where(lz2, p.loose_score_q[None, :], p.score_q[None, :])])
            k = len(r_true)
            drawn = _draw(q, u[2:5, rep_any].reshape(-1))
            ranges = r_true + drawn[:k]
            bearings = brg[rep_any] + drawn[k:2 * k]
            scores = drawn[2 * k:]
            out_boxes = boxes[rep_any]
            lz_i = np.flatnonzero(lz)
            if lz_i.size:
                li = rep_any[lz_i]
                d = p.loose_box_d[(u[6, li] * len(p.loose_box_d)).astype(np.int64)]
                out_boxes[lz_i] = out_boxes[lz_i] + d * box_h[li][:, None]
            if len(p.part_rows):  # part detections: a box on a stripe or part of the cone, detected or not
                pi = np.flatnonzero(u[7] < p.probability_of(feats, cls, kind="part"))
                if pi.size:
                    pr = p.part_rows[(u[8, pi] * len(p.part_rows)).astype(np.int64)]
                    rep = np.concatenate([rep, pr[:, 4].astype(np.int64)])
                    ranges = np.concatenate([ranges, rng_[pi] + pr[:, 6]])
                    bearings = np.concatenate([bearings, brg[pi] + pr[:, 7]])
                    scores = np.concatenate([scores, pr[:, 5]])
                    out_boxes = np.vstack([out_boxes, boxes[pi] + pr[:, :4] * box_h[pi][:, None]])
        else:
            rep = np.zeros(0, np.int64)
            ranges = bearings = scores = np.zeros(0)
            out_boxes = np.zeros((0, 4))
        m = self._fp_count(rng)
        if m:
            rows = self._fp_rows(rng, m)
            rep = np.concatenate([rep, rows[:, 2].astype(np.int64)])
            ranges = np.concatenate([ranges, rows[:, 0]])
            bearings = np.concatenate([bearings, rows[:, 1]])
            scores = np.concatenate([scores, rows[:, 3]])
            out_boxes = np.vstack([out_boxes, rows[:, 4:8]])
        return {"boxes": out_boxes.astype(np.float32), "scores": scores.astype(np.float32),
                "classes": rep.astype(np.int64), "ranges": ranges.astype(np.float32),
                "bearings": bearings.astype(np.float32)}

    def _fp_count(self, rng: np.random.Generator) -> int:
        p = self.point
        mean, var = p.fp_mean, p.fp_var
        if mean <= 0.0:
            return 0
        if var > mean * 1.01:  # over-dispersed: negative binomial with this mean and variance
            r = mean * mean / (var - mean)
            return int(rng.negative_binomial(r, r / (r + mean)))
        return int(rng.poisson(mean))

    def _fp_rows(self, rng: np.random.Generator, m: int) -> np.ndarray:
        p = self.point
        rows = p.fp_rows
        if not len(rows):
            return np.zeros((0, 8))
        split = p.stats.get("fp_rows_a")
        if split is None:
            return rows[rng.integers(0, len(rows), m)]
        na, w = int(split), float(p.stats["fp_weight_b"])
        nb = len(rows) - na
        from_b = rng.random(m) < w
        in_b = na + rng.integers(0, max(nb, 1), m)
        in_a = rng.integers(0, max(na, 1), m)
        if nb == 0 or na == 0:  # one of the two fitted points logged no false positive: the other's rows
            from_b[:] = nb > 0
        return rows[np.where(from_b, in_b, in_a)]
