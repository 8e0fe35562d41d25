"""Difference in differences with the simulator, on real-looking sets of another domain.

(c) domain-only control: the clear sets of another look, camera, over-exposure and an ego-vehicle
overlay, compared with the clean simulator: nothing is named as weather, the domain differences are
listed (with a clear reference: did mode; without: confounded). (d) the same domain plus a hidden
effect, with its clear reference: the effect is named.
"""

from __future__ import annotations

import pytest
from gap_cases import FAST, MEASURED_SEED

from weather_gym.camera.isp import CameraModel
from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow

# the "real-looking" domain is made from the plain world and the ideal camera (its records are stripped),
# so the simulator renders that world through that camera
DID = dict(mode="did", tracks=("small_track",), perception=False, scene="plain", camera_model=CameraModel.ideal(),
           **FAST)


def test_c_domain_only_names_nothing_and_lists_the_domain(shifted, gap_cache, tmp_path):
    report = run_gap(shifted["clear_b"], None, tmp_path / "did", GapConfig(**DID), reference=shifted["clear_a"],
                     cache_dir=gap_cache, plots=False)
    assert report["mode"] == "did" and "difference-in-differences" in report["mode_reason"]
    assert report["missing_effects"] == [], report["log"]
    names = [d["name"] for d in report["domain"]["differences"]]
    assert {"exposure", "ego vehicle"} <= set(names), names
    assert report["domain"]["compared"] == "clean simulator frames against the measured clear reference"


def test_c_without_a_reference_the_domain_is_confounded(shifted, gap_cache, tmp_path):
    report = run_gap(shifted["clear_b"], None, tmp_path / "conf",
                     GapConfig(tracks=("small_track",), perception=False, scene="plain",
                               camera_model=CameraModel.ideal(), **FAST), cache_dir=gap_cache, plots=False)
    assert report["confounded"] and report["missing_effects"] == [] and not report["steps"]
    assert report["verdict"].startswith("confounded")
    assert "exposure" in [d["name"] for d in report["domain"]["differences"]]


@pytest.mark.parametrize("name, params", [("noise", {"k": 0.5}), ("blur", {"k": 0.6})])
def test_d_domain_plus_hidden_effect_names_the_effect(name, params, shifted, gap_cache, tmp_path):
    from weather_gym.lab.gap.synthetic import degrade_dataset

    adverse = tmp_path / "adverse"
    degrade_dataset(shifted["clear_a"], adverse, [{"name": name, **params}], seed=MEASURED_SEED)
    report = run_gap(adverse, None, tmp_path / "out", GapConfig(**DID), reference=shifted["clear_a"],
                     cache_dir=gap_cache, plots=False)
    assert report["missing_effects"] == [name], report["log"]
    assert report["gap_after"] < report["gap_before"]
    assert "exposure" in [d["name"] for d in report["domain"]["differences"]]  # reported, not fitted
