"""The compiled sensor-noise pass equals the OpenCV passes it replaced (look-up, split, multiply,
subtract, masked add), byte for byte, for every frame shape, batch and table."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from weather_gym.weather._common import (
    _bank_plan,
    _half_normal_u8,
    add_sensor_noise,
    noise_bank,
    noise_table,
    sensor_noise_draw,
)


def _opencv(img, mean_lut, sigma_lut, raw):
    """The noise as OpenCV passes, frame by frame: sigma in 1/255 of its largest value (at most 4000),
    ``cv2.multiply`` by the bank's magnitudes with the scale, then subtract, then add where the sign is 1."""
    sigma = np.minimum(np.asarray(sigma_lut, np.float64), 4000.0)
    unit = float(sigma.max()) / 255.0 if sigma.max() > 0 else 1.0
    sig = np.clip(np.rint(sigma / unit), 0, 255).astype(np.uint8)
    mean = np.arange(256, dtype=np.uint8) if mean_lut is None else \
        np.clip(np.rint(np.asarray(mean_lut, np.float32)), 0, 255).astype(np.uint8)
    scale = unit * _half_normal_u8()[1]
    frames = img.reshape(-1, img.shape[-3], img.shape[-2] * img.shape[-1])
    rows, cols = frames.shape[1:]
    size, offsets, pitches = _bank_plan(rows, cols)
    bank = noise_bank(size)
    out = np.empty_like(frames)
    for i, (f, words) in enumerate(zip(frames, np.asarray(raw).reshape(len(frames), -1), strict=True)):
        start, pitch = int(words[0]) % offsets, cols + int(words[1]) % pitches
        z = np.lib.stride_tricks.as_strided(bank[start:], shape=(rows, cols), strides=(pitch, 1))
        signs = np.unpackbits(words[2:].view(np.uint8), count=rows * cols).reshape(rows, cols)
        base = cv2.LUT(f, mean)
        a = cv2.multiply(cv2.LUT(f, sig), np.ascontiguousarray(z), scale=scale)
        out[i] = cv2.subtract(base, a)
        cv2.add(base, a, dst=out[i], mask=signs)
    return out.reshape(img.shape)


def test_the_table_is_opencvs_multiply_then_saturating_subtract_or_add():
    """Every sign, value and magnitude: ``noise_table`` is what the OpenCV passes give."""
    rng = np.random.default_rng(0)
    v = np.repeat(np.arange(256, dtype=np.uint8), 256).reshape(256, 256)
    m = np.tile(np.arange(256, dtype=np.uint8), 256).reshape(256, 256)
    for top in (0.0, 0.3, 7.0, 55.0, 900.0, 6000.0):
        sigma = rng.uniform(0, top, 256).astype(np.float32)
        for mean in (None, rng.uniform(-30, 290, 256).astype(np.float32)):
            table = noise_table(None if mean is None else mean.tobytes(), sigma.tobytes()).reshape(2, 256, 256)
            s = np.minimum(sigma.astype(np.float64), 4000.0)
            unit = float(s.max()) / 255.0 if s.max() > 0 else 1.0
            sig = np.clip(np.rint(s / unit), 0, 255).astype(np.uint8)
            base = v if mean is None else np.clip(np.rint(mean), 0, 255).astype(np.uint8)[v]
            a = cv2.multiply(sig[v], m, scale=unit * _half_normal_u8()[1])
            np.testing.assert_array_equal(table[0], cv2.subtract(base, a))
            np.testing.assert_array_equal(table[1], cv2.add(base, a))


@pytest.mark.parametrize("seed", range(12))
def test_random_frames_and_batches_equal_the_opencv_passes(seed):
    """Frames and batches of random sizes (rows of whole sign bytes or not), with and without a mean table."""
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 70)), int(rng.integers(1, 100))
    shape = (h, w, 3) if seed % 2 else (int(rng.integers(1, 4)), h, w, 3)
    img = rng.integers(0, 256, shape, dtype=np.uint8)
    sigma = rng.uniform(0, rng.uniform(0.5, 80.0), 256).astype(np.float32)
    mean = None if seed % 3 == 0 else rng.uniform(-20, 280, 256).astype(np.float32)
    raw = sensor_noise_draw(np.random.default_rng(seed + 100), shape)
    np.testing.assert_array_equal(add_sensor_noise(img, mean, sigma, raw), _opencv(img, mean, sigma, raw))


@pytest.mark.parametrize("size", [(376, 672), (352, 608), (5, 8), (3, 7)])
def test_camera_sized_frames_equal_the_opencv_passes(size):
    """The cameras' sizes (2016 and 1824 values a row: whole sign bytes) and small odd ones."""
    rng = np.random.default_rng(size[0])
    img = rng.integers(0, 256, (*size, 3), dtype=np.uint8)
    mean = np.linspace(-5, 270, 256).astype(np.float32)
    sigma = np.sqrt(np.arange(256, dtype=np.float32)) * 1.7
    raw = sensor_noise_draw(np.random.default_rng(1), img.shape)
    out = np.full_like(img, 7)
    assert add_sensor_noise(img, mean, sigma, raw, out) is out
    np.testing.assert_array_equal(out, _opencv(img, mean, sigma, raw))


def test_a_strided_output_gets_the_result():
    """``out`` need not be contiguous (a view into a bigger frame)."""
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (20, 24, 3), dtype=np.uint8)
    sigma = np.full(256, 9.0, np.float32)
    raw = sensor_noise_draw(np.random.default_rng(4), img.shape)
    big = np.zeros((30, 40, 3), np.uint8)
    view = big[5:25, 8:32]
    assert add_sensor_noise(img, None, sigma, raw, view) is view
    np.testing.assert_array_equal(view, _opencv(img, None, sigma, raw))
    assert not big[:5].any() and not big[:, :8].any()
