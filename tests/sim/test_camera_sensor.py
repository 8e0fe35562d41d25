"""The camera sensor's per-frame array work gives exactly the straightforward formulas' bytes."""

from __future__ import annotations

import math

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.sim.camera_sensor import CameraSensor, depth_from_zbuffer
from weather_gym.sim.look import DEFAULT_LOOK
from weather_gym.sim.textures import sky_panorama


def test_depth_from_zbuffer_is_the_float32_formula():
    z = np.random.default_rng(0).random(5000, dtype=np.float32)
    z[:5], z[5:10] = 1.0, 0.0
    want = np.minimum(np.float32(80.0 * 0.1) / (np.float32(80.0) - np.float32(80.0 - 0.1) * z), np.float32(80.0))
    got = depth_from_zbuffer(z, near=0.1, far=80.0)
    assert got.dtype == np.float32 and np.array_equal(got, want)


def test_sky_fills_exactly_the_background_pixels_from_the_panorama():
    cam = CameraConfig(width=120, height=68)
    sensor = CameraSensor(cam, client=0, renderer=0)  # no PyBullet call before render()
    pano = sky_panorama(DEFAULT_LOOK)
    sensor.set_look(DEFAULT_LOOK, pano)
    rng = np.random.default_rng(1)
    for heading in (0.0, 2.5, -3.0):
        rgb = rng.integers(0, 256, (68, 120, 3), dtype=np.uint8)
        background = np.zeros((68, 120), bool)
        background[:30] = rng.random((30, 120)) < 0.7
        cols = np.round((heading + sensor._col_angles) / (2 * math.pi) * pano.shape[1]).astype(np.intp) % pano.shape[1]
        want = np.where(background[..., None], pano[sensor._sky_rows[:, None], cols[None, :]], rgb)
        sensor._composite_sky(rgb, background, heading)
        assert np.array_equal(rgb, want)


def test_cone_ground_truth_from_segmentation_is_the_whole_image_computation():
    """Boxes and pixel counts equal those found on the whole label image (the sensor searches only
    the band of rows with cone pixels)."""
    from scipy import ndimage

    rng = np.random.default_rng(2)
    n = 6
    cone_xy = rng.uniform(-10, 10, (n, 2))
    classes = rng.integers(0, 4, n)
    for _ in range(5):
        seg = np.full((50, 80), -1, np.int32)
        for i in rng.choice(n, 4, replace=False):
            y, x = rng.integers(0, 45), rng.integers(0, 75)
            seg[y:y + rng.integers(1, 6), x:x + rng.integers(1, 6)] = i
        gt = CameraSensor._ground_truth(seg, np.zeros(3), 0.3, cone_xy, classes)
        labels = seg + 1
        counts = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        visible = np.flatnonzero(counts)
        slices = ndimage.find_objects(labels, max_label=n)
        boxes = [[slices[i][1].start, slices[i][0].start, slices[i][1].stop, slices[i][0].stop] for i in visible]
        assert np.array_equal(gt["cone_ids"], visible) and np.array_equal(gt["pixels"], counts[visible])
        assert np.array_equal(gt["boxes"], np.array(boxes, np.float32))
    assert CameraSensor._ground_truth(np.full((5, 5), -1, np.int32), np.zeros(3), 0.0, cone_xy, classes).count == 0
