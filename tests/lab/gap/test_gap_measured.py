"""Measured members of the effect families, the natural ends of parameters, and the evidence ranking:
fast checks on synthetic arrays (no rendering)."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.lab.gap.fit import bound_ends, bounds_hit
from weather_gym.lab.gap.measured import MEASURED, estimate, make_measured
from weather_gym.lab.gap.weather_model import insert_position, read_model, write_model
from weather_gym.weather import make


def _scenes(n: int = 6, seed: int = 0) -> list[np.ndarray]:
    """Smooth random scenes with flat patches and every value from dark to bright."""
    import cv2

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        small = rng.integers(0, 256, (6, 8, 3)).astype(np.float32)
        out.append(np.clip(cv2.resize(small, (160, 120), interpolation=cv2.INTER_CUBIC), 0, 255).astype(np.uint8))
    return out


def test_a_natural_end_is_a_fit_and_a_clipping_bound_is_not():
    shot_only = make("noise", k=0.4, read_noise_e=0.001)  # no read noise: the component is absent
    ends = bound_ends(shot_only, ["read_noise_e"])
    assert [(b["param"], b["natural"]) for b in ends] == [("read_noise_e", True)]
    assert bounds_hit(shot_only, ["read_noise_e"]) == []
    s_curve = make("exposure", k=0.5, contrast=0.999)  # the contrast range clips the fit
    assert bounds_hit(s_curve, ["contrast"]) == ["contrast = 0.999 (bound of -1..1)"]
    assert bounds_hit(make("vignette", k=1.0)) == ["k = 1 (the top of its range)"]
    assert bounds_hit(make("blur", k=1.0, max_radius_frac=0.02), ["max_radius_frac"]) == []


def test_measured_members_round_trip_through_the_model_file(tmp_path):
    tone = estimate("tone_curve", _scenes(), [np.clip(np.rint(255 * (im / 255.0) ** 1.8), 0, 255).astype(np.uint8)
                                              for im in _scenes()])
    model = [make("blur", k=0.3), tone.with_params(k=0.9)]
    write_model(tmp_path / "m.toml", model)
    back = read_model(tmp_path / "m.toml")
    assert [e.name for e in back] == ["blur", "tone_curve"] and back[1] == model[1]
    text = (tmp_path / "m.toml").read_text()
    assert "[[effects]]" in text and "r = [" in text  # a TOML array (tomli-w writes one value a line)
    assert insert_position([make("exposure", k=0.2), make("noise", k=0.2)], "tone_curve") == 1
    assert insert_position([make("noise", k=0.2)], "noise_level") == 1


def test_bad_measured_curves_are_named():
    with pytest.raises(InputError, match="tone_curve: parameter g must be non-decreasing"):
        make_measured("tone_curve", k=1.0, g=[0.0, 0.6, 0.5, 1.0])
    with pytest.raises(InputError, match=r"noise_level: parameter r values must be finite and in \[0.0, 128.0\]"):
        make_measured("noise_level", k=1.0, r=[0.0, -1.0])
    with pytest.raises(InputError, match="unknown parameter"):
        make_measured("radial_gain", k=1.0, curve=[1.0, 0.5])
    with pytest.raises(InputError, match="unknown measured effect 'sharpen'"):
        MEASURED.get("sharpen")


def test_a_tone_curve_outside_the_exposure_family_is_measured():
    """An S-curve that no blend with smoothstep reaches, per channel (a warmer red)."""
    v = np.arange(256) / 255.0
    s = 1 / (1 + np.exp(-9 * (v - 0.5)))
    s = (s - s[0]) / (s[-1] - s[0])
    lut = np.stack([np.minimum(s * 1.1, 1.0), s, s], 1)
    clear = _scenes()
    adverse = [np.clip(np.rint(255 * lut[im, [0, 1, 2]]), 0, 255).astype(np.uint8) for im in clear]
    tone = estimate("tone_curve", clear, adverse)
    out = [tone(im) for im in clear]
    err = np.mean([np.abs(a.astype(int) - b.astype(int)).mean() for a, b in zip(out, adverse)])
    assert err < 2.0, err
    assert np.all(np.diff(tone.r) >= 0) and tone.r[8] > tone.g[8]


def test_a_noise_level_function_with_read_noise_is_measured():
    clear = _scenes()
    rng = np.random.default_rng(1)

    def noisy(im):  # shot noise growing with the value plus a floor of read noise, per channel
        x = im.astype(np.float64)
        return np.clip(np.rint(x + rng.normal(0, 1, x.shape) * np.sqrt(4.0 + 0.12 * x)), 0, 255).astype(np.uint8)

    nl = estimate("noise_level", clear, [noisy(im) for im in clear])
    sig = np.array(nl.g)
    assert 1.2 < sig[1] < 3.5 and 4.0 < sig[10] < 7.0 and sig[10] > sig[1], sig  # sqrt(4 + 0.12 x)


def test_a_cos4_falloff_is_measured_as_a_radial_gain():
    clear = _scenes()
    h, w = clear[0].shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    r = np.hypot(x + 0.5 - w / 2, y + 0.5 - h / 2) / (0.5 * np.hypot(w, h))
    g = np.cos(np.arctan(r * np.tan(np.deg2rad(45)))) ** 4
    adverse = [np.clip(np.rint(im * g[..., None]), 0, 255).astype(np.uint8) for im in clear]
    for paired in (True, False):
        rg = estimate("radial_gain", clear, adverse, paired=paired)
        assert rg.gain[0] == pytest.approx(1.0, abs=0.03 if paired else 0.15)
        assert rg.gain[-1] == pytest.approx(0.25, abs=0.05 if paired else 0.15)


def test_a_disc_kernel_is_measured_as_a_blur_kernel():
    """A hard-edged disc (no Gaussian has its shape): paired, the Wiener estimate reproduces the frames;
    unpaired, the power-spectrum estimate has the disc's spread."""
    import cv2

    rng = np.random.default_rng(3)
    clear = [np.clip(cv2.GaussianBlur(rng.integers(0, 256, (96, 128, 3)).astype(np.float32), (0, 0), 1.0), 0, 255)
             .astype(np.uint8) for _ in range(4)]
    y, x = np.mgrid[-3:4, -3:4]
    disc = (np.hypot(x, y) <= 3.0).astype(np.float32)
    disc /= disc.sum()
    adverse = [cv2.filter2D(im, -1, disc, borderType=cv2.BORDER_REFLECT) for im in clear]
    bk = estimate("blur_kernel", clear, adverse, paired=True)
    err = np.mean([np.abs(bk(a).astype(int) - b.astype(int)).mean() for a, b in zip(clear, adverse)])
    assert err < 1.5, err
    assert sum(bk.kernel) == pytest.approx(1.0, abs=1e-6) and "kernel, spread" in bk.summary()
    un = estimate("blur_kernel", clear, adverse, paired=False)
    k = np.asarray(un.kernel).reshape(un.side, un.side)
    c = un.side // 2
    assert k[c, c] < 0.3 and np.allclose(k, k[::-1, ::-1], atol=1e-3)  # spread out, zero phase
    with pytest.raises(InputError, match="odd square of weights"):
        make_measured("blur_kernel", k=1.0, kernel=[0.5, 0.5])
