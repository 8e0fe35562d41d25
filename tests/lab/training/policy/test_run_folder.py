"""A training run's folder: SIGTERM saves as Ctrl-C does (a real process), one writer at a time (the
project's lock), and ``--overwrite`` removes only what a run wrote (``RUN_FILES``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from weather_gym.cli import main
from weather_gym.core._lock import exclusive_folder
from weather_gym.lab.training.policy.run_outputs import RUN_FILES, _remove_run, holds_run

pytest.importorskip("stable_baselines3")
ROOT = Path(__file__).resolve().parents[4]
TINY = ["--n-envs", "1", "--vec", "dummy", "--track", "hairpin", "--n-steps", "64", "--batch-size", "64",
        "--n-epochs", "1", "--max-steps", "60", "--eval-freq", "0", "--checkpoint-freq", "64", "--pretrain", "none",
        "--perception", "gt_cones"]
"""A run that checkpoints every update of 64 steps and evaluates never (gt_cones: nothing rendered)."""


def _wait_for(predicate, proc: subprocess.Popen, what: str, limit_s: float = 300.0) -> None:
    """Poll until ``predicate()``; the limit only ends a hung run (the test asserts no timing)."""
    t0 = time.monotonic()
    while not predicate():
        if proc.poll() is not None:
            pytest.fail(f"training ended (exit {proc.returncode}) before {what}: {proc.stderr.read().decode()[-3000:]}")
        if time.monotonic() - t0 > limit_s:
            pytest.fail(f"no {what} after {limit_s:.0f} s")
        time.sleep(0.2)


@pytest.mark.slow
def test_sigterm_saves_like_ctrl_c_and_a_second_writer_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "weather_gym.cli", "train", "--out", str(out), *TINY,
                             "--timesteps", "10000000"], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    try:
        _wait_for(lambda: (out / "checkpoints" / "ppo_128_steps.zip").is_file(), proc, "second checkpoint")
        # a second writer while the first trains: refused at once, the folder left alone
        before = sorted(p.name for p in out.iterdir())
        assert main(["train", "--out", str(out), *TINY, "--timesteps", "10000000", "--resume"]) == 2
        err = capsys.readouterr().err
        assert "another weather-gym train is writing" in err and "Traceback" not in err
        assert main(["train", "--out", str(out), *TINY, "--timesteps", "64", "--overwrite"]) == 2
        assert "another weather-gym train is writing" in capsys.readouterr().err
        assert proc.poll() is None and sorted(p.name for p in out.iterdir()) == before
        proc.send_signal(signal.SIGTERM)  # a scheduler's stop, `docker stop`, `timeout`
        proc.wait(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    stderr = proc.stderr.read().decode()
    assert proc.returncode == 143, stderr[-3000:]
    assert "Traceback" not in stderr and "terminated (SIGTERM) after" in stderr
    meta = json.loads((out / "model.json").read_text())
    assert meta["timesteps"] >= 128 and (out / "model.zip").is_file()
    assert (out / "learning_curve.png").stat().st_size > 0
    segment = json.loads((out / "run.json").read_text())["segments"][-1]
    assert segment["interrupted"] is True and segment["signal"] == "SIGTERM"
    assert segment["to_steps"] == meta["timesteps"]
    from stable_baselines3 import PPO

    assert PPO.load(str(out / "model.zip"), device="cpu").num_timesteps == meta["timesteps"]  # a usable model
    # the stopped run resumes (its newest checkpoint already past 128 steps: nothing left to train)
    assert main(["train", "--out", str(out), *TINY, "--timesteps", "128", "--resume"]) == 0
    assert len(json.loads((out / "run.json").read_text())["segments"]) == 2


def test_a_locked_run_folder_refuses_a_resume_before_reading_it(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "run.json").write_text('{"settings": {}, "segments": []}')
    with exclusive_folder(out, busy="held by this test"):
        assert main(["train", "--out", str(out), *TINY, "--timesteps", "64", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "another weather-gym train is writing" in err and "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["run.json"]


def test_overwrite_refuses_a_folder_that_holds_no_run(tmp_path, capsys):
    out = tmp_path / "mine"
    (out / "logs").mkdir(parents=True)
    (out / "logs" / "notes.txt").write_text("mine")
    (out / "model.zip").write_text("mine too")
    assert main(["train", "--out", str(out), *TINY, "--timesteps", "64", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "holds no training run (no run.json of one)" in err and "Traceback" not in err
    assert (out / "logs" / "notes.txt").read_text() == "mine" and (out / "model.zip").read_text() == "mine too"


def test_overwrite_removes_only_what_a_run_wrote(tmp_path):
    out = tmp_path / "run"
    written = ["model.zip", "model.json", "run.json", "train.log", "learning_curve.png", "checkpoints/ppo_64_steps.zip",
               "checkpoints/ppo_64_steps.json", "checkpoints/ppo_vecnormalize_64_steps.pkl", "best/best_model.zip",
               "best/best_model.json", "logs/steps000000000/progress.csv", "logs/steps000000064/evaluations.npz"]
    written += [".model.zip.x1y2.tmp.zip", "checkpoints/.ppo_64_steps.zip.ab12.tmp.zip"]  # cut short by kill -9
    mine = ["notes.txt", "checkpoints/keep.zip", "logs/tb/events", "best/README", "model.zip.bak", ".hidden"]
    for name in written + mine:
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("{}")
    (out / "run.json").write_text('{"settings": {}, "segments": []}')
    assert holds_run(out)
    removed = {p.relative_to(out).as_posix() for p in _remove_run(out)}
    assert removed == set(written) - {"logs/steps000000000/progress.csv", "logs/steps000000064/evaluations.npz"} | {
        "logs/steps000000000", "logs/steps000000064"}
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert left == sorted(mine) and not holds_run(out)
    assert len(RUN_FILES) == 12  # the one list (docs/rl.md names each)


@pytest.mark.slow
def test_sigterm_to_the_whole_process_group_still_saves(tmp_path):
    """systemd and ``kill -TERM -PGID`` stop every process of the run: SplitVecEnv's worker ignores the
    signal (as it does Ctrl-C) so the main process can still step, stop and save."""
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    argv = [a if a != "dummy" else "split" for a in TINY]
    argv[argv.index("--n-envs") + 1], argv[argv.index("--n-steps") + 1] = "2", "32"
    proc = subprocess.Popen([sys.executable, "-m", "weather_gym.cli", "train", "--out", str(out), *argv,
                             "--track", "hairpin,oval", "--timesteps", "10000000"], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _wait_for(lambda: (out / "checkpoints" / "ppo_128_steps.json").is_file(), proc, "second checkpoint")
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    stderr = proc.stderr.read().decode()
    assert proc.returncode == 143 and "Traceback" not in stderr, stderr[-3000:]
    assert json.loads((out / "model.json").read_text())["timesteps"] >= 128
    assert json.loads((out / "run.json").read_text())["segments"][-1]["signal"] == "SIGTERM"
