"""Draw one frame's detections from a surrogate :class:`~weather_gym.surrogate.model.Point`.

:class:`FrameSampler` turns a frame's ground truth (the visible cones of ``info["gt"]``: boxes,
classes, cone ids, ranges, bearings) into what the detector would have reported: each cone is
detected with its model probability, modulated by the per-cone Markov chain (its state on the
previous frame, when it was visible then), reported in a class drawn from the confusion row (the
crowded one for a cone whose box overlaps another's), at the true range and bearing plus errors
drawn from that range bin's quantiles, with a score drawn from the score quantiles; each cone may
also carry a part detection (a logged one, placed relative to its box); then a negative-binomial
number of false positives away from the cones, drawn from the logged ones.
The logits of the three probability models are computed in one compiled kernel (numba; np.interp's
arithmetic, one knot lookup per feature for the three models), their tanh by numpy, the draws in a
second kernel (the same operations, cone by cone, written straight into the reported float32 arrays);
the random numbers come from the caller's generator only.

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

from weather_gym.camera.config import CameraConfig
from weather_gym.core._jit_cache import jit_cache
from weather_gym.surrogate.log import _HEIGHTS
from weather_gym.surrogate.model import CROWDED, ERR_RANGE_EDGES, QUANTILES, Point, crowding, hat_terms

__all__ = ["FrameSampler"]

_NQ = len(QUANTILES) - 1
_NB = len(ERR_RANGE_EDGES) - 1
_EDGES = np.array(ERR_RANGE_EDGES, np.float64)  # (a global of the compiled kernels: a constant)


class FrameSampler:
    """Per-episode sampler of detections from a fitted point (``reset()`` at each episode).

    Args:
        point: the model parameters for the current weather.
        camera: the camera (for the visibility feature); default ``CameraConfig()``.
        box_factor: box heights in this camera's pixels times this are the model's box-height feature
            (the same size at the detector's input; ``SurrogateModel.box_factor``; 1.0: the fitting camera).
        range_factor: a cone's range times this is the range at which it has the same box height in the
            fitting camera's pixels: its range error is drawn from that range bin (the depth inside a box
            of so many camera pixels; ``SurrogateModel.range_factor``; 1.0: the fitting camera).
        fit_camera: (W, H) of the camera the model was fitted at: the logged false positives' boxes are
            rescaled from it to ``camera`` (None: the same camera).
    """

    def __init__(self, point: Point, camera: Any = None, *, box_factor: float = 1.0,
                 fit_camera: tuple[int, int] | None = None, range_factor: float = 1.0) -> None:
        self.camera = camera if camera is not None else CameraConfig()
        self.box_factor = float(box_factor)
        self.range_factor = float(range_factor)
        fw, fh = fit_camera if fit_camera is not None else (self.camera.width, self.camera.height)
        self._fp_scale = np.array([self.camera.width / fw, self.camera.height / fh] * 2)
        self._rescale_fp = bool(np.any(self._fp_scale != 1.0))
        self.set_point(point)
        self._fy_h = self.camera.fy * _HEIGHTS
        self._last_step = np.full(256, -10, np.int64)
        self._last_det = np.zeros(256, bool)

    def set_point(self, point: Point) -> None:
        """New parameters (new weather) from the next frame; the cones' states are kept."""
        self.point = point
        self._tab = _Tables(point)
        split = point.stats.get("fp_rows_a")  # two fitted points' false-positive rows: (rows of a, weight of b)
        self._fp_split = None if split is None else (int(split), float(point.stats["fp_weight_b"]))

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
            box_f = box_h if self.box_factor == 1.0 else box_h * self.box_factor  # at the detector's input
            th = t.tanh_half(Point.features(rng_, brg, box_f, vis, crowd), cls)
            max_id = int(ids.max())
            if max_id >= len(self._last_step):
                self._grow(max_id)
            u = rng.random((9, n))
            det = _draw_cones(th, u, cls, ids, rng_, brg, boxes, box_h, t.zeros[:n] if crowd is None else crowd,
                              self.range_factor, self._last_step, self._last_det, step,
                              float(p.rho), t.cum, t.q, t.loose_box_d, t.part_rows)
        else:
            det = (np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros(0, np.float32),
                   np.zeros(0, np.float32), np.zeros((0, 4), np.float32))
        m = self._fp_count(rng)
        if not m:
            rep, ranges, bearings, scores, out_boxes = det
        else:
            rows = self._fp_rows(rng, m)
            if self._rescale_fp:  # logged at the fitting camera: the same place in this camera's frame
                rows = rows.astype(np.float64)
                rows[:, 4:8] *= self._fp_scale
            rows32 = rows.astype(np.float32)
            rep = np.concatenate([det[0], rows[:, 2].astype(np.int64)])
            ranges, bearings, scores = (np.concatenate([det[1 + i], rows32[:, c]]) for i, c in enumerate((0, 1, 3)))
            out_boxes = np.concatenate([det[4], rows32[:, 4:8]])
        return {"boxes": out_boxes, "scores": scores, "classes": rep, "ranges": ranges, "bearings": bearings}

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
        if self._fp_split is None:
            return rows[rng.integers(0, len(rows), m)]
        na, w = self._fp_split
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
        hats = [hat_terms(w) for w in (p.coef, p.coef_loose, p.coef_part)]  # type: ignore[arg-type]  # a sampled point has all three
        self.w0 = np.array([w[0] for w in (p.coef, p.coef_loose, p.coef_part)], np.float64)  # type: ignore[index]  # all three set
        # per feature: its knots (padded to the longest), and the hat values of each kind at them
        # (Point.probability_of's terms; the three kinds share the knots)
        knots = [hats[0][0][f][0] for f in range(5)]
        self.n_knots = np.array([len(k) for k in knots], np.int64)
        self.knots = np.zeros((5, self.n_knots.max()))
        self.vals = np.zeros((3, 5, self.n_knots.max()))
        for f, k in enumerate(knots):
            self.knots[f, :len(k)] = k
            for kind, h in enumerate(hats):
                self.vals[kind, f, :len(k)] = h[0][f][1]
        self.cls = np.ascontiguousarray([h[1] for h in hats], np.float64)
        self.cum = np.cumsum(np.stack([p.confusion, p.confusion_crowded, p.confusion_loose]), axis=-1)  # type: ignore[list-item]  # all three set
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
        in its order, for the three kinds at once (the logits in one compiled kernel: ``np.interp``'s
        arithmetic, one knot lookup per feature for the three kinds)."""
        th = self.tanh_half(x, cls)
        th += 1.0  # model._sigmoid: 0.5 * (1.0 + np.tanh(0.5 * z))
        th *= 0.5
        return th

    def tanh_half(self, x: tuple, cls: np.ndarray) -> np.ndarray:
        """(3, n) ``np.tanh(0.5 * z)`` of the logits ``z`` of :meth:`probabilities` (the probability is
        ``0.5 * (1.0 + this)``; :func:`_draw_cones` finishes it cone by cone)."""
        crowd = x[4]
        n = len(cls)
        if crowd is None and n > len(self.zeros):
            self.zeros = np.zeros(2 * n)
        f = [np.ascontiguousarray(v, np.float64).reshape(n) for v in x[:4]]
        c = self.zeros[:n] if crowd is None else np.ascontiguousarray(crowd, np.float64).reshape(n)
        z = _logits(f[0], f[1], f[2], f[3], c, crowd is not None, np.asarray(cls, np.int64).reshape(n),
                    self.knots, self.n_knots, self.vals, self.w0, self.cls)
        return np.tanh(z, out=z)  # numpy's tanh (the compiled kernel's could differ in the last bit)


@numba.njit(cache=jit_cache(__file__), nogil=True, inline="always")
def _interp_at(x, knots, vals, j, nk):  # pragma: no cover (compiled)
    """np.interp(x, knots[:nk], vals[:nk]) with the knot bin ``j`` of ``x`` (-1 below the first knot, nk
    above the last): numpy's arithmetic and special cases (arr_interp in compiled_base.c)."""
    if x != x:
        return x
    if j == -1:
        return vals[0]
    if j == nk or j == nk - 1 or knots[j] == x:
        return vals[min(j, nk - 1)]
    slope = (vals[j + 1] - vals[j]) / (knots[j + 1] - knots[j])
    r = slope * (x - knots[j]) + vals[j]
    if r != r:  # nan in one direction: the other
        r = slope * (x - knots[j + 1]) + vals[j + 1]
        if r != r and vals[j] == vals[j + 1]:
            r = vals[j]
    return r


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _logits(r, b, h, v, c, has_crowd, cls, knots, n_knots, vals, w0, cls_off):  # pragma: no cover (compiled)
    """(3, n) half logits of the three kinds: 0.5 * (w0 + the five features' interpolated terms + the
    class offset), summed in :meth:`Point.probability_of`'s order (crowding 0's term when ``has_crowd``
    is False)."""
    n = cls.shape[0]
    z = np.empty((3, n))
    for i in range(n):
        for k in range(3):
            z[k, i] = w0[k]
        for f in range(5):
            if f == 0:
                x = r[i]
            elif f == 1:
                x = b[i]
            elif f == 2:
                x = h[i]
            elif f == 3:
                x = v[i]
            else:
                x = c[i]
            nk = n_knots[f]
            if f == 4 and not has_crowd:
                for k in range(3):
                    z[k, i] = z[k, i] + vals[k, 4, 0]
                continue
            if x < knots[f, 0]:
                j = -1
            elif x > knots[f, nk - 1]:
                j = nk
            else:
                j = 0
                while j < nk - 1 and knots[f, j + 1] <= x:
                    j += 1
            for k in range(3):
                z[k, i] = z[k, i] + _interp_at(x, knots[f], vals[k, f], j, nk)
        for k in range(3):
            z[k, i] = 0.5 * (z[k, i] + cls_off[k, cls[i]])
    return z


