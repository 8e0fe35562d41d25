"""Gymnasium environments: ``ConeTrackEnv`` and the scenarios registered from ``envs/*.toml``.

Names are imported lazily, so registering the ids (on ``import weather_gym``) does not load
PyBullet; it is loaded when an env is made.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "ConeTrackEnv": "weather_gym.envs.cone_track",
    "STATE_FIELDS": "weather_gym.envs.cone_track",
    "RESET_OPTIONS": "weather_gym.envs.cone_track",
    "EnvConfig": "weather_gym.envs.config",
    "RewardConfig": "weather_gym.envs.config",
}
__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'weather_gym.envs' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
