"""The registry of weather effects: ``EFFECTS`` and ``make(name, k=..., **params)``.

Example:
    >>> from weather_gym.weather import EFFECTS, make
    >>> "droplets" in EFFECTS
    True
    >>> make("droplets", k=0.55).params()["k"]
    0.55
    >>> make("snow")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: unknown weather effect 'snow'; valid names: blur, dim, droplets, ...
"""

from __future__ import annotations

from typing import Any, TypeVar

from weather_gym.core.errors import check_known
from weather_gym.core.registry import Registry
from weather_gym.weather.base import KnobEffect

__all__ = ["EFFECTS", "make", "register_effect"]

#: name -> effect class (each a :class:`~weather_gym.weather.base.KnobEffect`).
EFFECTS: Registry[type[KnobEffect]] = Registry("weather effect")

E = TypeVar("E", bound=type[KnobEffect])


def register_effect(cls: E) -> E:
    """Class decorator: register an effect class under its ``name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    nominal = cls.NOMINAL_K
    if nominal is not None and (len(nominal) != 4 or not all(0.0 <= k <= 1.0 for k in nominal)):
        raise TypeError(f"{cls.__name__}.NOMINAL_K must be the k of severities 1-4, each in [0, 1] (or None), "
                        f"got {nominal!r}")
    EFFECTS.register(cls.name, cls)
    return cls


RESERVED = ("k", "name")
"""Names a weather item uses itself (its severity and its effect), so no effect has a parameter by them."""


def make(name: str, k: float = 0.0, **params: Any) -> KnobEffect:
    """Build the effect ``name`` with severity ``k`` and optional physical parameters."""
    cls = EFFECTS.get(name)
    check_known(params, cls.param_names(), what=name, kind="parameter")
    return cls(k=k, **params)
