"""A generic, resumable, parallel cell runner: one tidy CSV row per finished cell.

A *cell* is one unit of work described by a few key fields (a frozen dataclass or a dict), a
*cell function* turns a cell into a dict of scalar metrics. ``run_cells`` runs the cells that are not
yet in the results file, in parallel, and appends one row per finished cell as soon as it finishes
(flushed and fsynced; only the parent process writes, so rows never interleave). Re-running the same
command skips the cells already recorded as ``ok``, so an interrupted run loses nothing. A cell that
raises, or whose worker process dies (segfault, ``os._exit``, OOM kill), becomes a row with
``status = "failed"`` and a one-line ``error``; the run goes on.

The runner knows nothing about what a cell does: the robustness evaluation
(``weather_gym.evaluation.evaluate``) and the calibration sweep both use it.

Columns of the results file, in order: the key fields, ``status`` (``ok``/``failed``), ``error``
(empty when ok), ``elapsed_s`` (wall time of the cell in its worker), then the metrics in the order
the cell function first returned them. When a run finishes, the file is rewritten (atomically) with exactly one row per key,
the latest attempt: rows of other cells first in their file order, then this run's cells in the order
given, so an interrupted-and-resumed run ends with the same file as an uninterrupted one (up to the
timing columns).

Backends: ``"process"`` (default; ``ProcessPoolExecutor`` on a ``spawn`` context, workers limited
to one thread each, ending with their parent however it ends: Ctrl-C, SIGTERM, ``kill -9``; see
``docs/reliability.md``), ``"ray"`` (``ray.remote`` tasks on a local instance or ``ray_address``) and
``"serial"`` (in-process, for debugging; a segfault there ends the run).

Example:
    >>> import tempfile, pathlib
    >>> from weather_gym.evaluation.runner import run_cells
    >>> def square(cell): return {"y": cell["x"] ** 2}
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "results.csv"
    >>> rows = run_cells([{"x": 1}, {"x": 2}], square, path, backend="serial", progress=False)
    >>> [(r["x"], r["status"], r["y"]) for r in rows]
    [(1, 'ok', 1), (2, 'ok', 4)]
    >>> rows = run_cells([{"x": 1}, {"x": 2}, {"x": 3}], square, path, backend="serial", progress=False)
    >>> [r["y"] for r in rows]          # x=1 and x=2 were read back from the file, only x=3 ran
    [1, 4, 9]
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import csv
import ctypes
import dataclasses
import io
import json
import multiprocessing as mp
import os
import pickle
import re
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm.auto import tqdm

from weather_gym._io import atomic_file, check_not_input, open_append, write_failure
from weather_gym._lock import exclusive_folder
from weather_gym.errors import (
    FileFormatError,
    InputError,
    MissingDependencyError,
    MissingInputError,
    OutputPathError,
)

__all__ = [
    "RESERVED_COLUMNS",
    "THREAD_ENV_VARS",
    "ResultsFile",
    "cell_key",
    "cell_fields",
    "read_results",
    "run_cells",
]

RESERVED_COLUMNS = ("status", "error", "elapsed_s")
"""Columns the runner writes after the key fields; cells and metrics may not use these names."""

THREAD_ENV_VARS = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
}
"""Environment each worker process starts with: one thread per library, the parallelism is the pool's
(onnxruntime sessions are sized by their own options: ``ConeDetector(threads=1)`` is the default)."""

BACKENDS = ("process", "ray", "serial")

Cell = Any  # a frozen dataclass instance or a Mapping of field -> value
CellFn = Callable[[Any], Mapping[str, Any]]


# --------------------------------------------------------------------------------------------- cells
def cell_fields(cell: Cell) -> dict[str, Any]:
    """The fields of ``cell`` (a dataclass instance or a mapping) as a dict."""
    if dataclasses.is_dataclass(cell) and not isinstance(cell, type):
        return {f.name: getattr(cell, f.name) for f in dataclasses.fields(cell)}
    if isinstance(cell, Mapping):
        return dict(cell)
    raise TypeError(f"a cell must be a dataclass instance or a mapping, got {type(cell).__name__}")


def _format(value: Any) -> str:
    """The CSV text of one value (also the form keys are compared in)."""
    if value is None:
        return ""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, float):
        return repr(value)  # round-trips exactly; nan/inf as 'nan'/'inf'
    if isinstance(value, (int, str)):
        return str(value).replace("\r", " ").replace("\n", " ")
    if isinstance(value, (tuple, list, dict)):
        return json.dumps(value, sort_keys=True, default=_json_default)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json.dumps(dataclasses.asdict(value), sort_keys=True, default=_json_default)
    return str(value).replace("\r", " ").replace("\n", " ")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _parse(text: str) -> Any:
    """Inverse of ``_format`` for the types a tidy file holds: '' -> None, ints, floats, bools, JSON, str."""
    if text == "":
        return None
    if text in ("True", "False"):
        return text == "True"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        pass
    if text[0] in "[{":
        try:
            return json.loads(text)
        except ValueError:
            pass
    return text


def cell_key(cell: Cell, key_fields: Sequence[str]) -> tuple[str, ...]:
    """The identity of a cell in the results file: its key fields as CSV text."""
    fields = cell_fields(cell)
    missing = [k for k in key_fields if k not in fields]
    if missing:
        raise InputError(f"cell {fields!r} lacks key field(s) {', '.join(missing)}")
    return tuple(_format(fields[k]) for k in key_fields)


# -------------------------------------------------------------------------------------- results file
class ResultsFile:
    """The tidy CSV of one run: key fields, ``status``, ``error``, ``elapsed_s``, metrics.

    Rows are kept as text (exactly what is in the file). ``append`` writes one row and fsyncs; a row
    with new metric columns rewrites the file atomically with the wider header first.
    """

    def __init__(self, path: str | os.PathLike, key_fields: Sequence[str]) -> None:
        self.path = Path(path)
        self.key_fields = tuple(key_fields)
        self.columns: list[str] = [*self.key_fields, *RESERVED_COLUMNS]
        self.rows: list[dict[str, str]] = []
        self._needs_rewrite = False
        if self.path.exists() and self.path.stat().st_size > 0:
            self._load()

    # -- reading
    def _load(self) -> None:
        raw = self.path.read_bytes()
        tail = b""
        if not raw.endswith(b"\n"):
            # a last row without its newline: kept if it is complete (an editor that drops the final
            # newline), dropped if it was cut by an interruption mid-write (its cell runs again). The
            # file itself is not touched here; the next write rewrites it whole.
            cut = raw.rfind(b"\n") + 1
            raw, tail = raw[:cut], raw[cut:]
            self._needs_rewrite = True
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FileFormatError(f"{self.path} is not a UTF-8 text file ({exc.reason}); choose another output "
                                  "path") from None
        reader = csv.reader(io.StringIO(text, newline=""))
        try:
            header = next(reader)
        except StopIteration:
            return
        if "status" not in header:
            raise InputError(
                f"{self.path} is not a results file written by weather-gym's runner (no 'status' column; "
                f"header: {', '.join(header)}); choose another output path"
            )
        file_keys = tuple(header[: header.index("status")])
        if file_keys != self.key_fields or tuple(header[len(file_keys): len(file_keys) + 3]) != RESERVED_COLUMNS:
            raise InputError(
                f"{self.path} was written by a different configuration: its key fields are "
                f"({', '.join(file_keys)}), this run's are ({', '.join(self.key_fields)}); "
                "use another output path (nothing was changed)"
            )
        self.columns = header
        for lineno, values in enumerate(reader, start=2):
            if len(values) != len(header):
                raise InputError(
                    f"{self.path}, row {lineno}: {len(values)} values for {len(header)} columns; "
                    "the file was edited or corrupted - fix or remove that row"
                )
            self.rows.append(dict(zip(header, values, strict=True)))
        if tail:
            values = next(csv.reader(io.StringIO(tail.decode("utf-8", "replace"), newline="")), [])
            if len(values) == len(header) and values[header.index("status")] in ("ok", "failed"):
                self.rows.append(dict(zip(header, values, strict=True)))

    def latest(self) -> dict[tuple[str, ...], dict[str, str]]:
        """The last row for each key (the latest attempt)."""
        out: dict[tuple[str, ...], dict[str, str]] = {}
        for row in self.rows:
            out[tuple(row[k] for k in self.key_fields)] = row
        return out

    # -- writing
    def _line(self, row: Mapping[str, str]) -> str:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([row.get(c, "") for c in self.columns])
        return buf.getvalue()

    def append(self, row: Mapping[str, str]) -> None:
        """Write one row (text values) durably; widen the header first if it has new columns."""
        new_cols = [c for c in row if c not in self.columns]
        self.rows.append(dict(row))
        if new_cols or self._needs_rewrite or not self.path.exists() or self.path.stat().st_size == 0:
            self.columns.extend(new_cols)
            self.rewrite(self.rows)
            return
        try:
            with open_append(self.path) as f:
                f.write(self._line(row))
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:  # a full disk is the machine's state, not a bug
            raise write_failure(self.path, exc) from None

    def rewrite(self, rows: list[dict[str, str]], columns: list[str] | None = None) -> None:
        """Replace the file's content with ``rows`` atomically (temp file + rename + fsync)."""
        if columns is not None:
            self.columns = columns
        self.rows = list(rows)
        with atomic_file(self.path, overwrite=True, newline="") as f:  # the run's own file
            csv.writer(f, lineterminator="\n").writerow(self.columns)
            for r in self.rows:
                f.write(self._line(r))
        self._needs_rewrite = False


