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

from collections.abc import Iterable, Iterator
from typing import Any, cast

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.weather.base import Effect, EffectRun, SeedLike, check_seed

__all__ = ["Compose", "ComposeRun"]


class Compose(Effect):
    """Apply ``effects`` one after the other (each gets the depth, state and generator). Immutable."""

    name = "compose"

    def __init__(self, effects: Iterable[Effect] = ()) -> None:
        effects = tuple(effects)
        for i, e in enumerate(effects):
            if not isinstance(e, Effect):
                raise InputError(f"compose: item {i} must be a weather effect, got {type(e).__name__}")
        self._effects = effects

    @property
    def effects(self) -> tuple[Effect, ...]:
        return self._effects

    @property
    def stateful(self) -> bool:  # type: ignore[override]  # a ClassVar in Effect; here it depends on the effects
        return any(e.stateful for e in self.effects)

    def start(self, seed: SeedLike = None) -> ComposeRun:
        """A new episode: each effect gets a run seeded with its own child of ``SeedSequence(seed)``."""
        return ComposeRun(self, seed)

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any = None) -> tuple[Any, ...]:
        """One draw per effect, in order (``episode``: the effects' episode states, or None)."""
        episodes = episode if episode is not None else [e.new_episode() for e in self.effects]
        return tuple(e.sample(rng, shape, ep) for e, ep in zip(self.effects, episodes, strict=True))

    def params(self) -> dict[str, Any]:
        return {"effects": [e.params() | {"name": e.name} for e in self.effects]}

    def _render(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: Any,
                batched: bool) -> np.ndarray:
        out = img
        for e, d in zip(self.effects, draw, strict=True):
            out = np.ascontiguousarray(e._render(out, d, depth, state, batched))
        return out if out is not img else img.copy()

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Compose) and self.effects == other.effects

    def __hash__(self) -> int:
        return hash(("compose", self.effects))

    def __len__(self) -> int:
        return len(self.effects)

    def __iter__(self) -> Iterator[Effect]:
        return iter(self.effects)

    def __repr__(self) -> str:
        return f"Compose({list(self.effects)!r})"


class ComposeRun(EffectRun):
    """One episode of a :class:`Compose`: a run per effect; a frame goes through them in order."""

    effect: Compose
    runs: list[EffectRun]

    def restart(self, seed: SeedLike = None) -> None:
        ss = check_seed(seed, self.effect.name)
        self.runs = [e.start(child) for e, child in zip(self.effect.effects, ss.spawn(len(self.effect)), strict=True)]
        self.rng = np.random.default_rng(ss)
        self.episode = [r.episode for r in self.runs]

    def adopt(self, other: EffectRun) -> None:
        super().adopt(other)
        self.runs = cast(ComposeRun, other).runs

    @property
    def current(self) -> Compose:
        return Compose(r.current for r in self.runs)

    def sample(self, shape: tuple[int, ...], rng: np.random.Generator | None = None) -> Any:
        return tuple(r.sample(shape, rng) for r in self.runs)

    def _produce(self, img: np.ndarray, depth: np.ndarray | None, state: Any,
                 rng: np.random.Generator | None, batched: bool) -> np.ndarray:
        out = img
        for r in self.runs:  # each effect samples right before it renders
            out = np.ascontiguousarray(r._produce(out, depth, state, rng, batched))
        return out if out is not img else img.copy()
