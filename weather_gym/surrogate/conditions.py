"""Which surrogate condition a weather spec is: ``(condition, k)``.

The model is fitted per weather condition (``droplets``, ``low_light``) at the calibrated presets'
``k`` and interpolated in ``k`` between them; clear weather is ``("clear", 0.0)``, the shared
``k = 0`` end of every condition. A spec is one effect of a modelled kind (or none); anything else
(two effects at once, rain, fog, ...) is an :class:`~weather_gym.errors.InputError`, because the
surrogate knows nothing about it.

Example:
    >>> from weather_gym.surrogate.conditions import condition_of
    >>> condition_of("clear"), condition_of({"dim": 0.8}), condition_of({"droplets": 0.3})
    (('clear', 0.0), ('low_light', 0.8), ('droplets', 0.3))
    >>> from weather_gym.weather.presets import preset_spec
    >>> condition_of("low_light@2") == ("low_light", preset_spec("low_light", 2)[0]["k"])
    True
"""

from __future__ import annotations

from typing import Any

from weather_gym.errors import InputError
from weather_gym.weather import EFFECTS, current_spec, parse_weather

__all__ = ["EFFECT_CONDITION", "condition_defaults", "condition_of", "effect_params"]

EFFECT_CONDITION = {"droplets": "droplets", "dim": "low_light"}
"""Weather effect name -> surrogate condition."""


def _tables(weather: Any) -> list[dict[str, Any]]:
    """The spec as effect tables with every parameter filled in (defaults included)."""
    return current_spec(parse_weather(weather))


def condition_of(weather: Any) -> tuple[str, float]:
    """``(condition, k)`` of a weather spec (anything ``parse_weather`` takes, or a list of effect tables)."""
    tables = [t for t in _tables(weather) if float(t.get("k", 0.0)) > 0.0]
    if not tables:
        return "clear", 0.0
    if len(tables) > 1:
        raise InputError(f"the perception surrogate models one weather effect at a time, got "
                         f"{', '.join(str(t.get('name')) for t in tables)}")
    name = str(tables[0].get("name"))
    if name not in EFFECT_CONDITION:
        raise InputError(f"the perception surrogate has no model of weather effect {name!r}; modelled: "
                         f"{', '.join(EFFECT_CONDITION)} (conditions {', '.join(EFFECT_CONDITION.values())}, "
                         f"and clear)")
    return EFFECT_CONDITION[name], round(float(tables[0]["k"]), 6)


def effect_params(weather: Any) -> dict[str, Any]:
    """The effect's parameters other than ``k`` and ``name`` (``{}`` for clear): what a model was fitted with."""
    tables = [t for t in _tables(weather) if float(t.get("k", 0.0)) > 0.0]
    if not tables:
        return {}
    return {key: value for key, value in tables[0].items() if key not in ("k", "name")}


def condition_defaults(condition: str) -> dict[str, Any]:
    """Default parameters (other than ``k``) of the effect behind a condition (``{}`` if none).

    A model fitted before an effect gained a parameter was fitted with that parameter's default
    (a new parameter's default keeps the effect as it was).
    """
    names = [name for name, cond in EFFECT_CONDITION.items() if cond == condition]
    if not names:
        return {}
    return {key: value for key, value in EFFECTS.get(names[0])().params().items() if key != "k"}
