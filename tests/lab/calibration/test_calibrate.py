"""Calibration against the study's table with synthetic curves, and the presets file it writes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from calib_study import STUDY_TABLE

from weather_gym.lab.calibration.calibrate import calibrate, fill_from_curves, parse_use, write_presets
from weather_gym.lab.calibration.curve import Curve
from weather_gym.lab.calibration.measured import read_measured_table
from weather_gym.weather.presets import load_presets, preset_entry, preset_spec

K = np.linspace(0.0, 1.0, 21)


def _curve(label, mean, spread=0.01, name=None, params=None):
    seeds = np.stack([mean + d for d in (-spread, 0.0, spread)], axis=1)
    return Curve(label, K.copy(), (0, 1, 2), np.clip(seeds, 0, 1), name=name or label, params=params or {},
                 dataset_id="d", model_id="m")


@pytest.fixture
def curves():
    return {
        "droplets": _curve("droplets", 0.7 - 0.35 * K),             # reaches relative 0.5 at k = 1
        "dim": _curve("dim", 0.7 * np.exp(-4.0 * K), spread=0.0),   # reaches 0.018 relative at k = 1
        "dim_physical": _curve("dim_physical", 0.7 * (1 - K ** 3), name="dim", params={"mode": "physical"}),
    }


@pytest.fixture
def levels(tmp_path):
    p = tmp_path / "table2.csv"
    p.write_text(STUDY_TABLE)
    return read_measured_table(p)


def test_relative_calibration_of_the_study_table(curves, levels):
    out = {(c.condition, c.severity): c for c in calibrate(curves, levels)}
    assert len(out) == 10  # severities 0-4 of both conditions
    s0 = out["droplets", 0]
    assert s0.effects == [] and s0.k == 0.0
    s4 = out["droplets", 4]  # 0.7 - 0.35 k = 0.74 * 0.7  ->  k = 0.52
    assert s4.reachable and s4.k == pytest.approx(0.52, abs=1e-3)
    assert s4.effects == [{"name": "droplets", "k": s4.k, "mode": "faithful"}]
    lo, hi = s4.k_interval
    assert lo < s4.k < hi
    assert s4.k_other == pytest.approx(0.323, abs=1e-3)  # absolute 0.587: 0.7 - 0.35 k = 0.587
    assert math.isnan(out["droplets", 2].k_other)  # absolute 0.763 lies above our clean 0.7: out of reach
    s1 = out["droplets", 1]  # 1.004 relative: above clean, reported
    assert not s1.reachable and s1.k == 0.0 and "above" in s1.note
    ll2 = out["low_light", 2]  # exp(-4k) = 0.344
    assert ll2.k == pytest.approx(-np.log(0.344) / 4, abs=0.01)
    assert ll2.effects[0] == {"name": "dim", "k": ll2.k, "mode": "faithful"}  # the mode is spelled out
    assert ll2.k_interval[0] == ll2.k_interval[1] == ll2.k  # deterministic curve: no seed spread
    ll4 = out["low_light", 4]  # 0.013 is below exp(-4) = 0.018: unreachable, k at the end, reported
    assert not ll4.reachable and ll4.k == 1.0 and "cannot bring" in ll4.note


def test_absolute_matching_and_physical_curve(curves, levels):
    out = {(c.condition, c.severity): c for c in
           calibrate(curves, levels, match="absolute", use=parse_use(["low_light=dim_physical"]))}
    d2 = out["droplets", 2]  # 0.763 is above our clean 0.7: unreachable in absolute terms
    assert not d2.reachable and d2.k == 0.0
    ll1 = out["low_light", 1]  # 0.7 (1 - k^3) = 0.639
    assert ll1.k == pytest.approx((1 - 0.639 / 0.7) ** (1 / 3), abs=0.01)
    assert ll1.effects[0]["mode"] == "physical" and ll1.curve == "dim_physical"


def test_calibrate_refuses_missing_curves_and_bad_use(curves, levels):
    with pytest.raises(ValueError, match="curve 'dim'.*hold: droplets"):
        calibrate({"droplets": curves["droplets"]}, levels)
    with pytest.raises(ValueError, match="unknown weather condition 'snow'"):
        parse_use(["snow=dim"])
    with pytest.raises(ValueError, match="CONDITION=CURVE_LABEL"):
        parse_use(["low_light"])
    with pytest.raises(ValueError, match="unknown match"):
        calibrate(curves, levels, match="sideways")


def test_written_presets_load_and_are_used_by_name(tmp_path, curves, levels):
    calibs = calibrate(curves, levels)
    fill_from_curves(calibs, curves)
    path = write_presets(calibs, tmp_path / "presets.toml", meta={"source": "test", "match": "relative"})
    data = load_presets(path)
    assert data["calibrated_conditions"] == ("droplets", "low_light") and data["source"] == "test"
    e = preset_entry("low_light", 4, path)
    assert e["reachable"] is False and "cannot bring" in e["note"]
    assert e["measured_relative"] == 0.013
    assert preset_spec("dim", 2, path)[0]["k"] == pytest.approx(-np.log(0.344) / 4, abs=0.01)
    assert preset_spec("droplets", 0, path) == []
    d4 = preset_entry("droplets", 4, path)
    assert d4["achieved_relative"] == pytest.approx(0.74, abs=0.01)  # interpolated from the curve here
    assert d4["k_interval"][0] < d4["effects"][0]["k"] < d4["k_interval"][1]
    from weather_gym.weather import parse_weather, to_spec

    assert to_spec(parse_weather(preset_spec("low_light", 3, path)))[0]["mode"] == "faithful"


def test_write_presets_never_overwrites_and_copies_uncalibrated_conditions(tmp_path, curves, levels):
    only_drops = [lv for lv in levels if lv.condition in ("ideal", "droplets")]
    calibs = calibrate(curves, only_drops)
    path = write_presets(calibs, tmp_path / "p.toml", meta={"source": "test"})
    data = load_presets(path)
    assert data["calibrated_conditions"] == ("droplets",)  # low_light came from the shipped table
    ll = preset_entry("low_light", 2, path)
    assert ll["calibrated"] is False and "not calibrated here" in ll["note"]
    assert preset_entry("droplets", 2, path)["calibrated"] is True
    rain, shipped_rain = preset_entry("rain", 3, path), preset_entry("rain", 3)
    assert rain == shipped_rain and rain["calibrated"] is False  # nominal rows are kept as they are
    with pytest.raises(FileExistsError, match="--overwrite"):
        write_presets(calibs, path, meta={})
    write_presets(calibs, path, meta={"source": "again"}, overwrite=True)
    assert load_presets(path)["source"] == "again"
