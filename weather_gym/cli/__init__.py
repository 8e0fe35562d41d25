"""The ``weather-gym`` command line.

Every module in this package whose name does not start with ``_`` is one sub-command: it defines
``register(subparsers)`` which adds its parser and sets ``func`` (called with the parsed args,
returns an exit code), and :data:`COMMANDS` holds its one-line summary. Imports sit at module level;
only heavy optional packages are imported inside functions (the rule ``tests/test_architecture.py``
checks). :func:`main` imports only the sub-command it runs (``weather-gym lap --help`` loads nothing
of ``train`` or ``evaluate``; ``weather-gym --help`` loads no sub-command): a sub-command whose
packages are missing or broken cannot stop another from running.

Errors: a :class:`weather_gym.core.errors.WeatherGymError` (bad input, an output that exists, a path
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
import io
import os
import pkgutil
import signal
import sys
import traceback

import weather_gym.cli as pkg
from weather_gym.core.errors import InputError, WeatherGymError
from weather_gym.core.errors import Terminated as _Terminated
from weather_gym.core.version import __version__

BUG_REPORT = ("this is a bug in weather-gym, not a problem with your input: please report it with the command "
              "you ran and the traceback above")


INTERNAL_ERROR = 70
"""Exit status of an unexpected exception (a bug; ``EX_SOFTWARE`` of sysexits.h)."""


class CLIError(InputError):
    """A user error found by the command line itself: printed as ``error: ...`` with exit code 2."""


COMMANDS: dict[str, str] = {
    "bench": "run a speed benchmark and print its table",
    "calibrate": "presets from sweep curves and measured mAP (read off k per severity)",
    "dataset": "render or inspect COCO datasets of cone frames",
    "degrade": "apply weather to an image, a folder of images or a video",
    "detector": "train, score or run the ONNX cone detector",
    "evaluate": "robustness evaluation: agents x effects x severities x seeds x tracks",
    "gap": "find and fix the gap between simulated and measured frames",
    "lap": "drive laps with an agent; print lap times, cones hit, off-track events, cross-track error",
    "surrogate": "perception surrogate: log the full pipeline, fit, validate",
    "sweep": "detector mAP vs an effect's k on a fixed rendered set (the study's Figures 3 and 5)",
    "tracks": "list, plot or export cone tracks",
    "train": "train a PPO driver on the cone list (logs, checkpoints, held-out eval, resume)",
}
"""Sub-command -> its one-line summary (the ``help=`` its module registers; ``tests/cli/test_cli_lazy.py``
checks both agree and that every sub-command module is listed), so that the top-level help needs no
sub-command's imports."""

_ALL = object()


def build_parser(command: str | None | object = _ALL) -> argparse.ArgumentParser:
    """The ``weather-gym`` parser.

    With no argument every sub-command's module is imported and registered. With ``command`` (a
    name, or None for none) only that one is; the others are listed by name and summary, so their
    modules are not imported.
    """
    parser = argparse.ArgumentParser(
        prog="weather-gym",
        description="Repeatable bad weather for autonomous-racing perception: laps, weather effects, "
        "detector, robustness evaluation, calibration and the sim-vs-measured gap.",
    )
    parser.add_argument("--version", action="version", version=f"weather-gym {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    names = sorted(info.name for info in pkgutil.iter_modules(pkg.__path__) if not info.name.startswith("_"))
    for name in names:
        if command is _ALL or name == command:
            importlib.import_module(f"weather_gym.cli.{name}").register(sub)
        else:
            sub.add_parser(name, help=COMMANDS.get(name, ""), add_help=False)
    return parser


def command_of(argv: list[str]) -> str | None:
    """The sub-command ``argv`` names (its first word that is not an option), or None."""
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def run_command(func, *args, **kwargs) -> int:
    """Call ``func`` and turn the outcome into an exit status, the way every command does.

    A :class:`WeatherGymError` prints ``error: MESSAGE`` and gives 2; Ctrl-C (or SIGTERM) gives 130
    (143) after the ``finally`` blocks ran, so no temporary file is left; any other exception
    prints its traceback and a line asking to report the bug, and gives 70. Scripts in
    ``examples/`` use it too. Each call runs in a fresh ``contextvars`` context, so the inputs a
    command declares (``weather_gym.core._io.declare_inputs``) end with it.
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


@contextlib.contextmanager
def _names_print_as_given():
    """While a command runs, a file name that is not UTF-8 (``'caf\\udce9.png'``) prints as its own bytes
    on stdout and stderr (``surrogateescape``, as Python does under the C locale) instead of raising
    ``UnicodeEncodeError`` under a UTF-8 locale; the streams' error handlers are restored afterwards."""
    changed = []
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and stream.errors == "strict":
            with contextlib.suppress(Exception):
                stream.reconfigure(errors="surrogateescape")
                changed.append(stream)
    try:
        yield
    finally:
        for stream in changed:
            with contextlib.suppress(Exception):
                stream.reconfigure(errors="strict")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    with _names_print_as_given():
        parser = build_parser(command_of(argv))
        args = parser.parse_args(argv)
        return run_command(args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
