"""``weather-gym lap``: options, refusals, and short runs through the whole pipeline."""

from __future__ import annotations

import re

import cv2
import pytest

from weather_gym.cli import main
from weather_gym.cli.lap import parse_agent_args


def test_help_explains_itself(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["lap", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for needle in ("--track", "--agent", "--weather", "--perception", "--laps", "--video", "--strip",
                   "--overwrite", "oracle", "droplets:0.55", "Exit status"):
        assert needle in text, needle


def test_agent_args_are_parsed():
    assert parse_agent_args(["v_max=12", "a_lat_max=4.5", "path=runs/a.zip", "flag=true"]) == {
        "v_max": 12, "a_lat_max": 4.5, "path": "runs/a.zip", "flag": True}
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_agent_args(["v_max"])


@pytest.mark.parametrize("args,message", [
    (["--laps", "0"], "--laps must be >= 1"),
    (["--agent", "nope"], "unknown agent 'nope'"),
    (["--video", "out.avi"], "expected a file ending in .mp4"),
    (["--agent-arg", "oops"], "KEY=VALUE"),
    (["--detector", "missing.onnx"], "missing.onnx not found"),
    (["--agent", "mapper_pure_pursuit", "--depth-quantile", "0"], "depth_quantile must be a number in (0, 1]"),
    (["--depth-quantile", "0.25", "--perception", "oracle"], "it needs --perception detector"),
])
def test_bad_options_are_user_errors(args, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["lap", *args]) == 2
    assert message in capsys.readouterr().err


def test_depth_quantile_reaches_the_detector_wrapper(monkeypatch):
    import weather_gym.cli.lap as lap

    seen = {}

    def fake_make_env(*args, **kwargs):
        seen.update(kwargs)
        raise KeyboardInterrupt  # stop before anything is rendered

    monkeypatch.setattr(lap, "make_env", fake_make_env)
    with pytest.raises(KeyboardInterrupt):
        lap.run_laps(agent="mapper_pure_pursuit", env_id="WeatherGym/ConeTrackSmall-v0", depth_quantile=0.25)
    assert seen["perception"] == "detector" and seen["perception_kwargs"] == {"depth_quantile": 0.25}


def test_existing_outputs_are_never_overwritten(tmp_path, capsys):
    video = tmp_path / "lap.mp4"
    video.write_bytes(b"precious")
    assert main(["lap", "--video", str(video)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert video.read_bytes() == b"precious"


@pytest.mark.slow
def test_short_run_writes_video_and_strip(tmp_path, capsys):
    video, strip = tmp_path / "lap.mp4", tmp_path / "strip.png"
    code = main(["lap", "--track", "small_track", "--max-steps", "45", "--video", str(video), "--strip", str(strip),
                 "--strip-frames", "3", "--env-id", "WeatherGym/ConeTrackSmall-v0"])
    out = capsys.readouterr().out
    assert code == 1  # one lap was asked for and the step limit came first
    assert "laps completed: 0/1 (time_limit, 45 steps)" in out and "cross-track error: mean" in out
    cap = cv2.VideoCapture(str(video))
    frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, first = cap.read()
    cap.release()
    assert ok and frames == 46 and first.shape == (188, 336, 3)  # reset frame + 45 steps
    grid = cv2.imread(str(strip))
    assert grid is not None and grid.shape[1] == 3 * 336 + 2 * 2
    # again, without --overwrite: refused; with it: replaced
    assert main(["lap", "--max-steps", "5", "--video", str(video)]) == 2
    assert main(["lap", "--max-steps", "5", "--video", str(video), "--overwrite",
                 "--env-id", "WeatherGym/ConeTrackSmall-v0"]) == 1


@pytest.mark.slow
def test_mapper_stack_laps_with_oracle_perception(capsys):
    code = main(["lap", "--track", "hairpin", "--agent", "mapper_pure_pursuit", "--perception", "oracle",
                 "--env-id", "WeatherGym/ConeTrackSmall-v0"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "lap 1:" in out and "laps completed: 1/1" in out
    assert "cones hit: 0   off-track events: 0" in out
    assert "map:" in out and "confirmed cones" in out


@pytest.mark.slow
def test_weather_goes_into_the_pipeline(tmp_path, capsys):
    strip = tmp_path / "wet.png"
    clear = tmp_path / "clear.png"
    base = ["lap", "--agent", "mapper_pure_pursuit", "--perception", "oracle", "--max-steps", "10",
            "--env-id", "WeatherGym/ConeTrackSmall-v0", "--strip-frames", "1"]
    assert main([*base, "--weather", "droplets:0.55", "--strip", str(strip)]) == 1
    out = capsys.readouterr().out
    assert "weather droplets:0.55" in out and "perception oracle" in out
    assert main([*base, "--strip", str(clear)]) == 1
    assert "weather clear" in capsys.readouterr().out
    # the recorded camera view is the weathered one
    wet, dry = cv2.imread(str(strip)), cv2.imread(str(clear))
    assert wet.shape == dry.shape and float(cv2.absdiff(wet, dry).mean()) > 2.0


@pytest.mark.slow
def test_a_terminated_lap_leaves_no_video(tmp_path):
    """SIGTERM mid-run: exit 143, no half-written video at the path (a rerun is not refused), no temp file."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")])}
    video = tmp_path / "lap.mp4"
    proc = subprocess.Popen([sys.executable, "-m", "weather_gym.cli", "lap", "--laps", "3", "--video", str(video)],
                            cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        t0 = time.monotonic()
        while not list(tmp_path.glob(".lap.mp4.*")) and time.monotonic() - t0 < 120:
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.1)
        time.sleep(1.0)  # frames are being written to the temporary file
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, proc.stderr.read().decode()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_detector_lap_reports_map_latency_and_an_h264_video(tmp_path, capsys):
    video = tmp_path / "wet.mp4"
    code = main(["lap", "--agent", "mapper_pure_pursuit", "--weather", "droplets@3", "--max-steps", "20",
                 "--env-id", "WeatherGym/ConeTrackSmall-v0", "--video", str(video)])
    out = capsys.readouterr().out
    assert code == 1 and "perception detector | weather droplets@3" in out
    m = re.search(r"detector: mAP@0.5 (\d\.\d+), recall (\d\.\d+) on the 21 frames it saw", out)
    assert m and 0.0 < float(m.group(1)) <= 1.0, out
    m = re.search(r"added per step: weather (\d+\.\d) ms, detector (\d+\.\d) ms", out)
    assert m and float(m.group(2)) > 0, out
    assert f"video: {video} (21 frames, H.264)" in out


def test_gt_cones_laps_render_nothing_and_refuse_a_video(tmp_path, capsys):
    code = main(["lap", "--track", "hairpin", "--agent", "mapper_pure_pursuit", "--perception", "gt_cones"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "perception gt_cones" in out and "laps completed: 1/1 (laps)" in out and "renderer none" in out
    assert main(["lap", "--perception", "gt_cones", "--video", str(tmp_path / "v.mp4")]) == 2
    assert "renders none" in capsys.readouterr().err


def test_help_lists_every_registered_agent(capsys):
    from weather_gym.agents import AGENTS

    with pytest.raises(SystemExit):
        main(["lap", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "ppo_cones" in text and all(name in text for name in AGENTS)


def test_json_gives_the_result_machine_readable(capsys, tmp_path):
    import json

    assert main(["lap", "--track", "hairpin", "--perception", "gt_cones", "--json", "-"]) == 0
    result = json.loads(capsys.readouterr().out)  # stdout holds the one JSON object, nothing else
    assert main(["lap", "--track", "hairpin", "--perception", "gt_cones", "--json", str(tmp_path / "r.json")]) == 0
    assert f"json: {tmp_path / 'r.json'}" in capsys.readouterr().out  # with the text summary
    assert json.loads((tmp_path / "r.json").read_text())["lap_times_s"] == result["lap_times_s"]
    assert main(["lap", "--track", "hairpin", "--perception", "gt_cones", "--json", str(tmp_path / "r.json")]) == 2
    assert result["track"] == "hairpin" and result["completed"] is True and result["end"] == "laps"
    assert len(result["lap_times_s"]) == 1 and result["metrics"]["cones_hit"] == 0
    assert result["metrics"]["det_map50"] is None  # not measured (no detector): null, not NaN


def test_a_csv_track_is_printed_by_its_name(tmp_path, capsys):
    from weather_gym.core.paths import data_dir

    csv = tmp_path / "my_test_day.csv"
    csv.write_text((data_dir("tracks") / "eufs" / "Hairpin_02_03_2023.csv").read_text())
    assert main(["lap", "--track", str(csv), "--perception", "gt_cones"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("track my_test_day (trackdrive") and str(tmp_path) not in first
