"""``weather-gym evaluate`` killed mid-run leaves no process behind (workers, resource tracker).

The run is started in its own session; after the kill, every process of that session must be gone
within a few seconds, whatever the signal: SIGTERM (cleanup in the parent), SIGINT (Ctrl-C) or
SIGKILL (no cleanup possible: the workers see their parent die and end themselves).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")

REPO = Path(__file__).resolve().parents[3]


def _session(sid: int) -> dict[int, str]:
    """pid -> command name of every live (non-zombie) process in session ``sid``."""
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        name = stat[stat.index("(") + 1: stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        state, session = fields[0], int(fields[3])
        if session == sid and state != "Z":
            out[int(d.name)] = name
    return out


def _wait(predicate, timeout: float) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL], ids=lambda s: s.name)
def test_killed_evaluate_leaves_no_process(tmp_path, sig):
    cmd = [sys.executable, "-m", "weather_gym.cli", "evaluate", "--agent", "gt_pure_pursuit", "--perception",
           "oracle", "--effects", "droplets", "--severities", "0,1,2,3", "--seeds", "2", "--max-steps", "100000",
           "--laps", "5", "--env-kwargs", '{"camera": {"width": 64, "height": 36}}', "--workers", "2",
           "--quiet", "--out", str(tmp_path / "eval")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    sid = proc.pid
    try:
        # two workers (plus the resource tracker) running cells: at least 4 processes in the session
        assert _wait(lambda: len(_session(sid)) >= 4, 90), f"the workers did not start: {_session(sid)}"
        time.sleep(2.0)  # let them get into their cells
        os.kill(proc.pid, sig)
        proc.wait(timeout=180)  # a loaded 2-core machine (the suite beside it) shuts the workers down slowly
        assert _wait(lambda: not _session(sid), 20), f"left behind after {sig.name}: {_session(sid)}"
    finally:
        for pid in _session(sid):  # never leave anything running, even when the test fails
            os.kill(pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = proc.stderr.read().decode()
    if sig == signal.SIGTERM:
        assert proc.returncode == 143 and "Traceback" not in err, err
    if sig == signal.SIGINT:
        assert proc.returncode == 130 and "Traceback" not in err, err
    assert not list((tmp_path / "eval").glob(".*.tmp*"))  # no temporary file left either
