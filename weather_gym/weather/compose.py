"""``Compose``: several effects applied in order, itself an effect.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import Compose, make
    >>> weather = Compose([make("droplets", k=0.55), make("dim", k=0.3)])
    >>> weather.reset(7)
    >>> weather(np.zeros((376, 672, 3), np.uint8)).shape
    (376, 672, 3)
    >>> int(Compose([])(np.ones((2, 2, 3), np.uint8)).sum())   # no effect: an exact copy
    12
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np

from weather_gym.errors import InputError
from weather_gym.weather.base import Effect, SeedLike, check_seed

__all__ = ["Compose"]


@dataclasses.dataclass(frozen=True, init=False)
class Compose(Effect):
    """Apply ``effects`` one after the other (each gets the depth, state and generator)."""

    name: ClassVar[str] = "compose"

    effects: tuple[Effect, ...]

    def __init__(self, effects: Iterable[Effect] = ()) -> None:
        effects = tuple(effects)
        for i, e in enumerate(effects):
            if not isinstance(e, Effect):
                raise InputError(f"compose: item {i} must be a weather effect, got {type(e).__name__}")
        object.__setattr__(self, "effects", effects)
        object.__setattr__(self, "_rng", None)

    @property
    def stateful(self) -> bool:  # type: ignore[override]
        return any(e.stateful for e in self.effects)

    def reset(self, seed: SeedLike = None) -> None:
        """New episode: each effect is reset with its own child of ``SeedSequence(seed)``."""
        ss = check_seed(seed, self.name)
        object.__setattr__(self, "_rng", np.random.default_rng(ss))
        for e, child in zip(self.effects, ss.spawn(len(self.effects)), strict=True):
            e.reset(child)

    def params(self) -> dict[str, Any]:
        return {"effects": [e.params() | {"name": e.name} for e in self.effects]}

    def _episode_rng(self) -> np.random.Generator:
        if self._rng is None:
            self.reset(None)
        return self._rng

    def _process(self, img, depth, state, rng, batched):
        if rng is None:
            self._episode_rng()  # children get their seeds from the default seed on first use
        out = img
        for e in self.effects:
            out = np.ascontiguousarray(e._process(out, depth, state, rng, batched))
        return out if out is not img else img.copy()

    def __len__(self) -> int:
        return len(self.effects)

    def __iter__(self):
        return iter(self.effects)

    def __repr__(self) -> str:
        return f"Compose({list(self.effects)!r})"
