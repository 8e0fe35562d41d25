"""Detections -> cones: bearing from the pinhole model, range from depth or from the box height."""

from __future__ import annotations

import math

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import FIELD, unpack_cones
from weather_gym.perception.ranging import cones_to_observation, detections_to_cones, range_from_depth


def _det(boxes, classes, scores=None):
    boxes = np.array(boxes, float).reshape(-1, 4)
    return {"boxes": boxes, "classes": np.array(classes), "scores": np.array(scores or [0.9] * len(boxes))}


@pytest.mark.parametrize("dist", [3.0, 8.0, 15.0])
def test_range_from_box_height_matches_pinhole_geometry(dist):
    cam = CameraConfig()
    h = cam.fy * 0.325 / dist
    c = detections_to_cones(_det([[330, 180, 342, 180 + h]], [0]), cam)
    assert c["ranges"][0] == pytest.approx(dist, rel=1e-3)
    assert c["ranges_source"].tolist() == ["height"]
    big = detections_to_cones(_det([[330, 180, 342, 180 + cam.fy * 0.505 / dist]], [3]), cam)
    assert big["ranges"][0] == pytest.approx(dist, rel=1e-3)


def test_bearing_is_positive_left():
    cam = CameraConfig()
    c = detections_to_cones(_det([[0, 180, 20, 200], [652, 180, 672, 200]], [0, 1]), cam)
    assert c["bearings"][0] > 0 > c["bearings"][1]
    assert c["bearings"][0] == pytest.approx(math.atan2(cam.cx - 10, cam.fx))


def test_range_from_depth_uses_the_median_inside_the_box():
    cam = CameraConfig(pitch_deg=0.0)
    depth = np.full((cam.height, cam.width), cam.far, np.float32)
    depth[170:210, 320:352] = 6.0
    depth[172, 330] = 0.5  # a droplet-like outlier: the median ignores it
    c = detections_to_cones(_det([[320, 170, 352, 210]], [1]), cam, depth)
    assert c["ranges_source"].tolist() == ["depth"]
    assert c["ranges"][0] == pytest.approx(6.0 + 0.228 / 4, abs=0.02)


def test_a_low_depth_quantile_ranges_a_far_cone_whose_small_box_is_a_pixel_off():
    # a cone 22 m ahead is 4x6 px; the detector's box sits 2 px to its right, so half of the box's
    # central part is the ground 40 m behind it: the median ranges it 9 m long, the 0.25 quantile
    # finds the cone (the nearest surface there)
    cam = CameraConfig(pitch_deg=0.0)
    depth = np.full((cam.height, cam.width), 40.0, np.float32)
    depth[185:191, 330:334] = 22.0
    box = [[332, 185, 336, 191]]
    median = detections_to_cones(_det(box, [1]), cam, depth)["ranges"][0]
    low = detections_to_cones(_det(box, [1]), cam, depth, depth_quantile=0.25)["ranges"][0]
    assert median > 28.0
    assert low == pytest.approx(22.0 + 0.228 / 4, abs=0.1)
    assert range_from_depth(np.array(box, float), np.array([1]), depth, cam, quantile=0.25)[0] == pytest.approx(low)
    # on a box that covers its cone the two agree
    full = [[330, 185, 334, 191]]
    assert detections_to_cones(_det(full, [1]), cam, depth, depth_quantile=0.25)["ranges"][0] == pytest.approx(
        detections_to_cones(_det(full, [1]), cam, depth)["ranges"][0])


@pytest.mark.parametrize("q", [0, 0.0, -0.25, 1.5, float("nan"), True, "0.25", None])
def test_a_depth_quantile_outside_0_1_is_refused_by_name(q):
    cam = CameraConfig()
    with pytest.raises(InputError, match="depth_quantile"):
        detections_to_cones(_det([[330, 180, 342, 200]], [1]), cam, np.full((cam.height, cam.width), 9.0), depth_quantile=q)


