"""The proof: measured data with one hidden effect; the workflow names it and the held-out gap shrinks."""

from __future__ import annotations

import math
import tomllib

import pytest
from gap_cases import FAST

from weather_gym.lab.gap.workflow import GapConfig, run_gap

pytestmark = pytest.mark.slow

# hidden effect -> parameters the workflow is not told (k and, where the effect has them, others)
HIDDEN = {
    "blur": {"k": 0.6, "max_radius_frac": 0.015},
    "noise": {"k": 0.35, "read_noise_e": 6.0},
    "exposure": {"k": 0.4, "gamma_error": 0.3, "flare": 0.05},
    "fog": {"k": 0.5, "airlight": 0.75},
    "vignette": {"k": 0.6, "exponent": 3.0},
    "jpeg": {"k": 0.7},
    "motion_blur": {"k": 0.8, "exposure_s": 0.05},
}


@pytest.mark.parametrize("name", sorted(HIDDEN))
def test_names_the_hidden_effect_and_halves_the_gap(name, make_measured, gap_cache, tmp_path):
    measured = make_measured(name, [{"name": name, **HIDDEN[name]}])
    report = run_gap(measured, None, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["mode"] == "paired"
    assert report["missing_effects"] == [name], report["log"]
    assert report["gap_after"] <= 0.5 * report["gap_before"]
    assert report["steps"][0]["evidence"]["fixed"], "the step must say which signals it fixed"
    # the perception level is reported, first in the list of disagreements
    assert math.isfinite(report["perception_gap_before"]) and math.isfinite(report["perception_gap_after"])
    assert report["disagreements"][0]["level"] == "perception"
    with open(tmp_path / "out" / "model.toml", "rb") as f:
        effects = tomllib.load(f)["effects"]
    assert [e["name"] for e in effects] == [name]


def test_inserts_into_a_non_empty_model(make_measured, gap_cache, tmp_path, write_model):
    """A model with one right effect and one missing: the right one stays, the missing one joins the chain."""
    measured = make_measured("dim_jpeg", [{"name": "dim", "k": 0.35}, {"name": "jpeg", "k": 0.75}])
    model = write_model('[[effects]]\nname = "dim"\nk = 0.35\n')
    report = run_gap(measured, model, tmp_path / "out", GapConfig(**FAST), cache_dir=gap_cache, plots=False)
    assert report["missing_effects"] == ["jpeg"]
    assert [e["name"] for e in report["model_effects"]] == ["dim", "jpeg"]
    assert report["model_effects"][0]["k"] == pytest.approx(0.35, abs=0.02)
    assert report["gap_after"] <= 0.5 * report["gap_before"]
