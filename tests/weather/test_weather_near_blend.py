"""The motion smear's compiled blend equals the OpenCV calls it replaced (nearness weights from the
depth map, two multiplies by w / 255 and a saturating add), byte for byte."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from weather_gym.weather._near_blend import near_blend, near_weight


def _opencv_weight(depth, near_m):
    z = depth if float(depth.min()) >= 1e-3 else cv2.max(depth, 1e-3)
    return cv2.convertScaleAbs(np.divide(np.float32(255.0 * near_m), z))


def _opencv(img, blurred, w1):
    w3, inv3 = cv2.cvtColor(w1, cv2.COLOR_GRAY2RGB), cv2.cvtColor(cv2.bitwise_not(w1), cv2.COLOR_GRAY2RGB)
    return cv2.add(cv2.multiply(img, inv3, scale=1 / 255), cv2.multiply(blurred, w3, scale=1 / 255))


def _depth(rng, h, w):
    """Depths over the whole range the weight takes: 0, below 1 mm, around ``near`` and far."""
    kinds = [np.zeros((h, w)), rng.uniform(0, 1e-3, (h, w)), rng.uniform(0.5, 30, (h, w)),
             np.exp(rng.uniform(-8, 7, (h, w)))]
    depth = np.choose(rng.integers(0, 4, (h, w)), kinds).astype(np.float32)
    if rng.random() < 0.5:
        depth = np.maximum(depth, np.float32(1e-3))  # a map without anything nearer than 1 mm
    return depth


@pytest.mark.parametrize("seed", range(10))
def test_random_frames_equal_the_opencv_calls(seed):
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 70)), int(rng.integers(1, 90))
    img, blurred = rng.integers(0, 256, (2, h, w, 3), dtype=np.uint8)
    depth = _depth(rng, h, w)
    near_m = float(rng.uniform(0.5, 20))
    w1 = _opencv_weight(depth, near_m)
    np.testing.assert_array_equal(near_weight(depth, near_m), w1)
    want = _opencv(img, blurred, w1)
    out = np.empty_like(img)
    near_blend(img, blurred, depth, near_m, out)
    np.testing.assert_array_equal(out, want)
    out2 = np.empty_like(img)
    near_blend(img, blurred, w1, None, out2)  # the weights given (the flat-ground fallback's cache)
    np.testing.assert_array_equal(out2, want)


def test_every_weight_quotient_rounds_as_opencv():
    """Quotients at and around every half-integer from 0 to 256 (where rounding half to even matters)."""
    half = np.arange(0, 257, 0.5, dtype=np.float32)
    q = np.concatenate([half, np.nextafter(half, np.float32(-1)), np.nextafter(half, np.float32(1e9))])
    q = q[q > 1e-3]
    near_m = 2.0
    depth = (np.float32(255.0 * near_m) / q).astype(np.float32).reshape(1, -1)
    np.testing.assert_array_equal(near_weight(depth, near_m), _opencv_weight(depth, near_m))


def test_every_pair_of_values_blends_as_opencv():
    """All 256 x 256 values against all 256 weights."""
    v = np.arange(256, dtype=np.uint8)
    img = np.broadcast_to(v[:, None, None], (256, 256, 3)).copy()
    blurred = np.broadcast_to(v[None, :, None], (256, 256, 3)).copy()
    for w in range(256):
        w1 = np.full((256, 256), w, np.uint8)
        out = np.empty_like(img)
        near_blend(img, blurred, w1, None, out)
        np.testing.assert_array_equal(out, _opencv(img, blurred, w1))


def test_in_place_and_strided_outputs():
    rng = np.random.default_rng(7)
    img, blurred = rng.integers(0, 256, (2, 24, 31, 3), dtype=np.uint8)
    depth = _depth(rng, 24, 31)
    want = _opencv(img, blurred, _opencv_weight(depth, 3.0))
    same = img.copy()
    near_blend(same, blurred, depth, 3.0, same)  # out is img
    np.testing.assert_array_equal(same, want)
    big = np.zeros((40, 50, 3), np.uint8)
    near_blend(img, blurred, depth, 3.0, big[8:32, 10:41])
    np.testing.assert_array_equal(big[8:32, 10:41], want)
    assert not big[:8].any() and not big[:, :10].any() and not big[:, 41:].any()
