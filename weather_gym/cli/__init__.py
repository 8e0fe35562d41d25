"""The ``weather-gym`` command line.

Every module in this package whose name does not start with ``_`` is one sub-command: it defines
``register(subparsers)`` which adds its parser and sets ``func`` (called with the parsed args,
returns an exit code). Imports sit at module level; only heavy optional packages are imported
inside functions (the rule ``tests/test_architecture.py`` checks).

Errors: a :class:`weather_gym.errors.WeatherGymError` (bad input, an output that exists, a path
outside its folder, ...) is printed as ``error: MESSAGE`` with exit status 2; anything else is a
bug and keeps its traceback, followed by a line asking to report it (exit status 70). Ctrl-C exits
with 130, SIGTERM with 143, after cleaning up (no temporary file or worker process is left); output
into a pipe whose reader has gone (``| head``) ends the command quietly with 141, as SIGPIPE would.

Example:
    >>> from weather_gym.cli import main
    >>> main(["--version"])  # doctest: +SKIP

A command line parsed into the sub-command's function and options (nothing runs):
    >>> args = build_parser().parse_args(["lap", "--track", "peanut", "--laps", "2"])
    >>> args.command, args.track, args.laps, args.func.__module__
    ('lap', 'peanut', 2, 'weather_gym.cli.lap')
"""

from __future__ import annotations

import argparse
import contextlib
import contextvars
import importlib
import os
import pkgutil
import signal
import sys
import traceback

import weather_gym.cli as pkg
from weather_gym import __version__
from weather_gym.errors import InputError, WeatherGymError
from weather_gym.errors import Terminated as _Terminated

BUG_REPORT = ("this is a bug in weather-gym, not a problem with your input: please report it with the command "
              "you ran and the traceback above")


INTERNAL_ERROR = 70
"""Exit status of an unexpected exception (a bug; ``EX_SOFTWARE`` of sysexits.h)."""


class CLIError(InputError):
    """A user error found by the command line itself: printed as ``error: ...`` with exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="weather-gym",
        description="Repeatable bad weather for autonomous-racing perception: laps, weather effects, "
        "detector, robustness evaluation, calibration and the sim-vs-measured gap.",
    )
    parser.add_argument("--version", action="version", version=f"weather-gym {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if not info.name.startswith("_"):
            importlib.import_module(f"weather_gym.cli.{info.name}").register(sub)
    return parser


def run_command(func, *args, **kwargs) -> int:
    """Call ``func`` and turn the outcome into an exit status, the way every command does.

    A :class:`WeatherGymError` prints ``error: MESSAGE`` and gives 2; Ctrl-C (or SIGTERM) gives 130
    (143) after the ``finally`` blocks ran, so no temporary file is left; any other exception
    prints its traceback and a line asking to report the bug, and gives 70. Scripts in
    ``examples/`` use it too. Each call runs in a fresh ``contextvars`` context, so the inputs a
    command declares (``weather_gym._io.declare_inputs``) end with it.
    """
    with _terminate_as_exit():
        try:
            return int(contextvars.copy_context().run(func, *args, **kwargs) or 0)
        except WeatherGymError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        except BrokenPipeError:  # the reader of the output went away (`weather-gym tracks list | head -1`)
            with contextlib.suppress(OSError, ValueError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit's flush
            return 128 + signal.SIGPIPE
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return 130
        except _Terminated:
            print("terminated", file=sys.stderr)
            return 143
        except Exception:
            traceback.print_exc()
            print(f"weather-gym {__version__}: {BUG_REPORT}", file=sys.stderr)
            return INTERNAL_ERROR


@contextlib.contextmanager
def _terminate_as_exit():
    """While a command runs, SIGTERM unwinds the stack like Ctrl-C instead of killing the process outright."""
    def _raise(signum, frame):
        raise _Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, _raise)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_command(args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
