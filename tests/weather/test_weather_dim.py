"""Dim: the study's Pillow brightness byte for byte, and the physical low-light camera."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.weather import make
from weather_gym.weather.dim import auto_exposure
from weather_gym.weather.reference import study_dim

ALL_VALUES = np.arange(256, dtype=np.uint8).reshape(8, 32, 1).repeat(3, axis=2)


@pytest.mark.parametrize("k", [*np.linspace(0, 1, 101).tolist(), 0.78, 0.55, 1e-7, 0.3333333])
def test_faithful_mode_is_pillow_brightness_byte_for_byte(k):
    np.testing.assert_array_equal(make("dim", k=k)(ALL_VALUES), study_dim(ALL_VALUES, k))


def test_faithful_mode_on_a_frame_and_a_batch(scene):
    img = scene[0]
    np.testing.assert_array_equal(make("dim", k=0.78)(img), study_dim(img, 0.78))
    batch = np.stack([img, img[::-1].copy()])
    out = make("dim", k=0.41)(batch)
    np.testing.assert_array_equal(out[1], study_dim(batch[1], 0.41))


def test_auto_exposure_first_lengthens_the_exposure_then_raises_gain_then_gives_up():
    t, g, r = auto_exposure(0.5, 0.002, 1 / 60, 16)
    assert (t, g, r) == pytest.approx((0.004, 1.0, 1.0))
    t, g, r = auto_exposure(1 / 64, 0.002, 1 / 60, 16)
    assert t == pytest.approx(1 / 60) and g == pytest.approx(64 * 0.002 * 60) and r == pytest.approx(1.0)
    t, g, r = auto_exposure(1 / 4096, 0.002, 1 / 60, 16)
    assert g == 16 and r == pytest.approx(16 * (1 / 60) / 0.002 / 4096)


def test_physical_mode_keeps_brightness_while_it_can_and_adds_noise(scene):
    img, depth = scene
    still = {"speed": 0.0, "yaw_rate": 0.0}
    means, noise = [], []
    for k in (0.2, 0.5, 0.7, 0.95):
        e = make("dim", k=k, mode="physical")
        out = e(img, depth=depth, state=still, rng=np.random.default_rng(0))
        means.append(out.mean())
        noise.append(np.abs(out.astype(int) - img).mean())
    assert abs(means[0] - img.mean()) < 2  # auto-exposure compensates the lost light
    assert means[-1] < 0.5 * img.mean()  # out of exposure and gain: darker
    assert noise[0] < noise[1] < noise[2]  # more gain, more noise


def test_physical_mode_smears_with_motion_from_the_state(scene):
    img = scene[0]
    e = make("dim", k=0.6, mode="physical", read_noise_e=0.0, full_well_e=1e6)
    still = e(img, state={"speed": 0.0, "yaw_rate": 0.0}, rng=np.random.default_rng(0))
    turning = e(img, state={"speed": 0.0, "yaw_rate": 2.0}, rng=np.random.default_rng(0))

    def sharpness(a):
        return np.abs(np.diff(a.astype(int), axis=1)).mean()

    assert sharpness(turning) < 0.8 * sharpness(still)
    t, _, _ = e.exposure()
    assert t > e.exposure_s


def test_physical_k_is_in_stops():
    e = make("dim", k=0.5, mode="physical", stops=10)
    t, g, r = e.exposure()
    assert t / e.exposure_s * g * r == pytest.approx(2 ** 5)  # 5 stops of light made up for
