"""weather-gym: repeatable bad weather for autonomous-racing perception.

Importing the package registers the Gymnasium ids built from the scenario files in ``envs/``.
``make_env`` / ``make_vec_env`` (:mod:`weather_gym.pipeline`) build env -> weather -> perception.

Example:
    >>> import gymnasium as gym, weather_gym  # doctest: +SKIP
    >>> env = gym.make("WeatherGym/ConeTrack-v0")  # doctest: +SKIP
    >>> env = weather_gym.make_env(perception="detector", weather="droplets@3")  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path as _Path

from weather_gym.core._lazy import lazy_exports
from weather_gym.core.version import __version__
from weather_gym.envs.registration import register_envs as _register

# the old import paths (weather_gym.errors, weather_gym.evaluation, ...): one alias file each, found on the
# package's own path; see weather_gym.core.moved
__path__.append(str(_Path(__file__).with_name("_moved")))

_LAZY = {"make_env": "weather_gym.pipeline", "make_vec_env": "weather_gym.pipeline",
         "PERCEPTION_MODES": "weather_gym.pipeline"}
__all__ = ["__version__", "register_envs", *sorted(_LAZY)]
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)


def register_envs() -> list[str]:
    """Register every scenario in ``envs/`` as a Gymnasium id; returns the ids (idempotent)."""

    return _register()


try:  # registration must not make `import weather_gym` fail while the env layer is missing
    register_envs()
except ModuleNotFoundError as _exc:  # pragma: no cover
    if not (_exc.name or "").startswith("weather_gym.envs"):
        raise
