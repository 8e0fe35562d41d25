"""The night camera (``Dim(mode="night")``, behind ``low_light@N``) equals a straightforward reference
built from plain OpenCV and numpy calls, byte for byte: its compiled passes (area shrinks, colour
offsets, the luma and colour put back together) are speed only. The presets are calibrated on these
bytes and the resolution cache keys on them."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from weather_gym.weather import make
from weather_gym.weather._common import add_sensor_noise, focal_px, gauss_lut, smooth
from weather_gym.weather._near_blend import near_blend, near_weight
from weather_gym.weather._night_isp import blotch_grid
from weather_gym.weather.dim import _CHROMA_REF_CODE, _night_luts, chroma_grid
from weather_gym.weather.geometry import _fallback_weight, _zoom
from weather_gym.weather.option import weather_from_arg
from weather_gym.weather.sample import sample_frame

AREA, LINEAR = cv2.INTER_AREA, cv2.INTER_LINEAR


def _smear_split(e, img, depth, state, exposure_s):
    """geometry.smear_split with OpenCV's resizes and a zoom blur, no yaw box (the states below)."""
    h, w = img.shape[:2]
    hh, hw = (h + 1) // 2, (w + 1) // 2
    luma, half = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.resize(img, (hw, hh), interpolation=AREA)
    fx = focal_px(state, w, e.hfov_deg)
    scale = abs(state.get("speed", e.speed_mps)) * exposure_s / e.near_depth_m
    assert focal_px(state, w, e.hfov_deg) * abs(state.get("yaw_rate", e.yaw_rate_rps)) * exposure_s < 1.5
    disp = scale * 0.5 * math.hypot(w, h)
    if disp < 1.0:
        return luma, half
    small = half if not (disp > 16 and min(h, w) >= 16) else cv2.resize(half, (hw // 2, hh // 2), interpolation=AREA)
    f = 4 if small is not half else 2
    m = min(max(math.ceil(math.log2(disp / f + 1)), 1), 3)
    c = (1.0 + scale) ** (1.0 / (2 ** m - 1))
    acc = small
    for j in range(m):
        acc = cv2.addWeighted(acc, 0.5, _zoom(acc, c ** (2 ** j)), 0.5, 0)
    blurred_half = cv2.resize(acc, (hw, hh), interpolation=LINEAR) if acc.shape[:2] != (hh, hw) else acc
    blurred_luma = cv2.resize(cv2.cvtColor(acc, cv2.COLOR_RGB2GRAY), (w, h), interpolation=LINEAR)
    if depth is None:
        key = (e.camera_height_m, e.horizon_frac, e.near_depth_m, e.far_m)
        wt, wt_half = _fallback_weight((h, w, fx, *key), "dim"), _fallback_weight((hh, hw, fx * hw / w, *key), "dim")
    else:
        wt = near_weight(depth, e.near_depth_m)
        wt_half = near_weight(cv2.resize(depth, (hw, hh), interpolation=cv2.INTER_NEAREST), e.near_depth_m)
    luma_out, half_out = np.empty_like(luma), np.empty_like(half)
    near_blend(luma, blurred_luma, wt, None, luma_out)
    near_blend(half, blurred_half, wt_half, None, half_out)
    return luma_out, half_out


def _night(e, img, draw, depth, state):
    """dim._night with the colour offsets in numpy and the enlargement, table and sum in OpenCV."""
    t, gain, residual = e.exposure()
    sigma, chroma, black, desat = e.isp()
    tone, luma_noise, colour_tone, crush, noise = _night_luts(residual, gain, e.full_well_e, e.read_noise_e, black)
    h, w = img.shape[:2]
    luma, half = _smear_split(e, img, depth, state, t - e.exposure_s)
    noisy = np.empty((h, w), np.uint8)
    add_sensor_noise(luma.reshape(h, w, 1), tone, luma_noise, draw[0], noisy.reshape(h, w, 1))
    if sigma >= 0.3:
        smooth(noisy, sigma, noisy, exact=True)
    f32 = np.float32
    hv = half.astype(np.int32)
    y = (hv[..., 0] * 4899 + hv[..., 1] * 9617 + hv[..., 2] * 1868 + 8192) >> 14
    v = colour_tone[half] - colour_tone[y][..., None]  # float32 throughout, in the kernel's order
    bl = f32(0.0)
    if chroma > 0:
        gh, gw = chroma_grid(img.shape, e.chroma_cell_px)
        level = cv2.cvtColor(cv2.resize(half, (gw, gh), interpolation=AREA), cv2.COLOR_RGB2GRAY)
        grid = blotch_grid(draw[1], gauss_lut(), level, noise, float(noise[_CHROMA_REF_CODE]), chroma)
        b = cv2.resize(grid, (half.shape[1], half.shape[0]), interpolation=LINEAR)
        bl = (f32(0.299) * b[..., 0] + f32(0.587) * b[..., 1] + f32(0.114) * b[..., 2])[..., None]
        v += b - bl
    offsets = np.rint(f32(1.0 - desat) * v + bl).astype(np.int16)
    big = cv2.resize(offsets, (w, h), interpolation=LINEAR).astype(np.int32)
    return np.clip(cv2.LUT(noisy, crush).astype(np.int32)[..., None] + big, 0, 255).astype(np.uint8)


STILL_ISH = {"speed": 10.0, "yaw_rate": 0.02}


@pytest.mark.parametrize(("shape", "k", "with_depth", "state"), [
    ((376, 672), 0.87, True, STILL_ISH),                       # the default camera, low_light@2's k
    ((376, 672), 0.6, False, {"speed": 25.0, "yaw_rate": 0.0}),
    ((75, 41), 0.944, True, {"speed": 40.0, "yaw_rate": 0.0}),  # odd sizes: OpenCV's own paths
    ((64, 96), 1.0, False, {"speed": 0.0, "yaw_rate": 0.0}),    # no smear
    ((2, 2), 0.7, False, STILL_ISH),
])
def test_night_camera_equals_the_reference(shape, k, with_depth, state):
    h, w = shape
    img, depth = sample_frame(h, w, seed=h + w) if min(h, w) >= 8 else (
        np.random.default_rng(0).integers(0, 256, (h, w, 3), dtype=np.uint8), np.full((h, w), 5.0, np.float32))
    e = make("dim", k=k, mode="night")
    d = depth if with_depth else None
    draw = e.sample(np.random.default_rng(int(k * 1000)), img.shape)
    got = e.render(img, draw, depth=d, state=state)
    np.testing.assert_array_equal(got, _night(e, img, draw, d, state))


def test_presets_and_a_batch_equal_the_reference():
    img, depth = sample_frame(188, 336, seed=4)
    for severity in (1, 2, 3, 4):
        e = weather_from_arg(f"low_light@{severity}")
        draw = e.sample(np.random.default_rng(severity), img.shape)
        np.testing.assert_array_equal(e.render(img, draw, depth=depth, state=STILL_ISH),
                                      _night(e, img, draw, depth, STILL_ISH))
    e = make("dim", k=0.8, mode="night")
    batch = np.stack([img, img[::-1].copy()])
    draws = e.sample(np.random.default_rng(9), batch.shape)
    got = e.render(batch, draws, state=[STILL_ISH, STILL_ISH])
    for i in range(2):
        np.testing.assert_array_equal(got[i], _night(e, batch[i], draws[i], None, STILL_ISH))
