"""The perception surrogate model: fitted from logs, saved as a small validated ``.npz``.

One *point* per weather condition and fitted ``k`` (clear is ``("clear", 0)``, the ``k = 0`` end of
every condition); between points every parameter is interpolated linearly in ``k`` (logits,
quantiles, rates; false-positive rows as a mixture), beyond the last fitted ``k`` nothing is
extrapolated (an :class:`~weather_gym.errors.InputError`). Each point holds:

* **detection probability**: logistic regression on a linear B-spline ("hat") basis of range,
  |bearing|, log box height, visibility and crowding (the largest IoU of the cone's box with
  another cone's: what non-maximum suppression merges), plus the class (``coef``; L2-penalised
  maximum likelihood with scipy's L-BFGS);
* **loose detections**: a cone not detected may be boxed a little off (IoU 0.1-0.5: a scoring
  miss plus a false positive near the cone): their probability (``coef_loose``, the same basis),
  range/bearing error and score quantiles, and box offsets (``loose_box_d``);
* **time correlation**: a per-cone two-state Markov chain with persistence ``rho``:
  P(detected | detected before) = p + rho (1 - p), P(detected | missed before) = p (1 - rho), so a
  cone keeps its marginal p; ``rho`` by maximum likelihood on consecutive frames of the same cone
  (the empirical P(miss | miss) and P(miss | detected) are kept for the report);
* **class confusion** ``confusion[range bin, true, reported]`` (rows sum to 1; a little smoothing to
  the diagonal) of cones standing clear of others, ``confusion_crowded`` of crowded ones (crowding
  above :data:`CROWDED`: a cone partly behind or beside another is reported in the wrong class an
  order of magnitude more often), and ``confusion_loose`` of the loose detections;
* **range and bearing errors** (reported - true) as 41 quantiles per range bin
  (:data:`ERR_RANGE_EDGES`); **score** quantiles of true detections;
* **part detections**: a false positive whose box centre lies inside a cone's box but overlaps it by
  less than the loose IoU (a box on a near cone's stripe, on one cone of a pair, or on part of a far
  one) belongs to that cone, detected or not: its probability per cone (``coef_part``, the same
  basis), and up to :data:`MAX_FP_ROWS` logged ones (box relative to the cone's box, in units of its
  height; class, score, range and bearing error) resampled as they are. They scale with the cones in
  view, so a track with fewer or farther cones gets fewer, as the detector does;
* **false positives** away from every cone: count per frame, negative binomial by moments (Poisson
  when not over-dispersed), and up to :data:`MAX_FP_ROWS` logged ones (range, bearing, class,
  score, box) resampled as they are: where they appear and what they look like.

Example:
    >>> import numpy as np
    >>> from weather_gym.surrogate.model import fit_logistic, design
    >>> rng = np.random.default_rng(0)
    >>> r = rng.uniform(2, 40, 4000); h = 336 * 0.325 / r
    >>> X = design(r, np.zeros_like(r), h, np.ones_like(r), np.ones(len(r), np.int64))
    >>> y = rng.random(len(r)) < 1 / (1 + np.exp(-(3 - 0.2 * r)))
    >>> coef = fit_logistic(X, y)
    >>> p = 1 / (1 + np.exp(-design(np.array([5.0, 30]), np.zeros(2), 336 * 0.325 / np.array([5.0, 30]),
    ...                             np.ones(2), np.ones(2, np.int64)) @ coef))
    >>> np.round(p, 1).tolist()      # the true curve: 0.88 at 5 m, 0.05 at 30 m
    [0.9, 0.0]
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np
from scipy.optimize import minimize, minimize_scalar

from weather_gym._io import atomic_file, check_output
from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.errors import FileFormatError, InputError, MissingInputError
from weather_gym.surrogate.conditions import condition_defaults, condition_of, effect_params
from weather_gym.surrogate.log import loose_matches, part_matches, read_npz

__all__ = ["MODEL_SCHEMA", "SHIPPED_MODEL", "SurrogateModel", "Point", "design", "fit_logistic", "fit_point",
           "fit", "save_model", "load_model", "ERR_RANGE_EDGES", "QUANTILES"]

MODEL_SCHEMA = 1
SHIPPED_MODEL = Path(__file__).with_name("models") / "shipped.npz"
RANGE_KNOTS = np.array([0.0, 4.0, 8.0, 12.0, 16.0, 22.0, 30.0, 45.0, 80.0])
BEARING_KNOTS = np.array([0.0, 0.3, 0.6, 0.9])
LOGH_KNOTS = np.log(np.array([2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 160.0]))
VIS_KNOTS = np.array([0.0, 0.4, 0.7, 0.9, 1.0])
CROWD_KNOTS = np.array([0.0, 0.05, 0.15, 0.3, 0.6, 1.0])
N_CLASSES = len(CONE_CLASSES)
N_COEF = 1 + (len(RANGE_KNOTS) - 1) + (len(BEARING_KNOTS) - 1) + (len(LOGH_KNOTS) - 1) + (len(VIS_KNOTS) - 1) \
    + (len(CROWD_KNOTS) - 1) + (N_CLASSES - 1)
ERR_RANGE_EDGES = np.array([0.0, 5.0, 10.0, 15.0, 20.0, 30.0, np.inf])
QUANTILES = np.linspace(0.0, 1.0, 41)
MAX_FP_ROWS = 400
MIN_BIN_ROWS = 20
L2 = 1.0
CONFUSION_PRIOR = 1.0
CROWDED = 0.05  # crowding above which a cone's class confusion is the crowded one


def _hat(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Linear B-spline basis (N, K) on ``knots`` (x clipped to the knot range); rows sum to 1."""
    x = np.clip(np.asarray(x, np.float64), knots[0], knots[-1])
    i = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, len(knots) - 2)
    t = (x - knots[i]) / (knots[i + 1] - knots[i])
    out = np.zeros((len(x), len(knots)))
    rows = np.arange(len(x))
    out[rows, i] = 1.0 - t
    out[rows, i + 1] += t
    return out