def read_results(path: str | os.PathLike) -> list[dict[str, Any]]:
    """All rows of a results file, values parsed back to Python (``''`` -> None, numbers, bools).

    Example:
        >>> import tempfile, pathlib
        >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.csv"
        >>> _ = p.write_text("x,status,error,elapsed_s,y\\n1,ok,,0.5,2.5\\n")
        >>> read_results(p)
        [{'x': 1, 'status': 'ok', 'error': None, 'elapsed_s': 0.5, 'y': 2.5}]
    """
    path = Path(path)
    if not path.exists():
        raise MissingInputError(f"results file {path} does not exist")
    with open(path, encoding="utf-8", newline="") as f:
        header = next(csv.reader(f), None)
    if header is None or "status" not in header:
        raise InputError(f"{path} is not a results file written by weather-gym's runner")
    rf = ResultsFile(path, header[: header.index("status")])
    return [{c: _parse(r.get(c, "")) for c in rf.columns} for r in rf.rows]


# ------------------------------------------------------------------------------------------- workers
def _error_summary(exc: BaseException) -> str:
    """One line: ``Type: message [file:line in func <- ...]`` (innermost frames first, at most 3)."""
    msg = " ".join(str(exc).split()) or "(no message)"
    frames = traceback.extract_tb(exc.__traceback__)[-3:][::-1]
    where = " <- ".join(f"{Path(fr.filename).name}:{fr.lineno} in {fr.name}" for fr in frames)
    return f"{type(exc).__name__}: {msg}" + (f" [{where}]" if where else "")


