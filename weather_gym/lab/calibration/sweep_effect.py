"""An effect to sweep: :class:`SweepEffect` (a registry name and its fixed parameters) and
:func:`parse_effect`, the ``--effect NAME[:PARAM=VALUE,...]`` grammar of ``weather-gym sweep``.

The curve file (:mod:`weather_gym.lab.calibration.curve`) and the sweep
(:mod:`weather_gym.lab.calibration.sweep`) both build on it.

Example:
    >>> from weather_gym.lab.calibration.sweep_effect import parse_effect
    >>> e = parse_effect("dim:mode=physical")
    >>> e.label, e.name, e.params
    ('dim_physical', 'dim', {'mode': 'physical'})
    >>> e.table(0.5)
    {'name': 'dim', 'k': 0.5, 'mode': 'physical'}
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from weather_gym.core.errors import InputError
from weather_gym.weather import EFFECTS, make

__all__ = ["SweepEffect", "parse_effect"]


def _value(text: str) -> Any:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return text.strip()


@dataclass(frozen=True)
class SweepEffect:
    """An effect to sweep: its registry ``name`` and fixed non-``k`` ``params`` (canonical: defaults dropped).

    ``label`` names its curve: the name, then the non-default parameters, a choice by its value and
    any other as ``param=value`` (``dim`` + ``mode="physical"`` -> ``dim_physical``; + ``stops=10``
    -> ``dim_physical_stops=10.0``), so two effects with different parameters never share a label.
    """

    name: str
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        choices = getattr(EFFECTS.get(self.name), "CHOICES", {}) if self.name in EFFECTS else {}
        items = sorted(self.params.items(), key=lambda kv: (kv[0] not in choices, kv[0]))
        parts = [str(v) if p in choices else f"{p}={v}" for p, v in items]
        return "_".join([self.name, *parts]).replace(" ", "")

    @property
    def spec(self) -> str:
        """The non-default parameters as canonical JSON (a key field of the curve file)."""
        return json.dumps(self.params, sort_keys=True)

    def table(self, k: float) -> dict[str, Any]:
        """The effect table at ``k`` (as in presets and model files), with choice parameters spelled out.

        Example:
            >>> parse_effect("dim").table(0.3)
            {'name': 'dim', 'k': 0.3, 'mode': 'faithful'}
        """

        cls = EFFECTS.get(self.name)
        effect = cls(k=float(k), **self.params)
        explicit = {p: getattr(effect, p) for p in getattr(cls, "CHOICES", {})}
        return {"name": self.name, "k": float(k), **explicit, **self.params}

    def make(self, k: float):
        return make(self.name, k=float(k), **self.params)


def parse_effect(text: str) -> SweepEffect:
    """``NAME`` or ``NAME:PARAM=VALUE[,PARAM=VALUE...]`` -> :class:`SweepEffect` (validated).

    Unknown effects raise ``ValueError`` listing the valid names; unknown or invalid parameters name
    the parameter. ``k`` may not be fixed here (it is what the sweep varies).
    """

    if not isinstance(text, str) or not text.strip():
        raise InputError(f"--effect must be NAME or NAME:PARAM=VALUE,..., got {text!r}")
    name, _, rest = text.strip().partition(":")
    name = name.strip()
    EFFECTS.get(name)  # ValueError listing the valid names
    params: dict[str, Any] = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, val = item.partition("=")
        if not eq or not key.strip():
            raise InputError(f"effect {text!r}: parameter {item!r} must be PARAM=VALUE (e.g. dim:mode=physical)")
        key = key.strip()
        if key == "k":
            raise InputError(f"effect {text!r}: k is what the sweep varies; give it with --k, not in the effect")
        params[key] = _value(val)
    default = make(name, k=0.0)
    try:
        effect = make(name, k=0.0, **params)
    except (TypeError, ValueError) as exc:
        raise InputError(f"effect {text!r}: {exc}") from None
    canonical = {p: getattr(effect, p) for p in params if getattr(effect, p) != getattr(default, p)}
    return SweepEffect(name, canonical)
