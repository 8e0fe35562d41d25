"""``weather-gym detector predict``: the picture, the COCO results JSON, or both."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from pycocotools.coco import COCO

from weather_gym import make_env
from weather_gym.cli import main
from weather_gym.perception import load_detector


@pytest.fixture(scope="module")
def frame_png(tmp_path_factory):
    env = make_env(track="small_track", perception="camera")
    try:
        obs, _ = env.reset(seed=3)
    finally:
        env.close()
    rgb = obs["image"]
    path = tmp_path_factory.mktemp("predict") / "frame.png"
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path, rgb


def test_json_holds_the_detections_as_coco_results(frame_png, tmp_path, capsys):
    path, rgb = frame_png
    out = tmp_path / "dets.json"
    assert main(["detector", "predict", str(path), "--json", str(out), "--image-id", "42"]) == 0
    results = json.loads(out.read_text())
    expected = load_detector()(rgb)
    assert len(results) == len(expected) > 0
    assert {r["image_id"] for r in results} == {42}
    assert [r["category_id"] for r in results] == [int(c) + 1 for c in expected.classes]
    np.testing.assert_allclose([r["bbox"][:2] for r in results], expected.boxes[:, :2], rtol=1e-5)
    # pycocotools reads it as detections of the image
    gt = COCO()
    gt.dataset = {"images": [{"id": 42, "width": rgb.shape[1], "height": rgb.shape[0]}], "annotations": [],
                  "categories": [{"id": i} for i in range(1, 5)]}
    gt.createIndex()
    assert len(gt.loadRes(str(out)).getAnnIds(imgIds=[42])) == len(results)
    assert f"{len(results)} cones -> {out}" in capsys.readouterr().out


def test_it_needs_an_output_and_two_different_ones(frame_png, tmp_path, capsys):
    path, _ = frame_png
    assert main(["detector", "predict", str(path)]) == 2
    assert "give at least one" in capsys.readouterr().err
    assert main(["detector", "predict", str(path), "--json", str(tmp_path / "a.png")]) == 2
    assert "--json" in capsys.readouterr().err
