"""Gymnasium wrappers: ``WeatherWrapper`` (weather on image observations), ``DetectorWrapper``.

Imports are lazy (``__getattr__``) so ``import weather_gym.wrappers`` stays light; a new wrapper is
one module plus one line in ``_LAZY``.

Example:
    >>> from weather_gym.wrappers import WeatherWrapper  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import Any

# public name -> module that defines it
_LAZY = {
    "DetectorWrapper": "weather_gym.wrappers.detector",
    "WeatherWrapper": "weather_gym.wrappers.weather",
    "GroundTruthConeWrapper": "weather_gym.wrappers.ground_truth",
    "OracleNoise": "weather_gym.wrappers.ground_truth",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