@numba.njit(cache=jit_cache(__file__), nogil=True, inline="always")
def _range_bin(r):  # pragma: no cover (compiled)
    """The error bin of range ``r``: min(ERR_RANGE_EDGES.searchsorted(r, "right"), _NB) - 1, with numpy's
    indexing of -1 (the last bin) and its sorting of NaN after every edge."""
    c = 0
    if r != r:
        c = _EDGES.shape[0]
    else:
        while c < _EDGES.shape[0] and _EDGES[c] <= r:
            c += 1
    b = min(c, _NB) - 1
    return b + _NB if b < 0 else b


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _draw_cones(th, u, cls, ids, ranges, bearings, boxes, box_h, crowd, range_factor, last_step, last_det, step, rho,  # noqa: C901 (compiled)
                cum, q, loose_box_d, part_rows):  # pragma: no cover (compiled; tested through FrameSampler)
    """The per-cone draws of one frame from the probabilities ``0.5 * (1.0 + th)`` (3, n: detected,
    loose, part; :meth:`_Tables.tanh_half`), the range bins of ``ranges`` (range errors: of ``ranges *
    range_factor``, scaled back by ``1 / range_factor``) and the uniforms ``u`` (9, n): (classes,
    ranges, bearings, scores, boxes; float32 but the classes) of the reported cones, then of the part
    detections; updates the cones' Markov states."""
    n = cls.shape[0]
    prob = 0.5 * (1.0 + th)  # model._sigmoid's last operations
    err_scale = 1.0 / range_factor
    bins = np.empty(n, np.int64)
    rbins = np.empty(n, np.int64)
    for i in range(n):
        bins[i] = _range_bin(ranges[i])
        rbins[i] = bins[i] if range_factor == 1.0 else _range_bin(ranges[i] * range_factor)
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
            at = t * block + (base if t else (_NB if loose[i] else 0) + rbins[i]) * (_NQ + 1) + j
            out[o, t] = q[at] * (1.0 - f) + q[at + 1] * f
        out[o, 0] = out[o, 0] * err_scale + ranges[i]
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
    boxes32 = np.empty((m, 4), np.float32)  # the reported dtypes (the same rounding as numpy's astype)
    ranges32 = np.empty(m, np.float32)
    bearings32 = np.empty(m, np.float32)
    scores32 = np.empty(m, np.float32)
    for o in range(m):
        ranges32[o] = out[o, 0]
        bearings32[o] = out[o, 1]
        scores32[o] = out[o, 2]
        for j in range(4):
            boxes32[o, j] = out[o, 3 + j]
    return classes, ranges32, bearings32, scores32, boxes32
