"""The gap workflow on frames of the realistic world through its camera model.

Paired views re-render with their world, camera model and sensor noise (``render_view``), so clean data
shows no gap; a hidden study effect (lens droplets, dimming light) is named. Effects that act on the
sensor noise (fog, JPEG, noise itself) are tested on the noise-free plain world (test_gap_identify.py):
weather is applied to the finished frame, so fog also thins the camera's noise (docs/gap.md).
"""

from __future__ import annotations

import pytest
from gap_cases import FAST, MEASURED_SEED

from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow


def test_clean_realistic_frames_report_no_gap(realistic_clean_dir, gap_cache, tmp_path):
    report = run_gap(realistic_clean_dir, None, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["mode"] == "paired"
    assert report["gap_before"] == 0.0 and report["missing_effects"] == []
    assert not [d for d in report["disagreements"] if d["significant"]]


@pytest.mark.parametrize("hidden", [{"name": "droplets", "k": 0.6}, {"name": "dim", "k": 0.7}], ids=["droplets", "dim"])
def test_names_a_hidden_study_effect_in_realistic_frames(hidden, realistic_clean_dir, gap_cache, gap_root, tmp_path):
    from weather_gym.lab.gap.synthetic import degrade_dataset

    measured = gap_root / f"realistic_{hidden['name']}"
    degrade_dataset(realistic_clean_dir, measured, [hidden], seed=MEASURED_SEED)
    report = run_gap(measured, None, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["missing_effects"] == [hidden["name"]], report["log"]
    assert report["gap_after"] <= 0.5 * report["gap_before"]
