"""The envs a PPO run trains and evaluates on: the pipeline's env with a random start point
(:class:`RandomStart`), ``info["is_success"]`` for SB3's ``EvalCallback`` (:class:`LapSuccess`) and,
for PPO's own vector envs, only the few ``info`` entries SB3 reads (:class:`LeanInfo`).

Example:
    >>> env = make_training_env("WeatherGym/ConeTrack-v0", "small_track", "gt_cones", {}, 50, {})
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), "start_s" in info
    (['cones', 'mask', 'state'], True)
    >>> env.close()
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from weather_gym.agents.cone_memory import ConeMemory, ConeMemoryConfig
from weather_gym.core.errors import InputError
from weather_gym.pipeline import make_env
from weather_gym.pipeline.modes import PerceptionMode, perception_mode
from weather_gym.wrappers import GroundTruthConeWrapper, WeatherRandomizer

_SPAWN_KEY = (0x57A27,)  # the start-point draw, apart from the env's own streams for the same seed


class RandomStart(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Start an episode at a random arc length of the track (from the reset seed); ``info["start_s"]``.

    A share ``line_share`` of the episodes starts at the start line from rest instead: a policy trained
    only on rolling starts anywhere never learns to leave the line (docs/rl.md, "The start line").
    """

    def __init__(self, env: gym.Env, line_share: float = 0.25) -> None:
        if not 0.0 <= float(line_share) <= 1.0:
            raise InputError(f"RandomStart: line_share={line_share!r} must be in [0, 1]")
        gym.utils.RecordConstructorArgs.__init__(self, line_share=line_share)
        gym.Wrapper.__init__(self, env)
        self.line_share = float(line_share)
        self._rng: np.random.Generator | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY))
        options = dict(options or {})
        track = self.env.unwrapped.track  # type: ignore[attr-defined]  # a ConeTrackEnv
        at_line = self._rng.uniform() < self.line_share
        if track.closed and not at_line and "start_s" not in options and "start_pose" not in options:
            options["start_s"] = float(self._rng.uniform(0.0, track.length))
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {**info, "start_s": options.get("start_s", 0.0)}


class LapSuccess(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """``info["is_success"]`` at the end of an episode: the requested laps were driven (for EvalCallback)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info = {**info, "is_success": bool(info.get("lap", 0) >= max(1, self.env.unwrapped.config.laps)
                                               or info.get("finished", False))}
        return obs, reward, terminated, truncated, info


class RememberedCones(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The cone list with the confirmed cones seen in the last second added
    (:class:`~weather_gym.agents.cone_memory.ConeMemory`, reset with the episode): what a policy
    trained with ``--cone-memory`` reads, and what the ``sb3`` agent gives it when driving (from the
    settings the model's JSON records).

    Example:
        >>> plain = make_training_env("WeatherGym/ConeTrack-v0", "small_track", "gt_cones", {}, 50, {},
        ...                           random_start=False)
        >>> env = RememberedCones(make_training_env("WeatherGym/ConeTrack-v0", "small_track", "gt_cones", {}, 50, {},
        ...                                         random_start=False))
        >>> (obs, _), (seen, _) = env.reset(seed=0), plain.reset(seed=0)
        >>> for _ in range(45):             # 1.5 s from the line: some cones have left the camera's view
        ...     obs, seen = env.step([0.0, 0.5])[0], plain.step([0.0, 0.5])[0]
        >>> int(seen["mask"].sum()), int(obs["mask"].sum())
        (22, 24)
        >>> env.close()
    """

    def __init__(self, env: gym.Env, config: ConeMemoryConfig | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, config=config)
        gym.ObservationWrapper.__init__(self, env)
        self.memory = ConeMemory(config, camera=env.unwrapped.config.camera)  # type: ignore[attr-defined]  # a ConeTrackEnv

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self.memory.reset()
        return super().reset(seed=seed, options=options)

    def observation(self, observation: dict) -> dict:
        return self.memory(observation)


INFO_KEYS = ("is_success", "end_reason", "lap", "cones_hit", "off_track_events")
"""The ``info`` entries PPO's envs pass on (:class:`LeanInfo`): what SB3 and ``EvalCallback`` read
(``is_success``; SB3's own ``TimeLimit.truncated``, ``terminal_observation`` and ``VecMonitor``'s
``episode`` are added after) and the episode's counters."""


class LeanInfo(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Pass on only the ``info`` entries named in ``keys`` (default :data:`INFO_KEYS`); the rest
    (``gt``, ``detections``, ``pose``, ``camera``, ``weather``, ...) is dropped.

    SB3's ``DummyVecEnv`` deep-copies every env's info on every step: with the whole info, 8 surrogate
    envs stepped 1.17-1.27x slower (docs/rl.md, "Speed"). The observation and reward are untouched.

    Example:
        >>> env = LeanInfo(make_training_env("WeatherGym/ConeTrack-v0", "small_track", "gt_cones", {}, 50, {}))
        >>> _ = env.reset(seed=0)
        >>> env.step(env.action_space.sample())[4]
        {'is_success': False, 'lap': 0, 'cones_hit': 0, 'off_track_events': 0}
        >>> env.close()
    """

    def __init__(self, env: gym.Env, keys: tuple[str, ...] = INFO_KEYS) -> None:
        if isinstance(keys, str) or not all(isinstance(k, str) for k in keys):
            raise InputError(f"LeanInfo: keys must be a tuple of info keys (strings), got {keys!r}")
        gym.utils.RecordConstructorArgs.__init__(self, keys=tuple(keys))
        gym.Wrapper.__init__(self, env)
        self.keys = tuple(keys)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {k: info[k] for k in self.keys if k in info}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {k: info[k] for k in self.keys if k in info}


def make_training_env(env_id: str, track: str, perception: str, noise: dict[str, Any], max_steps: int,
                      env_kwargs: dict[str, Any], weather: dict[str, Any] | None = None,
                      random_start: bool = True, surrogate_weather: str = "clear",
                      lean_info: bool = False, cone_memory: dict[str, Any] | None = None) -> gym.Env:
    """One env of the run (module level, so vector-env workers can build it); ``lean_info``: wrapped
    in :class:`LeanInfo` (PPO's vector envs; the DAgger teacher's envs keep the whole info);
    ``cone_memory`` (``ConeMemoryConfig`` fields, ``{}`` for the defaults): the cone list through
    :class:`RememberedCones`."""
    mode = perception_mode(perception)
    pk = dict(noise) if takes_oracle_noise(mode) else {}
    env = make_env(env_id, track=track, perception=perception, perception_kwargs=pk or None,
                   max_episode_steps=max_steps, episode_statistics=False,
                   weather=_start_weather(mode, surrogate_weather), **dict(env_kwargs))
    if weather and mode.renders_frames:
        env = WeatherRandomizer(env, **weather)
    if cone_memory is not None:
        env = RememberedCones(env, ConeMemoryConfig.from_dict(cone_memory))
    if random_start:
        env = RandomStart(env)
    env = LapSuccess(env)
    return LeanInfo(env) if lean_info else env


def takes_oracle_noise(mode: PerceptionMode) -> bool:
    """Whether the mode's cone list is ground truth that ``--noise`` (``OracleNoise``) degrades."""
    return mode.wrapper is GroundTruthConeWrapper


def _start_weather(mode: PerceptionMode, surrogate_weather: str) -> str | None:
    """The weather an env starts in: the surrogate's own for a render-free mode that takes weather
    (it draws cones in it), none where the mode takes no weather, else clear (randomised per episode)."""
    if not mode.takes_weather:
        return None
    return surrogate_weather if not mode.renders_frames else "clear"
