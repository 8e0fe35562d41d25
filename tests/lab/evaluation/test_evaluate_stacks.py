"""The evaluation over physical weather states, per stack: cells, a driven cell, the per-sensor report."""

from __future__ import annotations

import json

import pytest

from weather_gym.cli import build_parser
from weather_gym.core.errors import InputError, LimitError
from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells, run_cell
from weather_gym.lab.evaluation.sensors import carrier, write_sensor_report


def test_condition_cells_carry_the_state_for_every_stack():
    for mode in ("detector", "lidar", "fused"):
        cells = make_cells(EvalConfig(perception=mode, conditions=("clear", "fog:60m+rain:8mm/h"), seeds=(0,)))
        assert [(c.effect, c.severity, json.loads(c.weather)) for c in cells] == [
            ("clear", 0, {"conditions": "clear"}), ("fog:60m+rain:8mm/h", 0, {"conditions": "fog:60m+rain:8mm/h"})]
        assert {c.perception for c in cells} == {mode}


@pytest.mark.parametrize("kw, error, word", [
    ({"conditions": ("fog:5m",)}, LimitError, "5 m"),
    ({"conditions": ("rain:2mm/h", "rain:2mm/h")}, InputError, "repeated"),
    ({"conditions": ("rain:2mm/h",), "perception": "surrogate"}, InputError, "surrogate"),
    ({"conditions": ("rain:2mm/h",), "perception": "lidar", "perception_kwargs": {"lidar_weather": "fog@1"}},
     InputError, "lidar_weather"),
])
def test_condition_grids_refuse(kw, error, word):
    with pytest.raises(error, match=word):
        make_cells(EvalConfig(**{"seeds": (0,), **kw}))


def test_a_lidar_cell_in_rain_drives_on_a_wet_road_and_scores_its_cone_list():
    (cell,) = make_cells(EvalConfig(perception="lidar", conditions=("rain:8mm/h",), seeds=(0,), max_steps=45))
    row = run_cell(cell)
    assert row["steps"] == 45 and 0 < row["cone_recall"] <= 1 and row["cone_recall_0_5m"] is not None
    assert row["det_map50"] is None  # no camera in this stack


def test_the_sensor_report_names_the_carrier_per_weather(tmp_path):
    rows = [{"perception": p, "track": "peanut", "effect": e, "severity": 0, "seed": 0, "status": "ok",
             "completed": c, "cones_hit": 0, "lap_time_s": t, "progress": 1.0 if c else 0.1,
             "end_reason": "laps" if c else "off_track", "cone_recall": r, "cone_recall_0_5m": r}
            for e, p, c, t, r in (("clear", "detector", 1, 20.0, 0.8), ("clear", "lidar", 1, 21.0, 0.7),
                                  ("dusk:5lux", "detector", 0, None, 0.1), ("dusk:5lux", "lidar", 1, 21.0, 0.7))]
    assert carrier([r for r in rows if r["effect"] == "dusk:5lux"]) == "lidar"
    path = write_sensor_report(rows, tmp_path)
    text = path.read_text()
    assert "| clear " in text and "20.00 s, 0 hit, recall 0.80" in text and "off_track at 10 %" in text
    assert (tmp_path / "plots" / "sensors_recall_by_range.png").stat().st_size > 0
    with pytest.raises(Exception, match="exists"):
        write_sensor_report(rows, tmp_path)  # nothing someone wrote is replaced without overwrite


def test_cli_parses_stacks_and_conditions():
    args = build_parser().parse_args(["evaluate", "--stacks", "detector,lidar,fused", "--conditions",
                                      "clear,rain:8mm/h", "--out", "x"])
    assert (args.stacks, args.conditions) == ("detector,lidar,fused", "clear,rain:8mm/h")
