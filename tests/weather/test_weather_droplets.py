"""Droplets: faithful to the study's recipe (byte for byte), its disc statistics, persistence."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from weather_gym.weather import Ramp, make
from weather_gym.weather.reference import fog_layout, study_droplets, study_fog_positions


@settings(max_examples=15, deadline=None)
@given(h=st.integers(1, 200), w=st.integers(1, 260), k=st.floats(0.0, 1.0), seed=st.integers(0, 10**6),
       fog_coef=st.sampled_from([0.4, 0.2, 0.75]))
def test_identical_to_the_study_recipe_byte_for_byte(h, w, k, seed, fog_coef):
    img = np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)
    ours = make("droplets", k=k, fog_coef=fog_coef)(img, rng=np.random.default_rng(seed))
    study = study_droplets(img, k, np.random.default_rng(seed), fog_coef=fog_coef)
    np.testing.assert_array_equal(ours, study)


def test_identical_to_the_study_at_the_cameras_resolution(scene):
    img = np.ascontiguousarray(np.resize(scene[0], (376, 672, 3)))
    for seed in range(3):
        np.testing.assert_array_equal(make("droplets", k=0.55)(img, rng=np.random.default_rng(seed)),
                                      study_droplets(img, 0.55, np.random.default_rng(seed)))


def test_disc_statistics_of_the_study():
    hw, radius, centres = fog_layout(376, 672, 0.4, np.random.default_rng(0))
    assert (hw, radius, len(centres)) == (89, 44, 24)  # two rounds: 8 then 16 discs
    c = np.array(centres)
    first = c[:8]  # first round: a box of half-size (2 hw, hw) around the centre
    assert (np.abs(first[:, 0] - 336) <= 2 * 89).all() and (np.abs(first[:, 1] - 188) <= 89).all()
    hw, radius, centres = fog_layout(720, 1280, 0.4, np.random.default_rng(0))
    assert (hw, radius, len(centres)) == (170, 85, 51)


def test_coverage_is_densest_at_the_centre():
    rng = np.random.default_rng(1)
    counts = np.zeros((376, 672))
    for _ in range(40):
        _, r, centres = fog_layout(376, 672, 0.4, rng)
        for x, y in centres:
            yy, xx = np.ogrid[:376, :672]
            counts += (xx - x) ** 2 + (yy - y) ** 2 <= r * r
    centre, corner = counts[150:226, 270:402].mean(), counts[:76, :132].mean()
    assert centre > 3 * corner


def test_k_sets_the_opacity_of_each_droplet():
    img = np.zeros((376, 672, 3), np.uint8)
    for k in (0.25, 0.55, 1.0):
        out = make("droplets", k=k)(img, rng=np.random.default_rng(0))
        levels = np.unique(out)
        assert levels[0] == 0 and levels[1] == round(255 * 0.4 * k)  # one droplet over black


def test_tiny_images_terminate_and_get_no_droplets():
    # the original loops forever on this size (its box stops growing); ours stops
    assert study_fog_positions(9, 4, 0.4, np.random.default_rng(0)) == []
    img = np.full((9, 4, 3), 7, np.uint8)
    np.testing.assert_array_equal(make("droplets", k=1.0)(img), img)


def _persistent(**kw):
    return make("droplets", k=0.55, persistent=True, **kw)


def test_persistent_first_frame_is_the_study_layout(scene):
    img = scene[0]
    p = _persistent()
    p.reset(5)
    plain = make("droplets", k=0.55)
    plain.reset(5)
    np.testing.assert_array_equal(p(img), plain(img))


def test_persistent_droplets_stay_in_place_between_frames(scene):
    img = scene[0]
    p = _persistent()
    p.reset(2)
    frames, drops = [], []
    for _ in range(30):
        frames.append(p(img))
        drops.append(p.drops)
    moved = []
    for a, b in zip(drops, drops[1:], strict=False):
        d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]).min(axis=1)
        moved.append(np.mean(d < 1.0))
    assert np.mean(moved) > 0.9  # nearly every droplet is where it was a frame before
    step = np.mean([np.abs(a.astype(int) - b).mean() for a, b in zip(frames, frames[1:], strict=False)])
    plain = make("droplets", k=0.55)
    jumps = np.mean([np.abs(plain(img).astype(int) - plain(img)).mean() for _ in range(10)])
    assert step < 0.2 * jumps  # the non-persistent droplets jump around every frame


def test_wipe_clears_the_lens(scene):
    img = scene[0]
    p = _persistent(spawn_per_s=0.0)
    p.reset(0)
    for _ in range(5):
        wet = p(img)
    assert (wet != img).any() and len(p.drops) > 0
    p.wipe()
    assert len(p.drops) == 0
    np.testing.assert_array_equal(p(img), img)
    p.reset(0)  # a new episode draws the droplets again
    assert (p(img) != img).any()


def test_droplets_land_grow_merge_and_run_off(scene):
    img = scene[0][:120, :240].copy()
    p = _persistent(growth_per_s=0.5, spawn_per_s=0.3, run_speed=1.0)
    p.reset(4)
    p(img)
    start = p.drops
    counts = []
    for _ in range(600):
        p(img)
        counts.append(len(p.drops))
    assert p.drops[:, 2].max() > start[:, 2].max()  # grown / merged
    assert np.mean(counts[300:]) > 1 and max(counts) < 4 * len(start) + 16  # bounded: they run off
    p.wipe()
    for _ in range(60):
        p(img)
    assert 0 < len(p.drops)  # new droplets land after a wipe


def test_default_persistent_dynamics_keep_about_the_study_count(scene):
    img = scene[0][:94, :168].copy()
    run = _persistent().start(1)
    run(img)
    n0 = len(run.episode.drops.r)
    for _ in range(3000):  # 100 s at 30 fps: sampling moves the lens on, nothing is rendered
        run.sample(img.shape)
    assert 0.3 * n0 <= len(run.episode.drops.r) <= 3 * n0


def test_persistent_droplets_survive_a_ramp_of_k(scene):
    img = scene[0]
    ramp = Ramp("droplets", k_start=0.2, k_end=0.8, steps=10, persistent=True)
    fixed = _persistent()
    ramp.reset(3)
    fixed.reset(3)
    for _ in range(5):
        ramp(img)
        fixed(img)
    assert ramp.current.k > 0.2
    np.testing.assert_allclose(ramp.current.drops, fixed.drops)  # k changes, the droplets go on


def test_persistent_state_restarts_when_the_image_size_changes(scene):
    p = _persistent()
    p.reset(0)
    p(scene[0])
    n_big = len(p.drops)
    p(scene[0][:60, :100].copy())
    assert len(p.drops) != n_big or p.drops[:, 2].max() < 44


@pytest.mark.parametrize("k", [0.0, 0.55])
def test_persistent_time_goes_on_at_k_zero(scene, k):
    p = _persistent(growth_per_s=3.0)
    p.reset(0)
    p(scene[0])
    r0 = p.drops[:, 2].copy()
    q = p.with_params(k=k)
    q(scene[0])
    assert q.drops[:, 2].mean() > r0.mean()
