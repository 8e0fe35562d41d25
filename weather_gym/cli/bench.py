"""``weather-gym bench TARGET``: speed benchmarks (median of many runs, baseline side by side).

Each module in ``weather_gym.lab.bench`` is one target with ``register(subparsers)``.

Example:
    >>> from weather_gym.cli import build_parser
    >>> build_parser().parse_args(["bench", "sim", "--repeats", "30"]).target
    'sim'
"""

from __future__ import annotations

import importlib
import pkgutil

import weather_gym.lab.bench as pkg


def register(sub) -> None:
    p = sub.add_parser("bench", help="run a speed benchmark and print its table",
                       description="Speed benchmarks: median of many runs, with a baseline in the same run.")
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if not info.name.startswith("_"):
            importlib.import_module(f"weather_gym.lab.bench.{info.name}").register(targets)
