"""Weather specs: every way a user can write weather, parsed into one effect, and back.

``parse_weather`` accepts

* ``None``, ``"clear"``, ``"none"``, ``{}``, ``[]``: no weather (an empty :class:`Compose`); an empty or
  blank string is an error (usually a variable that expanded to nothing), not silently clear;
* an effect, a :class:`Compose` or a :class:`Ramp`: returned as is;
* ``{"droplets": 0.55, "dim": 0.3}`` (name -> k) or ``{"droplets": {"k": 0.55, "persistent": True}}``;
* ``"droplets:0.55,dim:0.3"``, with parameters ``"dim:0.5:mode=physical"`` (``NAME:K:PARAM=VALUE:...``,
  values read as JSON, else as text);
* presets ``"droplets@3"``, ``"low_light@2"``, ``("low_light", 2)`` (see :mod:`.presets`);
* the list of effect tables of model files, ``[{"name": "dim", "k": 0.6, ...}]`` (a TOML
  ``[[effects]]`` array), where ``{"name": "ramp", "effect": "dim", "k_start": ..., ...}`` is a ramp;
* a list mixing all of the above (applied in order).

Commands that vary k themselves (sweeps) take the same strings with k left open:
``"droplets,dim:k:mode=physical"`` (``NAME`` or ``NAME:k:PARAM=VALUE:...``), read by
:func:`parse_open_k`.

One effect comes back as itself, several as a ``Compose``. ``to_spec`` is the inverse: a list of
plain tables, JSON/TOML serialisable, with every parameter.

Example:
    >>> from weather_gym.weather import parse_weather, to_spec
    >>> w = parse_weather("droplets:0.55,dim:0.3")
    >>> to_spec(w)[1]["name"], to_spec(w)[1]["k"]
    ('dim', 0.3)
    >>> parse_weather(to_spec(w)) == w
    True
    >>> to_spec(parse_weather("low_light@3"))[0]["name"]   # a calibrated preset
    'dim'
"""

from __future__ import annotations

import json
import numbers
from collections.abc import Mapping, Sequence
from typing import Any

from weather_gym.errors import InputError
from weather_gym.weather.base import Effect, EffectRun, KnobEffect
from weather_gym.weather.compose import Compose
from weather_gym.weather.presets import preset_spec
from weather_gym.weather.registry import RESERVED, make
from weather_gym.weather.schedule import Ramp
from weather_gym.weather.tables import effect_from_table

__all__ = ["current_spec", "parse_open_k", "parse_weather", "to_spec"]

_CLEAR = ("clear", "none")


def _number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _from_item(name: Any, value: Any) -> Effect:
    if not isinstance(name, str):
        raise InputError(f"weather spec key {name!r} must be an effect name")
    if _number(value):
        return make(name, k=value)
    if isinstance(value, Mapping):
        if "k" not in value:
            raise InputError(f"weather spec {name!r}: parameters {dict(value)!r} need 'k'")
        if "name" in value:
            raise InputError(f"weather spec {name!r}: 'name' is reserved (the effect's own name, the key of "
                             f"this table), not a parameter")
        return make(name, **value)
    raise InputError(f"weather spec {name!r}: expected k (a number in [0, 1]) or a table of parameters, "
                     f"got {value!r}")


def _preset(condition: Any, severity: Any) -> list[Effect]:
    return [effect_from_table(t) for t in preset_spec(condition, severity)]


def _param_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _from_string(text: str) -> list[Effect]:
    if not text.strip():
        raise InputError("empty weather spec; write 'clear' for no weather, or e.g. 'droplets:0.55' or 'low_light@2'")
    if text.strip().lower() in _CLEAR:
        return []
    out: list[Effect] = []
    for raw in text.split(","):
        item = raw.strip()
        if "@" in item:
            cond, _, sev = item.partition("@")
            try:
                severity = int(sev)
            except ValueError:
                raise InputError(f"weather spec item {item!r}: severity {sev!r} must be an integer 0-4") from None
            out += _preset(cond.strip(), severity)
        elif ":" in item:
            name, k, *params = (p.strip() for p in item.split(":"))
            try:
                kv = float(k)
            except ValueError:
                raise InputError(f"weather spec item {item!r}: k {k!r} must be a number in [0, 1] "
                                 "(the form is NAME:K or NAME:K:PARAM=VALUE:...)") from None
            out.append(make(name, k=kv, **_item_params(item, params)))
        else:
            raise InputError(f"weather spec item {item!r} must be NAME:K (e.g. droplets:0.55) or "
                             f"CONDITION@SEVERITY (e.g. droplets@3), or 'clear'")
    return out


