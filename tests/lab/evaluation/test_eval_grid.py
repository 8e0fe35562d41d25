"""The evaluation grid: cells from a config, validation before anything runs, map scoring, one real cell."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from weather_gym.lab.evaluation.evaluate import (
    CELL_KEY_FIELDS,
    METRICS,
    EvalCell,
    EvalConfig,
    make_cells,
    map_precision_recall,
    run_cell,
    stack_id,
)
from weather_gym.weather.presets import preset_spec


def test_cells_cover_the_grid_with_preset_weather():
    cfg = EvalConfig(agents=("gt_pure_pursuit",), effects=("droplets", "dim"), severities=(0, 2, 4),
                     seeds=(0, 1), tracks=("small_track", "peanut"))
    cells = make_cells(cfg)
    assert len(cells) == 1 * 2 * 2 * 3 * 2
    assert len(set(cells)) == len(cells)
    c = next(c for c in cells if (c.track, c.effect, c.severity, c.seed) == ("peanut", "dim", 4, 1))
    assert json.loads(c.weather) == preset_spec("low_light", 4)  # dim is an alias of low_light
    assert json.loads(next(c for c in cells if c.severity == 0).weather) == []
    assert CELL_KEY_FIELDS[:5] == ("agent", "effect", "severity", "seed", "track")


def test_other_presets_file_changes_the_cells(tmp_path):
    from weather_gym.weather.presets import DEFAULT_PRESETS

    (shipped,) = preset_spec("low_light", 4)
    line = f'{{ name = "dim", k = {shipped["k"]}'  # low_light@4's effect, however the writer lays out arrays
    assert DEFAULT_PRESETS.read_text().count(line) == 1
    custom = tmp_path / "presets.toml"
    custom.write_text(DEFAULT_PRESETS.read_text().replace(line, '{ name = "dim", k = 0.5'))
    base = EvalConfig(effects=("dim",), severities=(4,), seeds=(0,))
    a = make_cells(base)[0]
    b = make_cells(EvalConfig(effects=("dim",), severities=(4,), seeds=(0,), presets=str(custom)))[0]
    assert json.loads(a.weather) == [shipped]
    assert json.loads(b.weather) == [{**shipped, "k": 0.5}] and a.weather != b.weather


def test_stack_names_the_world_and_the_model_files(tmp_path):
    """A changed scenario default, detector or surrogate file gives other cells, so a resumed
    results file runs them again instead of mixing in rows of the old stack."""
    from weather_gym.perception.onnx_detector import DEFAULT_MODEL
    from weather_gym.surrogate.model import SHIPPED_MODEL

    base = {"effects": ("droplets",), "severities": (0,), "seeds": (0,)}
    plain = make_cells(EvalConfig(**base))[0]
    assert plain == make_cells(EvalConfig(**base))[0] and len(plain.stack) == 12
    realistic = make_cells(EvalConfig(**base, env_kwargs={"sim": {"scene": "realistic"}}))[0]
    assert realistic.stack != plain.stack
    other = tmp_path / "other.onnx"
    other.write_bytes(DEFAULT_MODEL.read_bytes() + b"\0")
    assert make_cells(EvalConfig(**base, perception_kwargs={"detector": str(other)}))[0].stack != plain.stack
    sur = make_cells(EvalConfig(**base, perception="surrogate"))[0]
    refit = tmp_path / "refit.npz"
    refit.write_bytes(SHIPPED_MODEL.read_bytes())
    assert make_cells(EvalConfig(**base, perception="surrogate", perception_kwargs={"model": str(refit)}))[0].stack \
        == sur.stack  # the same file's bytes, wherever it lies
    assert make_cells(EvalConfig(**{**base, "agents": ("gt_pure_pursuit", "ppo_cones")}))[0].stack \
        != make_cells(EvalConfig(**{**base, "agents": ("ppo_cones",)}))[0].stack  # the policy file counts
    policy = tmp_path / "policy.zip"
    policy.write_bytes(b"weights")
    sb3 = {**base, "agents": ("sb3",), "agent_kwargs": {"path": str(policy)}}
    without = stack_id(EvalConfig(**sb3), "sb3")
    policy.with_suffix(".json").write_text('{"cone_memory": false}')
    assert stack_id(EvalConfig(**sb3), "sb3") != without  # and the JSON the agent reads its settings from


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"agents": ("nope",)}, r"unknown agent 'nope'; valid names: .*gt_pure_pursuit.*mapper_pure_pursuit"),
        ({"effects": ("snow",)}, r"unknown weather condition 'snow'; valid conditions: droplets, low_light, blur"),
        ({"effects": ("dim", "low_light")}, "same condition twice"),
        ({"severities": (0, 5)}, r"invalid severity 5; valid severities: 0, 1, 2, 3, 4"),
        ({"severities": (-1,)}, "invalid severity -1"),
        ({"tracks": ()}, "list of tracks is empty"),
        ({"tracks": ("nowhere",)}, r"unknown track 'nowhere'; valid names"),
        ({"seeds": ()}, "list of seeds is empty"),
        ({"seeds": (0, 0)}, "seeds repeated: 0"),
        ({"perception": "sonar"}, r"unknown perception 'sonar'; valid: camera, detector, oracle, gt_cones"),
        ({"env_id": "CartPole-v1x"}, r"unknown env id 'CartPole-v1x'; weather-gym ids: .*WeatherGym/ConeTrack-v0"),
        ({"laps": 0}, "laps must be an integer >= 1"),
        ({"agent_kwargs": {"model": object()}}, "agent_kwargs must be JSON-serialisable"),
        ({"env_kwargs": {"track": "peanut"}}, "env_kwargs may not set track"),
    ],
)
def test_bad_config_is_refused_with_the_valid_choices(change, message):
    base = {"agents": ("gt_pure_pursuit",), "effects": ("dim",), "severities": (0,), "seeds": (0,)}
    with pytest.raises(ValueError, match=message):
        make_cells(EvalConfig(**{**base, **change}))


def test_map_precision_recall_counts_within_half_a_metre():
    true = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0], [15.0, 0.0]])
    mapped = np.array([[0.3, 0.3], [5.0, 0.49], [10.0, 0.51], [40.0, 40.0]])
    p, r = map_precision_recall(mapped, true)
    assert (p, r) == (0.5, 0.5)
    assert map_precision_recall(true, true) == (1.0, 1.0)
    p, r = map_precision_recall(np.zeros((0, 2)), true)
    assert math.isnan(p) and r == 0.0


@pytest.mark.slow
def test_one_real_cell_drives_and_reports_every_metric():
    cell = EvalCell(agent="gt_pure_pursuit", effect="dim", severity=2, seed=0, track="small_track",
                    env_id="WeatherGym/ConeTrackSmall-v0", perception="camera", max_steps=45,
                    weather=json.dumps(preset_spec("dim", 2)))
    m = run_cell(cell)
    assert set(m) == set(METRICS)
    assert m["steps"] == 45 and m["end_reason"] == "time_limit" and m["completed"] == 0
    assert 0.0 < m["progress"] < 0.2  # about 1.5 s of a 150 m lap
    assert m["cones_hit"] == 0 and m["off_track_events"] == 0 and m["cte_max_m"] < 0.5
    assert m["weather_latency_ms"] > 0 and m["detector_latency_ms"] == 0
    assert m["map_precision"] is None and m["det_map50"] is None  # no mapper, no detector
    again = run_cell(cell)  # same cell, same seed: same episode (only the timings differ)
    timing = ("weather_latency_ms", "detector_latency_ms", "added_latency_ms")
    assert {k: v for k, v in again.items() if k not in timing} == {k: v for k, v in m.items() if k not in timing}


def test_gt_cones_is_evaluated_in_clear_weather_only():
    assert len(make_cells(EvalConfig(perception="gt_cones", effects=("droplets",), severities=(0,), seeds=(0,)))) == 1
    with pytest.raises(ValueError, match="gt_cones renders no camera frame.*droplets@2"):
        make_cells(EvalConfig(perception="gt_cones", effects=("droplets",), severities=(0, 2), seeds=(0,)))
