"""The ``weather-gym`` command line.

Every module in this package whose name does not start with ``_`` is one sub-command: it defines
``register(subparsers)`` which adds its parser and sets ``func`` (called with the parsed args,
returns an exit code). Heavy imports happen inside ``func`` so ``--help`` stays fast.

Example:
    >>> from weather_gym.cli import main
    >>> main(["--version"])  # doctest: +SKIP
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from weather_gym import __version__


class CLIError(Exception):
    """A user error: printed as ``error: ...`` with exit code 2, no traceback."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="weather-gym",
        description="Repeatable bad weather for autonomous-racing perception: laps, weather effects, "
        "detector, robustness evaluation, calibration and the sim-vs-measured gap.",
    )
    parser.add_argument("--version", action="version", version=f"weather-gym {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    import weather_gym.cli as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if not info.name.startswith("_"):
            importlib.import_module(f"weather_gym.cli.{info.name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (CLIError, ValueError, FileNotFoundError, FileExistsError, PermissionError, KeyError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
