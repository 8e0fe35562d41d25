"""Reading measured levels (the study's Table 2 format) and picking the domain to calibrate against."""

from __future__ import annotations

import math

import pytest
from calib_study import STUDY_TABLE

from weather_gym.lab.calibration.measured import levels_by_condition, parse_measured_arg, read_measured_table


@pytest.fixture
def study_table(tmp_path):
    p = tmp_path / "table2.csv"
    p.write_text(STUDY_TABLE)
    return p


def test_reads_the_study_table(study_table):
    levels = read_measured_table(study_table)
    assert len(levels) == 10
    by, ideal, domain = levels_by_condition(levels)
    assert domain == "real" and ideal.map == 0.793
    assert sorted(by) == ["droplets", "low_light"]
    assert by["low_light"][2].relative == 0.344 and by["low_light"][2].description == "Sunset"
    assert by["droplets"][1].relative == 1.004  # above ideal: real very light droplets did not hurt


def test_relative_is_derived_from_the_ideal_of_the_same_domain(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("condition,domain,severity,map\nideal,a,0,0.8\ndim,a,2,0.4\nideal,b,0,0.5\ndroplets,b,3,0.45\n")
    levels = {(m.condition, m.domain): m for m in read_measured_table(p)}
    assert levels["low_light", "a"].relative == pytest.approx(0.5)  # 'dim' is an alias of low_light
    assert levels["droplets", "b"].relative == pytest.approx(0.9)
    with pytest.raises(ValueError, match="several domains.*--domain"):
        levels_by_condition(list(levels.values()))
    by, ideal, _ = levels_by_condition(list(levels.values()), domain="b")
    assert list(by) == ["droplets"] and ideal.map == 0.5


def test_relative_matching_without_an_ideal_is_refused(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("condition,severity,map\ndroplets,3,0.45\n")
    levels = read_measured_table(p)
    assert math.isnan(levels[0].relative)
    with pytest.raises(ValueError, match="no relative value.*ideal row"):
        levels_by_condition(levels, match="relative")
    by, _, _ = levels_by_condition(levels, match="absolute")
    assert by["droplets"][3].map == 0.45


@pytest.mark.parametrize("body, match", [
    ("condition,map\ndroplets,0.5\n", r"lacks column\(s\) severity"),
    ("condition,severity\ndroplets,2\n", "map or relative_to_ideal"),
    ("condition,severity,map\nsnow,2,0.5\n", "unknown condition 'snow'; valid: ideal, droplets, low_light"),
    ("condition,severity,map\ndroplets,7,0.5\n", "severity 7 is outside 0-4"),
    ("condition,severity,map\ndroplets,two,0.5\n", "severity must be an integer"),
    ("condition,severity,map\ndroplets,2,1.3\n", r"data row 1: map = 1.3 is outside \[0, 1\]"),
    ("condition,severity,map\ndroplets,2,high\n", "'map' must be a number, got 'high'"),
    ("condition,severity,map\ndroplets,2,\n", "neither map nor relative_to_ideal"),
    ("condition,severity,map\nideal,2,0.8\n", "must have severity 0"),
    ("condition,severity,map\ndroplets,2,0.5\ndroplets,2,0.4\n", "already given in data row 1"),
    ("condition,severity,map,relative_to_ideal\nideal,0,0.8,\ndroplets,2,0.4,0.9\n", "disagrees with map / ideal"),
])
def test_bad_tables_get_errors_naming_file_row_and_value(tmp_path, body, match):
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(ValueError, match=match) as exc:
        read_measured_table(p)
    assert "bad.csv" in str(exc.value)


def test_measured_arguments(tmp_path, study_table):
    assert parse_measured_arg(str(study_table)) == ("table", study_table)
    (tmp_path / "set").mkdir()
    assert parse_measured_arg(f"droplets@3={tmp_path / 'set'}") == ("dataset", ("droplets", 3, tmp_path / "set"))
    assert parse_measured_arg(f"ideal={tmp_path / 'set'}")[1][:2] == ("ideal", 0)
    assert parse_measured_arg(str(tmp_path / "set")) == ("dataset", (None, None, tmp_path / "set"))
    with pytest.raises(FileNotFoundError, match="no such file or folder"):
        parse_measured_arg(str(tmp_path / "nope.csv"))
    with pytest.raises(ValueError, match="CONDITION@SEVERITY=DIR"):
        parse_measured_arg("droplets=somewhere")
