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
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from weather_gym.core.errors import InputError
from weather_gym.weather.base import Effect, EffectRun, KnobEffect
from weather_gym.weather.compose import Compose
from weather_gym.weather.presets import canonical_condition, preset_source, preset_spec
from weather_gym.weather.registry import RESERVED, make
from weather_gym.weather.schedule import Ramp
from weather_gym.weather.tables import effect_from_table

__all__ = ["WeatherSpec", "current_spec", "parse_open_k", "parse_weather", "preset_items", "to_spec",
           "weather_source"]

_CLEAR = ("clear", "none")


@dataclass(frozen=True)
class WeatherSpec:
    """A weather spec with the presets file its ``CONDITION@SEVERITY`` items read (None: the shipped pool
    presets, or ``$WEATHER_GYM_PRESETS``): what ``make_env(weather=..., presets=...)`` hands down to the
    ``WeatherWrapper``, so an env built from a resolved presets file says so in ``info["weather_source"]``.

    Example:
        >>> WeatherSpec("low_light@2").source
        'pool'
        >>> WeatherSpec("droplets:0.5").source
        'given'
    """

    spec: Any
    presets: str | os.PathLike | None = None

    @property
    def source(self) -> str:
        return weather_source(self.spec, self.presets)


def _uses_preset(spec: Any) -> bool:
    if isinstance(spec, WeatherSpec):
        return _uses_preset(spec.spec)
    if isinstance(spec, str):
        return "@" in spec
    if (isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str)
            and isinstance(spec[1], numbers.Integral) and not isinstance(spec[1], bool)):
        return True
    if isinstance(spec, Sequence) and not isinstance(spec, str | bytes):
        return any(_uses_preset(x) for x in spec)
    return False


def preset_items(spec: Any) -> list[tuple[str, int]]:
    """The ``(condition, severity)`` items of ``spec`` that read a presets table (``CONDITION@SEVERITY``
    strings, ``(condition, severity)`` tuples), canonical names; explicit ``NAME:K`` items and effects are not.

    Example:
        >>> preset_items("low_light@2,droplets:0.3"), preset_items({"dim": 0.5})
        ([('low_light', 2)], [])
    """
    if isinstance(spec, WeatherSpec):
        return preset_items(spec.spec)
    if isinstance(spec, str):
        out = []
        for raw in spec.split(","):
            cond, at, sev = raw.strip().partition("@")
            if at and sev.strip().lstrip("-").isdigit():
                out.append((canonical_condition(cond.strip()), int(sev)))
        return out
    if (isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str)
            and isinstance(spec[1], numbers.Integral) and not isinstance(spec[1], bool)):
        return [(canonical_condition(spec[0]), int(spec[1]))]
    if isinstance(spec, Sequence) and not isinstance(spec, bytes | Mapping):
        return [x for item in spec for x in preset_items(item)]
    return []


def weather_source(spec: Any, presets: str | os.PathLike | None = None) -> str:
    """Where the k's of ``spec`` come from: ``"given"`` (no ``CONDITION@SEVERITY`` in it: every k is
    written out and never changed), else the presets' :func:`~weather_gym.weather.presets.preset_source`
    (``"pool"``, ``"resolved"`` or ``"file"``).

    Example:
        >>> weather_source("droplets@3"), weather_source({"dim": 0.5})
        ('pool', 'given')
    """
    if isinstance(spec, WeatherSpec):
        presets = spec.presets if spec.presets is not None else presets
    return preset_source(presets) if _uses_preset(spec) else "given"


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


def _preset(condition: Any, severity: Any, presets: Any = None) -> list[Effect]:
    return [effect_from_table(t) for t in preset_spec(condition, severity, presets)]


def _param_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _from_string(text: str, presets: Any = None) -> list[Effect]:
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
            out += _preset(cond.strip(), severity, presets)
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


def _effects(spec: Any, presets: Any = None) -> list[Effect]:
    if spec is None:
        return []
    if isinstance(spec, WeatherSpec):
        return _effects(spec.spec, spec.presets if spec.presets is not None else presets)
    if isinstance(spec, Compose):
        return list(spec.effects)
    if isinstance(spec, Effect):
        return [spec]
    if isinstance(spec, str):
        return _from_string(spec, presets)
    if (isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str)
            and isinstance(spec[1], numbers.Integral) and not isinstance(spec[1], bool)):
        return _preset(spec[0], spec[1], presets)
    if isinstance(spec, Mapping):
        if "name" in spec or "k" in spec:
            return [effect_from_table(spec)]
        return [_from_item(name, value) for name, value in spec.items()]
    if isinstance(spec, Sequence):
        out: list[Effect] = []
        for item in spec:
            out += _effects(item, presets)
        return out
    raise InputError(f"cannot read weather spec {spec!r}: expected None, 'clear', an effect, "
                     f"{{name: k}}, 'name:k,...', 'condition@severity' or a list of {{name, k, ...}} tables")


def parse_weather(spec: Any, presets: str | os.PathLike | None = None) -> Effect:
    """Parse any weather spec (see module doc) into one effect; errors name the bad part.

    ``presets``: the presets file ``CONDITION@SEVERITY`` items read (None: ``$WEATHER_GYM_PRESETS``, else the
    shipped pool presets); a :class:`WeatherSpec` brings its own. Explicit ``NAME:K`` items never change.
    """
    if isinstance(spec, Effect):
        return spec
    effects = _effects(spec, presets)
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
