"""Fixtures of the weather tests: small synthetic track scenes."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.weather.sample import sample_frame


@pytest.fixture(scope="session")
def scene():
    """(image, depth) of a synthetic track frame, 188 x 336."""
    return sample_frame(188, 336, seed=3)


@pytest.fixture(scope="session")
def scenes():
    return [sample_frame(188, 336, seed=s) for s in (1, 2)]


@pytest.fixture
def noisy_image():
    return np.random.default_rng(5).integers(0, 256, (37, 53, 3), dtype=np.uint8)
