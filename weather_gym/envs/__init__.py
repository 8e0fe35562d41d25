"""Gymnasium environments: ``ConeTrackEnv`` and the scenarios registered from ``envs/*.toml``.

Names are imported lazily, so registering the ids (on ``import weather_gym``) does not load
PyBullet; it is loaded when an env is made.

Example:
    >>> from weather_gym.envs import EnvConfig, END_REASONS
    >>> EnvConfig(track="peanut").track, "off_track" in END_REASONS
    ('peanut', True)
"""

from __future__ import annotations

from weather_gym.core._lazy import lazy_exports

_LAZY = {
    "ConeTrackEnv": "weather_gym.envs.cone_track",
    "STATE_FIELDS": "weather_gym.envs.cone_track",
    "RESET_OPTIONS": "weather_gym.envs.cone_track",
    "END_REASONS": "weather_gym.envs.cone_track",
    "GROUND_TRUTH_MODES": "weather_gym.envs.config",
    "EnvConfig": "weather_gym.envs.config",
    "RewardConfig": "weather_gym.envs.config",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
