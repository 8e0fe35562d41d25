"""Rendered evaluation sets for the calibration tests (rendered once per session, fixed seeds).

``CALIB_SET`` is the recipe of the calibration evaluation set (docs/calibration.md): four tracks (peanut
and two generated tracks held out from the detector's training, and fsds_training), default
bright-overcast look. Rendering is repeatable; the 40 frames here (10 per track) are a smaller render
of the same recipe as the 240-frame set the shipped presets were calibrated on.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

CALIB_SET = {"tracks": ["peanut", "random:80", "random:81", "fsds_training"], "seed": 606, "frames_per_episode": 10}


def subset_coco(src: Path, dst: Path, n: int) -> Path:
    """The first ``n`` frames of a COCO folder (images, depth, annotations) copied to ``dst``."""
    data = json.loads((src / "annotations.json").read_text())
    images = data["images"][:n]
    ids = {im["id"] for im in images}
    for sub in ("images", "depth"):
        (dst / sub).mkdir(parents=True, exist_ok=True)
    for im in images:
        shutil.copy(src / im["file_name"], dst / im["file_name"])
        if im.get("depth_file"):
            shutil.copy(src / im["depth_file"], dst / im["depth_file"])
    data["images"] = images
    data["annotations"] = [a for a in data["annotations"] if a["image_id"] in ids]
    (dst / "annotations.json").write_text(json.dumps(data))
    return dst


@pytest.fixture(scope="session")
def calib_set_40(tmp_path_factory) -> Path:
    """The first 40 frames of the calibration evaluation set."""
    from weather_gym.lab.datasets.render import render_dataset

    out = tmp_path_factory.mktemp("calib") / "eval40"
    render_dataset(out, frames=40, progress=False, **CALIB_SET)
    return out


@pytest.fixture(scope="session")
def calib_set_8(calib_set_40, tmp_path_factory) -> Path:
    """Its first 8 frames (fast end-to-end runs of the commands)."""
    return subset_coco(calib_set_40, tmp_path_factory.mktemp("calib8") / "eval8", 8)
