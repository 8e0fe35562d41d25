"""The study's two curve shapes: linear (droplets) and exponential (dimming), R^2 of each."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.lab.calibration.report import agreement
from weather_gym.lab.calibration.shapes import fit_shapes, r_squared

K = np.linspace(0.0, 1.0, 21)


def test_linear_data_prefers_the_linear_shape():
    fits = fit_shapes(K, 0.72 - 0.45 * K)
    assert fits["linear"].r2 == pytest.approx(1.0)
    assert fits["linear"].params == pytest.approx({"a": 0.72, "b": -0.45})
    assert fits["exponential"].r2 < fits["linear"].r2
    assert agreement("droplets", fits).startswith("yes")
    assert agreement("dim", fits).startswith("no")


def test_exponential_data_prefers_the_exponential_shape():
    fits = fit_shapes(K, 0.7 * np.exp(-3.0 * K))
    assert fits["exponential"].r2 == pytest.approx(1.0)
    assert fits["exponential"].params["b"] == pytest.approx(3.0, rel=1e-4)
    assert fits["linear"].r2 < 0.95
    assert agreement("dim", fits).startswith("yes")


def test_a_collapse_is_logistic_and_neither_study_shape_fits_well():
    y = 0.7 / (1 + np.exp(25 * (K - 0.85)))
    fits = fit_shapes(K, y)
    assert fits["logistic"].r2 == pytest.approx(1.0, abs=1e-6)
    assert max(fits["linear"].r2, fits["exponential"].r2) < 0.9


def test_r_squared_and_too_few_points():
    assert r_squared(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0])) == 1.0
    assert np.isnan(r_squared(np.ones(3), np.ones(3)))
    with pytest.raises(ValueError, match="at least 3 points"):
        fit_shapes([0.0, 1.0], [1.0, 0.5])
