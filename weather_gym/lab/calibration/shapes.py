"""The two curve shapes the study reported, fitted to ours: droplets ~ linear in k, dimming ~ exponential.

Both are two-parameter least-squares fits to the mean curve (in the units given: absolute or relative
mAP) over the swept k, with the coefficient of determination ``R^2 = 1 - SS_res / SS_tot`` as the
measure of agreement:

* ``linear``: ``y = a + b k``;
* ``exponential``: ``y = a exp(-b k)`` (fitted with ``scipy.optimize.curve_fit``, started from a
  log-linear fit).

A third, ``logistic`` ``y = a / (1 + exp(s (k - k50)))`` (three parameters), is reported for
diagnosis only: it describes a detector that holds up until the image has lost most of its
contrast and then collapses.

Example:
    >>> import numpy as np
    >>> from weather_gym.lab.calibration.shapes import fit_shapes
    >>> k = np.linspace(0, 1, 11)
    >>> fits = fit_shapes(k, 0.7 * np.exp(-2.0 * k))
    >>> round(fits["exponential"].r2, 6), fits["exponential"].params["b"]
    (1.0, 2.0)
    >>> fits["linear"].r2 < 0.99
    True
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from scipy.optimize import curve_fit

from weather_gym.core.errors import InputError

__all__ = ["SHAPES", "ShapeFit", "fit_shapes", "r_squared"]

SHAPES = ("linear", "exponential", "logistic")
"""Shapes fitted; the study reported ``linear`` for droplets and ``exponential`` for dimming."""

STUDY_SHAPE = {"droplets": "linear", "dim": "exponential"}
"""The shape the study reported for each effect (Sections 4.1 and 4.2)."""


@dataclass
class ShapeFit:
    shape: str
    params: dict[str, float]
    r2: float
    formula: str

    def predict(self, k: np.ndarray) -> np.ndarray:
        k = np.asarray(k, dtype=np.float64)
        p = self.params
        if self.shape == "linear":
            return p["a"] + p["b"] * k
        if self.shape == "exponential":
            return p["a"] * np.exp(-p["b"] * k)
        return p["a"] / (1.0 + np.exp(p["s"] * (k - p["k50"])))


def r_squared(y: np.ndarray, pred: np.ndarray) -> float:
    """``1 - SS_res / SS_tot`` (NaN when y is constant)."""
    y, pred = np.asarray(y, np.float64), np.asarray(pred, np.float64)
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    if ss_tot == 0.0:
        return math.nan
    return 1.0 - float(np.sum((y - pred) ** 2)) / ss_tot


def _round(params: dict[str, float]) -> dict[str, float]:
    return {k: float(np.round(v, 6)) for k, v in params.items()}


def fit_shapes(k: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> dict[str, ShapeFit]:
    """Least-squares fits of :data:`SHAPES` to the points ``(k, y)``; see the module doc."""

    k = np.asarray(k, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = np.isfinite(k) & np.isfinite(y)
    k, y = cast(np.ndarray, k[ok]), cast(np.ndarray, y[ok])
    if len(k) < 3:
        raise InputError(f"a shape fit needs at least 3 points, got {len(k)}")
    out: dict[str, ShapeFit] = {}
    b, a = np.polyfit(k, y, 1)
    lin = ShapeFit("linear", _round({"a": a, "b": b}), 0.0, "a + b k")
    lin.r2 = r_squared(y, lin.predict(k))
    out["linear"] = lin

    pos = y > 1e-6
    if pos.sum() >= 2:
        slope, icpt = np.polyfit(k[pos], np.log(y[pos]), 1)
        p0 = [float(np.exp(icpt)), float(-slope)]
    else:
        p0 = [float(max(y.max(), 1e-3)), 1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            (ea, eb), _ = curve_fit(lambda x, a_, b_: a_ * np.exp(-b_ * x), k, y, p0=p0, maxfev=20000)
        except RuntimeError:
            ea, eb = p0
    exp = ShapeFit("exponential", _round({"a": ea, "b": eb}), 0.0, "a exp(-b k)")
    exp.r2 = r_squared(y, exp.predict(k))
    out["exponential"] = exp

    top = float(max(y.max(), 1e-6))
    half = float(k[np.argmin(np.abs(y - top / 2))])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            (la, ls, lk), _ = curve_fit(lambda x, a_, s_, k_: a_ / (1.0 + np.exp(s_ * (x - k_))), k, y,
                                        p0=[top, 10.0, half], maxfev=20000)
        except RuntimeError:
            la, ls, lk = top, 10.0, half
    logi = ShapeFit("logistic", _round({"a": la, "s": ls, "k50": lk}), 0.0, "a / (1 + exp(s (k - k50)))")
    logi.r2 = r_squared(y, logi.predict(k))
    out["logistic"] = logi
    return out
