"""Register every scenario file in ``envs/`` as a Gymnasium id, and build envs from them.

``gym.make(id, **kwargs)``: kwargs override the scenario (``track="peanut"``,
``camera={"width": 336, "height": 188}``, ``laps=2``...). The step limit is Gymnasium's
``max_episode_steps`` (the scenario's ``[env] max_episode_steps`` unless ``gym.make`` is given
another; ``-1`` is Gymnasium's "no limit"). ``weather=`` (any weather spec, or a
condition name with ``severity=``) adds a ``WeatherWrapper``; ``detector=True`` (or a dict of
``DetectorWrapper`` arguments) adds the detector.

Example:
    >>> import gymnasium as gym
    >>> import weather_gym
    >>> "WeatherGym/ConeTrack-v0" in gym.registry
    True
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from weather_gym.envs.scenario import Scenario, build_config, load_scenario, scenario_files
from weather_gym.errors import InputError

_SCENARIOS: dict[str, Scenario] = {}
UNLIMITED_STEPS = 2**62
"""The env's own step limit under ``gymnasium.make``: none (Gymnasium's ``TimeLimit`` is the limit)."""


def register_envs() -> list[str]:
    """Register the shipped scenarios (idempotent); returns their ids."""
    ids = []
    for path in scenario_files():
        sc = load_scenario(path)
        if sc.env_id in _SCENARIOS and _SCENARIOS[sc.env_id].path != sc.path:
            raise InputError(f"duplicate env id {sc.env_id!r} in {sc.path} and {_SCENARIOS[sc.env_id].path}")
        _SCENARIOS[sc.env_id] = sc
        if sc.env_id not in gym.registry:
            gym.register(id=sc.env_id, entry_point="weather_gym.envs.registration:make_scenario_env",
                         kwargs={"scenario": str(path)},
                         max_episode_steps=build_config(sc).max_episode_steps)
        ids.append(sc.env_id)
    return ids


def make_scenario_env(scenario: str, render_mode: str | None = None, weather: Any = None, severity: int | None = None,
                      detector: Any = None, **overrides: Any) -> gym.Env:
    """Entry point used by ``gym.make``: the scenario's env, wrapped as the scenario and kwargs say."""
    from weather_gym.envs.cone_track import ConeTrackEnv

    sc = load_scenario(scenario)
    # The step limit is Gymnasium's TimeLimit (the spec's max_episode_steps = the scenario's, or
    # gymnasium.make(..., max_episode_steps=N)); the env's own limit is off so that N is not silently
    # cut to the scenario's value.
    overrides.setdefault("max_episode_steps", UNLIMITED_STEPS)
    env: gym.Env = ConeTrackEnv(build_config(sc, overrides), render_mode=render_mode)
    try:
        spec = _weather_spec(sc, weather, severity)
        if spec is not None:
            from weather_gym.wrappers import WeatherWrapper

            env = WeatherWrapper(env, weather=spec)
        det = sc.detector if detector is None else detector
        if isinstance(det, dict) and det.get("enabled", True) is False:
            det = None
        if det:
            from weather_gym.wrappers import DetectorWrapper

            kwargs = {k: v for k, v in det.items() if k != "enabled"} if isinstance(det, dict) else {}
            env = DetectorWrapper(env, **kwargs)
    except BaseException:
        env.close()
        raise
    return env


def _weather_spec(sc: Scenario, weather: Any, severity: int | None) -> Any:
    if weather is None and severity is None:
        if not sc.weather:
            return None
        if "spec" in sc.weather:
            return sc.weather["spec"]
        return (sc.weather["condition"], int(sc.weather.get("severity", 0)))
    if severity is not None:
        if not isinstance(weather, str):
            raise InputError(f"severity= needs weather= to be a condition name (e.g. 'low_light'), got {weather!r}")
        return (weather, int(severity))
    return weather
