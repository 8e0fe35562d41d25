"""Which surrogate condition a weather spec is: ``(condition, k)``, and the fallback for nominal effects.

The model is fitted per weather condition (``droplets``, ``low_light``) at the calibrated presets'
``k`` and interpolated in ``k`` between them; clear weather is ``("clear", 0.0)``, the shared
``k = 0`` end of every condition. Another registered effect (``rain``, ``fog``, ``blur``...: the
*nominal* presets, whose ``k`` was chosen, not calibrated) is its own condition, named after the
effect: a model fitted with logs of it covers it. A model without it falls back to **clear weather**
(:func:`split_nominal`, :data:`FALLBACK`) with a :class:`SurrogateFallbackWarning`: nothing measured
says how much such an effect hurts the detector, so the surrogate does not invent a damage level; it
reports what the detector sees without that effect, and says so. Two effects at once that the model
covers are an :class:`~weather_gym.core.errors.InputError`; an unknown effect name fails in ``parse_weather``.

Example:
    >>> from weather_gym.surrogate.conditions import condition_of, split_nominal
    >>> condition_of("clear"), condition_of({"dim": 0.8}), condition_of({"droplets": 0.3})
    (('clear', 0.0), ('low_light', 0.8), ('droplets', 0.3))
    >>> from weather_gym.weather.presets import preset_spec
    >>> condition_of("low_light@2") == ("low_light", preset_spec("low_light", 2)[0]["k"])
    True
    >>> condition_of("rain@2")
    ('rain', 0.5)
    >>> kept, dropped = split_nominal("rain@2", ["clear", "droplets", "low_light"])
    >>> kept, [t["name"] for t in dropped]
    ([], ['rain'])
"""

from __future__ import annotations

from typing import Any

from weather_gym.core.errors import InputError
from weather_gym.weather import EFFECTS, current_spec, parse_weather

__all__ = ["EFFECT_CONDITION", "FALLBACK", "SurrogateFallbackWarning", "condition_defaults", "condition_of",
           "effect_params", "fallback_note", "split_nominal"]

EFFECT_CONDITION = {"droplets": "droplets", "dim": "low_light"}
"""Weather effect name -> surrogate condition (the calibrated ones; any other effect is its own condition)."""

FALLBACK = "clear"
"""What a model without an effect's condition reports for it: the detector in clear weather."""


class SurrogateFallbackWarning(UserWarning):
    """A weather effect the surrogate model has no fit of is modelled as clear weather (:data:`FALLBACK`)."""


def _tables(weather: Any) -> list[dict[str, Any]]:
    """The spec as effect tables with every parameter filled in (defaults included)."""
    return current_spec(parse_weather(weather))


def condition_of(weather: Any) -> tuple[str, float]:
    """``(condition, k)`` of a weather spec (anything ``parse_weather`` takes, or a list of effect tables):
    the calibrated effects' conditions (:data:`EFFECT_CONDITION`), any other effect under its own name."""
    tables = [t for t in _tables(weather) if float(t.get("k", 0.0)) > 0.0]
    if not tables:
        return "clear", 0.0
    if len(tables) > 1:
        raise InputError(f"the perception surrogate models one weather effect at a time, got "
                         f"{', '.join(str(t.get('name')) for t in tables)}")
    name = str(tables[0].get("name"))
    return EFFECT_CONDITION.get(name, name), round(float(tables[0]["k"]), 6)


def split_nominal(weather: Any, conditions: Any) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The spec's active effect tables split into (those a model with ``conditions`` covers, the others):
    the others are modelled as :data:`FALLBACK` (see the module doc)."""
    kept: list[dict[str, Any]] = []
    dropped: list[dict[str, Any]] = []
    for t in _tables(weather):
        if float(t.get("k", 0.0)) <= 0.0:
            continue
        name = str(t.get("name"))
        (kept if EFFECT_CONDITION.get(name, name) in conditions else dropped).append(t)
    return kept, dropped


def fallback_note(dropped: list[dict[str, Any]], *, with_k: bool = True) -> str:
    """The one line that says which effects were modelled as clear weather, and why; ``with_k=False``
    leaves out their k (the warning's text: one warning per effect, whatever its severity)."""
    names = ", ".join(f"{t.get('name')}" + (f" (k {float(t.get('k', 0.0)):g})" if with_k else "") for t in dropped)
    return (f"perception surrogate: no fit of weather effect {names}: modelled as {FALLBACK} weather, i.e. the "
            f"detector's cone list without that effect (a nominal preset, its damage not measured; "
            f"docs/surrogate.md, 'Nominal effects')")


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
    names = [name for name, cond in EFFECT_CONDITION.items() if cond == condition] or [condition]
    if names[0] not in EFFECTS:
        return {}
    return {key: value for key, value in EFFECTS.get(names[0])().params().items() if key != "k"}
