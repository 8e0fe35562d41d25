"""``EpisodeStatistics``: a summary of each episode in the info of its last step.

Like Gymnasium's ``RecordEpisodeStatistics`` (``info["episode"]["r"]`` return, ``["l"]`` length,
which stable-baselines3 also reads), without the wall-clock time (so identical runs give identical
infos), plus what a lap is judged by: laps, lap times, progress, cones hit, off-track events,
cross-track error and why the episode ended. Put it outside ``TimeLimit`` (``weather_gym.make_env``
does) so that truncation is seen. Every value is a number, a string or a list: vector envs stack it.

:func:`latencies` reads the last step's weather and detector time off a wrapped env.

Example:
    >>> import gymnasium as gym, numpy as np
    >>> from weather_gym.wrappers import EpisodeStatistics
    >>> class Lap(gym.Env):
    ...     observation_space = gym.spaces.Box(0, 1, (1,)); action_space = gym.spaces.Box(-1, 1, (2,))
    ...     def reset(self, *, seed=None, options=None):
    ...         super().reset(seed=seed); self.t = 0; return np.zeros(1, np.float32), {}
    ...     def step(self, action):
    ...         self.t += 1
    ...         info = {"lap": self.t // 3, "lap_times": [0.1] * (self.t // 3), "progress": 2.0 * self.t,
    ...                 "cones_hit": 0, "off_track_events": 0, "cross_track_error": 0.1, "time": self.t / 30}
    ...         if self.t == 3: info["end_reason"] = "laps"
    ...         return np.zeros(1, np.float32), 2.0, self.t == 3, False, info
    >>> env = EpisodeStatistics(Lap())
    >>> _ = env.reset(seed=0)
    >>> for _ in range(3): *_, info = env.step(np.zeros(2, np.float32))
    >>> info["episode"]["r"], info["episode"]["l"], info["episode"]["end_reason"], info["episode"]["laps"]
    (6.0, 3, 'laps', 1)
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym

from weather_gym.wrappers.detector import DetectorWrapper
from weather_gym.wrappers.weather import WeatherWrapper

__all__ = ["EpisodeStatistics", "latencies"]


class EpisodeStatistics(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Adds ``info["episode"]`` on the last step of each episode (see the module doc).

    Keys: ``r`` (return), ``l`` (steps), ``end_reason`` (``laps``, ``off_track``, ``time_limit``),
    ``laps``, ``lap_times``, ``progress_m`` (metres along the centre line), ``cones_hit``,
    ``off_track_events``, ``cte_mean_m``, ``cte_max_m``, ``sim_time_s``. The last summary is also
    ``wrapper.last_episode``.
    """

    def __init__(self, env: gym.Env, info_key: str = "episode") -> None:
        gym.utils.RecordConstructorArgs.__init__(self, info_key=info_key)
        gym.Wrapper.__init__(self, env)
        self.info_key = info_key
        self.last_episode: dict[str, Any] | None = None
        self._reset_counters()

    def _reset_counters(self) -> None:
        self._return = 0.0
        self._length = 0
        self._cte_sum = 0.0
        self._cte_max = 0.0

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._reset_counters()
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._return += float(reward)
        self._length += 1
        cte = float(info.get("cross_track_error", 0.0))
        self._cte_sum += cte
        self._cte_max = max(self._cte_max, cte)
        if terminated or truncated:
            if terminated:
                end = str(info.get("end_reason", "terminated"))
            else:
                end = "time_limit"
            summary = {
                "r": self._return,
                "l": self._length,
                "end_reason": end,
                "laps": int(info.get("lap", 0)),
                "lap_times": [float(t) for t in info.get("lap_times", ())],
                "progress_m": float(info.get("progress", math.nan)),
                "cones_hit": int(info.get("cones_hit", 0)),
                "off_track_events": int(info.get("off_track_events", 0)),
                "cte_mean_m": self._cte_sum / self._length,
                "cte_max_m": self._cte_max,
                "sim_time_s": float(info.get("time", math.nan)),
            }
            self.last_episode = summary
            info = {**info, self.info_key: summary}
        return obs, reward, terminated, truncated, info


def latencies(env: gym.Env) -> dict[str, float]:
    """Milliseconds the weather and the detector wrappers in ``env``'s chain took on the last step
    (``{"weather_ms": ..., "detector_ms": ...}``, 0 for a stage that is not there)."""

    out = {"weather_ms": 0.0, "detector_ms": 0.0}
    e: Any = env
    while isinstance(e, gym.Wrapper):
        if isinstance(e, WeatherWrapper):
            out["weather_ms"] += e.latency_ms
        elif isinstance(e, DetectorWrapper):
            out["detector_ms"] += e.latency_ms
        e = e.env
    return out
