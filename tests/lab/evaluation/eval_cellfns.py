"""Deterministic cell functions for the runner tests (importable by spawned workers and Ray).

Imported by the tests in this folder as ``eval_cellfns`` (pytest puts the folder on ``sys.path``).
"""

from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Cell:
    effect: str
    severity: int
    seed: int


def grid(n_seeds: int = 2) -> list[Cell]:
    return [Cell(e, s, seed) for e in ("droplets", "dim") for s in range(3) for seed in range(n_seeds)]


def metrics(cell: Cell) -> dict:
    """A pure function of the cell: what every backend must agree on."""
    score = 1.0 / (1 + cell.severity) + 0.01 * cell.seed
    return {"score": score, "laps": 1 if cell.severity < 2 else 0, "label": f"{cell.effect}-{cell.seed}"}


def _log(cell: Cell) -> None:
    log = os.environ.get("EVAL_TEST_LOG")
    if log:
        with open(log, "a") as f:
            f.write(f"{cell.effect},{cell.severity},{cell.seed}\n")


def logged(cell: Cell) -> dict:
    _log(cell)
    return metrics(cell)


def flaky(cell: Cell) -> dict:
    """Fails on (dim, 1, *) while the file named by EVAL_TEST_FAIL exists."""
    _log(cell)
    flag = os.environ.get("EVAL_TEST_FAIL")
    if cell.effect == "dim" and cell.severity == 1 and flag and Path(flag).exists():
        raise RuntimeError(f"injected failure in {cell.effect}@{cell.severity}\nsecond line")
    return metrics(cell)


def segfault(cell: Cell) -> dict:
    """Kills its own process with SIGSEGV on (droplets, 2, 0); slow enough that others are in flight."""
    time.sleep(0.05)
    if (cell.effect, cell.severity, cell.seed) == ("droplets", 2, 0):
        os.kill(os.getpid(), signal.SIGSEGV)
    return metrics(cell)


def hard_exit(cell: Cell) -> dict:
    if cell.severity == 1 and cell.seed == 0:
        os._exit(3)
    return metrics(cell)


STARTED = threading.Event()
GATE = threading.Event()


def gated(cell: Cell) -> dict:
    """In this process (the serial backend): says it started, then waits for the test to open the gate."""
    STARTED.set()
    if not GATE.wait(120):
        raise TimeoutError("the test never opened the gate")
    return metrics(cell)


def gated_after_first_severity(cell: Cell) -> dict:
    """Cells of severity 0 run at once; the others wait (up to 2 minutes) for the file named by
    EVAL_TEST_GATE, so that a run is still going however loaded the machine is when the test stops it.
    A waiting process says so with a file ``GATE.waiting.PID``."""
    if cell.severity > 0:
        gate = Path(os.environ["EVAL_TEST_GATE"])
        gate.with_name(f"{gate.name}.waiting.{os.getpid()}").touch()
        deadline = time.monotonic() + 120
        while not gate.exists():
            if time.monotonic() > deadline:
                raise TimeoutError("the test never opened the gate")
            time.sleep(0.05)
    return metrics(cell)


def slow(cell: Cell) -> dict:
    time.sleep(float(os.environ.get("EVAL_TEST_SLEEP", "0.15")))
    return metrics(cell)


def with_env(cell: Cell) -> dict:
    """``metrics`` plus where it ran and with how many OpenMP threads."""
    return {**metrics(cell), "omp": os.environ.get("OMP_NUM_THREADS", ""), "pid": os.getpid()}


def not_a_dict(cell: Cell):
    return [1, 2]
