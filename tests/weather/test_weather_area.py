"""The compiled area shrinks equal OpenCV's INTER_AREA byte for byte (2x and 4x; other sizes are OpenCV's)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from weather_gym.weather._area import area_shrink


@pytest.mark.parametrize("seed", range(8))
def test_random_frames_equal_opencv(seed):
    rng = np.random.default_rng(seed)
    for _ in range(12):
        h, w = int(rng.integers(1, 50)), int(rng.integers(1, 90))
        f = int(rng.choice([2, 4, 2, 4, 3]))
        tail = [(3,), (3,), (), (4,), (1,)][int(rng.integers(0, 5))]
        shape = (f * h + int(rng.integers(0, 2) * (seed % 2)), f * w, *tail)
        img = rng.integers(0, 256, shape, dtype=np.uint8)
        if rng.random() < 0.4:  # blocks whose sums are exact halves: rounding matters
            img = (img // 64 * 64 + 8).astype(np.uint8)
        want = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
        np.testing.assert_array_equal(area_shrink(img, (w, h)), want)


def test_every_block_sum_rounds_as_opencv():
    """Every sum a 2x2 and a 4x4 block can have (0 .. 4 x 255 and 0 .. 16 x 255), as one row of blocks."""
    for f in (2, 4):
        n = f * f * 255 + 1
        img = np.zeros((f, f * n), np.uint8)
        for s in range(n):  # block s sums to s
            block = np.full(f * f, s // (f * f), np.int64)
            block[: s % (f * f)] += 1
            img[:, f * s:f * s + f] = block.reshape(f, f)
        np.testing.assert_array_equal(area_shrink(img, (n, 1)), cv2.resize(img, (n, 1), interpolation=cv2.INTER_AREA))
