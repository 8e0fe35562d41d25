"""The one episode driver: an agent drives one episode of an env; one result type comes back.

``run_episode(env, agent, seed=...)`` resets the env and the agent, then feeds every step's
observation and info to ``agent.act`` until the env terminates or Gymnasium's ``TimeLimit``
truncates it (the driver has no step limit of its own: build the env with ``max_episode_steps``).
The statistics come from :class:`~weather_gym.wrappers.EpisodeStatistics` (added for the episode
when the env does not already have it); the wall time and the mean latency the weather and the
detector added per step are measured on the side. ``on_step(step, obs, info, done)`` is called after
the reset (step 0) and after every step (videos, progress bars, scoring the detector...).

Example:
    >>> from weather_gym.pipeline import make_env
    >>> from weather_gym.agents import make_agent
    >>> from weather_gym.pipeline import run_episode
    >>> env = make_env(perception="gt_cones", track="hairpin", max_episode_steps=900)
    >>> agent = make_agent("mapper_pure_pursuit", env.unwrapped.track, env.unwrapped.config.camera)
    >>> result = run_episode(env, agent, seed=0)
    >>> result.end_reason, result.laps_completed, result.completed
    ('laps', 1, True)
    >>> env.close()
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any, cast

import gymnasium as gym
import numpy as np

from weather_gym.agents._checks import check_action
from weather_gym.core.errors import InputError
from weather_gym.wrappers._chain import find_wrapper
from weather_gym.wrappers.episode_statistics import EpisodeStatistics, latencies

__all__ = ["EpisodeResult", "run_episode"]


@dataclass(frozen=True)
class EpisodeResult:
    """What one episode gave.

    Attributes:
        end_reason: ``laps`` | ``off_track`` | ``stalled`` | ``time_limit`` (``weather_gym.envs.END_REASONS``).
        completed: all requested laps driven (an open event: its finish crossed).
        laps_completed, lap_times_s: laps finished and their times.
        progress: distance along the centre line / (track length x laps requested), clipped to 0..1.
        progress_m: that distance in metres. episode_return: sum of the rewards. steps: env steps.
        cones_hit, off_track_events, cte_mean_m, cte_max_m: how cleanly it drove.
        sim_time_s, wall_time_s: simulated and wall-clock time of the episode.
        weather_latency_ms, detector_latency_ms: mean time per step the weather / the detector added.
        seed: the reset seed.
    """

    end_reason: str
    completed: bool
    laps_completed: int
    lap_times_s: tuple[float, ...]
    progress: float
    progress_m: float
    episode_return: float
    steps: int
    cones_hit: int
    off_track_events: int
    cte_mean_m: float
    cte_max_m: float
    sim_time_s: float
    wall_time_s: float
    weather_latency_ms: float
    detector_latency_ms: float
    seed: int | None = None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["lap_times_s"] = list(self.lap_times_s)
        return d


def run_episode(env: gym.Env, agent: Any, *, seed: int | None = None, options: dict[str, Any] | None = None,
                on_step: Callable[[int, Any, dict, bool], None] | None = None,
                agent_name: str | None = None) -> EpisodeResult:
    """Drive one episode of ``env`` with ``agent`` (anything with ``reset(seed, info)`` and
    ``act(obs, info)``) and return its :class:`EpisodeResult`.

    ``env`` must end its episodes by itself: a ``TimeLimit`` in its wrapper chain (every env made by
    ``weather_gym.make_env`` / ``gym.make`` of a weather-gym id has one).
    """

    if find_wrapper(env, gym.wrappers.TimeLimit) is None:
        raise InputError("run_episode needs an env with a time limit (gymnasium.wrappers.TimeLimit; "
                         "weather_gym.make_env(..., max_episode_steps=N) has one)")
    stats = find_wrapper(env, EpisodeStatistics)
    driven = env if stats is not None else EpisodeStatistics(env)
    stats = stats or cast(EpisodeStatistics, driven)  # None: driven is a new EpisodeStatistics
    who = f"agent {agent_name!r}" if agent_name else "agent"
    base = env.unwrapped
    track = getattr(base, "track", None)
    laps_requested = max(int(getattr(getattr(base, "config", None), "laps", 1) or 1), 1)

    wall0 = time.perf_counter()
    obs, info = driven.reset(seed=seed, options=options)
    agent.reset(seed=seed, info=info)
    if on_step is not None:
        on_step(0, obs, info, False)
    weather_ms = detector_ms = 0.0
    steps = 0
    while True:
        action = check_action(agent.act(obs, info), who=who)
        obs, _, terminated, truncated, info = driven.step(action)
        steps += 1
        lat = latencies(driven)
        weather_ms += lat["weather_ms"]
        detector_ms += lat["detector_ms"]
        done = bool(terminated or truncated)
        if on_step is not None:
            on_step(steps, obs, info, done)
        if done:
            break
    wall = time.perf_counter() - wall0
    ep: dict[str, Any] = info.get(stats.info_key) or stats.last_episode  # type: ignore[assignment]  # the episode ended: its summary is set
    length = float(getattr(track, "length", math.nan))
    progress_m = float(ep["progress_m"])
    progress = progress_m / (length * laps_requested) if length > 0 else math.nan
    end = ep["end_reason"]
    return EpisodeResult(
        end_reason=end, completed=end == "laps", laps_completed=int(ep["laps"]),
        lap_times_s=tuple(ep["lap_times"]), progress=float(np.clip(progress, 0.0, 1.0)) if math.isfinite(progress)
        else math.nan, progress_m=progress_m, episode_return=float(ep["r"]), steps=int(ep["l"]),
        cones_hit=int(ep["cones_hit"]), off_track_events=int(ep["off_track_events"]),
        cte_mean_m=float(ep["cte_mean_m"]), cte_max_m=float(ep["cte_max_m"]), sim_time_s=float(ep["sim_time_s"]),
        wall_time_s=wall, weather_latency_ms=weather_ms / steps, detector_latency_ms=detector_ms / steps,
        seed=seed)
