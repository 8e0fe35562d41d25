"""The camera model finishing stage: off is the identity, on is deterministic, boxes follow distortion."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.camera.isp import CameraModel, CameraPipeline
from weather_gym.core.errors import InputError


def _scene(h=120, w=200) -> np.ndarray:
    rng = np.random.default_rng(0)
    return (rng.random((h, w, 3)) * 200 + 20).astype(np.uint8)


def test_off_is_the_identity():
    img = _scene()
    for off in (CameraModel(enabled=False), CameraModel.ideal(), CameraModel.from_dict({"enabled": False})):
        out = CameraPipeline(off, 200, 120).apply(img, np.random.default_rng(0))
        assert out is img  # the ideal camera: untouched, not even copied


def test_the_default_camera_is_the_realistic_one_and_a_table_changes_only_what_it_names():
    assert CameraModel() == CameraModel.realistic() and CameraModel().enabled
    tweaked = CameraModel.from_dict({"jpeg_quality": 0})  # a scenario table / reset option naming one key
    assert tweaked == CameraModel.realistic().with_(jpeg_quality=0)
    assert not CameraModel.ideal().enabled and CameraModel.ideal().with_(enabled=True).k1 == 0.0


def test_on_is_deterministic_with_the_seed_and_changes_the_frame():
    img = _scene()
    model = CameraModel.realistic()
    a = CameraPipeline(model, 200, 120).apply(img, np.random.default_rng(5))
    b = CameraPipeline(model, 200, 120).apply(img, np.random.default_rng(5))
    c = CameraPipeline(model, 200, 120).apply(img, np.random.default_rng(6))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)  # the noise comes from the RNG
    assert a.shape == img.shape and a.dtype == np.uint8 and not np.array_equal(a, img)


def test_exposure_clips_highlights_and_underexposure_darkens():
    img = np.full((20, 30, 3), 200, np.uint8)
    bright = CameraPipeline(CameraModel.ideal().with_(enabled=True, exposure_ev=2.0), 30, 20).apply(img, np.random.default_rng(0))
    dark = CameraPipeline(CameraModel.ideal().with_(enabled=True, exposure_ev=-2.0), 30, 20).apply(img, np.random.default_rng(0))
    assert (bright == 255).all()
    assert dark.mean() < 150


def test_distorted_boxes_cover_the_distorted_object():
    h, w = 120, 200
    img = np.zeros((h, w, 3), np.uint8)
    box = np.array([[14.0, 10.0, 40.0, 50.0], [150.0, 70.0, 190.0, 112.0], [95.0, 50.0, 105.0, 70.0]], np.float32)
    for x0, y0, x1, y1 in box.astype(int):
        img[y0:y1, x0:x1] = 255
    pipe = CameraPipeline(CameraModel.ideal().with_(enabled=True, k1=-0.2, k2=0.02), w, h)
    out = pipe.apply(img, np.random.default_rng(0))
    got = pipe.distort_boxes(box)
    assert not np.allclose(got[:2], box[:2], atol=1.0)  # the corners moved a visible amount
    labels = (out[..., 0] > 127).astype(np.uint8)
    from scipy import ndimage

    lab, n = ndimage.label(labels)
    assert n == 3
    for sl in ndimage.find_objects(lab):
        measured = np.array([sl[1].start, sl[0].start, sl[1].stop, sl[0].stop], np.float32)
        err = np.abs(got - measured).max(axis=1).min()
        assert err <= 1.5, (measured, got)


@pytest.mark.parametrize("field, value", [("exposure_ev", 9.0), ("k1", float("nan")), ("jpeg_quality", 101),
                                          ("enabled", 1), ("white_balance", (1.0, 1.0))])
def test_bad_parameters_are_input_errors_naming_the_field(field, value):
    with pytest.raises(InputError, match=field):
        CameraModel(**{field: value})


def test_unknown_key_names_it():
    with pytest.raises(InputError, match="nosuch"):
        CameraModel.from_dict({"enabled": True, "nosuch": 1})


def test_sensor_noise_is_the_integer_formula_saturated_at_both_ends():
    """The noise stage is exactly clip(img + (sigma*8 * z*32) >> 8, 0, 255) in integers (OpenCV's
    saturating add does the clipping), also where the noise pushes past black or white."""
    import cv2

    img = _scene()
    img[:20], img[20:40] = 0, 255
    model = CameraModel.ideal().with_(enabled=True, read_noise=25.0, shot_noise=10.0)
    pipe = CameraPipeline(model, 200, 120)
    out = pipe.apply(img, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    pipe.reseed(rng)
    oy, ox = (int(v) for v in rng.integers(0, 64, 2))
    toned = cv2.LUT(img, pipe._lut)
    z = pipe._bank[oy:oy + 120, ox:ox + 200].astype(np.int32)
    sigma8 = cv2.LUT(toned, pipe._sigma8).astype(np.int32)
    want = np.clip(toned.astype(np.int32) + ((sigma8 * z) >> 8), 0, 255).astype(np.uint8)
    assert np.array_equal(out, want)
    assert (out[:20] == 0).any() and (out[:20] > 0).any() and (out[20:40] == 255).any() and (out[20:40] < 255).any()


def test_distorted_boxes_are_the_float32_bounds_of_the_edge_points_clipped_to_the_image():
    """distort_boxes writes its bounds straight into float32: the same bytes as the bounds of the
    distorted edge points, cast, then clipped (boxes inside, across and outside the image)."""
    from weather_gym.camera.isp import _EDGE_POINTS

    pipe = CameraPipeline(CameraModel(), 672, 376, fx=336.0)
    assert pipe.model.distorts
    rng = np.random.default_rng(4)
    xy = rng.uniform(-300, 900, (200, 2))
    boxes = np.vstack([np.hstack([xy, xy + rng.exponential(40, (200, 2))]), [[0, 0, 672, 376], [5, 5, 5, 5]]])
    boxes = boxes.astype(np.float32)
    pts = boxes.astype(np.float64) @ _EDGE_POINTS
    x, y = pipe._distort_xy(pts[:, :32], pts[:, 32:])
    want = np.stack([x.min(1), y.min(1), x.max(1), y.max(1)], 1).astype(np.float32)
    want[:, 0::2] = np.clip(want[:, 0::2], 0, 672)
    want[:, 1::2] = np.clip(want[:, 1::2], 0, 376)
    got = pipe.distort_boxes(boxes)
    assert got.dtype == np.float32 and got.shape == (202, 4) and got.tobytes() == want.tobytes()
    assert pipe.distort_boxes(np.zeros((0, 4))).shape == (0, 4)
