"""Curve inversion, k ranges, effect specs and curve-file reading (synthetic curves, no detector)."""

from __future__ import annotations

import numpy as np
import pytest

from weather_gym.lab.calibration.curve import invert, load_curves, monotone_decreasing
from weather_gym.lab.calibration.sweep import parse_effect, parse_k_range, parse_seeds

KS = np.linspace(0.0, 1.0, 11)


def test_invert_linear_curve_recovers_k_with_interval_from_seed_spread():
    mean = 0.8 - 0.5 * KS
    r = invert(KS, mean, 0.55, sd=np.full_like(KS, 0.02))
    assert r.reachable and r.note == ""
    assert r.k == pytest.approx(0.5)
    lo, hi = r.k_interval
    # band mean -/+ 0.02 meets the target 0.02/0.5 = 0.04 earlier/later in k
    assert lo == pytest.approx(0.46) and hi == pytest.approx(0.54)
    assert r.achieved == pytest.approx(0.55)


def test_deterministic_curve_gives_a_point_interval():
    r = invert(KS, 0.8 - 0.5 * KS, 0.6)
    assert r.k_interval == (pytest.approx(0.4), pytest.approx(0.4))


def test_target_above_the_curve_is_reported_not_clamped_silently():
    r = invert(KS, 0.8 - 0.5 * KS, 0.85, what="our mAP")
    assert not r.reachable
    assert r.k == 0.0
    assert "above" in r.note and "0.850" in r.note


def test_target_below_the_reach_of_the_effect_is_reported():
    r = invert(KS, 0.8 - 0.5 * KS, 0.01, what="our mAP")
    assert not r.reachable and r.k == 1.0
    assert "cannot bring our mAP down to 0.010" in r.note and "0.300" in r.note


def test_non_monotone_mean_is_monotonised_before_inversion():
    mean = np.array([0.70, 0.72, 0.74, 0.6, 0.3, 0.0])
    ks = np.linspace(0, 1, 6)
    mono = monotone_decreasing(mean)
    assert np.all(np.diff(mono) <= 1e-12)
    assert mono[:3] == pytest.approx([0.72, 0.72, 0.72])
    r = invert(ks, mean, 0.45)
    assert r.monotonised and r.reachable
    assert r.k == pytest.approx(0.7)  # halfway between k=0.6 (0.6) and k=0.8 (0.3)


def test_flat_stretch_gives_the_smallest_k_reaching_the_target():
    ks = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    r = invert(ks, np.array([1.0, 0.5, 0.5, 0.5, 0.0]), 0.5)
    assert r.k == 0.25


def test_invert_rejects_bad_curves():
    with pytest.raises(ValueError, match="increasing"):
        invert([0.0, 0.0], [1.0, 0.5], 0.7)
    with pytest.raises(ValueError, match="no value at k = 0.5"):
        invert([0.0, 0.5, 1.0], [1.0, np.nan, 0.0], 0.7)


def test_parse_k_range():
    ks = parse_k_range("0:1:0.05")
    assert len(ks) == 21 and ks[1] == 0.05 and ks[3] == 0.15 and ks[-1] == 1.0
    assert parse_k_range("0.5,0,1") == (0.0, 0.5, 1.0)
    assert parse_k_range("0.3") == (0.3,)


@pytest.mark.parametrize("text, match", [
    ("0:1", "three numbers"),
    ("0:a:0.1", "must be numbers"),
    ("0:1:0", "STEP must be > 0"),
    ("1:0:0.1", "below START"),
    ("0:1.5:0.5", r"outside|\[0, 1\]"),
    ("-0.1,0.5", r"\[0, 1\]"),
    ("0.2,x", "numbers separated by commas"),
    ("0.2,0.2", "repeated"),
    ("", "START:STOP:STEP"),
])
def test_parse_k_range_errors(text, match):
    with pytest.raises(ValueError, match=match):
        parse_k_range(text)


