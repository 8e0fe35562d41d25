"""Dim: the study's Pillow brightness byte for byte, and the physical low-light camera."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.weather import make
from weather_gym.weather._common import gauss_lut, smooth
from weather_gym.weather.dim import (
    add_chroma_blotches,
    auto_exposure,
    black_level_lut,
    chroma_draw,
    chroma_grid,
)
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


# -- night mode ----------------------------------------------------------------------------------
STILL = {"speed": 0.0, "yaw_rate": 0.0}


def _hf_energy(a):
    return float(np.abs(cv2.Laplacian(cv2.cvtColor(a, cv2.COLOR_RGB2GRAY), cv2.CV_32F)).mean())


def test_night_noise_grows_with_k_and_brightness_falls_at_high_k(scene):
    img, depth = scene
    noise, means = [], []
    for k in (0.3, 0.45, 0.6, 0.75, 0.9, 1.0):
        e = make("dim", k=k, mode="night", denoise_px=0.0, chroma_noise=0.0, black_level=0.0, desaturate=0.0)
        outs = [e(img, depth=depth, state=STILL, rng=np.random.default_rng(s)) for s in (0, 1)]
        noise.append(float(np.abs(outs[0].astype(int) - outs[1]).mean()))  # two draws: noise only
        means.append(float(make("dim", k=k, mode="night")(img, depth=depth, state=STILL,
                                                          rng=np.random.default_rng(0)).mean()))
    assert noise[0] < noise[1] < noise[2], noise  # more gain, more noise
    assert means[2] > means[3] > means[4] > means[5], means  # out of exposure and gain: ever darker
    assert means[-1] < 0.25 * img.mean()


def test_night_denoiser_smear_removes_high_frequencies(scene):
    img, depth = scene
    args = dict(k=0.7, mode="night", chroma_noise=0.0, black_level=0.0, desaturate=0.0)
    raw = make("dim", denoise_px=0.0, **args)(img, depth=depth, state=STILL, rng=np.random.default_rng(0))
    denoised = make("dim", denoise_px=1.0, **args)(img, depth=depth, state=STILL, rng=np.random.default_rng(0))
    assert _hf_energy(denoised) < 0.5 * _hf_energy(raw)
    sigma, chroma, black, desat = make("dim", **args, denoise_px=1.0).isp()
    assert sigma > 0.5 and chroma == 0.0 and black == 0.0 and desat == 0.0


@pytest.mark.parametrize("sigma", [0.5, 0.85, 1.6, 3.0])  # a blended fraction; a box pass and a fraction; halved
def test_night_denoiser_smooths_the_luma_in_place_as_into_a_copy(sigma):
    luma = np.random.default_rng(4).integers(0, 256, (95, 171), np.uint8)  # one channel, odd sizes
    want = smooth(luma, sigma, exact=True)
    smooth(luma, sigma, luma, exact=True)  # what the night camera does with its noisy luma
    np.testing.assert_array_equal(luma, want)


def test_night_camera_keeps_its_properties_at_the_shipped_settings(scene):
    """Darker with k once gain runs out, noisier with the gain, colour suppressed at high gain,
    luma at full resolution, the same bytes for the same seed (frame and batch)."""
    img, depth = scene

    def run(k, seed=0, state=STILL, **kw):
        return make("dim", k=k, mode="night", **kw)(img, depth=depth, state=state, rng=np.random.default_rng(seed))

    def sat(x):
        return float(np.ptp(x.astype(int), axis=2).mean())

    means = [float(run(k).mean()) for k in (0.755, 0.843, 0.89, 0.917)]  # the shipped low_light rows
    assert means[0] > means[1] > means[2] > means[3], means
    gains = [make("dim", k=k, mode="night").exposure()[1] for k in (0.3, 0.45, 0.6)]
    assert gains[0] < gains[1] < gains[2]
    noise = [float(np.abs(run(k, 0).astype(int) - run(k, 1)).mean()) for k in (0.3, 0.45, 0.6)]
    assert noise[0] < noise[1] < noise[2], noise  # two draws differ by the noise only: it grows with gain
    assert sat(run(0.6)) < 0.5 * sat(run(0.25))  # chroma suppression at gain 16; none below gain 1
    # the luma keeps full-resolution detail: a one-pixel stripe survives, its colour is spread over two
    stripes = np.full((64, 96, 3), 128, np.uint8)
    stripes[:, ::2] = 200
    out = make("dim", k=0.3, mode="night")(stripes, state=STILL, rng=np.random.default_rng(0))
    assert float(np.abs(np.diff(out[:, :, 1].astype(int), axis=1)).mean()) > 40
    a, b = run(0.843, 7, state={"speed": 12.0, "yaw_rate": 0.5}), run(0.843, 7, state={"speed": 12.0, "yaw_rate": 0.5})
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, run(0.843, 8, state={"speed": 12.0, "yaw_rate": 0.5}))
    e = make("dim", k=0.843, mode="night")
    batch = np.stack([img, img[::-1].copy()])
    rng = np.random.default_rng(5)
    loop = [e(f, depth=depth, state=STILL, rng=rng) for f in batch]
    np.testing.assert_array_equal(e(batch, depth=np.stack([depth, depth]), state=STILL,
                                    rng=np.random.default_rng(5)), np.stack(loop))


def test_night_isp_strength_follows_the_gain():
    assert make("dim", k=0.1, mode="night").isp() == (0.0, 0.0, 0.0, 0.0)  # the exposure time suffices
    isps = [make("dim", k=k, mode="night").isp() for k in (0.3, 0.4, 0.5)]
    for a, b in zip(isps, isps[1:], strict=False):
        assert all(y > x for x, y in zip(a, b, strict=True)), isps
    e = make("dim", k=0.7, mode="night")
    assert e.exposure()[1] == e.max_gain and e.isp() == make("dim", k=1.0, mode="night").isp()


def test_night_chroma_suppression_pulls_colour_to_grey_and_keeps_luma(scene):
    img, depth = scene
    args = dict(k=0.8, mode="night", denoise_px=0.0, chroma_noise=0.0, black_level=0.0)
    kept = make("dim", desaturate=0.0, **args)(img, depth=depth, state=STILL, rng=np.random.default_rng(0))
    grey = make("dim", desaturate=1.0, **args)(img, depth=depth, state=STILL, rng=np.random.default_rng(0))
    half = make("dim", desaturate=0.5, **args)(img, depth=depth, state=STILL, rng=np.random.default_rng(0))

    def sat(x):
        return float(np.ptp(x.astype(int), axis=2).mean())

    assert sat(grey) <= 1.0 < 0.4 * sat(kept) < sat(half) < 0.8 * sat(kept)  # 1 - 0.5 of the colour left
    luma = [cv2.cvtColor(x, cv2.COLOR_RGB2GRAY).astype(int) for x in (kept, half)]
    diff = np.abs(luma[0] - luma[1])  # grey level unchanged: only the colour goes (the colour's half
    assert diff.mean() < 0.3 and np.percentile(diff, 99.5) <= 2  # resolution and saturation: a few units)


def test_night_colour_noise_is_colour_only():
    img = np.full((64, 96, 3), 100, np.uint8)
    add_chroma_blotches(img, 6.0, 8.0, np.random.default_rng(0))
    d = img.astype(float) - 100
    assert 3.0 < d.std() < 9.0
    assert np.abs(d.sum(axis=2)).mean() < 1.5  # the three offsets cancel: luma kept


def _blotches_as_two_saturating_passes(img, sigma, cell_px, raw, weight):
    """The colour blotches as first written: numpy's axis mean, then + the positive part and - the
    negative part of the blotch, each a saturating uint8 pass."""
    gh, gw = chroma_grid(img.shape, cell_px)
    z = gauss_lut()[raw].reshape(gh, gw, 3)
    z -= z.mean(axis=2, keepdims=True)
    z *= np.float32(sigma * math.sqrt(1.5))
    z *= weight[:, :, None]
    grid = np.clip(np.rint(z + 128.0), 0, 255).astype(np.uint8)
    big = cv2.resize(grid, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_LINEAR)
    out = cv2.add(img, cv2.subtract(big, np.full_like(big, 128)))
    return cv2.subtract(out, cv2.subtract(np.full_like(big, 128), big))


@pytest.mark.parametrize("shape, sigma, cell_px", [((376, 672, 3), 16.0, 8.0), ((67, 101, 3), 40.0, 5.0)])
def test_colour_blotches_in_one_pass_are_the_two_saturating_passes(shape, sigma, cell_px):
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, shape, np.uint8)
    img[: shape[0] // 3] //= 8  # shadows and highlights, where the saturations act
    img[-shape[0] // 3:] |= 0xF0
    raw = chroma_draw(rng, shape, cell_px)
    weight = rng.uniform(0.0, 4.0, chroma_grid(shape, cell_px)).astype(np.float32)
    want = _blotches_as_two_saturating_passes(img, sigma, cell_px, raw, weight)
    add_chroma_blotches(img, sigma, cell_px, raw, weight)
    np.testing.assert_array_equal(img, want)
    pairs = np.arange(1 << 16)  # the one pass on every (value, blotch) pair of bytes
    a, b = (pairs >> 8).astype(np.uint8).reshape(256, 256), (pairs & 255).astype(np.uint8).reshape(256, 256)
    two = cv2.subtract(cv2.add(a, cv2.subtract(b, np.full_like(b, 128))), cv2.subtract(np.full_like(b, 128), b))
    np.testing.assert_array_equal(cv2.addWeighted(a, 1.0, b, 1.0, -128.0), two)


def test_black_level_lut_crushes_shadows():
    np.testing.assert_array_equal(black_level_lut(0.0), np.arange(256))
    lut = black_level_lut(0.01)
    assert lut[25] == 0 and lut[255] == 255 and np.all(np.diff(lut.astype(int)) >= 0)


def test_night_parameters_leave_the_other_modes_alone(scene):
    img, depth = scene
    night_params = dict(denoise_px=3.0, chroma_noise=40.0, chroma_cell_px=2.0, black_level=0.1, desaturate=1.0)
    for mode in ("faithful", "physical"):
        a = make("dim", k=0.8, mode=mode)(img, depth=depth, state=STILL, rng=np.random.default_rng(3))
        b = make("dim", k=0.8, mode=mode, **night_params)(img, depth=depth, state=STILL,
                                                          rng=np.random.default_rng(3))
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(("param", "value", "range_"), [
    ("denoise_px", 3.5, "[0.0, 3.0]"), ("chroma_noise", -1.0, "[0.0, 40.0]"),
    ("black_level", 0.2, "[0.0, 0.1]"), ("chroma_cell_px", 1.0, "[2.0, 64.0]"), ("desaturate", 1.5, "[0.0, 1.0]"),
])
def test_night_parameters_are_range_checked(param, value, range_):
    with pytest.raises(InputError) as err:
        make("dim", k=0.5, mode="night", **{param: value})
    assert param in str(err.value) and str(value) in str(err.value) and range_ in str(err.value)
    with pytest.raises(InputError, match="mode='dusk' must be one of faithful, physical, night"):
        make("dim", k=0.5, mode="dusk")