def _check_metrics(metrics: Any, key_fields: Sequence[str]) -> dict[str, str]:
    if not isinstance(metrics, Mapping):
        raise TypeError(f"the cell function returned {type(metrics).__name__}; expected a dict of metrics")
    clash = sorted(set(metrics) & (set(RESERVED_COLUMNS) | set(key_fields)))
    if clash:
        raise InputError(f"the cell function returned metric name(s) {', '.join(clash)} that are "
                         "key fields or reserved columns")
    out: dict[str, str] = {}
    for name, value in metrics.items():
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value.item()
        if not (value is None or isinstance(value, (bool, int, float, str, np.generic))):
            raise TypeError(f"metric {name!r} is a {type(value).__name__}; a tidy row holds scalars only")
        out[str(name)] = _format(value)
    return out


def _execute(cell_fn: CellFn, cell: Cell, key_fields: Sequence[str]) -> tuple[str, Any, float]:
    """Run one cell where it is (any process): ``(status, metrics-as-text or error line, seconds)``."""
    t0 = time.perf_counter()
    try:
        metrics = _check_metrics(cell_fn(cell), key_fields)
        return "ok", metrics, time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 - a failing cell is recorded, the run goes on
        return "failed", _error_summary(exc), time.perf_counter() - t0


def _worker_init(parent_pid: int | None = None) -> None:
    """Process-pool initializer: end with the parent (:func:`_die_with_parent`), one thread per library
    (the environment is also set before the spawn)."""
    _die_with_parent(parent_pid)
    os.environ.update(THREAD_ENV_VARS)
    # Ctrl-C is the parent's to handle: it stops submitting, and the pool is torn down.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(Exception):
        cv2.setNumThreads(1)
    if "torch" in sys.modules:
        with contextlib.suppress(Exception):
            sys.modules["torch"].set_num_threads(1)


