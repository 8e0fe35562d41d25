"""Register every scenario file in ``envs/`` as a Gymnasium id.

Each id's entry point is :func:`weather_gym.pipeline.make_scenario_env` (env -> weather ->
perception; see :mod:`weather_gym.pipeline` for its keywords) and its ``max_episode_steps`` the
scenario's time limit at its control rate (``max_episode_s * control_hz``): Gymnasium's ``TimeLimit``
owns truncation, so ``gym.make(id, max_episode_steps=N)`` runs up to N steps (``-1``: Gymnasium's
"no limit"); ``weather_gym.make_env`` derives the steps from the env's own control rate. Gymnasium's
passive env checker is replaced by the entry point's ``env_checker=True`` (the same checks in the same
place, except that a first ``reset`` that refuses an option leaves the env usable:
:mod:`weather_gym.envs.checker`), so the spec says ``disable_env_checker=True``; ``gym.make(id,
env_checker=False)`` runs without it. This module only stores the entry point's
name, so the env layer imports nothing above it.

Example:
    >>> import gymnasium as gym
    >>> import weather_gym
    >>> spec = gym.spec("WeatherGym/ConeTrack-v0")
    >>> spec.entry_point, spec.max_episode_steps
    ('weather_gym.pipeline:make_scenario_env', 3000)
"""

from __future__ import annotations

import gymnasium as gym

from weather_gym.core.errors import InputError
from weather_gym.envs.scenario import Scenario, load_scenario, scenario_files

ENTRY_POINT = "weather_gym.pipeline:make_scenario_env"

_SCENARIOS: dict[str, Scenario] = {}


def register_envs() -> list[str]:
    """Register the shipped scenarios (idempotent); returns their ids."""
    ids = []
    for path in scenario_files():
        sc = load_scenario(path)
        if sc.env_id in _SCENARIOS and _SCENARIOS[sc.env_id].path != sc.path:
            raise InputError(f"duplicate env id {sc.env_id!r} in {sc.path} and {_SCENARIOS[sc.env_id].path}")
        _SCENARIOS[sc.env_id] = sc
        if sc.env_id not in gym.registry:
            gym.register(id=sc.env_id, entry_point=ENTRY_POINT, kwargs={"scenario": str(path), "env_checker": True},
                         max_episode_steps=sc.max_episode_steps, disable_env_checker=True)
        ids.append(sc.env_id)
    return ids


def check_env_id(env_id: str) -> None:
    """Refuse an id Gymnasium does not have registered, listing weather-gym's own ids."""
    if env_id not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("WeatherGym/"))
        raise InputError(f"unknown env id {env_id!r}; weather-gym ids: {', '.join(ours)}")


def scenario_of(env_id: str) -> Scenario:
    """The scenario registered as ``env_id``."""
    register_envs()
    try:
        return _SCENARIOS[env_id]
    except KeyError:
        raise InputError(f"unknown env id {env_id!r}; weather-gym ids: {', '.join(sorted(_SCENARIOS))}") from None
