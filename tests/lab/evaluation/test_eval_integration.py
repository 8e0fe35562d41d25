"""The evaluation of the real stack: mapper metrics with oracle perception, and the detector grid."""

from __future__ import annotations

import pytest

from weather_gym.lab.evaluation.evaluate import EvalConfig, evaluate, make_cells, run_cell
from weather_gym.lab.evaluation.report import write_report
from weather_gym.perception.onnx_detector import DEFAULT_MODEL


@pytest.mark.slow
def test_mapper_with_oracle_perception_builds_an_accurate_map():
    # perfect odometry too: the map is in the odometry frame and is scored against the true cones, so
    # odometry drift (up to ~1 m after 200 steps on some seeds) would count as mapping error
    perfect = {"speed_scale_std": 0.0, "speed_noise_std": 0.0, "gyro_bias_std": 0.0, "gyro_noise_std": 0.0}
    cell = make_cells(EvalConfig(agents=("mapper_pure_pursuit",), effects=("dim",), severities=(0,), seeds=(0,),
                                 perception="oracle", max_steps=200, env_id="WeatherGym/ConeTrackSmall-v0",
                                 env_kwargs={"odometry": perfect}))[0]
    m = run_cell(cell)
    assert m["end_reason"] == "time_limit" and m["off_track_events"] == 0 and m["cones_hit"] == 0
    assert m["progress"] > 0.1  # it drives on what it maps
    assert m["map_cones"] >= 10 and m["map_precision"] > 0.9  # perfect perception: mapped cones are real
    assert 0.1 < m["map_recall"] < 1.0  # 200 steps see part of the lap
    assert m["det_map50"] is None and m["detector_latency_ms"] == 0


@pytest.mark.slow
def test_detector_cells_score_the_frames_the_agent_saw(tmp_path):
    """Plumbing with any ONNX model (an untrained one here): frames, mAP, latency reach the row."""
    torch = pytest.importorskip("torch")
    pytest.importorskip("onnx")
    from weather_gym.lab.training.detector.conenet import ConeNet
    from weather_gym.lab.training.detector.train import export_onnx

    torch.manual_seed(0)
    model = export_onnx(ConeNet(), tmp_path / "untrained.onnx", (320, 192))
    cell = make_cells(EvalConfig(agents=("mapper_pure_pursuit",), effects=("dim",), severities=(2,), seeds=(0,),
                                 perception="detector", max_steps=20, env_id="WeatherGym/ConeTrackSmall-v0",
                                 perception_kwargs={"detector": str(model), "score_threshold": 0.0}))[0]
    m = run_cell(cell)
    assert m["det_frames"] == m["steps"] == 20
    assert 0.0 <= m["det_map50"] <= 1.0 and 0.0 <= m["det_recall"] <= 1.0
    assert m["detector_latency_ms"] > 0
    assert m["added_latency_ms"] == pytest.approx(m["detector_latency_ms"] + m["weather_latency_ms"])


@pytest.mark.slow
@pytest.mark.skipif(not DEFAULT_MODEL.is_file(), reason=f"the shipped detector {DEFAULT_MODEL.name} is not trained yet")
def test_reduced_grid_with_the_detector_degrades_with_severity(tmp_path):
    config = EvalConfig(agents=("mapper_pure_pursuit",), effects=("droplets", "dim"), severities=(0, 4), seeds=(0,),
                        perception="detector", max_steps=150)
    rows = evaluate(config, tmp_path, workers=2, progress=False)
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows]
    by = {(r["effect"], r["severity"]): r for r in rows}
    for effect in ("droplets", "dim"):
        clear, worst = by[effect, 0], by[effect, 4]
        assert clear["det_frames"] == 150  # the frames the agent acted on and clear["detector_latency_ms"] > 0
        assert worst["det_map50"] < clear["det_map50"], effect
    write_report(rows, tmp_path, config=config)  # the report is the caller's (weather-gym evaluate writes it)
    assert (tmp_path / "plots" / "det_map50.png").exists()
