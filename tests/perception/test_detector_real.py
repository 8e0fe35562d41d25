"""The shipped model on real Formula Student camera frames (FSKITTI Estoril, validation only).

The 23 frames are read in place from ``../shared/data/real/fskitti_estoril_autox2/`` (never copied
into the project; the test skips when they are absent), imported as a user would (``dataset import
kitti`` with the camera's intrinsics, 3D-only cones projected into ignore regions) with the proposed
ego-vehicle mask stored (``dataset mask``). The floor sits a little under the number measured in
docs/model_card.md, so a model that has not learned to find real cones (the first shipped model
scored 0.048 here) fails.
"""

from __future__ import annotations

import pytest

from weather_gym.lab.datasets import load_coco
from weather_gym.perception import ConeDetector, score_dataset

pytestmark = pytest.mark.slow  # the import and the mask proposal read 23 real frames

MAP50_BLUE_YELLOW_FLOOR = 0.85  # measured 0.883 with v6, 0.899 with v5, 0.819 with v4, 0.789 with v3 (docs/model_card.md, "Real camera frames")


def test_shipped_model_finds_real_cones_with_the_ego_vehicle_masked(real_dataset):
    ds = load_coco(real_dataset)
    assert ds.has_ignore_mask and len(ds) == 23
    r = score_dataset(ds, ConeDetector(threads=2))
    assert r.n_gt >= 150  # blue and yellow cones tall enough to score, outside the mask
    assert r.map50_blue_yellow >= MAP50_BLUE_YELLOW_FLOOR, r.table()
