"""The study's low-light case: dimming plus what its dimming missed (sensor gain noise, blur)."""

from __future__ import annotations

import pytest
from gap_cases import FAST

from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow

MEASURED = [{"name": "blur", "k": 0.5}, {"name": "dim", "k": 0.55}, {"name": "noise", "k": 0.3}]


def test_refits_k_and_names_the_missing_effects(make_measured, gap_cache, tmp_path, write_model):
    measured = make_measured("low_light", MEASURED)
    model = write_model('[[effects]]\nname = "dim"\nk = 0.3\n')  # dimming alone, with a wrong k
    report = run_gap(measured, model, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert sorted(report["missing_effects"]) == ["blur", "noise"], report["log"]
    dim = next(e for e in report["model_effects"] if e["name"] == "dim")
    assert dim["k"] == pytest.approx(0.55, abs=0.03)
    assert any(r["name"] == "dim" and r["changed"]["k"][0] == 0.3 for r in report["refits"])
    assert report["gap_after"] <= 0.5 * report["gap_before"]
    assert report["perception_gap_after"] < report["perception_gap_before"]
    assert not [d for d in report["disagreements_after"] if d["significant"] and d["level"] == "image"]
