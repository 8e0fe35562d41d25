"""The shipped model on a small fixed rendered set of a held-out track (peanut, never trained on).

The floor sits a little under the number measured on this exact set (see docs/model_card.md), so a
broken or badly retrained model fails here. The same frames under the study's dimming (k = 0.78)
must score clearly lower: the detector is sensitive to weather, as a real one is.
"""

from __future__ import annotations

import pytest

from weather_gym.datasets import load_coco, render_dataset
from weather_gym.perception import ConeDetector, score_dataset

pytestmark = pytest.mark.slow

# measured with v4 in the default world (plain, through the default camera model): 0.940; v3 0.929 (through
# the study's ideal camera 0.935; v2 0.932, the first model 0.921; docs/model_card.md)
MAP50_FLOOR = 0.90
HELD_OUT = dict(tracks=["peanut"], frames=40, seed=2024, randomize=False, frames_per_episode=10, progress=False)


@pytest.fixture(scope="module")
def held_out(tmp_path_factory):
    root = tmp_path_factory.mktemp("held_out") / "peanut"
    render_dataset(root, **HELD_OUT)
    return load_coco(root, cache_images=True)


@pytest.fixture(scope="module")
def detector():
    return ConeDetector(threads=2)


def test_shipped_model_meets_the_map_floor_on_a_held_out_track(held_out, detector):
    assert "peanut" not in detector.meta["training"]["tracks"]  # held out
    r = score_dataset(held_out, detector)
    assert r.n_gt > 100
    assert r.map50 >= MAP50_FLOOR, r.table()
    assert r.recall_by_range["0-5 m"][0] > 0.9


def test_dimming_at_the_study_point_lowers_map(held_out, detector):
    clean = score_dataset(held_out, detector).map50
    dim = score_dataset(held_out, detector, "dim:0.78", seed=0).map50
    assert dim < clean - 0.03  # v4: 0.940 -> 0.902; v3: 0.929 -> 0.856 (ideal camera 0.935 -> 0.887; realistic world 0.900 -> 0.815)


def test_droplets_at_the_study_point_lower_map(held_out, detector):
    clean = score_dataset(held_out, detector).map50
    drops = score_dataset(held_out, detector, "droplets:0.55", seed=0).map50
    assert drops < clean - 0.002  # v4: 0.940 -> 0.933; v3: 0.929 -> 0.915 (ideal camera 0.935 -> 0.932; realistic world 0.900 -> 0.887)
