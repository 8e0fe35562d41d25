"""Any weather spec as an Albumentations transform (``weather_gym.weather.augment.Weather``)."""

from __future__ import annotations

import numpy as np
import pytest

A = pytest.importorskip("albumentations")

from weather_gym.core.errors import InputError  # noqa: E402
from weather_gym.weather import parse_weather  # noqa: E402
from weather_gym.weather.augment import Weather  # noqa: E402


@pytest.fixture
def image():
    return np.random.default_rng(0).integers(0, 256, (96, 160, 3), dtype=np.uint8)


def test_same_seed_same_bytes_and_each_call_a_new_realisation(image):
    run = lambda seed: A.Compose([Weather("droplets@3")], seed=seed)  # noqa: E731
    a, b = run(5), run(5)
    first = [a(image=image)["image"] for _ in range(3)]
    assert all(np.array_equal(x, b(image=image)["image"]) for x in first)
    assert not np.array_equal(first[0], first[1])  # a new draw of the drops per call
    assert not np.array_equal(first[0], A.Compose([Weather("droplets@3")], seed=6)(image=image)["image"])


def test_it_applies_the_weather_effect_with_the_drawn_seed(image):
    t = Weather("low_light@2")
    out = t.apply(image, seed=11)
    assert np.array_equal(out, parse_weather("low_light@2").start(11)(image, rng=np.random.default_rng(11)))
    assert out.mean() < image.mean()  # darker
    assert Weather("clear").apply(image, seed=1).tobytes() == image.tobytes()


def test_probability_zero_leaves_the_image_and_serialisation_keeps_the_spec(image):
    assert np.array_equal(A.Compose([Weather("droplets@4", p=0.0)], seed=0)(image=image)["image"], image)
    d = A.to_dict(A.Compose([Weather("fog:0.4,dim:0.3", p=0.5)]))
    assert d["transform"]["transforms"][0]["weather"] == "fog:0.4,dim:0.3"


def test_bad_specs_and_images_are_typed_errors(image):
    with pytest.raises(InputError, match="nope"):
        Weather("nope@3")
    with pytest.raises(InputError, match=r"RGB uint8 images of shape \(H, W, 3\), got float32"):
        Weather("droplets@3").apply(image.astype(np.float32), seed=0)
    with pytest.raises(InputError, match=r"got uint8 \(96, 160\)"):
        Weather("droplets@3").apply(image[..., 0], seed=0)
