"""A generic, resumable, parallel cell runner on joblib: one stored row per finished cell.

A *cell* is a frozen dataclass or a dict of key fields; a *cell function* turns it into a dict of
metrics (JSON values). ``run_cells`` runs the cells not yet stored, on joblib (``loky`` worker
processes, or Ray through joblib's backend), stores each row the moment its cell ends
(:mod:`~weather_gym.lab.evaluation.results_store`: ``results.sqlite`` beside ``results.csv``) and rewrites
the CSV export: other cells' rows first, then this run's in the order given, so a resumed run exports
the same file as an uninterrupted one (up to the timing columns). Re-running skips the cells stored
``ok``. A cell that raises, or whose worker dies (segfault, ``os._exit``, OOM kill), is a ``failed`` row
with a one-line ``error``; the run goes on. A second run on the same results is refused.

Example:
    >>> import tempfile, pathlib
    >>> def square(cell): return {"y": cell["x"] ** 2}
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "results.csv"
    >>> rows = run_cells([{"x": 1}, {"x": 2}], square, path, backend="serial", progress=False)
    >>> [(r["x"], r["status"], r["y"]) for r in rows]
    [(1, 'ok', 1), (2, 'ok', 4)]
    >>> rows = run_cells([{"x": 1}, {"x": 2}, {"x": 3}], square, path, backend="serial", progress=False)
    >>> [r["y"] for r in rows]          # x=1 and x=2 were read back from the store, only x=3 ran
    [1, 4, 9]
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import pickle
import re
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import cv2
from joblib import Parallel, delayed, parallel_config, register_parallel_backend
from tqdm.auto import tqdm

from weather_gym.core.errors import InputError, MissingDependencyError
from weather_gym.lab.evaluation.results_store import (
    RESERVED_COLUMNS,
    ResultsStore,
    cell_key,
    check_results_path,
    read_results,
    store_path,
    table,
    to_json,
)

__all__ = ["RESERVED_COLUMNS", "THREAD_ENV_VARS", "cell_fields", "check_results_path", "read_results", "run_cells",
           "store_path"]

THREAD_ENV_VARS = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                    "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")}
"""A Ray worker's environment (loky's get joblib's ``inner_max_num_threads=1``): the pool is the parallelism."""
BACKENDS = {"process": "loky", "ray": "ray", "serial": None}
Cell = Any  # a frozen dataclass instance or a Mapping of field -> value
CellFn = Callable[[Any], Mapping[str, Any]]


def cell_fields(cell: Cell) -> dict[str, Any]:
    """The fields of ``cell`` (a dataclass instance or a mapping) as a dict."""
    if dataclasses.is_dataclass(cell) and not isinstance(cell, type):
        return {f.name: getattr(cell, f.name) for f in dataclasses.fields(cell)}
    if isinstance(cell, Mapping):
        return dict(cell)
    raise InputError(f"a cell must be a dataclass instance or a mapping, got {type(cell).__name__}")