def crowding(boxes: np.ndarray) -> np.ndarray:
    """Each box's largest IoU with another box of the same frame (0 when alone): cones boxed together
    are what non-maximum suppression merges.

    Example:
        >>> import numpy as np
        >>> crowding(np.array([[0, 0, 10, 10.], [5, 0, 15, 10.], [50, 50, 60, 60.]])).round(2).tolist()
        [0.33, 0.33, 0.0]
    """
    b = np.ascontiguousarray(boxes, np.float64).reshape(-1, 4)
    if len(b) < 2:
        return np.zeros(len(b))
    return _crowding(b)


@numba.njit(cache=True, nogil=True)
def _crowding(b):  # pragma: no cover (compiled; tested through crowding)
    """The kernel of :func:`crowding`: the IoU of log._iou_matrix(b, b), the same operations pair by
    pair (this runs every step of the surrogate env)."""
    n = b.shape[0]
    out = np.zeros(n)
    for i in range(n):
        area_i = (b[i, 2] - b[i, 0]) * (b[i, 3] - b[i, 1])
        best = 0.0
        for j in range(n):
            if j == i:
                continue
            w = max(min(b[i, 2], b[j, 2]) - max(b[i, 0], b[j, 0]), 0.0)
            h = max(min(b[i, 3], b[j, 3]) - max(b[i, 1], b[j, 1]), 0.0)
            inter = w * h
            union = area_i + (b[j, 2] - b[j, 0]) * (b[j, 3] - b[j, 1]) - inter
            if union > 0.0 and inter / union > best:
                best = inter / union
        out[i] = best
    return out


def crowding_column(cones: dict[str, np.ndarray]) -> np.ndarray:
    """:func:`crowding` of every row of a log's ``cones`` table, frame by frame."""
    key = cones["episode"].astype(np.int64) * 10_000_000 + cones["frame"]
    order = np.argsort(key, kind="stable")
    k = key[order]
    cuts = np.flatnonzero(np.r_[True, k[1:] != k[:-1], True])
    out = np.zeros(len(key))
    boxes = np.asarray(cones["box"], np.float64)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        rows = order[a:b]
        out[rows] = crowding(boxes[rows])
    return out


def design(ranges: np.ndarray, bearings: np.ndarray, box_h: np.ndarray, vis: np.ndarray,
           classes: np.ndarray, crowd: np.ndarray | None = None) -> np.ndarray:
    """The (N, ``N_COEF``) design matrix: intercept, hat bases (first column of each dropped), class.

    ``crowd``: :func:`crowding` of each cone (None: 0, every cone alone)."""
    n = len(ranges)
    cls = np.zeros((n, N_CLASSES))
    cls[np.arange(n), np.asarray(classes, np.int64)] = 1.0
    return np.hstack([
        np.ones((n, 1)),
        _hat(ranges, RANGE_KNOTS)[:, 1:],
        _hat(np.abs(bearings), BEARING_KNOTS)[:, 1:],
        _hat(np.log(np.maximum(box_h, 1e-3)), LOGH_KNOTS)[:, 1:],
        _hat(vis, VIS_KNOTS)[:, 1:],
        _hat(np.zeros(n) if crowd is None else crowd, CROWD_KNOTS)[:, 1:],
        cls[:, 1:],
    ])


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = L2) -> np.ndarray:
    """L2-penalised logistic regression (intercept unpenalised) by L-BFGS; the coefficients."""

    y = np.asarray(y, np.float64)
    pen = np.full(X.shape[1], l2)
    pen[0] = 0.0

    def f(w: np.ndarray) -> tuple[float, np.ndarray]:
        z = X @ w
        nll = float(np.sum(np.logaddexp(0.0, z) - y * z))
        p = 0.5 * (1.0 + np.tanh(0.5 * z))
        return nll + 0.5 * float(np.sum(pen * w * w)), X.T @ (p - y) + pen * w

    w0 = np.zeros(X.shape[1])
    m = float(np.clip(y.mean(), 1e-3, 1 - 1e-3)) if len(y) else 0.5
    w0[0] = math.log(m / (1 - m))
    res = minimize(f, w0, jac=True, method="L-BFGS-B", options={"maxiter": 500})
    return res.x


