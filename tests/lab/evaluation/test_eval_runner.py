"""The generic cell runner: tidy rows, resume, failures and crashes recorded, backends agree, one writer."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import eval_cellfns as fns
import pytest

from weather_gym.core.errors import OutputPathError
from weather_gym.lab.evaluation.runner import read_results, run_cells

HERE = Path(__file__).resolve().parent


def _table(path: Path, drop=("elapsed_s",)) -> list[list[str]]:
    """The file's cells as text, without the timing column (which differs run to run)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    keep = [i for i, c in enumerate(rows[0]) if c not in drop]
    return [[r[i] for i in keep] for r in rows]


def _calls(log: Path) -> list[str]:
    return log.read_text().splitlines() if log.exists() else []


@pytest.fixture
def env_log(tmp_path, monkeypatch):
    log = tmp_path / "calls.log"
    monkeypatch.setenv("EVAL_TEST_LOG", str(log))
    return log


def test_rows_are_tidy_and_typed(tmp_path):
    path = tmp_path / "out" / "results.csv"
    rows = run_cells(fns.grid(), fns.metrics, path, backend="serial", progress=False)
    assert len(rows) == 12
    header = next(csv.reader(open(path)))
    assert header == ["effect", "severity", "seed", "status", "error", "elapsed_s", "score", "laps", "label"]
    first = rows[0]
    assert (first["effect"], first["severity"], first["seed"], first["status"]) == ("droplets", 0, 0, "ok")
    assert first["error"] is None and first["score"] == 1.0 and first["laps"] == 1
    assert [r["label"] for r in rows[:2]] == ["droplets-0", "droplets-1"]
    assert read_results(path) == rows