_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent_pid: int | None) -> None:
    """Make this worker end when the process that started it ends, however it ends (``kill -9``
    included), so that no worker is left behind holding memory and CPU.

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``; then, if the parent already died before this ran,
    exit now. Elsewhere: a daemon thread that exits when the parent process is gone.
    ``parent_pid`` None skips the check (a forkserver's workers are the server's children).
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "prctl failed")
        except (OSError, AttributeError):
            pass
        else:
            if parent_pid is not None and os.getppid() != parent_pid:
                os._exit(1)  # the parent died before the death signal was armed
            return

    original = os.getppid() if parent_pid is None else parent_pid

    def _watch() -> None:
        while os.getppid() == original:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=_watch, name="weather-gym-parent-watch", daemon=True).start()


def _isolated_target(conn, cell_fn: CellFn, cell: Cell, key_fields: Sequence[str], parent_pid: int | None) -> None:
    _worker_init(parent_pid)
    conn.send(_execute(cell_fn, cell, key_fields))
    conn.close()


def _run_isolated(ctx, cell_fn: CellFn, cell: Cell, key_fields: Sequence[str]) -> tuple[str, Any, float]:
    """Run one cell alone in a fresh process; a dead process becomes a failed result naming the signal."""
    recv, send = ctx.Pipe(duplex=False)
    t0 = time.perf_counter()
    proc = ctx.Process(target=_isolated_target, args=(send, cell_fn, cell, key_fields, _parent_pid(ctx)),
                       daemon=True)
    proc.start()
    send.close()
    result = None
    try:
        result = recv.recv()
    except EOFError:
        pass
    except BaseException:
        proc.terminate()
        raise
    finally:
        proc.join()
        recv.close()
    if result is not None:
        return result
    return "failed", _death_message(proc.exitcode), time.perf_counter() - t0


def _death_message(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"WorkerDied: the worker process was killed by {name} (exit code {exitcode}) while running this cell"
    return f"WorkerDied: the worker process exited with code {exitcode} while running this cell"


@contextlib.contextmanager
def _thread_env() -> Iterator[None]:
    """Set ``THREAD_ENV_VARS`` in this process so spawned workers start with them; restore after."""
    saved = {k: os.environ.get(k) for k in THREAD_ENV_VARS}
    os.environ.update(THREAD_ENV_VARS)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


# -------------------------------------------------------------------------------------------- backends
Done = Callable[[int, tuple[str, Any, float]], None]


def _run_serial(todo: list[tuple[int, Cell]], cell_fn: CellFn, key_fields, done: Done, **_: Any) -> None:
    for i, cell in todo:
        done(i, _execute(cell_fn, cell, key_fields))


def _run_process(todo: list[tuple[int, Cell]], cell_fn: CellFn, key_fields, done: Done, *,
                 workers: int, mp_context: str = "spawn", **_: Any) -> None:
    """At most ``workers`` cells in flight, so a dead worker's suspects are known exactly.

    When a worker dies the pool is broken and every cell in flight fails with ``BrokenProcessPool``;
    those cells are re-run one at a time in fresh processes: the one that kills its process again is
    recorded failed with the signal, the innocent ones get their real result. Then a new pool goes on.
    """
    ctx = mp.get_context(mp_context)
    queue = list(reversed(todo))  # pop() from the end keeps the given order
    with _thread_env():
        while queue:
            suspects: list[tuple[int, Cell]] = []
            pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                                          initargs=(_parent_pid(ctx),))
            try:
                inflight: dict[cf.Future, tuple[int, Cell]] = {}
                while queue or inflight:
                    while queue and len(inflight) < workers:
                        i, cell = queue.pop()
                        try:
                            inflight[pool.submit(_execute, cell_fn, cell, key_fields)] = (i, cell)
                        except cf.process.BrokenProcessPool:
                            queue.append((i, cell))
                            break
                    if not inflight:
                        break
                    finished, _ = cf.wait(inflight, return_when=cf.FIRST_COMPLETED)
                    for fut in finished:
                        i, cell = inflight.pop(fut)
                        exc = fut.exception()
                        if exc is None:
                            done(i, fut.result())
                        elif isinstance(exc, cf.process.BrokenProcessPool):
                            suspects.append((i, cell))
                        elif isinstance(exc, Exception):  # e.g. the cell could not be pickled
                            done(i, ("failed", _error_summary(exc), 0.0))
                        else:  # KeyboardInterrupt/SystemExit from a worker: stop, record nothing
                            raise exc
                    if suspects:
                        suspects.extend(inflight.values())
                        inflight.clear()
                        break
            except BaseException:
                _terminate_pool(pool)
                raise
            if suspects:
                _terminate_pool(pool)
                for i, cell in sorted(suspects, key=lambda s: s[0]):
                    done(i, _run_isolated(ctx, cell_fn, cell, key_fields))
            else:
                pool.shutdown(wait=True)


def _parent_pid(ctx) -> int | None:
    """The pid a worker's parent has (this process), or None when a forkserver starts the workers."""
    return None if ctx.get_start_method() == "forkserver" else os.getpid()


