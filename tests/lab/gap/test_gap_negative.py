"""Negative control: measured data made with exactly the model -> nothing is missing, nothing disagrees."""

from __future__ import annotations

import pytest
from gap_cases import FAST

from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow

MODEL = '[[effects]]\nname = "dim"\nk = 0.4\n\n[[effects]]\nname = "noise"\nk = 0.25\n'


def test_exact_model_reports_no_gap(make_measured, gap_cache, tmp_path, write_model):
    # the measured noise is another draw than the workflow's: only the distribution is the same
    measured = make_measured("exact", [{"name": "dim", "k": 0.4}, {"name": "noise", "k": 0.25}])
    report = run_gap(measured, write_model(MODEL), tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache,
                     plots=False)
    assert report["missing_effects"] == []
    assert report["steps"] == [] and report["refits"] == []
    assert not [d["signal"] for d in report["disagreements"] if d["significant"]]
    assert report["model_effects"] == [{"name": "dim", "k": 0.4}, {"name": "noise", "k": 0.25}]
    assert report["gap_after"] == report["gap_before"]


def test_clean_data_and_clean_model_report_no_gap(clean_dir, gap_cache, tmp_path):
    report = run_gap(clean_dir, None, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["missing_effects"] == [] and report["gap_before"] == 0.0
    assert report["perception_gap_before"] == 0.0
    assert not [d for d in report["disagreements"] if d["significant"]]
