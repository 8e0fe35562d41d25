"""Draw one frame's detections from a surrogate :class:`~weather_gym.surrogate.model.Point`.

:class:`FrameSampler` turns a frame's ground truth (the visible cones of ``info["gt"]``: boxes,
classes, cone ids, ranges, bearings) into what the detector would have reported: each cone is
detected with its model probability, modulated by the per-cone Markov chain (its state on the
previous frame, when it was visible then), reported in a class drawn from the confusion row (the
crowded one for a cone whose box overlaps another's), at the true range and bearing plus errors
drawn from that range bin's quantiles, with a score drawn from the score quantiles; each cone may
also carry a part detection (a logged one, placed relative to its box); then a negative-binomial
number of false positives away from the cones, drawn from the logged ones.
The probabilities are computed with numpy over the cones of the frame, the draws from them in one
compiled kernel (numba; the same operations, cone by cone); the random numbers come from the
caller's generator only.

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

import numba
import numpy as np

from weather_gym.camera_config import CameraConfig
from weather_gym.surrogate.log import _HEIGHTS
from weather_gym.surrogate.model import CROWDED, ERR_RANGE_EDGES, QUANTILES, Point, crowding, hat_terms

__all__ = ["FrameSampler"]

_NQ = len(QUANTILES) - 1
_NB = len(ERR_RANGE_EDGES) - 1
try:  # np.interp without its Python-level argument checks (the same C function, the same numbers)
    from numpy._core._multiarray_umath import interp as _interp
except ImportError:  # pragma: no cover (another numpy layout)
    _interp = np.interp


class FrameSampler:
    """Per-episode sampler of detections from a fitted point (``reset()`` at each episode).

    Args:
        point: the model parameters for the current weather.
        camera: the camera (for the visibility feature); default ``CameraConfig()``.
    """

    def __init__(self, point: Point, camera: Any = None) -> None:
        self.camera = camera if camera is not None else CameraConfig()
        self.set_point(point)
        self._fy_h = self.camera.fy * _HEIGHTS
        self._last_step = np.full(256, -10, np.int64)
        self._last_det = np.zeros(256, bool)

    def set_point(self, point: Point) -> None:
        """New parameters (new weather) from the next frame; the cones' states are kept."""
        self.point = point
        self._tab = _Tables(point)

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
        t = self._tab
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
            z = t.probabilities(Point.features(rng_, brg, box_h, vis, crowd), cls)
            max_id = int(ids.max())
            if max_id >= len(self._last_step):
                self._grow(max_id)
            u = rng.random((9, n))
            bins = np.minimum(ERR_RANGE_EDGES.searchsorted(rng_, "right"), _NB) - 1
            bins %= _NB  # (numpy's indexing of a bin -1)
            parts = [_draw_cones(z, u, cls, ids, rng_, brg, boxes, box_h, t.zeros[:n] if crowd is None else crowd,
                                 bins, self._last_step, self._last_det, step, float(p.rho), t.cum, t.q,
                                 t.loose_box_d, t.part_rows)]
        else:
            parts = [(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 4)))]
        m = self._fp_count(rng)
        if m:
            rows = self._fp_rows(rng, m)
            parts.append((rows[:, 2].astype(np.int64), rows[:, 0], rows[:, 1], rows[:, 3], rows[:, 4:8]))
        if len(parts) > 1:
            rep, ranges, bearings, scores, out_boxes = (np.concatenate(a) for a in zip(*parts, strict=True))
        else:
            rep, ranges, bearings, scores, out_boxes = parts[0]
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