def _item_params(item: str, params: list[str]) -> dict[str, Any]:
    kwargs: dict[str, Any] = {}
    for p in params:
        key, sep, value = p.partition("=")
        if not sep or not key.strip():
            raise InputError(f"weather spec item {item!r}: parameter {p!r} must be PARAM=VALUE "
                             "(the form is NAME:K:PARAM=VALUE:..., e.g. dim:0.5:mode=physical)")
        if key.strip() in RESERVED:
            raise InputError(f"weather spec item {item!r}: {key.strip()!r} is reserved, not a parameter "
                             "(the form is NAME:K:PARAM=VALUE:...; k is the number after the name)")
        kwargs[key.strip()] = _param_value(value.strip())
    return kwargs


def parse_open_k(text: str) -> list[tuple[str, dict[str, Any]]]:
    """A weather spec string with k left open -> ``[(effect name, parameters), ...]`` (validated).

    Each comma-separated item is ``NAME`` or ``NAME:k:PARAM=VALUE:...``: the spec grammar with the
    letter ``k`` where the number goes, for commands that choose k themselves (sweeps).

    Example:
        >>> parse_open_k("droplets,dim:k:mode=physical")
        [('droplets', {}), ('dim', {'mode': 'physical'})]
    """
    if not isinstance(text, str) or not text.strip():
        raise InputError(f"expected effects with k left open, e.g. 'droplets,dim:k:mode=physical', got {text!r}")
    out = []
    for raw in text.split(","):
        item = raw.strip()
        name, *rest = (p.strip() for p in item.split(":"))
        if "@" in item or (rest and rest[0] != "k"):
            raise InputError(f"weather spec item {item!r}: here k is left open (it is varied); write NAME or "
                             f"NAME:k[:PARAM=VALUE...], e.g. droplets or dim:k:mode=physical")
        kwargs = _item_params(item, rest[1:])
        if "k" in kwargs:
            raise InputError(f"weather spec item {item!r}: k is left open here (it is varied), not a parameter")
        make(name, k=0.0, **kwargs)  # names an unknown effect or parameter
        out.append((name, kwargs))
    return out


def _effects(spec: Any) -> list[Effect]:
    if spec is None:
        return []
    if isinstance(spec, Compose):
        return list(spec.effects)
    if isinstance(spec, Effect):
        return [spec]
    if isinstance(spec, str):
        return _from_string(spec)
    if (isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str)
            and isinstance(spec[1], numbers.Integral) and not isinstance(spec[1], bool)):
        return _preset(spec[0], spec[1])
    if isinstance(spec, Mapping):
        if "name" in spec or "k" in spec:
            return [effect_from_table(spec)]
        return [_from_item(name, value) for name, value in spec.items()]
    if isinstance(spec, Sequence):
        out: list[Effect] = []
        for item in spec:
            out += _effects(item)
        return out
    raise InputError(f"cannot read weather spec {spec!r}: expected None, 'clear', an effect, "
                     f"{{name: k}}, 'name:k,...', 'condition@severity' or a list of {{name, k, ...}} tables")


def parse_weather(spec: Any) -> Effect:
    """Parse any weather spec (see module doc) into one effect; errors name the bad part."""
    if isinstance(spec, Effect):
        return spec
    effects = _effects(spec)
    return effects[0] if len(effects) == 1 else Compose(effects)


def to_spec(effect: Effect) -> list[dict[str, Any]]:
    """The list of effect tables that :func:`parse_weather` turns back into ``effect``."""
    if isinstance(effect, Compose):
        return [t for e in effect.effects for t in to_spec(e)]
    if isinstance(effect, KnobEffect | Ramp):
        return [{"name": effect.name, **effect.params()}]
    raise InputError(f"cannot write {type(effect).__name__} as a weather spec")


def current_spec(weather: Effect | EffectRun) -> list[dict[str, Any]]:
    """Like :func:`to_spec`, but a ramp appears as its effect with the k of the last frame it made.

    ``weather``: a run (:meth:`Effect.start`), or an effect (then its own run).
    """
    return to_spec(weather.current)
