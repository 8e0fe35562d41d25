"""Behaviour of each effect beyond the shared contract: what its physics promises."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.weather import make
from weather_gym.weather._common import gauss_lut, ground_depth, noise_bank, smooth, srgb_decode, srgb_encode
from weather_gym.weather.dim import _physical_luts
from weather_gym.weather.noise import noise_sigma_lut


def _sharpness(a):
    return np.abs(np.diff(a.astype(int), axis=1)).mean() + np.abs(np.diff(a.astype(int), axis=0)).mean()


def test_gaussian_table_is_a_unit_normal():
    q = gauss_lut()
    assert abs(q.mean()) < 1e-6 and q.std() == pytest.approx(1.0, abs=1e-6)
    assert np.all(np.diff(q) > 0)


def test_srgb_round_trip():
    v = np.arange(256) / 255
    np.testing.assert_allclose(srgb_encode(srgb_decode(v)), v, atol=1e-12)


def test_fog_follows_koschmieder_with_depth():
    img = np.zeros((10, 40, 3), np.uint8)
    depth = np.tile(np.linspace(1, 60, 40, dtype=np.float32), (10, 1))
    e = make("fog", k=0.5, min_visibility_m=20.0, airlight=1.0)
    out = e(img, depth=depth, state={"fx": 1e6})  # huge fx: rays along the axis, range = depth
    expected = 255 * (1 - np.exp(-e.beta * depth))
    assert np.abs(out[..., 0].astype(float) - expected).max() <= 2.0
    assert np.all(np.diff(out[5, :, 0].astype(int)) >= 0)  # farther, foggier


def test_fog_airlight_tint_colours_the_haze_and_keeps_its_level():
    """A sky-coloured airlight: bluish at t > 0 (red (1 - t) of blue), warm at t < 0; grey at 0."""
    img = np.zeros((6, 8, 3), np.uint8)
    depth = np.full((6, 8), 500.0, np.float32)  # far: all airlight
    grey = make("fog", k=1.0, airlight=0.8)(img, depth=depth)[3, 4].astype(int)
    blue = make("fog", k=1.0, airlight=0.8, airlight_tint=0.1)(img, depth=depth)[3, 4].astype(int)
    warm = make("fog", k=1.0, airlight=0.8, airlight_tint=-0.1)(img, depth=depth)[3, 4].astype(int)
    assert grey[0] == grey[1] == grey[2] == 204
    assert blue[2] == 204 and abs(blue[0] - 0.9 * 204) <= 1 and blue[0] < blue[1] < blue[2]
    assert warm[0] == 204 and abs(warm[2] - 0.9 * 204) <= 1 and warm[2] < warm[1] < warm[0]
    np.testing.assert_array_equal(make("fog", k=0.4, airlight_tint=0.0)(img), make("fog", k=0.4)(img))
    with pytest.raises(InputError, match="airlight_tint"):
        make("fog", k=0.4, airlight_tint=0.5)


def test_fog_default_space_keeps_its_bytes():
    """The presets are calibrated on the code-value mix: its output must not move (digest from before
    ``space`` existed); ``space="srgb"`` spelled out is the same effect."""
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (48, 80, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 120.0, (48, 80)).astype(np.float32)
    h = hashlib.sha256()
    for kw in ({"k": 0.3}, {"k": 0.9, "airlight": 0.7, "airlight_tint": 0.1}, {"k": 0.5, "airlight_tint": -0.15}):
        h.update(make("fog", **kw)(img).tobytes())
        h.update(make("fog", **kw)(img, depth=depth).tobytes())
        np.testing.assert_array_equal(make("fog", space="srgb", **kw)(img, depth=depth), make("fog", **kw)(img, depth=depth))
    assert h.hexdigest() == "0d901a471f4d4e7794bd39e14e752d5a3ef24eb347624244236c4d648ccf1de2"


def test_fog_linear_mixes_radiance():
    """``space="linear"``: Koschmieder on decoded light, within a code of the exact curve; monotone in
    density, the same airlight far away, the image itself at k -> 0; it differs from the code-value mix."""
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (20, 40, 3), dtype=np.uint8)
    depth = np.tile(np.linspace(1, 60, 40, dtype=np.float32), (20, 1))
    e = make("fog", k=0.5, airlight=0.8, airlight_tint=0.05, space="linear")
    out = e(img, depth=depth, state={"fx": 1e6})  # range = depth
    t = np.exp(-e.beta * depth)[..., None]
    a = np.array([0.8 * 0.95, 0.8 * 0.975, 0.8])  # tint 0.05: red 0.95 of blue, green half-way
    a_lin = srgb_decode(np.rint(255 * a) / 255)  # the airlight is a code value, decoded
    exact = 255 * srgb_encode(srgb_decode(img / 255.0) * t + a_lin * (1 - t))
    assert np.abs(out.astype(float) - exact).max() <= 1.01
    srgb = make("fog", k=0.5, airlight=0.8, airlight_tint=0.05)(img, depth=depth, state={"fx": 1e6})
    assert np.abs(out.astype(int) - srgb).mean() > 2.0
    grey = rng.integers(0, 256, (1, 64, 3), dtype=np.uint8)
    mids = [make("fog", k=k, space="linear")(grey, depth=np.full((1, 64), 20.0, np.float32)).astype(int)
            for k in (0.1, 0.3, 0.6, 1.0)]
    airlight = 217  # 0.85 * 255
    for near, far in zip(mids, mids[1:]):  # denser: every pixel moves towards the airlight, never past it
        assert np.all(np.abs(far - airlight) <= np.abs(near - airlight))
    far_out = make("fog", k=1.0, space="linear")(img, depth=np.full((20, 40), 500.0, np.float32))
    assert np.all(far_out == airlight)
    np.testing.assert_array_equal(make("fog", k=1e-7, space="linear")(img, depth=depth), img)
    assert make("fog", k=0.5, space="linear")(img).shape == img.shape  # the ground-plane fallback
    with pytest.raises(InputError, match="space"):
        make("fog", k=0.5, space="log")


def test_fog_airlight_green_is_the_other_white_balance_axis():
    img = np.zeros((6, 8, 3), np.uint8)
    depth = np.full((6, 8), 500.0, np.float32)
    green = make("fog", k=1.0, airlight=0.8, airlight_green=0.1)(img, depth=depth)[3, 4].astype(int)
    magenta = make("fog", k=1.0, airlight=0.8, airlight_green=-0.1)(img, depth=depth)[3, 4].astype(int)
    assert green[1] == 204 and green[0] == green[2] and abs(green[0] - 0.9 * 204) <= 1
    assert magenta[0] == magenta[2] == 204 and abs(magenta[1] - 0.9 * 204) <= 1


def test_fog_without_depth_uses_the_ground_plane():
    black = np.zeros((188, 336, 3), np.uint8)
    fog = make("fog", k=0.6)(black)[:, 168, 0].astype(int)  # = airlight * (1 - transmittance)
    assert fog[0] == fog[93] >= 215  # at and above the horizon: far_m away, fully fogged
    assert np.all(np.diff(fog[94:]) <= 0) and fog[-1] < 0.4 * fog[0]  # the road ahead clears
    z = ground_depth(100, 10, 50.0, 1.0, 0.5, 200.0)
    assert z[0, 0] == 200.0 and z[-1, 0] < z[60, 0] < 200.0


def test_fog_rejects_bad_depth():
    img = np.zeros((4, 5, 3), np.uint8)
    for bad in (np.nan, -1.0, np.inf):
        depth = np.ones((4, 5), np.float32)
        depth[1, 1] = bad
        with pytest.raises(ValueError, match="finite metres >= 0"):
            make("fog", k=0.5)(img, depth=depth)


def test_motion_blur_uses_speed_and_yaw_rate(scene):
    img, depth = scene
    e = make("motion_blur", k=1.0)
    still = e(img, depth=depth, state={"speed": 0.0, "yaw_rate": 0.0})
    np.testing.assert_array_equal(still, img)
    yaw = e(img, depth=depth, state={"speed": 0.0, "yaw_rate": 1.0})
    dx = np.abs(np.diff(yaw.astype(int), axis=1)).mean() / np.abs(np.diff(img.astype(int), axis=1)).mean()
    dy = np.abs(np.diff(yaw.astype(int), axis=0)).mean() / np.abs(np.diff(img.astype(int), axis=0)).mean()
    assert dx < 0.8 and dx < dy  # a horizontal smear
    fast = e(img, depth=depth, state={"speed": 30.0, "yaw_rate": 0.0})
    h = img.shape[0]
    near = np.abs(fast[-h // 5:].astype(int) - img[-h // 5:]).mean()
    far = np.abs(fast[: h // 3].astype(int) - img[: h // 3]).mean()
    assert near > far  # the road right ahead smears, the sky does not
    short = e(img, depth=depth, state={"speed": 30.0, "yaw_rate": 0.0, "exposure_s": 0.002})
    assert _sharpness(short) > _sharpness(fast)


@pytest.mark.parametrize("n_px", [2, 3, 4, 5, 7])
def test_motion_blur_keeps_a_uniform_frame_uniform(n_px):
    # OpenCV 5.0's 2-px box filter adds 1 to every value (255 wraps to 0): the yaw smear must not
    for v in (0, 1, 128, 254, 255):
        img = np.full((30, 50, 3), v, np.uint8)
        out = make("motion_blur", k=1.0, exposure_s=0.01)(img, state={"speed": 0.0, "yaw_rate": n_px, "fx": 100.0})
        np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("sigma", [0.3, 0.5, 0.84, 1.0, 1.2, 1.68, 2.2, 2.6, 3.36, 6.72, 15.0])
def test_smooth_has_the_asked_standard_deviation(sigma):
    impulse = np.zeros((201, 201, 3), np.float32)
    impulse[100, 100] = 1.0
    psf = smooth(impulse, sigma)[..., 0].astype(np.float64)
    x = np.arange(201)
    assert psf.sum() == pytest.approx(1.0, abs=3e-3)
    for profile in (psf.sum(axis=0), psf.sum(axis=1)):
        mean = (profile * x).sum()
        assert np.sqrt((profile * (x - mean) ** 2).sum()) == pytest.approx(sigma, rel=0.08)  # the old: 16 %


def test_blur_scales_with_image_width(scene):
    img = scene[0]
    soft = make("blur", k=1.0)(img)
    assert _sharpness(soft) < 0.7 * _sharpness(img)
    assert abs(float(soft.mean()) - float(img.mean())) < 1.0


def test_noise_is_unbiased_and_grows_with_the_signal():
    dark = np.full((64, 64, 3), 40, np.uint8)
    mid = np.full((64, 64, 3), 160, np.uint8)
    e = make("noise", k=1.0, read_noise_e=0.0)
    a, b = e(dark, rng=np.random.default_rng(0)), e(mid, rng=np.random.default_rng(0))
    assert abs(a.mean() - 40) < 0.5 and abs(b.mean() - 160) < 0.5
    # shot noise: variance ~ signal in linear light; sigma in code values via the sRGB slope
    assert b.std() > 5 and a.std() > 5
    assert make("noise", k=0.25)(mid, rng=np.random.default_rng(0)).std() < b.std()


@pytest.mark.parametrize("level", [10, 60, 128, 230])
def test_noise_has_the_model_sigma_and_no_bias(level):
    e = make("noise", k=0.5)
    rng = np.random.default_rng(level)
    frames = e(np.full((16, 40, 60, 3), level, np.uint8), rng=rng).astype(np.float64) - level
    sigma = float(noise_sigma_lut(0.5 * e.max_gain, e.full_well_e, e.read_noise_e)[level])
    clipped = level - 2 * sigma < 0 or level + 2 * sigma > 255
    if not clipped:  # clipping at 0 or 255 biases dark pixels under strong read noise, as in a camera
        assert abs(frames.mean()) < 0.05 * sigma + 0.1
        assert frames.std() == pytest.approx(np.sqrt(sigma ** 2 + 1 / 12), rel=0.04)
    assert frames.var(axis=0, ddof=1).mean() == pytest.approx(frames.var(), rel=0.05)  # each pixel over time


def test_noise_is_uncorrelated_in_space_and_between_frames():
    rng = np.random.default_rng(7)
    e = make("noise", k=1.0)
    gray = np.full((120, 160, 3), 128, np.uint8)
    a, b = (e(gray, rng=rng).astype(np.float64) - 128 for _ in range(2))

    def corr(x, y):
        x, y = x - x.mean(), y - y.mean()
        return float((x * y).sum() / np.sqrt((x * x).sum() * (y * y).sum()))

    assert abs(corr(a, b)) < 0.02  # same pixel, next frame
    assert abs(corr(a[:, 1:], a[:, :-1])) < 0.02 and abs(corr(a[1:], a[:-1])) < 0.02  # neighbours
    assert abs(corr(a[..., 0], a[..., 1])) < 0.02  # channels
    # the next frame's signs are fresh: no shift of it matches this frame
    worst = max(abs(corr(a[20:100, 20:140], b[20 + dy:100 + dy, 20 + dx:140 + dx]))
                for dy in range(-8, 9) for dx in range(-8, 9))
    assert worst < 0.03


def test_noise_table_is_the_same_whatever_size_asked_first():
    first = noise_bank(1000)[:1000].copy()
    big = noise_bank(3 * 2**20)
    np.testing.assert_array_equal(big[:1000], first)
    z = big[: 2**20].astype(np.float64) / 64  # |z| of 128 equiprobable levels, 1/64 resolution
    assert big.max() == round(64 * float(gauss_lut().max())) and len(np.unique(big)) > 100
    assert (z ** 2).mean() == pytest.approx(1.0, abs=0.01) and z.mean() == pytest.approx(np.sqrt(2 / np.pi), abs=0.01)


def test_physical_dim_noise_follows_its_tables():
    e = make("dim", k=0.78, mode="physical", speed_mps=0.0, yaw_rate_rps=0.0)
    _, gain, residual = e.exposure()
    mean, sigma = _physical_luts(residual, gain, e.full_well_e, e.read_noise_e)
    out = e(np.full((8, 60, 80, 3), 200, np.uint8), rng=np.random.default_rng(0)).astype(np.float64)
    assert out.mean() == pytest.approx(round(float(mean[200])), abs=0.1)
    assert out.std() == pytest.approx(np.sqrt(float(sigma[200]) ** 2 + 1 / 12), rel=0.04)


def test_exposure_under_and_over(scene):
    img = scene[0]
    under = make("exposure", k=1.0)(img)
    over = make("exposure", k=1.0, direction="over")(img)
    assert under.mean() < img.mean() < over.mean()
    assert (over == 255).mean() > (img == 255).mean()  # highlights clip
    lifted = make("exposure", k=1.0, max_stops=0.25, flare=0.2)(np.zeros((2, 2, 3), np.uint8))
    assert lifted.min() == 51


def test_vignette_darkens_the_corners_only():
    img = np.full((101, 151, 3), 200, np.uint8)
    out = make("vignette", k=0.6)(img)
    assert out[50, 75, 0] == 200 and out[0, 0, 0] < out[25, 37, 0] < 200


def test_rain_density_and_veil_grow_with_k():
    img = np.zeros((120, 200, 3), np.uint8)
    light = make("rain", k=0.2, haze=0.0)(img, rng=np.random.default_rng(0))
    heavy = make("rain", k=1.0, haze=0.0)(img, rng=np.random.default_rng(0))
    assert (heavy > 0).mean() > 2 * (light > 0).mean()
    veiled = make("rain", k=1.0, haze=0.5, density=0.1)(img, rng=np.random.default_rng(0))
    assert np.median(veiled) == round(0.5 * 0.8 * 255)


def test_glare_is_strongest_at_the_source():
    img = np.full((90, 160, 3), 60, np.uint8)
    out = make("glare", k=0.8, source_x=0.2, source_y=0.2, bloom=0.0)(img)
    near, far = out[18, 32].astype(int).sum(), out[80, 150].astype(int).sum()
    assert near > far > img[0, 0].astype(int).sum()  # the veil lifts everything a little


def test_glare_bloom_spreads_light_from_bright_areas():
    img = np.zeros((80, 160, 3), np.uint8)
    img[30:50, 70:90] = 255
    no = make("glare", k=1.0, bloom=0.0, veil=0.0, source_x=-1.0, source_y=-1.0)(img)
    yes = make("glare", k=1.0, bloom=1.0, veil=0.0, source_x=-1.0, source_y=-1.0)(img)
    assert yes[40, 60].sum() > no[40, 60].sum()


def test_jpeg_quality_follows_k(scene):
    img = scene[0]
    assert make("jpeg", k=0.0).quality == 100 and make("jpeg", k=1.0).quality == 5
    err = [np.abs(make("jpeg", k=k)(img).astype(int) - img).mean() for k in (0.2, 0.6, 1.0)]
    assert err[0] < err[1] < err[2]


@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize(("shape", "sigma"), [((40, 60, 3), 0.8), ((40, 60, 3), 2 ** 0.5), ((40, 60, 3), 1.6),
                                              ((40, 60, 3), 3.0), ((6, 7, 3), 3.0)])
def test_smooth_in_place_equals_smoothing_into_a_new_frame(shape, sigma, exact):
    """``smooth(img, sigma, img)`` is the same bytes as into a new frame, also where it is one box pass."""
    img = np.random.default_rng(3).integers(0, 256, shape, dtype=np.uint8)
    want = smooth(img, sigma, exact=exact)
    same = img.copy()
    assert smooth(same, sigma, same, exact=exact) is same
    np.testing.assert_array_equal(same, want)
