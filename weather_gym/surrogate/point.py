"""One fitted point of the perception surrogate (:class:`Point`: one condition at one ``k``) and the
features its probabilities are functions of: a linear B-spline ("hat") basis of range, |bearing|, log
box height, visibility and crowding (:func:`design`), plus the class.

Example:
    >>> import numpy as np
    >>> crowding(np.array([[0, 0, 10, 10], [5, 0, 15, 10], [40, 40, 50, 50.]])).round(3).tolist()
    [0.333, 0.333, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache
from weather_gym.core.cone_spec import CONE_CLASSES

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


@numba.njit(cache=jit_cache(__file__), nogil=True)
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
        assert w is not None  # a point that models the kind has its coefficients
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
                part_rows=near.part_rows if len(near.part_rows) else far.part_rows)  # type: ignore[arg-type]  # both have part rows here
    out.stats = {"fp_weight_b": w, "fp_rows_a": float(len(a.fp_rows))}
    return out
