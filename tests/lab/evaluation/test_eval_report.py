"""The report: aggregated table (mean ± std over seeds) and metric-vs-severity plots."""

from __future__ import annotations

import math

import pytest

from weather_gym.lab.evaluation.report import aggregate, plot_metric, write_report


def _rows():
    rows = []
    for effect, slope in (("droplets", 0.1), ("dim", 0.2)):
        for sev in range(5):
            for seed in range(3):
                rows.append({"agent": "mapper_pure_pursuit", "track": "small_track", "effect": effect,
                             "severity": sev, "seed": seed, "status": "ok", "error": None,
                             "weather": "[]" if sev == 0 else f'[{{"k": {sev / 5}, "name": "{effect}"}}]',
                             "progress": 1.0 - slope * sev + 0.01 * seed, "det_map50": None,
                             "cones_hit": seed})
    rows.append({**rows[-1], "seed": 3, "status": "failed", "error": "RuntimeError: boom", "progress": None})
    return rows


def test_aggregate_mean_std_over_seeds_and_counts_failures():
    agg = aggregate(_rows(), ("effect", "severity"), ("progress", "det_map50"))
    assert len(agg) == 10
    dim4 = next(a for a in agg if (a["effect"], a["severity"]) == ("dim", 4))
    assert dim4["n"] == 3 and dim4["n_failed"] == 1
    assert dim4["progress_mean"] == pytest.approx(0.2 + 0.01)
    assert dim4["progress_std"] == pytest.approx(0.01)
    assert (dim4["progress_min"], dim4["progress_max"]) == pytest.approx((0.2, 0.22))
    assert math.isnan(dim4["det_map50_mean"]) and dim4["det_map50_count"] == 0


def test_report_has_table_plots_and_failed_cells(tmp_path):
    path = write_report(_rows(), tmp_path, command="weather-gym evaluate --out x")
    text = path.read_text()
    flat = " ".join(text.split())  # the Markdown tables' cells, without tabulate's column padding
    assert "weather-gym evaluate --out x" in text
    assert "| mapper_pure_pursuit | small_track | dim | 4 | 3/1 | 0.210 ± 0.010 |" in flat
    assert "det_map50" not in text.split("## Results")[1].split("\n")[2]  # no column without values
    assert "RuntimeError: boom" in text and "## Failed cells" in text
    assert "![progress](plots/progress.png)" in text
    png = tmp_path / "plots" / "progress.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (tmp_path / "plots" / "det_map50.png").exists()
    assert "| dim | 4 | `[{\"k\": 0.8, \"name\": \"dim\"}]` |" in flat


def test_plot_has_one_line_per_effect(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    captured = {}
    real_savefig = plt.Figure.savefig

    def spy(fig, *args, **kwargs):
        ax = fig.axes[0]
        captured["labels"] = [line.get_label() for line in ax.get_lines()]
        captured["ys"] = [list(line.get_ydata()) for line in ax.get_lines()]
        return real_savefig(fig, *args, **kwargs)

    plt.Figure.savefig = spy
    try:
        plot_metric(_rows(), "progress", tmp_path / "p.png")
    finally:
        plt.Figure.savefig = real_savefig
    assert captured["labels"] == ["droplets", "dim"]
    assert captured["ys"][1] == pytest.approx([1.01, 0.81, 0.61, 0.41, 0.21])


def test_a_baseline_agent_gives_ratios_cell_by_cell(tmp_path):
    rows = []
    for agent, time_s, hits in (("mapper_pure_pursuit", 20.0, 0), ("ppo_cones", 22.0, 1)):
        for sev in (0, 2):
            for seed in (0, 1):
                rows.append({"agent": agent, "track": "small_track", "effect": "dim", "severity": sev, "seed": seed,
                             "status": "ok", "completed": 1, "lap_time_s": time_s + (sev if agent == "ppo_cones" else 0),
                             "cones_hit": hits, "weather": "[]", "progress": 1.0})
    rows.append({**rows[-1], "seed": 2})  # no baseline cell of that seed: not compared
    text = write_report(rows, tmp_path, baseline="mapper_pure_pursuit").read_text()
    flat = " ".join(text.split())
    assert "## Against the baseline agent `mapper_pure_pursuit`" in text
    assert "| ppo_cones | small_track | dim | 0 | 2 | 1.100 ± 0.000 | 1.000 ± 0.000 | 2/2 |" in flat
    assert "| ppo_cones | small_track | dim | 2 | 2 | 1.200 ± 0.000 |" in flat
    assert (tmp_path / "plots" / "lap_time_ratio.png").read_bytes()[:4] == b"\x89PNG"
    assert "Against the baseline" not in write_report(rows, tmp_path / "plain").read_text()


def test_evaluate_refuses_a_baseline_outside_the_grid(tmp_path, capsys):
    from weather_gym.cli import main

    assert main(["evaluate", "--agent", "gt_pure_pursuit", "--baseline", "mapper_pure_pursuit",
                 "--perception", "oracle", "--out", str(tmp_path / "e")]) == 2
    assert "--baseline 'mapper_pure_pursuit' must be one of the agents of --agent" in capsys.readouterr().err
