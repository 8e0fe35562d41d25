"""Unpaired mode: no car poses (a real recording of the same track) -> distributions over the sets."""

from __future__ import annotations

import pytest
from gap_cases import FAST

from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow


def test_without_poses_runs_unpaired_and_still_names_a_strong_effect(make_measured, gap_cache, tmp_path):
    measured = make_measured("unpaired_jpeg", [{"name": "jpeg", "k": 0.8}], strip_poses=True)
    report = run_gap(measured, None, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["mode"] == "unpaired"
    assert "pose" in report["mode_reason"]
    assert report["frames"]["simulated"] == report["frames"]["measured"]
    assert report["missing_effects"] == ["jpeg"]
    assert report["gap_after"] <= 0.5 * report["gap_before"]


def test_paired_mode_without_poses_is_a_clear_error(make_measured, gap_cache, tmp_path):
    measured = make_measured("unpaired_jpeg", [{"name": "jpeg", "k": 0.8}], strip_poses=True)
    with pytest.raises(ValueError, match="paired mode needs 'track' and 'pose'"):
        run_gap(measured, None, tmp_path / "out", GapConfig(mode="paired", **FAST), cache_dir=gap_cache)
