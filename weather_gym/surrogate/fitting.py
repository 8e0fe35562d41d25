"""Fitting one surrogate point from logged episodes (:func:`fit_point`): the logistic regressions of
detection, loose and part detections, the persistence ``rho``, class confusions, error and score
quantiles and the false-positive counts (negative binomial by moments).

Example:
    >>> import numpy as np
    >>> from weather_gym.surrogate.fitting import fit_logistic, design
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

import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from weather_gym.core.errors import InputError
from weather_gym.surrogate.point import (
    CROWDED,
    ERR_RANGE_EDGES,
    N_CLASSES,
    N_COEF,
    QUANTILES,
    Point,
    _sigmoid,
    crowding_column,
    design,
)

MAX_FP_ROWS = 400
MIN_BIN_ROWS = 20
L2 = 1.0
CONFUSION_PRIOR = 1.0


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