# ------------------------------------------------------------------------------------------- workers
def _error_line(exc: BaseException) -> str:
    """One line: ``Type: message [file:line in func <- ...]`` (innermost frames first, at most 3); a lost
    worker (loky's ``TerminatedWorkerError``, a Ray error) as ``WorkerDied`` with its exit code or Ray's words."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    if codes := re.search(r"exit codes of the workers are \{([^}]*)\}", text):
        if not codes[1].strip():  # loky waits 0.25 s for the system to report it: a loaded machine may not have
            return "WorkerDied: the worker process running this cell ended (its exit code was not known yet)"
        return f"WorkerDied: the worker process running this cell ended with {codes[1]}"
    frames = traceback.extract_tb(exc.__traceback__)[-3:][::-1]
    where = " <- ".join(f"{Path(fr.filename).name}:{fr.lineno} in {fr.name}" for fr in frames)
    words = " ".join(w for w in text.split() if not set(w) <= {"^", "~"}) or "(no message)"
    return f"{type(exc).__name__}: {words}"[:500] + (f" [{where}]" if where else "")


def _confine_worker(parent: int | None = None) -> None:
    """Worker start: one OpenCV thread, Ctrl-C left to the parent and, given the ``parent`` pid, an end
    with the parent however it ends (``kill -9`` too: the worker sees itself re-parented)."""
    cv2.setNumThreads(1)
    with contextlib.suppress(ValueError):  # not the main thread (a Ray actor): Ray owns its signals
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        threading.Thread(target=_exit_with, args=(parent,), name="weather-gym-parent-watch", daemon=True).start()


def _exit_with(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)


def _execute(i: int, cell_fn: CellFn, cell: Cell, key_fields: Sequence[str], confine: bool = False) -> tuple:
    """Run one cell where it is: ``(i, status, metrics as JSON or an error line, seconds)``; ``confine``: in Ray."""
    if confine:
        _confine_worker()
    t0 = time.perf_counter()
    try:
        metrics = cell_fn(cell)
        if not isinstance(metrics, Mapping):
            raise TypeError(f"the cell function returned {type(metrics).__name__}; expected a dict of metrics")
        if clash := sorted(set(map(str, metrics)) & {*RESERVED_COLUMNS, *key_fields}):
            raise InputError(f"the cell function returned metric name(s) {', '.join(clash)} that are key fields or "
                             "reserved columns")
        return i, "ok", to_json(dict(metrics)), round(time.perf_counter() - t0, 4)
    except Exception as exc:  # noqa: BLE001 - a failing cell is recorded, the run goes on
        return i, "failed", _error_line(exc), round(time.perf_counter() - t0, 4)


def _parallel(todo: list[tuple[int, Cell]], cell_fn: CellFn, key_fields: Sequence[str], done: Callable,
              backend: str, workers: int) -> None:
    """At most ``workers`` cells in flight. A dead worker ends joblib's call: the cells then in flight
    run again one at a time (the one that dies again is recorded failed), then the rest goes on."""
    queue = todo
    while queue:
        dispatched: list[int] = []
        finished: set[int] = set()
        tasks = (delayed(_execute)(i, cell_fn, c, key_fields, backend == "ray")
                 for i, c in queue if not dispatched.append(i))  # type: ignore[func-returns-value]  # each cell noted as joblib takes it
        extra = {"inner_max_num_threads": 1, "initializer": _confine_worker, "initargs": (os.getpid(),)}
        with parallel_config(backend=backend, n_jobs=max(2, workers), **(extra if backend == "loky" else {})):
            results = Parallel(return_as="generator_unordered", batch_size=1, pre_dispatch=workers)(tasks)
            with contextlib.closing(results):  # n_jobs 2 at least: joblib runs n_jobs=1 in this process
                while True:
                    try:
                        i, *result = next(results)
                    except StopIteration:
                        return
                    except Exception as exc:  # noqa: BLE001 - a lost worker: loky's TerminatedWorkerError, Ray's
                        crash = exc
                        break
                    finished.add(i)
                    done(i, *result)
        suspects = [(i, c) for i, c in queue if i in dispatched and i not in finished]
        queue = [(i, c) for i, c in queue if i not in dispatched]
        if not suspects:
            raise crash
        if len(suspects) == 1:
            done(suspects[0][0], "failed", _error_line(crash), 0.0)
            continue
        for suspect in suspects:
            _parallel([suspect], cell_fn, key_fields, done, backend, 1)


def _start_ray(stack: contextlib.ExitStack, workers: int, address: str | None) -> None:
    """Ray as joblib's ``ray`` backend (``ray.util.joblib``'s, streaming results as they come); a local
    instance with ``workers`` CPUs (or the cluster at ``address``) unless Ray already runs."""
    try:
        import ray
        from ray.util.joblib.ray_backend import RayBackend
    except ModuleNotFoundError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError("backend 'ray' needs Ray: pip install 'weather-gym[ray]'") from exc
    register_parallel_backend("ray", type("StreamingRay", (RayBackend,), {"supports_return_generator": True}))
    if not ray.is_initialized():
        env = dict(THREAD_ENV_VARS)
        if not address:  # a local instance sees this machine's files: give it the driver's import path
            env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(p for p in sys.path if p and os.path.isdir(p)))
        where = {"address": address} if address else {"num_cpus": workers, "include_dashboard": False}
        ray.init(log_to_driver=False, runtime_env={"env_vars": env}, **where)
        stack.callback(ray.shutdown)


def _check_picklable(cell_fn: CellFn, cell: Cell) -> None:
    """Refuse a cell function or cell that cannot be pickled to a worker process, naming it."""
    for what, obj in (("the cell function", cell_fn), ("cell", cell)):
        try:
            pickle.dumps(obj)
        except Exception as exc:  # noqa: BLE001 - pickling raises several types
            raise InputError(f"{what} {getattr(obj, '__qualname__', obj)!r} cannot be sent to worker processes "
                             f"({type(exc).__name__}: {exc}); define it at module level, or use backend='serial'"
                             ) from None


def run_cells(cells: Iterable[Cell], cell_fn: CellFn, results_path: str | os.PathLike, *,
              key_fields: Sequence[str] | None = None, workers: int | None = None, backend: str = "process",
              progress: bool = True, retry_failed: bool = True, ray_address: str | None = None,
              desc: str = "cells") -> list[dict[str, Any]]:
    """Run every cell not yet stored for ``results_path`` (the CSV export; the store is
    :func:`store_path`); return one typed row per cell, in cell order, with every metric column.

    ``cells``: dataclass instances or mappings with unique keys (``key_fields``, default all fields;
    a store with other key fields is refused). ``cell_fn``: a module-level ``cell -> {metric: value}``.
    ``workers``: cells in flight (default one per CPU). ``backend``: ``process`` (loky processes, one
    thread per library), ``ray`` (Ray through joblib; ``ray_address``: an existing cluster) or
    ``serial`` (here, for debugging). ``retry_failed``: run cells stored ``failed`` again.
    """
    cells = list(cells)
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    path = check_results_path(results_path)
    if not cells:
        return []
    key_fields = list(key_fields if key_fields is not None else cell_fields(cells[0]))
    if not key_fields or set(key_fields) & set(RESERVED_COLUMNS):
        raise InputError(f"key fields ({', '.join(key_fields)}) must be given and not use the reserved names "
                         f"{', '.join(RESERVED_COLUMNS)}; rename them")
    keys = [cell_key(cell_fields(c), key_fields) for c in cells]
    first: dict[str, int] = {}
    for i, k in enumerate(keys):
        if first.setdefault(k, i) != i:
            raise InputError(f"cells {first[k]} and {i} have the same key {k}")
    if backend == "process":
        _check_picklable(cell_fn, cells[0])

    with contextlib.ExitStack() as stack:
        store = stack.enter_context(ResultsStore(path, key_fields, cell_fields(cells[0])))
        todo = [(i, c) for i, (c, k) in enumerate(zip(cells, keys, strict=True))
                if k not in store.rows or (retry_failed and store.rows[k]["status"] != "ok")]
        bar = stack.enter_context(tqdm(total=len(cells), initial=len(cells) - len(todo), desc=desc, unit="cell",
                                       dynamic_ncols=True, disable=not progress))
        failed, next_export = 0, 0.0

        def done(i: int, status: str, payload: str, elapsed: float) -> None:
            nonlocal failed, next_export
            ok = status == "ok"
            store.put(keys[i], status, None if ok else payload, elapsed, payload if ok else "{}")
            if (now := time.monotonic()) >= next_export:  # the CSV follows; its rewrites take <= ~10% of the time
                store.export(keys)
                next_export = now + 10 * (time.monotonic() - now)
            failed += not ok
            bar.update(1)
            if failed:
                bar.set_postfix(failed=failed)

        if backend == "serial":
            for i, cell in todo:
                done(*_execute(i, cell_fn, cell, key_fields))
        elif todo:
            if backend == "ray":
                _start_ray(stack, workers, ray_address)
            _parallel(todo, cell_fn, key_fields, done, cast(str, BACKENDS[backend]), min(workers, len(todo)))
        store.export(keys)
        return table([store.rows[k] for k in keys])[1]