def test_parse_effect():
    e = parse_effect("dim:mode=physical")
    assert (e.label, e.name, e.params) == ("dim_physical", "dim", {"mode": "physical"})
    assert parse_effect("dim:mode=faithful") == parse_effect("dim")  # defaults are dropped: one curve
    # a choice is named by its value, any other parameter with its name: different effects, different curves
    assert parse_effect("dim:mode=physical,stops=10").label == "dim_physical_stops=10.0"
    assert {parse_effect("dim:mode=night,chroma_noise=0").label, parse_effect("dim:mode=night,desaturate=0").label} == {
        "dim_night_chroma_noise=0.0", "dim_night_desaturate=0.0"}
    assert parse_effect("droplets").table(0.4) == {"name": "droplets", "k": 0.4, "mode": "faithful"}
    with pytest.raises(ValueError, match="valid names: .*droplets"):
        parse_effect("snow")
    with pytest.raises(ValueError, match="give it with --k"):
        parse_effect("dim:k=0.5")
    with pytest.raises(ValueError, match="PARAM=VALUE"):
        parse_effect("dim:physical")
    with pytest.raises(ValueError, match="mode"):
        parse_effect("dim:mode=sideways")
    with pytest.raises(ValueError, match="unknown parameter"):
        parse_effect("dim:colour=2")


def test_parse_seeds():
    assert parse_seeds(3) == (0, 1, 2)
    assert parse_seeds(None, "4,7") == (4, 7)
    with pytest.raises(ValueError):
        parse_seeds(0)
    with pytest.raises(ValueError):
        parse_seeds(None, "1,1")


HEADER = "effect,spec,k,seed,dataset_id,model_id,status,error,elapsed_s,map50\n"


def _curve_file(tmp_path, body, header=HEADER):
    p = tmp_path / "curves.csv"
    p.write_text(header + body)
    return p


def test_load_curves_reads_seeds_and_skips_failed_rows(tmp_path):
    rows = []
    for k in (0.0, 0.5, 1.0):
        for s in (0, 1):
            rows.append(f"droplets,{{}},{k},{s},d1,m1,ok,,0.1,{0.8 - 0.4 * k + 0.01 * s}\n")
    rows.append("droplets,{},0.5,2,d1,m1,failed,boom,0.1,\n")
    c = load_curves(_curve_file(tmp_path, "".join(rows)))["droplets"]
    assert c.seeds == (0, 1)
    assert c.mean == pytest.approx([0.805, 0.605, 0.405])
    assert c.sd[0] == pytest.approx(np.std([0.8, 0.81], ddof=1))
    assert c.ideal == pytest.approx(0.805)
    assert c.name == "droplets" and c.model_id == "m1"


def test_load_curves_errors_name_file_column_and_value(tmp_path):
    with pytest.raises(FileNotFoundError, match="weather-gym sweep"):
        load_curves(tmp_path / "missing.csv")
    p = _curve_file(tmp_path, "droplets,0.0,0,0.8\n", header="effect,k,seed,map\n")
    with pytest.raises(ValueError, match=r"lacks column\(s\) map50"):
        load_curves(p)
    p = _curve_file(tmp_path, "droplets,{},1.5,0,d,m,ok,,0,0.5\n")
    with pytest.raises(ValueError, match=r"row 2: k = 1.5 is outside \[0, 1\]"):
        load_curves(p)
    p = _curve_file(tmp_path, "droplets,{},0.5,0,d,m,ok,,0,1.7\n")
    with pytest.raises(ValueError, match=r"map50 = 1.7 is outside \[0, 1\]"):
        load_curves(p)
    p = _curve_file(tmp_path, "droplets,{},0.5,0,d,m,ok,,0,abc\n")
    with pytest.raises(ValueError, match="'map50' must be a number, got 'abc'"):
        load_curves(p)
    p = _curve_file(tmp_path, "droplets,{},0.0,0,d,m1,ok,,0,0.7\ndroplets,{},0.5,0,d,m2,ok,,0,0.6\n")
    with pytest.raises(ValueError, match="mixes 2 values of model_id"):
        load_curves(p)
    assert load_curves(p, model_id="m2")["droplets"].ks.tolist() == [0.5]


def test_relative_curve_needs_k0(tmp_path):
    p = _curve_file(tmp_path, "dim,{},0.5,0,d,m,ok,,0,0.6\ndim,{},1.0,0,d,m,ok,,0,0.1\n")
    c = load_curves(p)["dim"]
    with pytest.raises(ValueError, match="no k = 0 row"):
        c.scaled(relative=True)
