"""The shipped model on a small fixed rendered set of a held-out track (peanut, never trained on).

The floor sits a little under the number measured on this exact set (see docs/model_card.md), so a
broken or badly retrained model fails here. The same frames in the shipped low-light presets (the
dimming calibrated for this detector) must score clearly lower, and under the study's droplets (k = 0.55)
lower: the detector is sensitive to weather, as a real one is.
"""

from __future__ import annotations

import pytest

from weather_gym.lab.datasets import load_coco, render_dataset
from weather_gym.perception import ConeDetector, score_dataset

pytestmark = pytest.mark.slow

# measured with v6 in the default world (plain, through the default camera model): 0.955; v5 0.951, v4 0.940, v3 0.929
# (through the study's ideal camera 0.935; v2 0.932, the first model 0.921; docs/model_card.md)
MAP50_FLOOR = 0.92
HELD_OUT = dict(tracks=["peanut"], frames=40, seed=2024, randomize=False, frames_per_episode=10, progress=False)
# a generated track used nowhere in training, without orange cones in these frames
NO_ORANGE = dict(HELD_OUT, tracks=["random:78"])
MAX_PHANTOM_ORANGE = 15  # v6: 6 orange or big orange boxes at the operating threshold in the 40 frames; v5: 46


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


def test_far_tiny_cones_are_not_reported_as_orange_start_line_cones(tmp_path, detector):
    # v5 was never told what a cone too small to be scored is *not*: it reported far blue and yellow cones as
    # big orange ones at scores up to 0.67. v6 trains with tiny cones as negatives for the other classes.
    render_dataset(tmp_path / "r78", **NO_ORANGE)
    ds = load_coco(tmp_path / "r78")
    phantoms = 0
    for i in range(len(ds)):
        assert not (ds.gt(i)["classes"] >= 2).any()  # no orange cone in the frame
        d = detector.detect(ds.image(i))
        phantoms += int((d.classes >= 2).sum())
    assert phantoms <= MAX_PHANTOM_ORANGE


def test_the_calibrated_low_light_presets_lower_map(held_out, detector):
    # the study's own point, dim k = 0.78, was calibrated for its detector: v4 lost 0.940 -> 0.902 there, v5
    # (trained 5x longer) only 0.951 -> 0.950, so the presets calibrated for v5 dim harder (docs/calibration.md);
    # v6 on these frames with the presets calibrated for it: 0.955, low_light@1 0.877, low_light@2 0.508
    clean = score_dataset(held_out, detector).map50
    s1 = score_dataset(held_out, detector, "low_light@1", seed=0).map50
    s2 = score_dataset(held_out, detector, "low_light@2", seed=0).map50
    assert s2 < s1 < clean - 0.03, (clean, s1, s2)


def test_droplets_at_the_study_point_lower_map(held_out, detector):
    clean = score_dataset(held_out, detector).map50
    drops = score_dataset(held_out, detector, "droplets:0.55", seed=0).map50
    assert drops < clean - 0.002  # v6: 0.955 -> 0.943; v5: 0.951 -> 0.939; v4: 0.940 -> 0.933; v3: 0.929 -> 0.915 (ideal camera 0.935 -> 0.932; realistic world 0.900 -> 0.887)
