"""One registry per kind of thing (effects, agents, tracks, env ids).

Example:
    >>> from weather_gym.core.registry import Registry
    >>> shapes = Registry("shape")
    >>> @shapes.register("square")
    ... def square(n): return n * n
    >>> shapes.get("square")(3)
    9
    >>> shapes.get("circle")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: unknown shape 'circle'; valid names: square
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, TypeVar, overload

from weather_gym.core.errors import InputError

T = TypeVar("T")


def add_unique(items: dict[str, T], kind: str, name: str, obj: T) -> T:
    """Put ``obj`` in ``items`` under ``name``; a name already taken by another object is an error.

    The one registration rule: :class:`Registry` uses it, and so do the registries kept as plain
    ordered dicts because their order means something (perception modes, metrics).
    """
    if name in items and items[name] is not obj:
        raise InputError(f"{kind} {name!r} is already registered")
    items[name] = obj
    return obj


class Registry(Generic[T]):
    """A name -> object mapping whose lookup errors list the valid names."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, T] = {}

    @overload
    def register(self, name: str) -> Callable[[T], T]: ...
    @overload
    def register(self, name: str, obj: T) -> T: ...
    def register(self, name: str, obj: T | None = None) -> Callable[[T], T] | T:
        """Register ``obj`` under ``name``; without ``obj`` acts as a decorator."""

        def _add(o: T) -> T:
            return add_unique(self._items, self.kind, name, o)

        return _add if obj is None else _add(obj)

    def get(self, name: str) -> T:
        try:
            return self._items[name]
        except KeyError:
            raise InputError(
                f"unknown {self.kind} {name!r}; valid names: {', '.join(sorted(self._items))}"
            ) from None

    __getitem__ = get

    def names(self) -> list[str]:
        return sorted(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._items))

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"
