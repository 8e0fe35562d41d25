"""The compiled blend of the refractive drops equals OpenCV's resize, multiply and add, byte for byte."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from weather_gym.weather._drop_blend import blend_drops, resize_tables


def _opencv(out, content, keeps, half, cx, cy):
    """The calls the kernel replaces, drop by drop: resize the content, multiply by keep / 255, add."""
    out = out.copy()
    h, w = out.shape[:2]
    start = 0
    for keep, hf, x, y in zip(keeps, half, cx, cy, strict=True):
        n, side = hf + 1, 2 * hf + 1
        big = cv2.resize(content[start:start + n * n].reshape(n, n, 3), (side, side), interpolation=cv2.INTER_LINEAR)
        start += n * n
        x0, y0, x1, y1 = max(x - hf, 0), max(y - hf, 0), min(x + hf + 1, w), min(y + hf + 1, h)
        sl = (slice(y0 - y + hf, y1 - y + hf), slice(x0 - x + hf, x1 - x + hf))
        roi = out[y0:y1, x0:x1]
        cv2.multiply(roi, keep[sl], dst=roi, scale=1.0 / 255.0)
        cv2.add(roi, big[sl], dst=roi)
    return out


def _drops(rng, h, w, half):
    """Random contents and keeps for drops of half-sides ``half`` at random centres, some over the border."""
    half = np.asarray(half)
    cx = rng.integers(-10, w + 10, len(half))
    cy = rng.integers(-10, h + 10, len(half))
    on = (np.minimum(cx + half + 1, w) > np.maximum(cx - half, 0)) & (np.minimum(cy + half + 1, h) > np.maximum(cy - half, 0))
    half, cx, cy = half[on], cx[on], cy[on]
    content = rng.integers(0, 256, (int(((half + 1) ** 2).sum()), 3), dtype=np.uint8)
    keeps = [rng.integers(0, 256, (2 * hf + 1, 2 * hf + 1, 3), dtype=np.uint8) for hf in half.tolist()]
    return content, keeps, half, cx, cy


def _blend(out, content, keeps, half, cx, cy):
    h, w = out.shape[:2]
    blend_drops(out, content, keeps, half, cx, cy, np.maximum(cx - half, 0), np.maximum(cy - half, 0),
                np.minimum(cx + half + 1, w), np.minimum(cy + half + 1, h))


@pytest.mark.parametrize("n", list(range(2, 70)) + [97, 130, 200])
def test_one_drop_is_opencvs_resize_then_blend(n):
    """Every content size a drop can have, and sizes past the first table (64): OpenCV's bilinear upscaling
    (its clamped columns, fractional border rows and vectorised rounding), then multiply and add."""
    rng = np.random.default_rng(n)
    side = 2 * n - 1
    content = rng.integers(0, 256, (n * n, 3), dtype=np.uint8)
    out = np.zeros((side + 4, side + 6, 3), np.uint8)
    _blend(out, content, [np.zeros((side, side, 3), np.uint8)], np.array([n - 1]), np.array([n + 1]), np.array([n]))
    want = cv2.resize(content.reshape(n, n, 3), (side, side), interpolation=cv2.INTER_LINEAR)
    np.testing.assert_array_equal(out[1:1 + side, 2:2 + side], want)
    assert not out[0].any() and not out[:, :2].any()  # nothing outside the box
    frame = rng.integers(0, 256, out.shape, dtype=np.uint8)
    keep = rng.integers(0, 256, (side, side, 3), dtype=np.uint8)
    got = frame.copy()
    _blend(got, content, [keep], np.array([n - 1]), np.array([n + 1]), np.array([n]))
    np.testing.assert_array_equal(got, _opencv(frame, content, [keep], [n - 1], [n + 1], [n]))


@pytest.mark.parametrize("seed", range(6))
def test_many_overlapping_drops_in_order_over_the_border(seed):
    rng = np.random.default_rng(100 + seed)
    h, w = 120, 200
    content, keeps, half, cx, cy = _drops(rng, h, w, rng.integers(1, 40, 60))
    frame = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    got = frame.copy()
    _blend(got, content, keeps, half, cx, cy)
    np.testing.assert_array_equal(got, _opencv(frame, content, keeps, half.tolist(), cx.tolist(), cy.tolist()))


def test_a_strided_output_is_written():
    """A view that is not C-contiguous (a crop of a bigger frame) gets the drops too."""
    rng = np.random.default_rng(7)
    content, keeps, half, cx, cy = _drops(rng, 60, 80, rng.integers(2, 15, 12))
    big = rng.integers(0, 256, (70, 100, 3), dtype=np.uint8)
    want = _opencv(big[5:65, 10:90], content, keeps, half.tolist(), cx.tolist(), cy.tolist())
    view = big[5:65, 10:90]
    _blend(view, content, keeps, half, cx, cy)
    np.testing.assert_array_equal(big[5:65, 10:90], want)


def test_tables_are_read_only_and_cover_every_n():
    xo, xa, yo, ya = resize_tables(64)
    assert all(not a.flags.writeable for a in (xo, xa, yo, ya))
    assert (xa[1:].sum(axis=2)[:, :1] == 2048).all() and (ya[2:, :3].sum(axis=2) == 2048).all()
    with pytest.raises(ValueError):
        xo[3, 0] = 1


def test_no_drops_leave_the_frame_as_it_is():
    frame = np.random.default_rng(3).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    out = frame.copy()
    blend_drops(out, np.zeros((0, 3), np.uint8), [], np.zeros(0, np.int64), *(np.zeros(0, np.int64),) * 6)
    np.testing.assert_array_equal(out, frame)
