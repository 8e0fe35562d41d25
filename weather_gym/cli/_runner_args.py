"""The options of every command that runs cells on the evaluation runner (evaluate, sweep, calibrate).

One definition, so that ``--workers``, ``--backend``, ``--ray-address``, ``--skip-failed`` and
``--no-progress`` mean the same everywhere and are checked the same way before anything runs.

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_runner_args(parser)
    >>> args = parser.parse_args(["--workers", "2", "--backend", "serial"])
    >>> check_runner_args(args)
    >>> args.workers, args.backend, args.skip_failed
    (2, 'serial', False)
"""

from __future__ import annotations

import os

from weather_gym.core._option_alias import alias
from weather_gym.core.errors import InputError, LimitError, MissingDependencyError


def add_runner_args(p, *, what: str = "cells", resumable: bool = True) -> None:
    """Add the runner options to the parser (or argument group) ``p``."""
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help=f"{what} in parallel (one per CPU unless given)")
    p.add_argument("--backend", default="process", choices=("process", "ray", "serial"),
                   help="process: local worker processes (joblib/loky); ray: Ray through joblib; serial: in this "
                        "process (debugging)")
    p.add_argument("--ray-address", default=None,
                   help="Ray cluster address ('auto', 'ray://host:10001'); default: a local instance")
    if resumable:
        p.add_argument("--skip-failed", action="store_true",
                       help="on resume, keep failed cells as they are instead of retrying them")
    p.add_argument("--quiet", dest="no_progress", action="store_true", help="no progress bar")
    alias(p, "--quiet", "--no-progress")


def check_runner_args(args) -> None:
    """Refuse bad runner options before any cell runs (a typed error naming the option)."""
    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    most = 4 * (os.cpu_count() or 1)
    if args.backend == "process" and args.workers > most:
        raise LimitError(f"--workers {args.workers}: at most {most} local worker processes (4 per CPU core; "
                         "each holds a simulator); use --backend ray --ray-address for a cluster")
    if args.backend == "ray":
        try:
            import ray  # noqa: F401
        except ModuleNotFoundError:
            raise MissingDependencyError("--backend ray needs Ray: pip install 'weather-gym[ray]'") from None
