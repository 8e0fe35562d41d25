"""The validation report on a small case, and its statistics on known input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.lab.training.surrogate.validate import STAT_NAMES, miss_runs, validate


def test_miss_runs_counts_consecutive_misses_per_cone():
    ep = np.zeros(7, int)
    cone = np.array([1, 1, 1, 1, 2, 2, 2])
    frame = np.array([0, 1, 2, 4, 0, 1, 2])  # cone 1 is not visible on frame 3: a run ends there
    det = np.array([0, 0, 1, 0, 0, 0, 0], bool)
    assert miss_runs(ep, cone, frame, det).tolist() == [2, 1, 3]


def test_validate_writes_the_report(tmp_path):
    res = validate(track="hairpin", conditions=["droplets"], severities=[0, 2], seeds=[0, 1], surrogate_seeds=[0, 1],
                   steps=12, out=tmp_path / "val")
    text = (tmp_path / "val" / "report.md").read_text()
    assert "| clear |" in text and "| droplets@2 |" in text
    assert all((tmp_path / "val" / name).stat().st_size > 1000 for name in ("recall_by_range.png", "fp_and_runs.png"))
    data = json.loads((tmp_path / "val" / "validation.json").read_text())
    assert [r["weather"] for r in data["rows"]] == ["clear", "droplets@2"]
    assert set(res["rows"][0]["stats"]) == set(STAT_NAMES)
    assert (tmp_path / "val" / "full_logs" / "droplets_2.npz").is_file()  # recorded once, reused next time
    with pytest.raises(InputError, match="was used for fitting"):
        validate(track="small_track", severities=[0], out=tmp_path / "val2")


@pytest.mark.slow
def test_validate_at_another_camera_and_a_nominal_effect(tmp_path):
    res = validate(track="hairpin", weathers=["clear", "rain@2"], seeds=[0], surrogate_seeds=[0], steps=6,
                   camera=(336, 188), out=tmp_path / "val")
    text = (tmp_path / "val" / "report.md").read_text()
    assert "camera 336x188" in text and "| rain@2 |" in text
    assert "rain@2: perception surrogate: no fit of weather effect rain" in text  # the fallback, said
    assert res["camera"] == "336x188" and "fallback" in res["rows"][1] and "fallback" not in res["rows"][0]
    with pytest.raises(InputError, match="a log of a 336x188 camera, not 672x376"):
        validate(track="hairpin", weathers=["clear"], seeds=[0, 1], surrogate_seeds=[0], steps=8, camera=(672, 376),
                 full_logs=tmp_path / "val" / "full_logs", out=tmp_path / "val2")