class _Tables:
    """A point's parameters arranged for :class:`FrameSampler`'s per-step draws (once per point):
    the three probability models (detected, loose, part) side by side, the confusion rows cumulated,
    the quantile rows in one flat table."""

    def __init__(self, p: Point) -> None:
        hats = [hat_terms(w) for w in (p.coef, p.coef_loose, p.coef_part)]
        self.w0 = np.array([[w[0]] for w in (p.coef, p.coef_loose, p.coef_part)])
        # per feature: its knots, and the hat values of each kind (Point.probability_of's terms)
        self.interp = [(hats[0][0][f][0], [h[0][f][1] for h in hats]) for f in range(5)]
        self.cls = np.array([h[1] for h in hats])
        self.crowd0 = np.array([[vals[0]] for vals in self.interp[4][1]])  # no other cone: crowding 0
        self.terms = np.zeros((5, 3, 256))
        self.cum = np.cumsum(np.stack([p.confusion, p.confusion_crowded, p.confusion_loose]), axis=-1)
        score_q = np.broadcast_to(p.score_q, p.range_err_q.shape)
        loose_score_q = np.broadcast_to(p.loose_score_q, p.range_err_q.shape)
        q = np.stack([np.stack([p.range_err_q, p.loose_range_err_q]), np.stack([p.bearing_err_q, p.loose_bearing_err_q]),
                      np.stack([score_q, loose_score_q])]).astype(np.float64)  # (3, matched/loose, bin, quantile)
        self.q = np.ascontiguousarray(q).reshape(-1)
        self.loose_box_d = np.ascontiguousarray(p.loose_box_d, np.float64)
        self.part_rows = np.ascontiguousarray(p.part_rows, np.float64)
        self.zeros = np.zeros(256)

    def probabilities(self, x: tuple, cls: np.ndarray) -> np.ndarray:
        """(3, n): P(detected), P(loose | not detected), P(part) of each cone, from ``x`` =
        :meth:`Point.features` (crowding None: no other cone): :meth:`Point.probability_of`'s operations,
        in its order, for the three kinds at once."""
        n = len(cls)
        if n > self.terms.shape[2]:
            self.terms = np.zeros((5, 3, 2 * n))
        terms = self.terms
        for f, (knots, vals) in enumerate(self.interp):
            if x[f] is not None:
                for kind in range(3):
                    terms[f, kind, :n] = _interp(x[f], knots, vals[kind])
        z = self.w0 + terms[0, :, :n]
        z += terms[1, :, :n]
        z += terms[2, :, :n]
        z += terms[3, :, :n]
        z += self.crowd0 if x[4] is None else terms[4, :, :n]
        z += self.cls[:, cls]
        return 0.5 * (1.0 + np.tanh(0.5 * z))  # model._sigmoid


@numba.njit(cache=True, nogil=True)
def _draw_cones(prob, u, cls, ids, ranges, bearings, boxes, box_h, crowd, bins, last_step, last_det, step, rho,  # noqa: C901 (compiled)
                cum, q, loose_box_d, part_rows):  # pragma: no cover (compiled; tested through FrameSampler)
    """The per-cone draws of one frame from the probabilities ``prob`` (3, n: detected, loose, part)
    and the uniforms ``u`` (9, n): (classes, ranges, bearings, scores, boxes) of the reported cones,
    then of the part detections; updates the cones' Markov states."""
    n = cls.shape[0]
    det = np.empty(n, np.bool_)
    loose = np.empty(n, np.bool_)
    k = 0
    for i in range(n):  # detected (with the cone's state on the previous frame), else loose, or missed
        p = prob[0, i]
        if last_step[ids[i]] == step - 1:
            p = p + rho * (1.0 - p) if last_det[ids[i]] else p * (1.0 - rho)
        det[i] = u[0, i] < p
        loose[i] = not det[i] and u[5, i] < prob[1, i]
        k += det[i] or loose[i]
    for i in range(n):
        last_step[ids[i]] = step
        last_det[ids[i]] = det[i]
    n_part = 0
    if part_rows.shape[0]:
        for i in range(n):
            n_part += u[7, i] < prob[2, i]
    m = k + n_part
    classes = np.empty(m, np.int64)
    out = np.empty((m, 7))  # range, bearing, score, box
    n_cls = cum.shape[3]
    block = 2 * _NB * (_NQ + 1)  # the quantile rows of range error, bearing error, score
    o = 0
    for i in range(n):
        if not (det[i] or loose[i]):
            continue
        # the reported class: the confusion row (loose, else crowded, else clear), cumulated
        which = 2 if loose[i] else (1 if crowd[i] > CROWDED else 0)
        c = 0
        for j in range(n_cls):
            c += u[1, i] > cum[which, bins[i], cls[i], j]
        classes[o] = min(c, n_cls - 1)
        # range error, bearing error, score: inverse-CDF draws from the loose or the matched quantiles
        base = (_NB if loose[i] else 0) + bins[i]
        for t in range(3):
            pos = u[2 + t, i] * _NQ
            j = min(int(pos), _NQ - 1)
            f = pos - j
            at = t * block + base * (_NQ + 1) + j
            out[o, t] = q[at] * (1.0 - f) + q[at + 1] * f
        out[o, 0] += ranges[i]
        out[o, 1] += bearings[i]
        if loose[i]:  # a box a little off
            d = loose_box_d[int(u[6, i] * loose_box_d.shape[0])]
            for j in range(4):
                out[o, 3 + j] = boxes[i, j] + d[j] * box_h[i]
        else:
            out[o, 3:] = boxes[i]
        o += 1
    if n_part:  # part detections: a box on a stripe or part of the cone, detected or not
        for i in range(n):
            if u[7, i] < prob[2, i]:
                pr = part_rows[int(u[8, i] * part_rows.shape[0])]
                classes[o] = int(pr[4])
                out[o, 0] = ranges[i] + pr[6]
                out[o, 1] = bearings[i] + pr[7]
                out[o, 2] = pr[5]
                for j in range(4):
                    out[o, 3 + j] = boxes[i, j] + pr[j] * box_h[i]
                o += 1
    return classes, out[:, 0], out[:, 1], out[:, 2], out[:, 3:]
