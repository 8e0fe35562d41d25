"""Compose and Ramp: order, seeding, time-varying k."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.weather import Compose, Ramp, make


def test_compose_applies_effects_in_order(scene):
    img = scene[0]
    a, b = make("dim", k=0.5), make("exposure", k=0.5, direction="over")
    np.testing.assert_array_equal(Compose([a, b])(img), b(a(img)))
    assert not np.array_equal(Compose([a, b])(img), Compose([b, a])(img))


def test_compose_reset_seeds_each_effect_differently(scene):
    img = scene[0]
    w = Compose([make("noise", k=1.0), make("noise", k=1.0)])
    w.reset(0)
    x = w(img)
    single = make("noise", k=1.0)
    single.reset(0)
    assert not np.array_equal(x, single(single(img)))  # the two get different children of the seed
    w.reset(0)
    np.testing.assert_array_equal(w(img), x)


def test_compose_rejects_non_effects():
    with pytest.raises(ValueError, match="item 1 must be a weather effect"):
        Compose([make("dim", k=0.1), "fog:0.2"])


def test_ramp_moves_k_then_holds(scene):
    img = scene[0]
    ramp = Ramp("dim", k_start=0.1, k_end=0.5, steps=4)
    ks = []
    for _ in range(6):
        out = ramp(img)
        ks.append(ramp.k)
        np.testing.assert_array_equal(out, make("dim", k=ramp.k)(img))
    assert ks == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5, 0.5])
    ramp.reset(0)
    ramp(img)
    assert ramp.k == 0.1 and ramp.step == 1


def test_ramp_on_a_batch_is_one_step_per_frame(scene):
    img = scene[0]
    ramp = Ramp("dim", 0.0, 0.9, steps=3)
    out = ramp(np.stack([img] * 4))
    loop = Ramp("dim", 0.0, 0.9, steps=3)
    for i in range(4):
        np.testing.assert_array_equal(out[i], loop(img))


def test_ramp_validation():
    with pytest.raises(ValueError, match="k_end=1.2 must be a number in"):
        Ramp("dim", 0.0, 1.2)
    with pytest.raises(ValueError, match="steps=0 must be an integer >= 1"):
        Ramp("dim", 0.0, 1.0, steps=0)
    with pytest.raises(ValueError, match="unknown weather effect"):
        Ramp("dusk", 0.0, 1.0)
    with pytest.raises(ValueError, match="unknown parameter"):
        Ramp("dim", 0.0, 1.0, radius=2)
    with pytest.raises(ValueError, match="not k"):
        Ramp("dim", k=0.3)


def test_ramp_batch_of_a_random_effect_equals_the_loop(scene):
    frames = np.stack([scene[0]] * 3)
    a, b = Ramp("noise", 0.2, 1.0, steps=2), Ramp("noise", 0.2, 1.0, steps=2)
    a.reset(4)
    b.reset(4)
    np.testing.assert_array_equal(a(frames), np.stack([b(f) for f in frames]))  # episode generators
    rng = np.random.default_rng(1)
    np.testing.assert_array_equal(a(frames, rng=np.random.default_rng(1)), np.stack([b(f, rng=rng) for f in frames]))
    assert a.step == b.step == 6
