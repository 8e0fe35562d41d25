"""The refractive droplets mode (``droplets:K:mode=refractive``) and its drop renderer."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from weather_gym.weather import Ramp, make, parse_weather
from weather_gym.weather.lens_drops import (
    _THETA_BIN,
    _drop_maps,
    _small_copy,
    drop_layout,
    render_lens_drops,
)


def _sky_ground(h=188, w=336):
    img = np.zeros((h, w, 3), np.uint8)
    img[: h // 2] = 230  # bright top half, dark bottom half
    img[h // 2:] = 20
    return img


def _refr(k=0.6, **kw):
    return make("droplets", k=k, mode="refractive", **kw)


def test_spec_string_selects_the_mode():
    e = parse_weather("droplets:0.7:mode=refractive")
    assert e.mode == "refractive" and e.k == 0.7
    assert make("droplets").mode == "faithful"


def test_a_drop_shows_the_scene_inverted():
    img = _sky_ground()
    cx, cy, r = 168.0, 94.0, 24.0  # a drop on the horizon
    out = render_lens_drops(img, [cx], [cy], [r], [70.0], look_up=0.0, highlight=0.0)
    upper = out[int(cy - 0.5 * r), int(cx)].astype(int)
    lower = out[int(cy + 0.5 * r), int(cx)].astype(int)
    assert (img[int(cy - 0.5 * r), int(cx)] == 230).all() and (img[int(cy + 0.5 * r), int(cx)] == 20).all()
    assert lower.mean() > upper.mean() + 80  # sky at the bottom of the drop, ground at its top


def test_a_drop_on_the_ground_looks_up_at_the_sky():
    img = _sky_ground()
    out = render_lens_drops(img, [168.0], [150.0], [18.0], [70.0], look_up=1.0, highlight=0.0)
    assert out[150 + 9, 168].mean() > 60  # lower half of the drop shows the bright sky above it


def test_the_rim_is_darker_than_the_centre():
    img = np.full((120, 160, 3), 200, np.uint8)
    out = render_lens_drops(img, [80.0], [60.0], [30.0], [60.0], highlight=0.0)
    centre = out[60, 80].mean()
    rim = min(out[60, 80 + 28].mean(), out[60 + 28, 80].mean(), out[60, 80 - 28].mean())
    assert rim < centre - 60
    assert out[60, 80 + 45].mean() == 200  # outside the drop (and its blurred edge) untouched


def test_highlight_brightens_the_upper_left():
    img = np.full((120, 160, 3), 100, np.uint8)
    plain = render_lens_drops(img, [80.0], [60.0], [30.0], [60.0], highlight=0.0)
    lit = render_lens_drops(img, [80.0], [60.0], [30.0], [60.0], highlight=1.0)
    y, x = 60 - int(0.4 * 30), 80 - int(0.35 * 30)
    assert lit[y, x].mean() > plain[y, x].mean() + 100
    assert lit[60 + 20, 80 + 20].mean() == pytest.approx(plain[60 + 20, 80 + 20].mean(), abs=2)


def test_drops_at_the_border_and_tiny_images():
    img = _sky_ground(40, 60)
    out = render_lens_drops(img, [0.0, 59.0, 200.0], [0.0, 39.0, 10.0], [8.0, 30.0, 5.0], [40.0, 90.0, 60.0])
    assert out.shape == img.shape and (out != img).any()
    one = np.full((1, 1, 3), 9, np.uint8)
    assert _refr(1.0)(one, rng=np.random.default_rng(0)).shape == (1, 1, 3)


def test_severity_adds_drops_and_grows_them():
    h, w = 188, 336
    x, y, r, th, u = drop_layout(h, w, np.random.default_rng(0), 400, 0.05, 60.0)
    assert 0.3 * h * 0.05 < r.min() and r.max() < 2 * h * 0.05 and 15 <= th.min() and th.max() <= 90
    img = np.full((h, w, 3), 128, np.uint8)
    covered = []
    for k in (0.25, 0.5, 1.0):
        out = _refr(k)(img, rng=np.random.default_rng(3))
        covered.append(np.mean(np.abs(out.astype(int) - img).sum(axis=2) > 6))
    assert covered[0] < covered[1] < covered[2] and covered[2] > 0.15


def test_not_white_discs():
    img = np.full((188, 336, 3), 60, np.uint8)
    out = _refr(1.0)(img, rng=np.random.default_rng(1))
    assert out.max() < 255 and np.mean(out < 60) > 0.02  # darkened rims, no white fill


def test_persistent_drops_stay_and_wipe_clears_them(scene):
    img = scene[0]
    p = _refr(0.8, persistent=True, spawn_per_s=0.0)
    p.reset(2)
    a, b = p(img), p(img)
    assert (a != img).any()
    assert np.abs(a.astype(int) - b).mean() < 0.2 * np.abs(a.astype(int) - img).mean()  # the drops stay
    assert p.drops.shape[1] == 3 and 0.8 * p.drop_count <= len(p.drops) <= p.drop_count  # a few merged
    p.wipe()
    assert len(p.drops) == 0
    np.testing.assert_array_equal(p(img), img)


def test_persistent_drops_grow_merge_and_run_off(scene):
    img = scene[0][:94, :168].copy()
    p = _refr(1.0, persistent=True, growth_per_s=0.5, spawn_per_s=0.3, run_speed=1.0)
    p.reset(4)
    p(img)
    start = p.drops
    counts = []
    for _ in range(300):
        p(img)
        counts.append(len(p.drops))
    assert p.drops[:, 2].max() > start[:, 2].max()
    assert max(counts) <= 4 * p.drop_count + 16 and np.mean(counts[150:]) > 1


def test_persistent_drops_survive_a_ramp_and_a_mode_switch(scene):
    img = scene[0]
    ramp = Ramp("droplets", k_start=0.2, k_end=0.8, steps=10, persistent=True, mode="refractive")
    fixed = _refr(0.55, persistent=True)
    ramp.reset(3)
    fixed.reset(3)
    for _ in range(5):
        ramp(img)
        fixed(img)
    np.testing.assert_allclose(ramp.current.drops, fixed.drops)
    study = fixed.with_params(mode="faithful")
    study(img)  # the study's layout starts again, and back
    back = study.with_params(mode="refractive")
    assert back(img).shape == img.shape


@pytest.mark.parametrize(("param", "value"), [
    ("mode", "glass"), ("drop_count", 0), ("drop_count", 2.5), ("drop_radius", 0.5), ("contact_deg", 5.0),
    ("hfov_deg", 180.0), ("look_up", -0.1), ("defocus", 0.2), ("blur", 1.0), ("rim", 1.5),
    ("highlight", float("nan")),
])
def test_bad_parameters_name_the_parameter_value_and_range(param, value):
    with pytest.raises(ValueError, match=f"droplets: parameter {param}="):
        make("droplets", k=0.5, **{"mode": "refractive", param: value})
    with pytest.raises(ValueError, match=f"parameter {param}="):
        parse_weather(f"droplets:0.5:mode=refractive:{param}={value}" if param != "mode"
                      else f"droplets:0.5:mode={value}")


def _per_drop_opencv(img, x, y, r, theta, *, hfov_deg=90.0, look_up=0.3, defocus=0.006, blur=0.02, rim=0.6,
                     highlight=0.5):
    """The renderer as OpenCV calls drop by drop: remap, multiply, add, resize, multiply, add."""
    out = img.copy()
    h, w = img.shape[:2]
    small, sx, sy = _small_copy(img, blur * h)
    fx = round(0.5 * w / math.tan(math.radians(hfov_deg) / 2), 1)
    edge = round(defocus * h, 2)
    for rad, t, cx, cy in zip(np.maximum(np.rint(r), 1).astype(int).tolist(),
                              np.minimum(_THETA_BIN * np.rint(np.asarray(theta) / _THETA_BIN), 90.0).tolist(),
                              np.rint(x).astype(int).tolist(), np.rint(y).astype(int).tolist(), strict=True):
        pad, mxy, mf, gain, add, keep, _ = _drop_maps(rad, t, fx, look_up, edge, rim, highlight, round(sx, 6), round(sy, 6))
        half, n = rad + pad, rad + pad + 1
        x0, y0, x1, y1 = max(cx - half, 0), max(cy - half, 0), min(cx + half + 1, w), min(cy + half + 1, h)
        if x0 >= x1 or y0 >= y1:
            continue
        dx, dy = round((cx + 0.5) / sx - 0.5), round((cy + 0.5) / sy - 0.5)
        src = cv2.remap(small, cv2.add(mxy.reshape(n, n, 2), (dx, dy, 0.0, 0.0)), mf.reshape(n, n), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
        src = cv2.add(cv2.multiply(src, gain.reshape(n, n, 3), scale=1.0 / 255.0), add.reshape(n, n, 3))
        src = cv2.resize(src, (2 * half + 1, 2 * half + 1), interpolation=cv2.INTER_LINEAR)
        sl = (slice(y0 - cy + half, y1 - cy + half), slice(x0 - cx + half, x1 - cx + half))
        roi = out[y0:y1, x0:x1]
        cv2.multiply(roi, keep[sl], dst=roi, scale=1.0 / 255.0)
        cv2.add(roi, src[sl], dst=roi)
    return out


@pytest.mark.parametrize(("h", "w", "count", "kw"), [
    (188, 336, 60, {}),
    (120, 90, 30, {"contact_deg": 90.0, "defocus": 0.0, "blur": 0.0}),
    (100, 160, 12, {"drop_radius": 0.2, "contact_deg": 20.0, "defocus": 0.05, "blur": 0.1, "highlight": 1.0}),
    (9, 13, 5, {}),
    (188, 336, 40, {"hfov_deg": 20.0, "look_up": 1.0, "drop_radius": 0.25}),  # samples far outside the frame
])
def test_drops_computed_together_equal_opencv_drop_by_drop(scene, h, w, count, kw):
    """All drops' contents made in one remap (from a copy padded out to where they sample), multiply
    and add equal each drop's own calls: overlapping drops, drops over the border, samples further
    out than the pad, every option, a tiny frame, a strided input."""
    img = cv2.resize(scene[0], (w, h), interpolation=cv2.INTER_AREA)
    geo = {key: kw.pop(key) for key in ("drop_radius", "contact_deg") if key in kw}
    x, y, r, th, _ = drop_layout(h, w, np.random.default_rng(h), count, geo.get("drop_radius", 0.055),
                                 geo.get("contact_deg", 60.0))
    x, y = x * 1.2 - 0.1 * w, y * 1.2 - 0.1 * h  # some drops partly or wholly off the frame
    want = _per_drop_opencv(img, x, y, r, th, **kw)
    np.testing.assert_array_equal(render_lens_drops(img, x, y, r, th, **kw), want)
    np.testing.assert_array_equal(render_lens_drops(img[:, ::-1][:, ::-1], x, y, r, th, **kw), want)  # a strided view
