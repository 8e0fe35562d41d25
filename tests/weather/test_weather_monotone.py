"""More k, more degradation: mean structural loss (1 - SSIM to the clean frame) never decreases."""

from __future__ import annotations

import numpy as np
import pytest
from weather_cases import VARIANT_IDS, VARIANTS, build

from weather_gym.weather.image_measures import rms_contrast, ssim

KS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
STATE = {"speed": 10.0, "yaw_rate": 0.3}


@pytest.mark.parametrize(("name", "params"), VARIANTS, ids=VARIANT_IDS)
def test_degradation_does_not_decrease_with_k(name, params, scenes):
    loss = []
    for k in KS:
        vals = []
        for img, depth in scenes:
            for seed in (0, 1):
                e = build(name, params, k)
                e.reset(seed)
                out = e(img, depth=depth, state=STATE)
                vals.append(1.0 - ssim(img, out))
        loss.append(float(np.mean(vals)))
    assert loss[0] == 0.0
    assert loss[-1] > 0.02, f"{name} barely degrades at k = 1: {loss}"
    assert all(b >= a - 1e-3 for a, b in zip(loss, loss[1:], strict=False)), f"{name}: {loss}"


def test_ssim_and_contrast_measures(scene):
    img = scene[0]
    assert ssim(img, img) == 1.0
    assert ssim(img, np.zeros_like(img)) < 0.2
    assert rms_contrast(np.full((4, 4, 3), 9, np.uint8)) == 0.0
    with pytest.raises(ValueError, match="shapes differ"):
        ssim(img, img[1:])