def test_depth_without_valid_pixels_falls_back_to_height():
    cam = CameraConfig()
    depth = np.full((cam.height, cam.width), np.nan, np.float32)  # a stereo hole
    depth[:, :100] = 0.0  # and nothing valid nearer than the near plane
    c = detections_to_cones(_det([[330, 180, 342, 200], [10, 180, 22, 200]], [0, 1]), cam, depth)
    assert c["ranges_source"].tolist() == ["height", "height"] and np.isfinite(c["ranges"]).all()


def test_a_box_where_depth_sees_nothing_is_ranged_at_the_far_plane():
    # a false detection in the sky: the box height would put it a few metres ahead; the depth says
    # nothing is there, so its range is the far plane and the mapper's range gate drops it
    cam = CameraConfig()
    depth = np.full((cam.height, cam.width), cam.far, np.float32)
    depth[170:210, 320:352] = 6.0
    c = detections_to_cones(_det([[160, 40, 180, 70], [320, 170, 352, 210]], [0, 1]), cam, depth)
    assert c["ranges_source"].tolist() == ["far", "depth"]
    assert c["ranges"][0] == cam.far and c["ranges"][1] == pytest.approx(6.0, abs=0.1)


def test_no_detections_give_an_empty_cone_list():
    cam = CameraConfig()
    c = detections_to_cones(_det([], []), cam, np.zeros((cam.height, cam.width), np.float32))
    assert all(len(v) == 0 for v in c.values())
    cones, mask = cones_to_observation(c, cam, 16)
    assert cones.shape == (16, 14) and mask.sum() == 0 and not cones.any()


def test_packed_rows_carry_class_range_bearing_and_score():
    cam = CameraConfig()
    c = detections_to_cones(_det([[100, 190, 120, 220], [500, 185, 510, 200]], [1, 0], [0.7, 0.8]), cam)
    cones, mask = cones_to_observation(c, cam, 8)
    u = unpack_cones(cones, mask)
    assert mask.sum() == 2
    order = np.argsort(c["ranges"])
    assert u["classes"].tolist() == c["classes"][order].tolist()
    np.testing.assert_allclose(u["range"], c["ranges"][order], rtol=1e-6)
    assert cones[0, FIELD["size_px"]] == pytest.approx(c["boxes"][order[0], 3] - c["boxes"][order[0], 1])


def test_bad_classes_and_depth_shape_raise():
    cam = CameraConfig()
    with pytest.raises(ValueError, match="classes"):
        detections_to_cones(_det([[0, 0, 10, 10]], [7]), cam)
    with pytest.raises(ValueError, match="depth"):
        detections_to_cones(_det([[0, 0, 10, 10]], [0]), cam, np.zeros((3, 3, 3)))


def test_a_calibrated_stack_undoes_the_lens_before_bearing_and_range():
    """Through a distorting camera model a box lands elsewhere and bigger (barrel distortion, zoom);
    with the lens's inverse (``CameraPipeline.undistort_points``) the bearing and the box-height range
    are those of the pinhole box again, without it they are off."""
    from weather_gym.camera.isp import CameraModel, CameraPipeline

    cam = CameraConfig()
    pipe = CameraPipeline(CameraModel.realistic(), cam.width, cam.height, fx=cam.fx, cx=cam.cx, cy=cam.cy)
    dist = 6.0
    h = cam.fy * 0.325 / dist
    pinhole = np.array([[560.0, 200.0, 572.0, 200.0 + h]])  # a cone far right, where the lens bends most
    seen = pipe.distort_boxes(pinhole).astype(np.float64)
    truth = detections_to_cones(_det(pinhole, [0]), cam)
    fixed = detections_to_cones(_det(seen, [0]), cam, undistort=pipe.undistort_points)
    raw = detections_to_cones(_det(seen, [0]), cam)
    assert fixed["bearings"][0] == pytest.approx(truth["bearings"][0], abs=2e-3)
    assert fixed["ranges"][0] == pytest.approx(truth["ranges"][0], rel=0.02)
    assert abs(raw["bearings"][0] - truth["bearings"][0]) > 0.02
    assert abs(raw["ranges"][0] - truth["ranges"][0]) > 0.2  # 4 % off at 6.8 m
    np.testing.assert_array_equal(fixed["boxes"], seen)  # the boxes stay those of the image
