"""``weather-gym evaluate``: clear errors before any cell runs; a tiny real run end to end, resumed."""

from __future__ import annotations

import csv

import pytest

from weather_gym.cli import main


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--agent", "nope"], "unknown agent 'nope'; valid names: gt_pure_pursuit, mapper_pure_pursuit"),
        (["--effects", "droplets,snow"], "unknown weather condition 'snow'; valid conditions: droplets, low_light"),
        (["--severities", "0,7"], "invalid severity 7; valid severities: 0, 1, 2, 3, 4"),
        (["--severities", "0,x"], "--severities: 'x' is not an integer"),
        (["--track", ","], "the list of tracks is empty"),
        (["--seeds", "0"], "--seeds must be >= 1"),
        (["--workers", "0"], "--workers must be >= 1"),
        (["--agent-kwargs", "{v_max: 3}"], "--agent-kwargs: not valid JSON"),
        (["--presets", "missing.toml"], "--presets: missing.toml not found"),
    ],
)
def test_bad_input_is_refused_before_any_cell_runs(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main(["evaluate", *args, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_unwritable_output_is_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["evaluate", "--agent", "gt_pure_pursuit", "--out", str(blocker / "out")]) == 2
    assert "cannot write results to" in capsys.readouterr().err


@pytest.mark.slow
def test_tiny_evaluation_end_to_end_and_resume(tmp_path, capsys):
    out = tmp_path / "eval"
    args = ["evaluate", "--agent", "gt_pure_pursuit", "--perception", "camera", "--effects", "dim",
            "--severities", "0,4", "--seeds", "1", "--max-steps", "20", "--env-id", "WeatherGym/ConeTrackSmall-v0",
            "--backend", "serial", "--quiet", "--out", str(out)]
    assert main(args) == 0
    assert "2 ok, 0 failed" in capsys.readouterr().out
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert [(r["effect"], r["severity"], r["status"], r["steps"]) for r in rows] == [
        ("dim", "0", "ok", "20"), ("dim", "4", "ok", "20")]
    assert (out / "plots" / "progress.png").exists()
    assert "| gt_pure_pursuit | small_track | dim | 4 | 1/0 |" in " ".join((out / "report.md").read_text().split())
    before = (out / "results.csv").read_bytes()
    assert main(args) == 0  # resumed: nothing left to run, the file is unchanged
    assert (out / "results.csv").read_bytes() == before
    # the same grid in another world: a new stack, so both cells run again (not resumed from the
    # plain world's rows, which stay in the file)
    assert main(args + ["--env-kwargs", '{"sim": {"scene": "realistic"}}']) == 0
    assert "2 ok, 0 failed" in capsys.readouterr().out
    rows = list(csv.DictReader(open(out / "results.csv")))
    assert len(rows) == 4 and len({r["stack"] for r in rows}) == 2


def test_evaluate_takes_every_perception_mode_gt_cones_included(tmp_path, capsys):
    from weather_gym.pipeline import PERCEPTION_MODES

    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    assert "{" + ",".join(("auto", *PERCEPTION_MODES)) + "}" in capsys.readouterr().out
    out = tmp_path / "eval"
    assert main(["evaluate", "--agent", "gt_pure_pursuit", "--perception", "gt_cones", "--effects", "dim",
                 "--severities", "0", "--seeds", "1", "--max-steps", "10", "--backend", "serial",
                 "--quiet", "--out", str(out)]) == 0
    assert "1 ok, 0 failed" in capsys.readouterr().out


def test_perception_auto_takes_the_mode_lap_would_take_for_every_agent():
    import argparse

    from weather_gym.cli.evaluate import resolve_auto_perception
    from weather_gym.core.errors import InputError

    args = argparse.Namespace(perception="auto", agents="mapper_pure_pursuit")
    resolve_auto_perception(args)
    assert args.perception == "detector"  # lap's auto for a cone-list driver
    args = argparse.Namespace(perception="auto", agents="mapper_pure_pursuit,gt_pure_pursuit")
    with pytest.raises(InputError, match="--perception auto gives the agents different modes"):
        resolve_auto_perception(args)
    args = argparse.Namespace(perception="oracle", agents="gt_pure_pursuit")
    resolve_auto_perception(args)
    assert args.perception == "oracle"  # a named mode stays
