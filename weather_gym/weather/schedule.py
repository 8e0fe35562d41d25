"""Weather that changes during an episode: ``Ramp`` moves one effect's k from start to end.

A ramp is itself an effect: each frame it processes is one step, so it works anywhere an effect
does (``Compose``, ``WeatherWrapper``, ``weather-gym degrade`` on a video). ``reset`` starts again
from ``k_start``. Like the study's dusk, where light faded from late afternoon to night in 20
minutes: ``Ramp("dim", 0.0, 0.92, steps=20 * 60 * 30)`` at 30 frames per second.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import Ramp
    >>> dusk = Ramp("dim", k_start=0.0, k_end=0.8, steps=4)
    >>> img = np.full((2, 2, 3), 100, np.uint8)
    >>> [int(dusk(img)[0, 0, 0]) for _ in range(6)]
    [100, 80, 60, 40, 20, 20]
"""

from __future__ import annotations

import math
import numbers
from typing import Any, cast

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.weather.base import Effect, EffectRun, KnobEffect, SeedLike, check_seed
from weather_gym.weather.registry import make

__all__ = ["Ramp", "RampRun"]


class Ramp(Effect):
    """Effect ``effect`` whose k goes linearly from ``k_start`` to ``k_end`` over ``steps`` frames, then holds.

    Immutable; the position in the ramp lives in its run (:class:`RampRun`, see
    :class:`~weather_gym.weather.base.EffectRun`).
    """

    name = "ramp"
    stateful = True

    def __init__(self, effect: str, k_start: float = 0.0, k_end: float = 1.0, steps: int = 600,
                 **params: Any) -> None:
        for key, v in (("k_start", k_start), ("k_end", k_end)):
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (0.0 <= float(v) <= 1.0):
                raise InputError(f"ramp: {key}={v!r} must be a number in [0, 1]")
        if isinstance(steps, bool) or not isinstance(steps, numbers.Integral) or steps < 1:
            raise InputError(f"ramp: steps={steps!r} must be an integer >= 1 (frames)")
        if "k" in params:
            raise InputError("ramp: give k_start and k_end, not k")
        make(effect, k=float(k_start), **params)  # validates the effect name and its parameters
        self._config: tuple[str, float, float, int, tuple[tuple[str, Any], ...]] = (effect, float(k_start), float(k_end), int(steps), tuple(sorted(params.items())))

    effect = property(lambda self: self._config[0], doc="Name of the ramped effect.")
    k_start = property(lambda self: self._config[1], doc="k of the first frame.")
    k_end = property(lambda self: self._config[2], doc="k from frame ``steps`` on.")
    steps = property(lambda self: self._config[3], doc="Frames the ramp takes.")
    effect_params = property(lambda self: self._config[4], doc="The effect's other parameters, sorted.")

    def k_at(self, step: int) -> float:
        """k after ``step`` frames of the episode."""
        return float(self.k_start + (self.k_end - self.k_start) * min(step / self.steps, 1.0))

    def first(self) -> KnobEffect:
        """The effect at ``k_start``."""
        return make(self.effect, k=self.k_start, **dict(self.effect_params))

    def start(self, seed: SeedLike = None) -> RampRun:
        return RampRun(self, seed)

    @property
    def step(self) -> int:
        """Frames processed in the episode of the ramp's own run."""
        return cast(RampRun, self._own_run).step

    @property
    def k(self) -> float:
        return cast(KnobEffect, self.current).k

    def params(self) -> dict[str, Any]:
        return {"effect": self.effect, "k_start": self.k_start, "k_end": self.k_end, "steps": self.steps,
                **dict(self.effect_params)}

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any = None) -> Any:
        """``(effect at this frame's k, its draw)``, or a list of them for a batch; moves ``episode``
        (a :class:`RampRun`'s state: pass ``run.episode``) on."""
        run = episode if episode is not None else self.start(None).episode
        return run.draw(shape, rng)

    def _render(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: Any,
                batched: bool) -> np.ndarray:
        if not batched:
            effect, d = draw
            return effect._render(img, d, depth, state, False)  # type: ignore[no-any-return]  # draw: (KnobEffect, its draw)
        out = np.empty_like(img)
        for i, (effect, d) in enumerate(draw):  # each frame written straight into the batch
            if effect.k == 0.0:
                np.copyto(out[i], img[i])
            else:
                effect._render_into(img[i], d, None if depth is None else depth[i], state[i], out[i])
        return out

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Ramp) and self._config == other._config

    def __hash__(self) -> int:
        return hash(("ramp", self._config))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"Ramp({args})"


class _RampEpisode:
    """Where a ramp is: frames done and the effect run of the current k."""

    def __init__(self, ramp: Ramp, seed: SeedLike) -> None:
        self.ramp = ramp
        self.step = 0
        self.effect = ramp.first()
        self.effect.reset(seed)

    def draw(self, shape: tuple[int, ...], rng: np.random.Generator | None) -> Any:
        if len(shape) == 4:
            return [self.draw(shape[1:], rng) for _ in range(shape[0])]
        effect = self._advance()
        return effect, effect._own_run.sample(shape, rng)

    def _advance(self) -> KnobEffect:
        """The effect for the next frame (its k for this step); counts the frame."""
        k = self.ramp.k_at(self.step)
        if not math.isclose(k, self.effect.k, rel_tol=0, abs_tol=1e-12):
            self.effect = self.effect.with_params(k=k)  # its run continues the episode
        self.step += 1
        return self.effect


class RampRun(EffectRun):
    """One episode of a :class:`Ramp`: the frame count and the run of the effect at the current k."""

    effect: Ramp
    episode: _RampEpisode

    def restart(self, seed: SeedLike = None) -> None:
        self.rng = np.random.default_rng(check_seed(seed, self.effect.name))
        self.episode = _RampEpisode(self.effect, seed)

    @property
    def step(self) -> int:
        """Frames processed in this episode."""
        return self.episode.step

    @property
    def current(self) -> KnobEffect:
        return self.episode.effect

    def sample(self, shape: tuple[int, ...], rng: np.random.Generator | None = None) -> Any:
        return self.episode.draw(tuple(shape), rng)