def _terminate_pool(pool: cf.ProcessPoolExecutor) -> None:
    """Stop a pool now: cancel queued work and end its worker processes (ours, by pid): SIGTERM,
    then SIGKILL for any still alive after 5 s."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        with contextlib.suppress(Exception):
            if p.is_alive():
                p.terminate()
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(timeout=5)
            if p.is_alive():
                p.kill()
                p.join(timeout=5)


def _ray_execute(cell_fn: CellFn, cell: Cell, key_fields: Sequence[str]) -> tuple[str, Any, float]:
    _worker_init_env_only()
    return _execute(cell_fn, cell, key_fields)


def _worker_init_env_only() -> None:
    os.environ.update(THREAD_ENV_VARS)
    with contextlib.suppress(Exception):
        cv2.setNumThreads(1)


def _run_ray(todo: list[tuple[int, Cell]], cell_fn: CellFn, key_fields, done: Done, *,
             workers: int, ray_address: str | None = None, **_: Any) -> None:
    """Ray tasks (1 CPU each); at most ``workers`` in flight. A crashed worker's task is retried once
    by Ray, then recorded failed with Ray's error."""
    try:
        import ray
    except ModuleNotFoundError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError(
            "backend 'ray' needs Ray: pip install 'weather-gym[ray]'"
        ) from exc
    started_here = False
    if not ray.is_initialized():
        env_vars = dict(THREAD_ENV_VARS)
        if not ray_address:
            # a local instance sees this machine's files: give its workers the driver's import path,
            # so cell functions defined in scripts and test folders unpickle there too
            paths = [p for p in sys.path if p and os.path.isdir(p)]
            env_vars["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": env_vars})
        else:
            ray.init(address=ray_address, log_to_driver=False, runtime_env={"env_vars": env_vars})
        started_here = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=1)(_ray_execute)
        fn_ref = ray.put(cell_fn)
        queue = list(reversed(todo))
        inflight: dict[Any, tuple[int, Cell]] = {}
        try:
            while queue or inflight:
                while queue and len(inflight) < workers:
                    i, cell = queue.pop()
                    inflight[remote.remote(fn_ref, cell, tuple(key_fields))] = (i, cell)
                ready, _ = ray.wait(list(inflight), num_returns=1)
                for ref in ready:
                    i, _cell = inflight.pop(ref)
                    try:
                        done(i, ray.get(ref))
                    except ray.exceptions.RayError as exc:
                        done(i, ("failed", _ray_error_line(exc), 0.0))
        except BaseException:
            for ref in inflight:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            raise
    finally:
        if started_here:
            ray.shutdown()


