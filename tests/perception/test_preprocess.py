"""Letterboxing and decoding of the detector's output (numpy only)."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.perception.preprocess import PAD_VALUE, decode, letterbox, letterbox_params


@pytest.mark.parametrize("size", [(672, 376), (1280, 720), (400, 400), (100, 300)])
def test_letterbox_round_trip_maps_boxes_back(size):
    w, h = size
    img = np.zeros((h, w, 3), np.uint8)
    x, lb = letterbox(img, (512, 288))
    assert x.shape == (288, 512, 3)
    box = np.array([[w * 0.25, h * 0.5, w * 0.5, h * 0.75]])
    inp = box * lb.scale + np.array([lb.pad[0], lb.pad[1], lb.pad[0], lb.pad[1]])
    np.testing.assert_allclose(lb.to_original(inp), box, atol=1e-6)


def test_letterbox_pads_with_grey_and_centres():
    img = np.full((100, 300, 3), 7, np.uint8)
    x, lb = letterbox(img, (512, 288))
    assert lb.pad[0] == 0 and lb.pad[1] > 0
    assert (x[0] == PAD_VALUE).all() and (x[lb.pad[1] + 1, 10] == 7).all()
    assert letterbox_params(300, 100, (512, 288)) == lb


def test_decode_places_a_peak_at_its_box_and_respects_threshold():
    out = np.zeros((1, 8, 72, 128), np.float32)
    out[0, 1, 30, 40] = 0.9  # class yellow, cell (x=40, y=30)
    out[0, 4, 30, 40], out[0, 5, 30, 40] = 20.0, 32.0  # w, h input px
    out[0, 6, 30, 40], out[0, 7, 30, 40] = 0.5, 0.25
    out[0, 0, 10, 10] = 0.2  # below threshold
    (boxes, scores, classes), = decode(out, 4, 4, 0.3)
    assert classes.tolist() == [1] and scores.tolist() == pytest.approx([0.9])
    cx, cy = (40 + 0.5) * 4, (30 + 0.25) * 4
    np.testing.assert_allclose(boxes[0], [cx - 10, cy - 16, cx + 10, cy + 16])
    assert len(decode(out, 4, 4, 0.1)[0][0]) == 2


def test_decode_nms_removes_a_cone_reported_under_two_classes():
    out = np.zeros((1, 8, 72, 128), np.float32)
    for c, s in ((1, 0.9), (2, 0.5)):
        out[0, c, 30, 40] = s
    out[0, 4:6, 30, 40] = 20.0
    (boxes, scores, classes), = decode(out, 4, 4, 0.3, nms_iou=0.7)
    assert classes.tolist() == [1]
    assert len(decode(out, 4, 4, 0.3, nms_iou=None)[0][0]) == 2
