"""``WeatherRandomizer``: random weather per episode or per step, drawn from the reset seed.

``RandomWeather`` says what to draw: a preset (a condition from ``presets`` at a severity from
``severities``), plus each effect of ``effects`` with probability ``p`` and k uniform in its range,
or clear weather with probability ``p_clear``. ``schedule`` says when: ``"episode"`` (one draw per
episode, passed down as ``reset(options={"weather": ...})``), ``"step"`` (a new draw every ``every``
steps, through ``set_weather`` mid-episode) or ``"ramp"`` (one draw per episode whose every effect's
k rises from 0 to the drawn k over ``every`` steps, like a dusk).

The draws come from the wrapper's own generator, seeded by ``reset(seed=...)`` (a ``SeedSequence``
child distinct from the env's and the weather's streams; ``reset(seed=None)`` continues it), so a
seed gives the same weather sequence every time. ``info["weather_draw"]`` names the episode's (or
the current) draw, e.g. ``"rain@2 + fog:0.31"``; ``info["weather"]`` (from the ``WeatherWrapper``)
is the exact effect list. An explicit ``reset(options={"weather": ...})`` wins over the draw.

The wrapper sits anywhere above a ``WeatherWrapper`` (a ``DetectorWrapper`` between them is fine);
on an env with an image observation and no ``WeatherWrapper`` it adds one.

Example:
    >>> import numpy as np
    >>> from weather_gym.wrappers import RandomWeather
    >>> rw = RandomWeather(presets=("rain", "droplets"), severities=(1, 2, 3), effects={"fog": (0.1, 0.5)}, p=0.5)
    >>> spec, label = rw.sample(np.random.default_rng(0))
    >>> label, [t["name"] for t in spec]
    ('droplets@1 + fog:0.1066', ['droplets', 'fog'])
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Annotated, Any, SupportsFloat

import gymnasium as gym
import numpy as np

from weather_gym.core.errors import InputError, check_known
from weather_gym.core.schema import OneOf, PositiveInt, Share, check_fields
from weather_gym.weather import make
from weather_gym.weather.presets import canonical_condition, preset_spec
from weather_gym.wrappers.weather import WeatherWrapper

__all__ = ["RandomWeather", "SCHEDULES", "WeatherRandomizer"]

SCHEDULES = ("episode", "step", "ramp")
_SPAWN_KEY = (0x5EA7,)  # separates the draws from the env's and the weather's streams for the same seed


def _k_range(name: str, value: Any) -> tuple[float, float]:
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        lo = hi = float(value)
    elif isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2:
        lo, hi = (float(v) for v in value)
    else:
        raise InputError(f"RandomWeather: effects[{name!r}] k must be a number or a (low, high) range, got {value!r}")
    if not (0.0 <= lo <= hi <= 1.0):
        raise InputError(f"RandomWeather: effects[{name!r}] k range ({lo}, {hi}) must satisfy 0 <= low <= high <= 1")
    return lo, hi


@dataclass(frozen=True)
class RandomWeather:
    """What ``WeatherRandomizer`` draws (see the module doc).

    Attributes:
        presets: conditions (``"droplets"``, ``"low_light"``, ``"rain"``, ... any preset condition); a
            draw takes one uniformly, at a severity drawn uniformly from ``severities``. Empty: none.
        severities: preset severities to draw from (0-4).
        effects: effect name -> k (a number), a ``(low, high)`` range drawn uniformly, or a table
            ``{"k": ..., <effect parameters>}``; each is added with probability ``p``, in this order
            after the preset.
        p: probability of each entry of ``effects`` in a draw.
        p_clear: probability that a draw is clear weather (nothing else is drawn then).
        schedule: ``"episode"``, ``"step"`` (redraw every ``every`` steps) or ``"ramp"`` (k rises
            from 0 to the drawn k over ``every`` steps).
        every: steps between draws (``"step"``) or length of the ramp (``"ramp"``).
    """

    presets: tuple[str, ...] = ("droplets", "low_light")
    severities: tuple[int, ...] = (0, 1, 2, 3, 4)
    effects: Mapping[str, Any] = field(default_factory=dict)
    p: Share = 0.5
    p_clear: Share = 0.0
    schedule: Annotated[str, OneOf(SCHEDULES)] = "episode"
    every: PositiveInt = 300  # steps

    @cached_property
    def _tables(self) -> dict[str, tuple[tuple[float, float], dict[str, Any]]]:
        """effect name -> ``((k low, k high), other parameters)``, checked."""
        tables: dict[str, tuple[tuple[float, float], dict[str, Any]]] = {}
        for name, value in dict(self.effects).items():
            params = dict(value) if isinstance(value, Mapping) else {"k": value}
            if "k" not in params:
                raise InputError(f"RandomWeather: effects[{name!r}] = {value!r} needs 'k' (a number or a range)")
            lo, hi = _k_range(name, params.pop("k"))
            make(name, k=hi, **params)  # names an unknown effect or parameter
            tables[name] = ((lo, hi), params)
        return tables

    def __post_init__(self) -> None:
        presets = (self.presets,) if isinstance(self.presets, str) else tuple(self.presets)
        object.__setattr__(self, "presets", tuple(canonical_condition(c) for c in presets))  # one or several
        object.__setattr__(self, "severities", tuple(self.severities))
        if self.presets and not self.severities:
            raise InputError("RandomWeather: presets need at least one severity")
        for c in self.presets:
            for s in self.severities:
                preset_spec(c, s)  # names an unknown condition or severity
        tables = self._tables  # checks every entry
        if not self.presets and not tables:
            raise InputError("RandomWeather: give presets and/or effects to draw from")
        check_fields(self, who="RandomWeather")  # p, p_clear, schedule, every

    def sample(self, rng: np.random.Generator) -> tuple[list[dict[str, Any]], str]:
        """One draw: ``(effect tables for parse_weather, a short label)``; ``([], "clear")`` when clear.

        Every draw takes the same count of numbers from ``rng``, whatever it draws.
        """

        u_clear = rng.random()
        c_idx = int(rng.integers(len(self.presets))) if self.presets else 0
        s_idx = int(rng.integers(len(self.severities))) if self.presets else 0
        picks = [(rng.random(), rng.random()) for _ in self._tables]
        if u_clear < self.p_clear:
            return [], "clear"
        spec: list[dict[str, Any]] = []
        labels: list[str] = []
        if self.presets:
            cond, sev = self.presets[c_idx], int(self.severities[s_idx])
            spec += [dict(t) for t in preset_spec(cond, sev)]
            labels.append(f"{cond}@{sev}")
        for (name, ((lo, hi), params)), (u_in, u_k) in zip(self._tables.items(), picks):
            if u_in < self.p:
                k = round(lo + (hi - lo) * u_k, 4)
                spec.append({"name": name, "k": k, **params})
                labels.append(f"{name}:{k:g}")
        if self.schedule == "ramp":
            spec = [{"name": "ramp", "effect": t["name"], "k_start": 0.0, "k_end": t["k"], "steps": self.every,
                     **{k: v for k, v in t.items() if k not in ("name", "k")}} for t in spec]
        return spec, " + ".join(labels) or "clear"


class WeatherRandomizer(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Draw the weather of each episode (or every few steps) from ``RandomWeather``; see the module doc.

    Args:
        env: an env with a ``WeatherWrapper`` somewhere below (added when missing and possible).
        config: a ``RandomWeather``; or pass its fields as keywords (``presets=("rain",)``, ...).
    """

    def __init__(self, env: gym.Env, config: RandomWeather | None = None, **fields: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, config=config, **fields)
        if config is not None and fields:
            raise InputError("WeatherRandomizer: pass either config=RandomWeather(...) or its fields, not both")
        check_known(fields, list(RandomWeather.__dataclass_fields__), what="WeatherRandomizer", kind="option")
        self.config = config or RandomWeather(**fields)
        try:
            env.get_wrapper_attr("set_weather")
        except AttributeError:
            try:
                env = WeatherWrapper(env)
            except ValueError as exc:
                raise InputError("WeatherRandomizer needs a WeatherWrapper below it (put it under any "
                                 f"DetectorWrapper), and could not add one: {exc}") from None
        gym.Wrapper.__init__(self, env)
        self._rng: np.random.Generator | None = None
        self._steps = 0
        self.draw: str = "clear"

    def _next(self) -> list[dict[str, Any]]:
        assert self._rng is not None
        spec, self.draw = self.config.sample(self._rng)
        return spec

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=_SPAWN_KEY))
        options = dict(options or {})
        spec = self._next()  # drawn even when overridden, so the sequence does not depend on options
        if "weather" in options:
            self.draw = "explicit"
        else:
            options["weather"] = spec
        self._steps = 0
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {**info, "weather_draw": self.draw}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if (self.config.schedule == "step" and self.draw != "explicit" and self._steps > 0
                and self._steps % self.config.every == 0):
            self.env.get_wrapper_attr("set_weather")(self._next())
        self._steps += 1
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "weather_draw": self.draw}