def _ray_error_line(exc: BaseException) -> str:
    """Ray's error as one readable line: no colour codes, no caret lines, at most 500 characters."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    words = [w for w in text.split() if not set(w) <= {"^", "~"}]
    return f"{type(exc).__name__}: {' '.join(words)}"[:500]


_BACKEND_FNS = {"serial": _run_serial, "process": _run_process, "ray": _run_ray}


# ------------------------------------------------------------------------------------------ run_cells
def _exclusive(path: Path):
    """Hold an exclusive ``flock`` on the results file's folder while a run writes there, so two runs
    never append to one results file (no lock file is left behind)."""
    return exclusive_folder(path.parent, busy=(
        f"another run is writing results in {path.parent} (for {path.name} or a sibling); "
        "wait for it to finish or use another output folder"))


def _default_key_fields(cells: list[Cell]) -> tuple[str, ...]:
    return tuple(cell_fields(cells[0]))


def check_results_path(results_path: str | os.PathLike) -> Path:
    """Create the results file's folder and check it is writable (:class:`OutputPathError` if not)."""
    path = Path(results_path)
    check_not_input(path, what="results path")
    if path.is_dir():
        raise OutputPathError(f"results path {path} is a folder; give a file path such as {path / 'results.csv'} "
                              "(or move the folder away)")
    if path.exists() and not path.is_file():
        raise OutputPathError(f"results path {path} exists and is not a regular file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".write-test-"):
            pass
        if path.exists() and not os.access(path, os.W_OK):
            raise OutputPathError(f"results file {path} is not writable")
    except OSError as exc:
        if isinstance(exc, OutputPathError):
            raise
        raise OutputPathError(f"cannot write results to {path}: {exc.strerror or exc}") from None
    return path


def run_cells(
    cells: Iterable[Cell],
    cell_fn: CellFn,
    results_path: str | os.PathLike,
    *,
    key_fields: Sequence[str] | None = None,
    workers: int | None = None,
    backend: str = "process",
    progress: bool = True,
    retry_failed: bool = True,
    ray_address: str | None = None,
    desc: str = "cells",
    mp_context: str = "spawn",
) -> list[dict[str, Any]]:
    """Run every cell not yet recorded in ``results_path``; return this run's rows in cell order.

    Args:
        cells: frozen dataclass instances or mappings, all with the same fields; each must be
            picklable (process/ray backends) and have a unique key.
        cell_fn: ``cell -> {metric: scalar}``; a module-level function (it is pickled by reference).
            An exception it raises is recorded as a failed row; so is the death of its process.
        results_path: the tidy CSV (created with its folder; an existing file is resumed, never clobbered).
        key_fields: the fields that identify a cell and become the first columns (default: all
            fields of the first cell). A file with other key fields is refused with ``ValueError``.
        workers: parallel cells (default ``os.cpu_count()``); ignored by ``serial``.
        backend: ``"process"`` (default), ``"ray"`` or ``"serial"``.
        progress: show a tqdm progress bar.
        retry_failed: re-run cells whose latest row is ``failed`` (default); ``False`` keeps them.
        ray_address: address of an existing Ray cluster (``"auto"``, ``"ray://host:10001"``); default
            a local instance with ``workers`` CPUs.
        desc: progress-bar label.
        mp_context: multiprocessing start method of the process backend (``spawn`` or ``forkserver``;
            ``fork`` is unsafe with PyBullet/onnxruntime).

    Returns:
        One dict per given cell (key fields, ``status``, ``error``, ``elapsed_s``, metrics), parsed
        from the file (``''`` -> None, numbers, bools), in the order of ``cells``.
    """
    cells = list(cells)
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    if mp_context not in ("spawn", "forkserver", "fork"):
        raise InputError(f"unknown mp_context {mp_context!r}; valid: spawn, forkserver, fork")
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    path = check_results_path(results_path)
    if not cells:
        return []
    key_fields = tuple(key_fields) if key_fields is not None else _default_key_fields(cells)
    if not key_fields:
        raise InputError("key_fields is empty; a cell needs at least one field that identifies it")
    clash = sorted(set(key_fields) & set(RESERVED_COLUMNS))
    if clash:
        raise InputError(f"cell field name(s) {', '.join(clash)} are reserved by the runner; rename them")
    keys = [cell_key(c, key_fields) for c in cells]
    seen: dict[tuple[str, ...], int] = {}
    for i, k in enumerate(keys):
        if k in seen:
            raise InputError(f"cells {seen[k]} and {i} have the same key {dict(zip(key_fields, k, strict=True))}")
        seen[k] = i

    if backend == "process":
        _check_picklable(cell_fn, cells[0])

    with _exclusive(path):
        results = ResultsFile(path, key_fields)
        latest = results.latest()
        todo = []
        for i, (cell, k) in enumerate(zip(cells, keys, strict=True)):
            row = latest.get(k)
            if row is None or (row["status"] != "ok" and retry_failed):
                todo.append((i, cell))
        n_failed = 0
        bar = None
        if progress:
            bar = tqdm(total=len(cells), initial=len(cells) - len(todo), desc=desc, unit="cell",
                       dynamic_ncols=True)

        def done(i: int, result: tuple[str, Any, float]) -> None:
            nonlocal n_failed
            status, payload, elapsed = result
            row = dict(zip(key_fields, keys[i], strict=True))
            row.update(status=status, error="" if status == "ok" else payload, elapsed_s=_format(round(elapsed, 4)))
            if status == "ok":
                row.update(payload)
            else:
                n_failed += 1
            results.append(row)
            if bar is not None:
                bar.update(1)
                if n_failed:
                    bar.set_postfix(failed=n_failed)

        try:
            if todo:
                _BACKEND_FNS[backend](todo, cell_fn, key_fields, done, workers=min(workers, len(todo)),
                                      ray_address=ray_address, mp_context=mp_context)
        finally:
            if bar is not None:
                bar.close()
        _compact(results, keys)
        final = results.latest()
        return [{c: _parse(final[k].get(c, "")) for c in results.columns} for k in keys]


def _check_picklable(cell_fn: CellFn, cell: Cell) -> None:
    """Worker processes receive the cell function and cells by pickle: refuse what cannot travel."""

    try:
        pickle.dumps(cell_fn)
    except Exception as exc:  # noqa: BLE001 - pickling raises several types
        raise InputError(
            f"the cell function {getattr(cell_fn, '__qualname__', cell_fn)!r} cannot be sent to worker processes "
            f"({type(exc).__name__}: {exc}); define it at module level, or use backend='serial'"
        ) from None
    try:
        pickle.dumps(cell)
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"cell {cell!r} cannot be sent to worker processes ({type(exc).__name__}: {exc})") from None


def _compact(results: ResultsFile, keys: list[tuple[str, ...]]) -> None:
    """One row per key (the latest); other cells' rows first in file order, then ``keys`` in order.

    Columns keep their order (key fields, reserved columns, metrics in the order the cell function
    first returned them).
    """
    latest = results.latest()
    wanted = set(keys)
    ordered = [k for k in latest if k not in wanted] + [k for k in keys if k in latest]
    rows = [latest[k] for k in ordered]
    if rows != results.rows:
        results.rewrite(rows)
