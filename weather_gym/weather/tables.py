"""Effect tables (``{"name": "dim", "k": 0.6, ...}``, a TOML ``[[effects]]`` entry) to effects.

The one reader of tables, below both :mod:`.spec` (every spec form) and :mod:`.presets` (whose
file holds tables), so neither imports the other's reader.

Example:
    >>> from weather_gym.weather.tables import effect_from_table
    >>> effect_from_table({"name": "dim", "k": 0.5, "mode": "physical"}).params()["mode"]
    'physical'
    >>> effect_from_table({"name": "ramp", "effect": "dim", "k_end": 0.8}).k_end
    0.8
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from weather_gym.core.errors import InputError, check_known
from weather_gym.weather.base import Effect, KnobEffect, param_schema
from weather_gym.weather.compose import Compose
from weather_gym.weather.registry import EFFECTS, make
from weather_gym.weather.schedule import Ramp

__all__ = ["effect_from_table", "effect_table_schema"]


def effect_from_table(table: Mapping[str, Any]) -> Effect:
    """The effect (a ``ramp`` or ``compose`` table included) that ``table`` describes; errors name it."""
    if not isinstance(table, Mapping):
        raise InputError(f"expected a weather table {{name, k, ...}}, got {table!r}")
    name = table.get("name")
    if not isinstance(name, str):
        raise InputError(f"weather table {dict(table)!r} needs a 'name' (one of {', '.join(EFFECTS.names())}, ramp)")
    rest = {k: v for k, v in table.items() if k != "name"}
    if name == "ramp":
        if "effect" not in rest:
            raise InputError(f"weather table {dict(table)!r}: a ramp needs 'effect'")
        return Ramp(**rest)
    if name == "compose":
        check_known(rest, ("effects",), what=f"weather table {dict(table)!r}", kind="key",
                    hint=" (a compose table holds only 'name' and 'effects', a list of effect tables)")
        effects = rest.get("effects", [])
        if isinstance(effects, (str, bytes, Mapping)) or not isinstance(effects, Sequence):
            raise InputError(f"weather table {dict(table)!r}: 'effects' must be a list of effect tables, got {effects!r}")
        return Compose([effect_from_table(t) for t in effects])
    if "k" not in rest:
        raise InputError(f"weather table {dict(table)!r} needs 'k' (severity in [0, 1])")
    return make(name, **rest)


def effect_table_schema(effects: Mapping[str, type[KnobEffect]] | None = None) -> dict[str, Any]:
    """The JSON Schema of one effect table: one alternative per effect (its ``name`` and its parameters with
    their types, ranges and choices, from :func:`~weather_gym.weather.base.param_schema`; ``k`` required),
    plus ``ramp`` and ``compose`` tables. ``effects``: name -> class (default: every registered effect).

    Example:
        >>> alternatives = effect_table_schema()["oneOf"]
        >>> dim = next(a for a in alternatives if a["properties"]["name"] == {"const": "dim"})
        >>> dim["properties"]["k"]["maximum"], dim["required"]
        (1.0, ['name', 'k'])
    """
    chosen = effects if effects is not None else {name: EFFECTS.get(name) for name in EFFECTS.names()}
    tables: list[dict[str, Any]] = []
    for name, cls in chosen.items():
        params = param_schema(cls).model_json_schema()
        tables.append({"type": "object", "title": name, "properties": {"name": {"const": name}, **params["properties"]},
                       "required": ["name", "k"], "additionalProperties": False})
    tables.append({"type": "object", "title": "ramp", "properties": {"name": {"const": "ramp"}},
                   "required": ["name", "effect"]})
    tables.append({"type": "object", "title": "compose",
                   "properties": {"name": {"const": "compose"}, "effects": {"type": "array"}},
                   "required": ["name"], "additionalProperties": False})
    return {"oneOf": tables}
