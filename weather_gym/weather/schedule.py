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

import dataclasses
import math
import numbers
from typing import Any, ClassVar

import numpy as np

from weather_gym.errors import InputError
from weather_gym.weather.base import Effect, KnobEffect, SeedLike
from weather_gym.weather.registry import make

__all__ = ["Ramp"]


@dataclasses.dataclass(frozen=True, init=False)
class Ramp(Effect):
    """Effect ``effect`` whose k goes linearly from ``k_start`` to ``k_end`` over ``steps`` frames, then holds."""

    name: ClassVar[str] = "ramp"
    stateful: ClassVar[bool] = True

    effect: str
    k_start: float
    k_end: float
    steps: int
    effect_params: tuple[tuple[str, Any], ...]

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
        object.__setattr__(self, "effect", effect)
        object.__setattr__(self, "k_start", float(k_start))
        object.__setattr__(self, "k_end", float(k_end))
        object.__setattr__(self, "steps", int(steps))
        object.__setattr__(self, "effect_params", tuple(sorted(params.items())))
        object.__setattr__(self, "_rng", None)
        self._reset_state()

    def k_at(self, step: int) -> float:
        """k after ``step`` frames of the episode."""
        return self.k_start + (self.k_end - self.k_start) * min(step / self.steps, 1.0)

    @property
    def step(self) -> int:
        """Frames processed in this episode."""
        return self._step

    @property
    def current(self) -> KnobEffect:
        """The effect (with its k) that the next frame gets."""
        return self._current

    @property
    def k(self) -> float:
        return self._current.k

    def params(self) -> dict[str, Any]:
        return {"effect": self.effect, "k_start": self.k_start, "k_end": self.k_end, "steps": self.steps,
                **dict(self.effect_params)}

    def reset(self, seed: SeedLike = None) -> None:
        super().reset(seed)
        self._current.reset(seed)

    def _reset_state(self) -> None:
        object.__setattr__(self, "_step", 0)
        object.__setattr__(self, "_current", make(self.effect, k=self.k_start, **dict(self.effect_params)))

    def _episode_rng(self) -> np.random.Generator:
        if self._rng is None:
            self.reset(None)
        return self._rng

    def _process(self, img, depth, state, rng, batched):
        if not batched:
            return self._frame(img, depth, state, rng)
        out = np.empty_like(img)
        for i in range(img.shape[0]):  # each frame written straight into the batch
            cur = self._advance()
            cur._run_into(img[i], None if depth is None else depth[i], state[i],
                          rng if rng is not None else cur._episode_rng(), out[i])
        return out

    def _advance(self) -> KnobEffect:
        """The effect for the next frame (its k for this step); counts the frame."""
        if self._rng is None:
            self.reset(None)
        k = self.k_at(self._step)
        if not math.isclose(k, self._current.k, rel_tol=0, abs_tol=1e-12):
            object.__setattr__(self, "_current", self._current.with_params(k=k))
        object.__setattr__(self, "_step", self._step + 1)
        return self._current

    def _frame(self, img, depth, state, rng):
        return self._advance()._process(img, depth, state, rng, False)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"Ramp({args})"
