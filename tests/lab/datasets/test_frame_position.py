"""Where in the frame a set's cones are: the edge share and its line in ``weather-gym dataset info``."""

import numpy as np
import pytest

from weather_gym.cli import main
from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.coco_writer import CocoWriter
from weather_gym.lab.datasets.frame_position import EDGE_RADIUS, edge_radius, edge_share

W, H = 200, 100
BLUE, YELLOW, ORANGE = (CONE_CLASSES.index(c) for c in ("blue", "yellow", "orange"))


def _write(root, frames):
    with CocoWriter(root) as w:
        for boxes, classes in frames:
            w.add(np.zeros((H, W, 3), np.uint8), {"track": "demo"},
                  {"boxes": np.array(boxes, np.float64).reshape(-1, 4), "classes": np.array(classes)})
    return load_coco(root)


def test_radius_is_zero_at_the_centre_one_at_the_side_middles_and_beyond_in_the_corners():
    boxes = np.array([[90, 40, 20, 20], [180, 40, 20, 20], [0, 0, 20, 20]], np.float64)  # xywh
    r = edge_radius(boxes, W, H)
    assert r[0] == pytest.approx(0.0)
    assert r[1] == pytest.approx(0.9)
    assert r[2] > 1.2 > EDGE_RADIUS


def test_edge_share_counts_scored_blue_and_yellow_cones_only(tmp_path):
    centre, corner, side = [90, 30, 110, 70], [2, 2, 22, 42], [178, 30, 198, 70]
    tiny_corner = [180, 90, 182, 92]  # too small to be scored: flagged, not counted
    ds = _write(tmp_path / "ds", [
        ([centre, corner, side], [BLUE, YELLOW, ORANGE]),  # the orange cone is not a boundary cone
        ([centre, tiny_corner], [YELLOW, BLUE]),
    ])
    assert edge_share(ds) == (1, 3)
    assert edge_share(ds, classes=("blue", "yellow", "orange")) == (2, 4)
    assert edge_share(ds, radius=1.5) == (0, 3)
    assert edge_share(ds, scored=lambda a: True) == (2, 4)  # the caller's rule: the tiny corner cone counts


def test_dataset_info_prints_the_edge_share(tmp_path, capsys):
    _write(tmp_path / "ds", [([[90, 30, 110, 70], [2, 2, 22, 42]], [BLUE, YELLOW])])
    assert main(["dataset", "info", str(tmp_path / "ds")]) == 0
    out = capsys.readouterr().out
    assert "blue/yellow cones near the frame's edge (box centre beyond 0.8 of the half-diagonal): 1 of 2 (50.0 %" in out
