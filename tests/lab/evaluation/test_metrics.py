"""The metric registry: one entry per metric feeds the results, the lap summary, the report's table and plots."""

from __future__ import annotations

from weather_gym.lab.evaluation.metrics import (
    METRICS,
    DetectorScoring,
    Metric,
    lap_lines,
    plot_metrics,
    table_metrics,
)
from weather_gym.pipeline.modes import perception_mode

SMALL = "WeatherGym/ConeTrackSmall-v0"

TOY = Metric("mean_speed_mps", "distance driven along the centre line / simulated time (m/s)",
             lambda e: e.result.progress_m / e.result.sim_time_s, "mean speed (m/s)", "m/s", table=True, plot=True)


def test_the_report_columns_and_plots_come_from_the_registry():
    assert table_metrics() == ["completed", "progress", "lap_time_s", "cones_hit", "off_track_events", "cte_mean_m",
                               "cte_max_m", "map_precision", "map_recall", "det_map50", "added_latency_ms",
                               "cone_recall", "cone_precision"]
    assert set(plot_metrics()) == set(table_metrics()) - {"cte_max_m", "cone_precision"}
    assert all(m.doc and m.label for m in METRICS.values())


def test_the_detector_observer_scores_only_scored_modes_and_the_final_frame_on_request():
    import numpy as np

    gt = {"boxes": np.array([[10, 10, 30, 50.]]), "classes": np.array([1]), "ranges": np.array([6.0])}
    det = {"boxes": np.array([[11, 10, 30, 49.]]), "scores": np.array([0.9]), "classes": np.array([1])}
    info = {"gt": gt, "detections": det}
    for mode, final, frames in (("detector", False, 1), ("detector", True, 2), ("surrogate", True, 0)):
        obs = DetectorScoring(perception_mode(mode), final_frame=final)
        obs(0, None, info, False)
        obs(1, None, info, True)  # the last step's frame: seen, not acted on
        scores = obs.scores()
        assert (scores.n_images if scores else 0) == frames, (mode, final)


def test_a_metric_registered_in_one_place_reaches_results_lap_table_and_plot(monkeypatch, tmp_path):
    from weather_gym.cli.lap import format_result, run_laps
    from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells, run_cell
    from weather_gym.lab.evaluation.report import write_report

    monkeypatch.setitem(METRICS, TOY.name, TOY)
    cells = make_cells(EvalConfig(agents=("gt_pure_pursuit",), effects=("dim",), severities=(0,), seeds=(0, 1),
                                  perception="gt_cones", max_steps=60, env_id=SMALL))
    rows = []
    for c in cells:
        row = run_cell(c)
        assert 0 < row[TOY.name] < 30  # m/s on the small track
        rows.append({**c.__dict__, "status": "ok", "error": None, **row})
    text = write_report(rows, tmp_path).read_text()
    header = next(line for line in text.splitlines() if line.startswith("| agent"))
    assert TOY.name in header.split("|")[-2]  # the last column of the table
    assert (tmp_path / "plots" / f"{TOY.name}.png").read_bytes()[:4] == b"\x89PNG"
    assert f"- `{TOY.name}`: {TOY.doc}" in text

    result = run_laps(env_id=SMALL, agent="gt_pure_pursuit", perception="gt_cones", max_steps=60)
    assert f"mean speed (m/s): {result['metrics'][TOY.name]:.3f} m/s" in format_result(result)
    assert lap_lines(result["metrics"])[-1].startswith("mean speed (m/s):")