def hat_terms(w: np.ndarray) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """A probability model's coefficients ``w`` (:data:`N_COEF`) as ``(knots, values)`` per feature
    (range, |bearing|, log box height, visibility, crowding: values at the knots, 0 at the first) and the
    class offsets (0 for the first class); ``w[0]`` is the intercept."""
    i = 1
    terms = []
    for knots in (RANGE_KNOTS, BEARING_KNOTS, LOGH_KNOTS, VIS_KNOTS, CROWD_KNOTS):
        terms.append((knots, np.r_[0.0, w[i:i + len(knots) - 1]]))
        i += len(knots) - 1
    return terms, np.r_[0.0, w[i:]]


def _sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def _pairs(cones: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Row indices (prev, cur) of the same cone on consecutive frames of an episode."""
    key = (cones["episode"].astype(np.int64) << 40) | (cones["cone_id"].astype(np.int64) << 20) \
        | cones["frame"].astype(np.int64)
    order = np.argsort(key, kind="stable")
    k = key[order]
    consecutive = (k[1:] - k[:-1]) == 1
    return order[:-1][consecutive], order[1:][consecutive]


def _fit_rho(p: np.ndarray, prev: np.ndarray, cur: np.ndarray) -> float:
    """Persistence by maximum likelihood; 0 where it cannot be told (no frame pair, or the cones were
    never / always detected: then every rho explains the data equally and the optimiser would drift
    to its bound, making a weather change mid-episode keep the last weather's detections)."""
    if not len(p) or cur.all() or not cur.any() or prev.all() or not prev.any():
        return 0.0
    p = np.clip(p, 1e-4, 1 - 1e-4)

    def nll(rho: float) -> float:
        q = np.where(prev, p + rho * (1 - p), p * (1 - rho))
        q = np.clip(q, 1e-9, 1 - 1e-9)
        return -float(np.sum(np.where(cur, np.log(q), np.log1p(-q))))

    return float(minimize_scalar(nll, bounds=(0.0, 0.98), method="bounded").x)


def _confusion(ranges: np.ndarray, true: np.ndarray, reported: np.ndarray) -> np.ndarray:
    """``confusion[range bin, true, reported]``, rows summing to 1 (``CONFUSION_PRIOR`` on the diagonal)."""
    conf = np.zeros((len(ERR_RANGE_EDGES) - 1, N_CLASSES, N_CLASSES))
    np.add.at(conf, (_range_bin(ranges), np.asarray(true, np.int64), np.asarray(reported, np.int64)), 1.0)
    conf += CONFUSION_PRIOR * np.eye(N_CLASSES)[None]
    return conf / conf.sum(axis=2, keepdims=True)


def _range_bin(ranges: np.ndarray) -> np.ndarray:
    """Index of each range's bin of :data:`ERR_RANGE_EDGES`."""
    return np.minimum(np.searchsorted(ERR_RANGE_EDGES, ranges, side="right"), len(ERR_RANGE_EDGES) - 1) - 1


def _quantiles(values: np.ndarray, bins: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(len(edges) - 1, len(QUANTILES)) quantiles of ``values`` per bin; pooled where a bin is thin."""
    v = np.asarray(values, np.float64)
    ok = np.isfinite(v)
    pooled = np.quantile(v[ok], QUANTILES) if ok.sum() else np.zeros(len(QUANTILES))
    out = np.tile(pooled, (len(edges) - 1, 1))
    idx = np.clip(np.searchsorted(edges, bins, side="right") - 1, 0, len(edges) - 2)
    for b in range(len(edges) - 1):
        sel = ok & (idx == b)
        if sel.sum() >= MIN_BIN_ROWS:
            out[b] = np.quantile(v[sel], QUANTILES)
    return out


@dataclass
class Point:
    """The fitted parameters of one (condition, k); see the module doc."""

    coef: np.ndarray
    rho: float
    confusion: np.ndarray
    range_err_q: np.ndarray
    bearing_err_q: np.ndarray
    score_q: np.ndarray
    fp_mean: float
    fp_var: float
    fp_rows: np.ndarray  # (M, 8): range, bearing, cls, score, x1, y1, x2, y2
    coef_loose: np.ndarray
    loose_range_err_q: np.ndarray
    loose_bearing_err_q: np.ndarray
    loose_score_q: np.ndarray
    det_box_d: np.ndarray  # (M, 4): reported box - true box, in units of the true box height
    loose_box_d: np.ndarray
    confusion_loose: np.ndarray
    confusion_crowded: np.ndarray | None = None  # None: as ``confusion`` (a model fitted without it)
    coef_part: np.ndarray | None = None  # None: no part detections (a model fitted without them)
    part_rows: np.ndarray | None = None  # (M, 8): box - cone box (4, in cone box heights), cls, score, range/bearing err
    stats: dict[str, float] = field(default_factory=dict)

    ARRAYS = ("coef", "confusion", "range_err_q", "bearing_err_q", "score_q", "fp_rows", "coef_loose",
              "loose_range_err_q", "loose_bearing_err_q", "loose_score_q", "det_box_d", "loose_box_d",
              "confusion_loose", "confusion_crowded", "coef_part", "part_rows")
    OPTIONAL = ("confusion_crowded", "coef_part", "part_rows")  # absent from models fitted before them

    def __post_init__(self) -> None:
        if self.confusion_crowded is None:
            self.confusion_crowded = self.confusion
        if self.coef_part is None or self.part_rows is None or not len(self.part_rows):
            self.coef_part = np.r_[-20.0, np.zeros(N_COEF - 1)]
            self.part_rows = np.zeros((0, 8))

    def detection_probability(self, ranges, bearings, box_h, vis, classes, crowd=None, *,
                              loose: bool = False) -> np.ndarray:
        """Marginal P(detected) of each cone (``loose``: P(loosely detected | not detected); part
        detections: :meth:`probability_of` with ``kind="part"``); the same
        as ``sigmoid(design(...) @ coef)``, summed term by term: a hat basis times its coefficients
        is the piecewise-linear interpolation of them."""
        return self.probability_of(self.features(ranges, bearings, box_h, vis, crowd), classes,
                                   kind="loose" if loose else "detected")

    @staticmethod
    def features(ranges, bearings, box_h, vis, crowd=None) -> tuple:
        """The per-cone inputs of :meth:`probability_of` (computed once for both models)."""
        return ranges, np.abs(bearings), np.log(np.maximum(box_h, 1e-3)), vis, crowd

    def probability_of(self, features: tuple, classes, *, kind: str = "detected") -> np.ndarray:
        """P(detected) (``kind`` "detected"), P(loose | not detected) ("loose") or P(a part detection)
        ("part") of each cone, from :meth:`features`."""
        w = {"detected": self.coef, "loose": self.coef_loose, "part": self.coef_part}[kind]
        name = f"_terms_{kind}"
        terms = self.__dict__.get(name)
        if terms is None:
            terms = self.__dict__[name] = hat_terms(w)
        ((rk, rv), (bk, bv), (hk, hv), (vk, vv), (ck, cv)), cls = terms
        ranges, abs_bearings, log_h, vis, crowd = features
        z = (w[0] + np.interp(ranges, rk, rv) + np.interp(abs_bearings, bk, bv)
             + np.interp(log_h, hk, hv) + np.interp(vis, vk, vv)
             + (cv[0] if crowd is None else np.interp(crowd, ck, cv)) + cls[np.asarray(classes, np.int64)])
        return _sigmoid(z)


def _box_deltas(reported: np.ndarray, true: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    h = np.maximum(true[:, 3] - true[:, 1], 1.0)[:, None]
    d = (np.asarray(reported, np.float64) - true) / h
    d = d[np.all(np.isfinite(d), axis=1)]
    if len(d) > MAX_FP_ROWS:
        d = d[np.sort(rng.choice(len(d), MAX_FP_ROWS, replace=False))]
    return d if len(d) else np.zeros((1, 4))


def fit_point(cones: dict[str, np.ndarray], fps: dict[str, np.ndarray], frames: dict[str, np.ndarray],
              rng: np.random.Generator | None = None, loose: np.ndarray | None = None,
              part: np.ndarray | None = None) -> Point:
    """Fit one point from the rows of one condition and k.

    ``loose``: for each false positive the ``cones`` row it loosely matches, -1 for none
    (:func:`weather_gym.surrogate.log.loose_matches`; None: no loose detections). ``part``: for each
    false positive the ``cones`` row it is a part detection of, -1 for none
    (:func:`weather_gym.surrogate.log.part_matches`; None: none).
    """
    rng = rng or np.random.default_rng(0)
    if not len(cones["frame"]):
        raise InputError("surrogate fit: a condition has no logged cones")
    loose = np.full(len(fps["frame"]), -1, np.int64) if loose is None else np.asarray(loose, np.int64)
    part = np.full(len(fps["frame"]), -1, np.int64) if part is None else np.asarray(part, np.int64)
    part = np.where(loose >= 0, -1, part)
    crowd = crowding_column(cones)
    X = design(cones["range"], cones["bearing"], cones["box_h"], cones["visibility"], cones["cls"], crowd)
    y = cones["detected"].astype(bool)
    coef = fit_logistic(X, y)
    p = _sigmoid(X @ coef)
    prev, cur = _pairs(cones)
    rho = _fit_rho(p[cur], y[prev], y[cur])
    is_loose = loose >= 0
    lrow = loose[is_loose]
    y_loose = np.zeros(len(y), bool)
    y_loose[lrow] = True
    coef_loose = fit_logistic(X[~y], y_loose[~y]) if (~y).any() else np.full(N_COEF, 0.0)
    if not y_loose.any():
        coef_loose = np.r_[-20.0, np.zeros(N_COEF - 1)]
    clear_of = y & (crowd <= CROWDED)
    crowded = y & (crowd > CROWDED)
    conf = _confusion(cones["range"][clear_of], cones["cls"][clear_of], cones["det_cls"][clear_of])
    conf_crowded = _confusion(cones["range"][crowded], cones["cls"][crowded], cones["det_cls"][crowded])
    conf_loose = _confusion(cones["range"][lrow], cones["cls"][lrow], fps["cls"][is_loose])
    rr = cones["range"][y]
    is_part = part >= 0
    y_part = np.zeros(len(y), bool)
    y_part[part[is_part]] = True
    coef_part = fit_logistic(X, y_part) if y_part.any() else None
    prow = part[is_part]
    pbox = cones["box"][prow].astype(np.float64)
    part_rows = np.column_stack([(fps["box"][is_part] - pbox) / np.maximum(pbox[:, 3:4] - pbox[:, 1:2], 1.0),
                                 fps["cls"][is_part], fps["score"][is_part], fps["range"][is_part] - cones["range"][prow],
                                 fps["bearing"][is_part] - cones["bearing"][prow]]).astype(np.float64)
    part_rows = part_rows[np.all(np.isfinite(part_rows), axis=1)]
    if len(part_rows) > MAX_FP_ROWS:
        part_rows = part_rows[np.sort(rng.choice(len(part_rows), MAX_FP_ROWS, replace=False))]
    free = ~is_loose & ~is_part
    rows = np.column_stack([fps["range"], fps["bearing"], fps["cls"], fps["score"], fps["box"]]).astype(np.float64)
    rows = rows[free]
    rows = rows[np.all(np.isfinite(rows), axis=1)]
    if len(rows) > MAX_FP_ROWS:
        rows = rows[np.sort(rng.choice(len(rows), MAX_FP_ROWS, replace=False))]
    fkey = fps["episode"].astype(np.int64) * 10_000_000 + fps["frame"]
    frkey = frames["episode"].astype(np.int64) * 10_000_000 + frames["frame"]
    n_free = np.zeros(len(frkey))
    if free.any():
        pos = np.searchsorted(frkey, fkey[free])  # frames are in (episode, frame) order
        np.add.at(n_free, np.clip(pos, 0, len(frkey) - 1), 1.0)
    miss_prev = ~y[prev]
    n_fp = frames["n_fp"].astype(np.float64)
    stats = {
        "frames": float(len(frames["frame"])), "cones": float(len(y)), "recall": float(y.mean()),
        "p_miss_after_miss": float(np.mean(~y[cur][miss_prev])) if miss_prev.any() else math.nan,
        "p_miss_after_detected": float(np.mean(~y[cur][~miss_prev])) if (~miss_prev).any() else math.nan,
        "false_positives": float(n_fp.sum()), "loose": float(is_loose.sum()), "part": float(is_part.sum()),
    }
    lr = cones["range"][lrow]
    return Point(coef=coef, rho=rho, confusion=conf,
                 range_err_q=_quantiles(cones["range_err"][y], rr, ERR_RANGE_EDGES),
                 bearing_err_q=_quantiles(cones["bearing_err"][y], rr, ERR_RANGE_EDGES),
                 score_q=np.quantile(cones["det_score"][y], QUANTILES) if y.any() else np.full(len(QUANTILES), 0.5),
                 fp_mean=float(n_free.mean()) if len(n_free) else 0.0,
                 fp_var=float(n_free.var(ddof=1)) if len(n_free) > 1 else 0.0, fp_rows=rows,
                 coef_loose=coef_loose,
                 loose_range_err_q=_quantiles(fps["range"][is_loose] - lr, lr, ERR_RANGE_EDGES),
                 loose_bearing_err_q=_quantiles(fps["bearing"][is_loose] - cones["bearing"][lrow], lr, ERR_RANGE_EDGES),
                 loose_score_q=np.quantile(fps["score"][is_loose], QUANTILES) if is_loose.any()
                 else np.full(len(QUANTILES), 0.5),
                 det_box_d=np.zeros((1, 4)),  # the log keeps no matched box: reported = true box (IoU 1)
                 loose_box_d=_box_deltas(fps["box"][is_loose], cones["box"][lrow].astype(np.float64), rng),
                 confusion_loose=conf_loose, confusion_crowded=conf_crowded, coef_part=coef_part,
                 part_rows=part_rows, stats=stats)


def _mix(a: Point, b: Point, w: float) -> Point:
    """The point a fraction ``w`` of the way from ``a`` to ``b`` (false-positive rows: both, weighted)."""
    if w <= 0.0:
        return a
    if w >= 1.0:
        return b

    def lerp(x, y):
        return (1.0 - w) * np.asarray(x) + w * np.asarray(y)

    conf = lerp(a.confusion, b.confusion)
    conf_loose = lerp(a.confusion_loose, b.confusion_loose)
    conf_crowded = lerp(a.confusion_crowded, b.confusion_crowded)
    near, far = (b, a) if w >= 0.5 else (a, b)  # box deltas and part rows: from the nearer point
    out = Point(coef=lerp(a.coef, b.coef), rho=float(lerp(a.rho, b.rho)), confusion=conf / conf.sum(-1, keepdims=True),
                range_err_q=lerp(a.range_err_q, b.range_err_q), bearing_err_q=lerp(a.bearing_err_q, b.bearing_err_q),
                score_q=lerp(a.score_q, b.score_q), fp_mean=float(lerp(a.fp_mean, b.fp_mean)),
                fp_var=float(lerp(a.fp_var, b.fp_var)), fp_rows=np.vstack([a.fp_rows, b.fp_rows]),
                coef_loose=lerp(a.coef_loose, b.coef_loose),
                loose_range_err_q=lerp(a.loose_range_err_q, b.loose_range_err_q),
                loose_bearing_err_q=lerp(a.loose_bearing_err_q, b.loose_bearing_err_q),
                loose_score_q=lerp(a.loose_score_q, b.loose_score_q), det_box_d=near.det_box_d,
                loose_box_d=near.loose_box_d, confusion_loose=conf_loose / conf_loose.sum(-1, keepdims=True),
                confusion_crowded=conf_crowded / conf_crowded.sum(-1, keepdims=True),
                coef_part=lerp(a.coef_part, b.coef_part),
                part_rows=near.part_rows if len(near.part_rows) else far.part_rows)
    out.stats = {"fp_weight_b": w, "fp_rows_a": float(len(a.fp_rows))}
    return out


@dataclass
class SurrogateModel:
    """Fitted points per condition (``points[condition]``: a list of ``(k, Point)`` sorted by k)."""

    clear: Point
    points: dict[str, list[tuple[float, Point]]]
    effects: dict[str, dict[str, Any]]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def camera_size(self) -> tuple[int, int] | None:
        cam = self.meta.get("camera") or {}
        return (int(cam["width"]), int(cam["height"])) if "width" in cam and "height" in cam else None

    def conditions(self) -> list[str]:
        return ["clear", *self.points]

    def point(self, weather: Any) -> Point:
        """The parameters for a weather spec (interpolated in k between fitted points).

        Example:
            >>> from weather_gym.surrogate.model import load_model
            >>> m = load_model()
            >>> 0 < m.point("droplets@3").fp_mean
            True
        """
        cond, k = condition_of(weather)
        if cond == "clear":
            return self.clear
        if cond not in self.points:
            raise InputError(f"the surrogate model has no condition {cond!r}; it has {', '.join(self.conditions())}")
        fitted = self.effects.get(cond, {})
        given = effect_params(weather)
        dflt = condition_defaults(cond)  # a parameter the effect gained after the fit: its default
        differ = sorted(key for key in set(fitted) | set(given)
                        if fitted.get(key, dflt.get(key)) != given.get(key, dflt.get(key)))
        if differ:
            raise InputError(f"the surrogate model's {cond} was fitted with other effect parameters "
                             f"({', '.join(f'{d}={fitted.get(d, dflt.get(d))!r}, given {given.get(d)!r}' for d in differ)}); "
                             f"refit it for this weather (docs/surrogate.md)")
        ks = [0.0] + [kk for kk, _ in self.points[cond]]
        pts = [self.clear] + [p for _, p in self.points[cond]]
        if k > ks[-1] + 1e-9:
            raise InputError(f"{cond} k={k:g} is beyond the surrogate's fitted range 0..{ks[-1]:g} (no extrapolation)")
        i = int(np.clip(np.searchsorted(ks, k, side="right") - 1, 0, len(ks) - 2))
        if abs(k - ks[i + 1]) < 1e-9:
            return pts[i + 1]
        return _mix(pts[i], pts[i + 1], (k - ks[i]) / (ks[i + 1] - ks[i]))

    def summary(self) -> str:
        """One line per fitted point: recall, P(miss | miss), P(miss | detected), rho, false positives per frame
        away from every cone, loose and part detections per frame."""
        lines = ["condition    k       frames  cones   recall  P(miss|miss) P(miss|det) rho    FP/frame loose/frame "
                 "part/frame"]
        rows = [("clear", 0.0, self.clear)] + [(c, k, p) for c, pts in self.points.items() for k, p in pts]
        for cond, k, p in rows:
            s = p.stats
            lines.append(f"{cond:<12} {k:<7.3f} {s.get('frames', 0):>6.0f} {s.get('cones', 0):>7.0f} "
                         f"{s.get('recall', math.nan):>6.3f}  {s.get('p_miss_after_miss', math.nan):>11.3f} "
                         f"{s.get('p_miss_after_detected', math.nan):>11.3f} {p.rho:.3f}  {p.fp_mean:>8.2f} "
                         f"{s.get('loose', math.nan) / max(s.get('frames', 1.0), 1.0):>11.2f} "
                         f"{s.get('part', math.nan) / max(s.get('frames', 1.0), 1.0):>10.2f}")
        return "\n".join(lines)


def fit(log: Any, sources: Sequence[str] = ()) -> SurrogateModel:
    """Fit a :class:`SurrogateModel` from a :class:`~weather_gym.surrogate.log.SurrogateLog` (all its conditions)."""
    groups: dict[tuple[str, float], list[int]] = {}
    effects: dict[str, dict[str, Any]] = {}
    for i, ep in enumerate(log.episodes):
        key = (str(ep["condition"]), round(float(ep["k"]), 6))
        groups.setdefault(key, []).append(i)
        if key[0] != "clear":
            params = effect_params(ep["weather"])
            if key[0] in effects and effects[key[0]] != params:
                raise InputError(f"surrogate fit: the logs have {key[0]} with different effect parameters; "
                                 f"fit one parameter set per condition")
            effects[key[0]] = params
    if ("clear", 0.0) not in groups:
        raise InputError("surrogate fit: the logs have no clear-weather episodes (the k = 0 point of every condition)")
    rng = np.random.default_rng(0)
    fitted: dict[tuple[str, float], Point] = {}
    for key, eps in sorted(groups.items()):
        sub = log.select(eps)
        lm = loose_matches(sub)
        fitted[key] = fit_point(sub.cones, sub.fps, sub.frames, rng, loose=lm, part=part_matches(sub, lm))
    points: dict[str, list[tuple[float, Point]]] = {}
    for (cond, k), p in sorted(fitted.items()):
        if cond != "clear":
            points.setdefault(cond, []).append((k, p))
    meta = {"schema": MODEL_SCHEMA, "camera": log.meta.get("camera", {}), "detector": log.meta.get("detector"),
            "tracks": sorted({str(e.get("track")) for e in log.episodes}), "sources": [os.path.basename(s) for s in sources],
            "episodes": len(log.episodes)}
    return SurrogateModel(clear=fitted[("clear", 0.0)], points=points, effects=effects, meta=meta)


# ------------------------------------------------------------------------------------------ file
def _point_arrays(prefix: str, p: Point) -> dict[str, np.ndarray]:
    out = {f"{prefix}/{name}": np.asarray(getattr(p, name), np.float32 if name == "fp_rows" else np.float64)
           for name in Point.ARRAYS}
    out[f"{prefix}/scalars"] = np.array([p.rho, p.fp_mean, p.fp_var])
    return out


def save_model(model: SurrogateModel, path: str | os.PathLike, *, overwrite: bool = False) -> str:
    """Write the model as one compressed ``.npz`` (arrays per point and a ``meta`` JSON)."""
    check_output(path, overwrite=overwrite, suffixes=(".npz",), what="surrogate model")
    arrays = _point_arrays("clear", model.clear)
    index = []
    for cond, pts in model.points.items():
        for j, (k, p) in enumerate(pts):
            arrays.update(_point_arrays(f"{cond}/{j}", p))
            index.append({"condition": cond, "k": k, "key": f"{cond}/{j}", "stats": p.stats})
    meta = {**model.meta, "schema": MODEL_SCHEMA, "points": index, "clear_stats": model.clear.stats,
            "effects": model.effects, "basis": {"range": RANGE_KNOTS.tolist(), "bearing": BEARING_KNOTS.tolist(),
                                                "log_box_h": LOGH_KNOTS.tolist(), "visibility": VIS_KNOTS.tolist(),
                                                "crowding": CROWD_KNOTS.tolist()},
            "err_range_edges": [float(x) for x in ERR_RANGE_EDGES[:-1]], "quantiles": len(QUANTILES)}
    arrays["meta"] = np.array(json.dumps(meta))
    with atomic_file(path, "wb", overwrite=overwrite, encoding=None) as f:
        np.savez_compressed(f, **arrays)
    return str(path)


_QSHAPE = (len(ERR_RANGE_EDGES) - 1, len(QUANTILES))
_CSHAPE = (len(ERR_RANGE_EDGES) - 1, N_CLASSES, N_CLASSES)
_SHAPES = {"coef": (N_COEF,), "coef_loose": (N_COEF,), "confusion": _CSHAPE, "confusion_loose": _CSHAPE,
           "confusion_crowded": _CSHAPE, "coef_part": (N_COEF,),
           "range_err_q": _QSHAPE, "bearing_err_q": _QSHAPE, "loose_range_err_q": _QSHAPE,
           "loose_bearing_err_q": _QSHAPE, "score_q": (len(QUANTILES),), "loose_score_q": (len(QUANTILES),),
           "scalars": (3,)}
_ROWS = {"fp_rows": 8, "det_box_d": 4, "loose_box_d": 4, "part_rows": 8}


def _load_point(data: dict[str, np.ndarray], prefix: str, where: str, stats: Any) -> Point:
    arrays = {}
    for name in (*Point.ARRAYS, "scalars"):
        key = f"{prefix}/{name}"
        if key not in data and name in Point.OPTIONAL:
            continue
        if key not in data:
            raise FileFormatError(f"{where}: missing array {key!r}")
        a = np.asarray(data[key], np.float64)
        if name in _ROWS:
            want: Any = f"(M, {_ROWS[name]})"
            shape_ok = a.ndim == 2 and a.shape[1] == _ROWS[name]
        else:
            want = _SHAPES[name]
            shape_ok = a.shape == want
        if not shape_ok:
            raise FileFormatError(f"{where}: array {key!r} has shape {a.shape}, expected {want}")
        if not np.all(np.isfinite(a)):
            raise FileFormatError(f"{where}: array {key!r} has non-finite values")
        arrays[name] = a
    for name in ("confusion", "confusion_loose", "confusion_crowded"):
        if name not in arrays:
            continue
        conf = arrays[name]
        if np.any(conf < 0) or not np.allclose(conf.sum(axis=-1), 1.0, atol=1e-6):
            raise FileFormatError(f"{where}: {prefix}/{name} must have non-negative rows summing to 1")
    for name in ("range_err_q", "bearing_err_q", "score_q", "loose_range_err_q", "loose_bearing_err_q", "loose_score_q"):
        if np.any(np.diff(arrays[name], axis=-1) < -1e-9):
            raise FileFormatError(f"{where}: {prefix}/{name} quantiles must be non-decreasing")
    rho, fp_mean, fp_var = arrays["scalars"]
    if not (0.0 <= rho < 1.0) or fp_mean < 0 or fp_var < 0:
        raise FileFormatError(f"{where}: {prefix}/scalars (rho {rho}, fp_mean {fp_mean}, fp_var {fp_var}) out of range: "
                              f"need 0 <= rho < 1 and non-negative rates")
    rows = arrays["fp_rows"]
    if len(rows) and (rows[:, 2].min() < 0 or rows[:, 2].max() >= N_CLASSES):
        raise FileFormatError(f"{where}: {prefix}/fp_rows has classes outside 0..{N_CLASSES - 1}")
    prows = arrays.get("part_rows")
    if prows is not None and len(prows) and (prows[:, 4].min() < 0 or prows[:, 4].max() >= N_CLASSES):
        raise FileFormatError(f"{where}: {prefix}/part_rows has classes outside 0..{N_CLASSES - 1}")
    if fp_mean > 0 and not len(rows):
        raise FileFormatError(f"{where}: {prefix} has false positives per frame {fp_mean} but no false-positive rows")
    for name in ("det_box_d", "loose_box_d"):
        if not len(arrays[name]):
            raise FileFormatError(f"{where}: {prefix}/{name} has no rows")
    named = {n: arrays.get(n) for n in Point.ARRAYS}
    return Point(**named, rho=float(rho), fp_mean=float(fp_mean), fp_var=float(fp_var),
                 stats=dict(stats) if isinstance(stats, dict) else {})


_CACHE: dict[tuple[str, float, int], SurrogateModel] = {}


def load_model(path: str | os.PathLike | None = None) -> SurrogateModel:
    """Read and validate a model (None: the shipped one); :class:`FileFormatError` naming what is wrong.

    Loaded models are cached by path, modification time and size (the envs of a vector env share one).
    """
    p = os.fspath(path) if path is not None else os.fspath(SHIPPED_MODEL)
    where = f"surrogate model {p}"
    if not os.path.isfile(p):
        raise MissingInputError(f"{where} does not exist")
    st = os.stat(p)
    key = (os.path.abspath(p), st.st_mtime, st.st_size)
    if key in _CACHE:
        return _CACHE[key]
    data, meta = read_npz(p, where, "surrogate model", MODEL_SCHEMA)
    index = meta.get("points")
    if not isinstance(index, list):
        raise FileFormatError(f"{where}: meta 'points' must be a list")
    clear = _load_point(data, "clear", where, meta.get("clear_stats"))
    points: dict[str, list[tuple[float, Point]]] = {}
    for entry in index:
        if not (isinstance(entry, dict) and isinstance(entry.get("condition"), str) and isinstance(entry.get("key"), str)
                and isinstance(entry.get("k"), int | float) and 0 < entry["k"] <= 1):
            raise FileFormatError(f"{where}: a meta 'points' entry needs condition, key and k in (0, 1], got {entry!r}")
        points.setdefault(entry["condition"], []).append(
            (float(entry["k"]), _load_point(data, entry["key"], where, entry.get("stats"))))
    for cond, pts in points.items():
        pts.sort(key=lambda t: t[0])
        ks = [k for k, _ in pts]
        if len(set(ks)) != len(ks):
            raise FileFormatError(f"{where}: condition {cond!r} has the same k twice ({ks})")
    effects = meta.pop("effects", {})
    if not isinstance(effects, dict):
        raise FileFormatError(f"{where}: meta 'effects' must be a table")
    model = SurrogateModel(clear=clear, points=points, effects=effects, meta=meta)
    _CACHE[key] = model
    return model
