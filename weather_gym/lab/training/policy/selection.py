"""Which saved policy a run keeps: held-out laps from the start line, in the weathers a driver is held to.

``weather-gym train`` drives the policy (deterministic, with the cone memory it trains with) on
tracks it never trained on, from the start line at rest, in each weather of a list, through a
perception that stands for the one the driver will see (by default the perception surrogate, the
detector's fitted statistics, nothing rendered; ``detector`` renders and runs the detector). The
score orders runs of the same episodes (fixed seeds): more laps first, then fewer cones hit, then
less time. The best policy is written to ``best/`` and becomes the run's ``model.zip``.

Example:
    >>> a = HeldOutResult(rows=(EpisodeRow("small_track", "clear", True, 0, 21.0, 1.0),))
    >>> b = HeldOutResult(rows=(EpisodeRow("small_track", "clear", True, 2, 20.0, 1.0),))
    >>> a.score() > b.score(), a.laps, b.cones_per_lap
    (True, 1, 2.0)
    >>> HeldOutConfig(tracks=("small_track",), weathers=("clear",), max_steps=0)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: --eval-max-steps must be an integer >= 1, got 0
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, Field

from weather_gym.agents.cone_memory import ConeMemoryConfig
from weather_gym.core.schema import ListAsTuple, PositiveInt, check_fields, option
from weather_gym.pipeline import make_env
from weather_gym.pipeline.modes import perception_mode

__all__ = ["EpisodeRow", "HeldOutConfig", "HeldOutResult", "held_out_laps"]

_SEED = 20_000  # episode seeds of the held-out drives: the same every evaluation, apart from training's


#: one or more names (a list is taken as the tuple it lists)
Names = Annotated[Annotated[tuple[str, ...], Field(min_length=1)], ListAsTuple]


def _known_mode(name: str) -> str:
    perception_mode(name)  # InputError naming the modes
    return name


@dataclass(frozen=True)
class HeldOutConfig:
    """The held-out drives (``--eval-track``, ``--eval-weathers``, ``--eval-perception``,
    ``--eval-max-steps``, ``--eval-episodes``): every track in every weather (one drive per track in a
    perception that takes no weather), ``episodes`` seeds each."""

    tracks: Annotated[Names, option("--eval-track")]
    weathers: Annotated[Names, option("--eval-weathers")] = ("clear", "droplets@1", "droplets@2", "droplets@3",
                                                            "low_light@1")
    perception: Annotated[str, AfterValidator(_known_mode), option("--eval-perception")] = "surrogate"
    max_steps: Annotated[PositiveInt, option("--eval-max-steps")] = 1800
    episodes: Annotated[PositiveInt, option("--eval-episodes")] = 1

    def __post_init__(self) -> None:
        check_fields(self, by_option=True)  # each field against its annotation, named by its option

    @classmethod
    def from_dict(cls, fields: dict[str, Any]) -> HeldOutConfig:
        """The config a run recorded (``run.json``'s ``settings["held_out"]``, lists for tuples)."""
        return cls(tracks=tuple(fields["tracks"]), weathers=tuple(fields["weathers"]), perception=fields["perception"],
                   max_steps=int(fields["max_steps"]), episodes=int(fields["episodes"]))

    def drives(self) -> list[tuple[str, str | None, int]]:
        """(track, weather or None, seed) of every held-out episode, in order."""
        weathers = self.weathers if perception_mode(self.perception).takes_weather else (None,)
        return [(t, w, _SEED + e) for t in self.tracks for w in weathers for e in range(self.episodes)]


@dataclass(frozen=True)
class EpisodeRow:
    """One held-out episode: a lap or not, cones hit, time driven (s), share of the lap driven, largest
    distance from the centre line (m)."""

    track: str
    weather: str | None
    lap: bool
    cones: int
    time_s: float
    progress: float
    max_cross_track_m: float = 0.0


@dataclass(frozen=True)
class HeldOutResult:
    """The held-out episodes of one policy; :meth:`score` orders policies (higher is better)."""

    rows: tuple[EpisodeRow, ...]

    @property
    def laps(self) -> int:
        return sum(r.lap for r in self.rows)

    @property
    def cones(self) -> int:
        return sum(r.cones for r in self.rows)

    @property
    def cones_per_lap(self) -> float:
        return self.cones / max(self.laps, 1)

    @property
    def lap_time_s(self) -> float:
        """Total time of the episodes that were laps (s)."""
        return float(sum(r.time_s for r in self.rows if r.lap))

    def score(self) -> tuple[int, int, float]:
        """(laps, -cones, -lap time): more laps, then fewer cones, then faster."""
        return (self.laps, -self.cones, -round(self.lap_time_s, 3))

    def summary(self) -> str:
        return (f"{self.laps}/{len(self.rows)} laps, {self.cones} cones ({self.cones_per_lap:.2f} per lap), "
                f"{self.lap_time_s:.1f} s of laps, mean progress {np.mean([r.progress for r in self.rows]):.2f}, "
                f"cross-track error up to {max(r.max_cross_track_m for r in self.rows):.2f} m")

    def to_dict(self) -> dict[str, Any]:
        return {"laps": self.laps, "episodes": len(self.rows), "cones": self.cones,
                "cones_per_lap": round(self.cones_per_lap, 3), "lap_time_s": round(self.lap_time_s, 2),
                "episodes_detail": [dataclasses.asdict(r) for r in self.rows]}


def held_out_laps(act: Callable[[dict], Any], config: HeldOutConfig, env_id: str,
                  env_kwargs: dict[str, Any] | None = None, cone_memory: dict[str, Any] | None = None) -> HeldOutResult:
    """Drive ``act`` (observation -> action) from the start line on every drive of ``config``.

    ``cone_memory``: ``ConeMemoryConfig`` fields (the policy's), or None for the plain cone list.
    """
    from weather_gym.lab.training.policy.training_env import RememberedCones

    rows = []
    for track, weather, seed in config.drives():
        env = make_env(env_id, track=track, perception=config.perception, weather=weather,
                       max_episode_steps=config.max_steps, episode_statistics=False, **dict(env_kwargs or {}))
        if cone_memory is not None:
            env = RememberedCones(env, ConeMemoryConfig.from_dict(cone_memory))
        try:
            obs, info = env.reset(seed=seed)
            done, xte = False, 0.0
            while not done:
                obs, _, terminated, truncated, info = env.step(np.asarray(act(obs), np.float32).reshape(-1))
                done = terminated or truncated
                xte = max(xte, float(info.get("cross_track_error", 0.0)))
            length = float(env.unwrapped.track.length)  # type: ignore[attr-defined]  # a ConeTrackEnv
            lap = bool(info.get("lap", 0) >= 1 or info.get("finished", False))
            time_s = float(info["lap_times"][0]) if lap and info.get("lap_times") else float(info.get("time", 0.0))
            progress = 1.0 if lap else min(float(info.get("progress", 0.0)) / max(length, 1e-9), 1.0)
            rows.append(EpisodeRow(track, weather, lap, int(info.get("cones_hit", 0)), round(time_s, 3),
                                   round(progress, 3), round(xte, 3)))
        finally:
            env.close()
    return HeldOutResult(rows=tuple(rows))