def test_resume_skips_recorded_cells(tmp_path, env_log):
    path = tmp_path / "results.csv"
    run_cells(fns.grid()[:5], fns.logged, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == 5
    rows = run_cells(fns.grid(), fns.logged, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == 12  # only the 7 new cells ran
    assert [r["status"] for r in rows] == ["ok"] * 12
    reference = tmp_path / "reference.csv"
    run_cells(fns.grid(), fns.metrics, reference, backend="serial", progress=False)
    assert _table(path) == _table(reference)


def test_failed_cell_is_recorded_and_retried(tmp_path, env_log, monkeypatch):
    flag = tmp_path / "fail-now"
    flag.touch()
    monkeypatch.setenv("EVAL_TEST_FAIL", str(flag))
    path = tmp_path / "results.csv"
    rows = run_cells(fns.grid(), fns.flaky, path, backend="serial", progress=False)
    failed = [r for r in rows if r["status"] == "failed"]
    assert [(r["effect"], r["severity"], r["seed"]) for r in failed] == [("dim", 1, 0), ("dim", 1, 1)]
    err = failed[0]["error"]
    assert err.startswith("RuntimeError: injected failure in dim@1 second line") and "eval_cellfns.py" in err
    assert failed[0]["score"] is None and sum(r["status"] == "ok" for r in rows) == 10

    # retry_failed=False keeps the failed rows and runs nothing
    n = len(_calls(env_log))
    run_cells(fns.grid(), fns.flaky, path, backend="serial", progress=False, retry_failed=False)
    assert len(_calls(env_log)) == n

    # default: the failed cells (only those) run again; once fixed, the file equals an uninterrupted run
    flag.unlink()
    rows = run_cells(fns.grid(), fns.flaky, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == n + 2 and all(r["status"] == "ok" for r in rows)
    reference = tmp_path / "reference.csv"
    run_cells(fns.grid(), fns.metrics, reference, backend="serial", progress=False)
    assert _table(path) == _table(reference)


def test_first_cell_failing_still_gives_full_header(tmp_path, monkeypatch):
    flag = tmp_path / "fail-now"
    flag.touch()
    monkeypatch.setenv("EVAL_TEST_FAIL", str(flag))
    cells = [fns.Cell("dim", 1, 0), fns.Cell("dim", 0, 0)]
    path = tmp_path / "results.csv"
    rows = run_cells(cells, fns.flaky, path, backend="serial", progress=False)
    assert [r["status"] for r in rows] == ["failed", "ok"]
    assert _table(path)[0] == ["effect", "severity", "seed", "status", "error", "score", "laps", "label"]


def test_process_backend_matches_serial_and_limits_threads(tmp_path):
    serial, proc = tmp_path / "serial.csv", tmp_path / "process.csv"
    run_cells(fns.grid(), fns.metrics, serial, backend="serial", progress=False)
    rows = run_cells(fns.grid(), fns.with_env, proc, backend="process", workers=2, progress=False)
    assert _table(proc, drop=("elapsed_s", "omp", "pid")) == _table(serial)
    assert {r["omp"] for r in rows} == {"1"}  # workers start with one thread per library
    assert os.getpid() not in {r["pid"] for r in rows}


def test_segfault_is_a_failed_cell_and_innocent_cells_survive(tmp_path):
    path = tmp_path / "results.csv"
    rows = run_cells(fns.grid(1), fns.segfault, path, backend="process", workers=2, progress=False)
    by_key = {(r["effect"], r["severity"], r["seed"]): r for r in rows}
    bad = by_key.pop(("droplets", 2, 0))
    assert bad["status"] == "failed", bad
    _assert_worker_died(bad["error"], "SIGSEGV(-11)")
    assert all(r["status"] == "ok" for r in by_key.values()) and len(by_key) == 5
    expected = {k: fns.metrics(fns.Cell(*k))["score"] for k in by_key}
    assert {k: r["score"] for k, r in by_key.items()} == expected


def test_process_exit_is_reported_with_its_code(tmp_path):
    cells = [fns.Cell("dim", 1, 0), fns.Cell("dim", 0, 0)]
    rows = run_cells(cells, fns.hard_exit, tmp_path / "results.csv", backend="process", workers=2, progress=False)
    assert [r["status"] for r in rows] == ["failed", "ok"]
    _assert_worker_died(rows[0]["error"], "EXIT(3)")


def _assert_worker_died(error: str, code: str) -> None:
    """What a dead worker's row is guaranteed to say: that the worker died, and its exit code when loky
    knew it (it waits 0.25 s for the system to report the code; a loaded machine may be slower)."""
    assert error.startswith("WorkerDied: the worker process running this cell ended"), error
    assert code in error or error.endswith("(its exit code was not known yet)"), error


def test_a_dead_workers_error_line_with_and_without_its_exit_code():
    from joblib.externals.loky.process_executor import TerminatedWorkerError

    from weather_gym.lab.evaluation.runner import _error_line

    words = "A worker process managed by the executor was unexpectedly terminated.\nThe exit codes of the workers are "
    assert _error_line(TerminatedWorkerError(words + "{SIGSEGV(-11)}\nDetailed")) == \
        "WorkerDied: the worker process running this cell ended with SIGSEGV(-11)"
    assert _error_line(TerminatedWorkerError(words + "{}\nDetailed")) == \
        "WorkerDied: the worker process running this cell ended (its exit code was not known yet)"


def test_bad_return_value_is_a_failed_cell(tmp_path):
    rows = run_cells([{"i": 0}], fns.not_a_dict, tmp_path / "r.csv", backend="serial", progress=False)
    assert rows[0]["status"] == "failed" and "expected a dict of metrics" in rows[0]["error"]


def test_cut_last_row_is_dropped_and_rerun(tmp_path, env_log):
    path = tmp_path / "results.csv"
    run_cells(fns.grid()[:3], fns.metrics, path, backend="serial", progress=False)
    with open(path, "a") as f:
        f.write("dim,2,1,ok,,0.01,0.33")  # a row cut by a kill mid-write: no newline
    rows = run_cells(fns.grid(), fns.logged, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == 9 and "dim,2,1" in _calls(env_log)
    assert all(r["status"] == "ok" for r in rows)


def test_complete_last_row_without_newline_is_kept_and_reading_changes_nothing(tmp_path, env_log):
    path = tmp_path / "results.csv"
    run_cells(fns.grid()[:3], fns.metrics, path, backend="serial", progress=False)
    text = path.read_text()
    path.write_text(text[:-1])  # an editor that dropped the final newline
    before = path.read_bytes()
    assert len(read_results(path)) == 3 and path.read_bytes() == before  # reading never writes
    rows = run_cells(fns.grid(), fns.logged, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == 9 and all(r["status"] == "ok" for r in rows)  # the 3 rows were not re-run
    assert path.read_text().endswith("\n") and len(read_results(path)) == 12


def test_other_configuration_is_refused_and_file_kept(tmp_path):
    path = tmp_path / "results.csv"
    run_cells(fns.grid()[:2], fns.metrics, path, backend="serial", progress=False)
    before = path.read_bytes()
    with pytest.raises(ValueError, match=r"different configuration.*\(effect, severity, seed\).*\(agent, seed\)"):
        run_cells([{"agent": "a", "seed": 0}], fns.metrics, path, backend="serial", progress=False)
    other = tmp_path / "notes.csv"
    other.write_text("name,value\nx,1\n")
    with pytest.raises(ValueError, match="not a results file"):
        run_cells(fns.grid()[:1], fns.metrics, other, backend="serial", progress=False)
    assert path.read_bytes() == before and other.read_text() == "name,value\nx,1\n"
    assert not (tmp_path / "notes.sqlite").exists()  # no store is started beside a file that is not ours


def test_a_results_csv_without_its_store_is_imported_once(tmp_path, env_log):
    """A results.csv of the version that kept only the CSV resumes: its cells are not run again."""
    reference, path = tmp_path / "reference.csv", tmp_path / "results.csv"
    run_cells(fns.grid(), fns.metrics, reference, backend="serial", progress=False)
    path.write_text("".join(reference.read_text().splitlines(keepends=True)[:6]))  # header and 5 rows, no store
    assert [r["score"] for r in read_results(path)][:2] == [1.0, 1.01]
    rows = run_cells(fns.grid(), fns.logged, path, backend="serial", progress=False)
    assert len(_calls(env_log)) == 7 and all(r["status"] == "ok" for r in rows)
    assert _table(path) == _table(reference) and (tmp_path / "results.sqlite").exists()
    other = tmp_path / "stack" / "results.csv"  # a key that reads as a number stays the cells' text
    other.parent.mkdir()
    other.write_text("stack,seed,status,error,elapsed_s,y\n6104597533e3,0,ok,,0.1,5\n")
    rows = run_cells([{"stack": "6104597533e3", "seed": 0}], lambda cell: {"y": 0}, other, backend="serial",
                     progress=False)
    assert (rows[0]["stack"], rows[0]["y"]) == ("6104597533e3", 5)  # resumed, not run again


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="same key"):
        run_cells([{"x": 1}, {"x": 1}], fns.metrics, tmp_path / "r.csv", backend="serial")
    with pytest.raises(ValueError, match="unknown backend 'dask'; valid: process, ray, serial"):
        run_cells([{"x": 1}], fns.metrics, tmp_path / "r.csv", backend="dask")
    with pytest.raises(ValueError, match="reserved"):
        run_cells([{"status": 1}], fns.metrics, tmp_path / "r.csv", backend="serial")
    with pytest.raises(ValueError, match="cannot be sent to worker processes.*module level"):
        run_cells([{"x": 1}], lambda cell: {}, tmp_path / "r.csv", backend="process")
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    with pytest.raises(OutputPathError, match="cannot write results to"):
        run_cells([{"x": 1}], fns.metrics, blocker / "results.csv", backend="serial")


def test_second_writer_is_refused(tmp_path):
    path = tmp_path / "results.csv"
    fns.STARTED.clear()
    fns.GATE.clear()
    first = threading.Thread(target=run_cells, args=(fns.grid(), fns.gated, path),
                             kwargs={"backend": "serial", "progress": False})
    first.start()  # a concurrent run holds the results while it writes them: its cell waits for the gate
    try:
        assert fns.STARTED.wait(60), "the first run started no cell"
        with pytest.raises(FileExistsError, match="another run is writing results in"):
            run_cells(fns.grid(), fns.metrics, path, backend="serial", progress=False)
    finally:
        fns.GATE.set()
        first.join()
    rows = run_cells(fns.grid(), fns.logged, path, backend="serial", progress=False)  # released: resumes
    assert all(r["status"] == "ok" for r in rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv", "results.sqlite"]  # nothing else left


_SCRIPT = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, {here!r})
    import eval_cellfns as fns
    from weather_gym.lab.evaluation.runner import run_cells
    if __name__ == "__main__":
        run_cells(fns.grid(4), fns.gated_after_first_severity, sys.argv[1], backend=sys.argv[2], workers=2,
                  progress=False)
    """
)


def _start(tmp_path: Path, path: Path, backend: str) -> subprocess.Popen:
    script = tmp_path / "run.py"
    script.write_text(_SCRIPT.format(here=str(HERE)))
    env = {**os.environ, "EVAL_TEST_GATE": str(tmp_path / "gate-never-opened")}  # the run waits until stopped
    return subprocess.Popen([sys.executable, str(script), str(path), backend], start_new_session=True, env=env)


def _stored(path: Path) -> int:
    """Rows in the results store (read once the run has ended: a run holds the store exclusively)."""
    return len(read_results(path)) if path.with_name("results.sqlite").exists() else 0


def _wait_gate(tmp_path: Path, waiting: int, proc: subprocess.Popen, timeout: float = 120) -> None:
    """Until ``waiting`` processes wait at the gate (every cell of severity 0 has run by then)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if len(list(tmp_path.glob("gate-never-opened.waiting.*"))) >= waiting:
            return
        assert proc.poll() is None, "the run ended before it could be interrupted"
        time.sleep(0.05)
    raise AssertionError("no cell reached the gate")


@pytest.mark.parametrize(("backend", "sig"), [("serial", signal.SIGKILL), ("process", signal.SIGINT)])
def test_interrupted_run_resumes_to_the_same_result(tmp_path, backend, sig):
    path = tmp_path / "results.csv"
    proc = _start(tmp_path, path, backend)
    try:
        _wait_gate(tmp_path, 1 if backend == "serial" else 2, proc)
        os.kill(proc.pid, sig)
        proc.wait(timeout=180)  # a loaded 2-core machine (the suite beside it) shuts the workers down slowly
    finally:
        if proc.poll() is None:
            proc.kill()
    n_done = _stored(path)
    if backend == "serial":  # each row is stored before the next cell starts: the 4 cells of severity 0
        assert n_done == 4
    assert n_done < 24, "the run was not interrupted midway"  # the other cells never ran
    rows = run_cells(fns.grid(4), fns.metrics, path, backend="serial", progress=False)
    assert len(rows) == 24 and all(r["status"] == "ok" for r in rows)
    reference = tmp_path / "reference.csv"
    run_cells(fns.grid(4), fns.metrics, reference, backend="serial", progress=False)
    assert _table(path) == _table(reference)


@pytest.mark.slow
def test_ray_backend_matches_serial_and_records_crashes(tmp_path):
    pytest.importorskip("ray")
    serial, viaray = tmp_path / "serial.csv", tmp_path / "ray.csv"
    run_cells(fns.grid(), fns.metrics, serial, backend="serial", progress=False)
    run_cells(fns.grid(), fns.metrics, viaray, backend="ray", workers=2, progress=False)
    assert _table(viaray) == _table(serial)
    rows = run_cells(fns.grid(), fns.segfault, tmp_path / "crash.csv", backend="ray", workers=2, progress=False)
    bad = [r for r in rows if r["status"] == "failed"]
    assert [(r["effect"], r["severity"], r["seed"]) for r in bad] == [("droplets", 2, 0)]
    assert "Worker" in bad[0]["error"] or "crash" in bad[0]["error"].lower()
