"""Gymnasium wrappers: ``WeatherWrapper`` (weather on image observations), ``WeatherRandomizer``
(random weather per episode or step), ``DetectorWrapper``, ``GroundTruthConeWrapper`` (oracle /
ground-truth cone lists), ``SurrogatePerceptionWrapper`` (the detector's statistics, nothing rendered), ``EpisodeStatistics`` (a summary of each episode in its last info), and
``RecordVideo`` (H.264 videos of ``render()``, defined in ``weather_gym.viz``).

Every wrapper records its constructor arguments (``gymnasium.utils.RecordConstructorArgs``), so
``env.spec`` lists the stack and ``gymnasium.make(env.spec)`` rebuilds it.

Imports are lazy (``__getattr__``) so ``import weather_gym.wrappers`` stays light; a new wrapper is
one module plus one line in ``_LAZY``.

Example:
    >>> from weather_gym.wrappers import WeatherWrapper  # doctest: +SKIP

The lazily exported names:
    >>> import weather_gym.wrappers as wrappers
    >>> "GroundTruthConeWrapper" in wrappers.__all__, wrappers.GroundTruthConeWrapper.__module__
    (True, 'weather_gym.wrappers.ground_truth')
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from weather_gym.core._lazy import lazy_exports

if TYPE_CHECKING:  # the lazily exported names, for type checkers
    from weather_gym.wrappers.conditions import ConditionsWrapper  # noqa: F401
    from weather_gym.wrappers.detector import DetectorWrapper  # noqa: F401
    from weather_gym.wrappers.episode_statistics import EpisodeStatistics, latencies  # noqa: F401
    from weather_gym.wrappers.fusion import FusionWrapper  # noqa: F401
    from weather_gym.wrappers.ground_truth import GroundTruthConeWrapper, OracleNoise  # noqa: F401
    from weather_gym.wrappers.surrogate import SurrogatePerceptionWrapper  # noqa: F401
    from weather_gym.wrappers.weather import WeatherWrapper  # noqa: F401
    from weather_gym.wrappers.weather_randomizer import RandomWeather, WeatherRandomizer  # noqa: F401

# public name -> module that defines it
_LAZY = {
    "DetectorWrapper": "weather_gym.wrappers.detector",
    "WeatherWrapper": "weather_gym.wrappers.weather",
    "GroundTruthConeWrapper": "weather_gym.wrappers.ground_truth",
    "LidarConeWrapper": "weather_gym.wrappers.lidar",
    "FusionWrapper": "weather_gym.wrappers.fusion",
    "ConditionsWrapper": "weather_gym.wrappers.conditions",
    "OracleNoise": "weather_gym.wrappers.ground_truth",
    "EpisodeStatistics": "weather_gym.wrappers.episode_statistics",
    "latencies": "weather_gym.wrappers.episode_statistics",
    "SurrogatePerceptionWrapper": "weather_gym.wrappers.surrogate",
    "RandomWeather": "weather_gym.wrappers.weather_randomizer",
    "RecordVideo": "weather_gym.viz.record_video",
    "WeatherRandomizer": "weather_gym.wrappers.weather_randomizer",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
