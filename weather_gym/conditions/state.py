"""One physical weather state for every sensor and the tyres, and the spec that names it.

:class:`WeatherState` (a frozen dataclass; every field has a declared range in :data:`RANGES`):

* ``mor_m``: visibility as meteorological optical range (m; ``inf``: clear air), extinction
  ``beta = ln(20) / MOR``;
* ``rain_mm_h``: rain rate (mm/h); ``snow_mm_h``: snowfall rate (mm/h of melted water);
* ``illuminance_lux``: light on the scene (lux); the simulator's clean frame is daylight of
  :data:`DAYLIGHT_LUX`;
* ``water_film_mm``: water on the road (mm); None: derived from the rain rate (:meth:`WeatherState.film_mm`);
* ``lens_wetness``: how wet the camera's lens is at the start (0-1); it moves towards the rain's
  equilibrium over ``lens_wet_up_s`` seconds (:meth:`WeatherState.lens_equilibrium`).

A spec names a state: items joined by ``+``, each ``NAME:VALUE UNIT``: ``fog:60m`` (MOR),
``rain:8mm/h``, ``snow:1mm/h``, ``dusk:20lux``, ``film:0.5mm`` (``wet:`` is the same), ``lens:0.3``,
``lensup:60s``; ``clear`` is the dry, clear daylight state. A bad item, unit or value raises an
:class:`~weather_gym.core.errors.InputError` (a value outside its range: ``LimitError``) naming it
and the range.

Example:
    >>> from weather_gym.conditions import parse_state
    >>> s = parse_state("rain:8mm/h+fog:60m")
    >>> s.rain_mm_h, s.mor_m, s.film_mm(), s.spec()
    (8.0, 60.0, 1.0, 'fog:60m+rain:8mm/h')
    >>> parse_state("dusk:20lux").illuminance_lux
    20.0
    >>> parse_state("fog:5m")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.LimitError: weather fog:5m: visibility (MOR) 5 m is outside [12, inf] m
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields, replace
from typing import Any

from weather_gym.conditions.grip import MAX_FILM_MM
from weather_gym.core.errors import InputError, LimitError

__all__ = ["CLEAR", "DAYLIGHT_LUX", "ITEMS", "RANGES", "WeatherState", "parse_state"]

DAYLIGHT_LUX = 10_000.0
"""The illuminance the simulator's clean frame stands for (overcast daylight; an assumption: the renderer
has no photometric scale)."""
MIN_LUX = DAYLIGHT_LUX * 2.0 ** -12
"""The darkest light the camera's low-light model reaches (12 stops below daylight, about 2.4 lux)."""

RANGES: dict[str, tuple[float, float, str]] = {
    "mor_m": (12.0, math.inf, "m"),
    "rain_mm_h": (0.0, 50.0, "mm/h"),
    "snow_mm_h": (0.0, 10.0, "mm/h"),
    "illuminance_lux": (MIN_LUX, DAYLIGHT_LUX, "lux"),
    "water_film_mm": (0.0, MAX_FILM_MM, "mm"),
    "lens_wetness": (0.0, 1.0, ""),
    "lens_wet_up_s": (1.0, 3600.0, "s"),
}
"""Declared range and unit of every field (inclusive). The lower MOR is where the camera's fog reaches its
densest (k = 1); rain stops at 50 mm/h (natural rain rarely exceeds 25 mm/h); the film at the Bosch
table's puddles; light between daylight and 12 stops darker (the low-light model's range)."""

_NAMES = {"mor_m": "visibility (MOR)", "rain_mm_h": "rain rate", "snow_mm_h": "snowfall rate",
          "illuminance_lux": "illuminance", "water_film_mm": "water film", "lens_wetness": "lens wetness",
          "lens_wet_up_s": "lens wetting time"}

ITEMS: dict[str, tuple[str, tuple[str, ...]]] = {
    "fog": ("mor_m", ("m",)),
    "rain": ("rain_mm_h", ("mm/h",)),
    "snow": ("snow_mm_h", ("mm/h",)),
    "dusk": ("illuminance_lux", ("lux", "lx")),
    "film": ("water_film_mm", ("mm",)),
    "wet": ("water_film_mm", ("mm",)),
    "lens": ("lens_wetness", ("",)),
    "lensup": ("lens_wet_up_s", ("s",)),
}
"""Spec item name -> (field, accepted units)."""

LIGHT_RAIN_MM_H, HEAVY_RAIN_MM_H = 2.5, 7.6
"""The American Meteorological Society's light (< 2.5 mm/h) and heavy (> 7.6 mm/h) rain."""
LENS_HALF_MM_H = 5.0
"""Rain rate at which the lens's equilibrium wetness is one half (an assumption, see the docs)."""


@dataclass(frozen=True)
class WeatherState:
    """A physical weather state (see the module doc); the defaults are dry, clear daylight."""

    mor_m: float = math.inf
    rain_mm_h: float = 0.0
    snow_mm_h: float = 0.0
    illuminance_lux: float = DAYLIGHT_LUX
    water_film_mm: float | None = None
    lens_wetness: float = 0.0
    lens_wet_up_s: float = 60.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name == "water_film_mm":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
                raise InputError(f"WeatherState.{f.name} must be a number, got {v!r}")
            lo, hi, unit = RANGES[f.name]
            if not lo <= v <= hi:
                raise LimitError(f"{_NAMES[f.name]} {v:g} {unit} is outside [{lo:g}, {hi:g}] {unit}".replace("  ", " "))
            object.__setattr__(self, f.name, float(v))

    @property
    def beta(self) -> float:
        """Extinction of the fog (1/m): ``ln(20) / MOR``; 0 in clear air."""
        return 0.0 if math.isinf(self.mor_m) else math.log(20.0) / self.mor_m

    def film_mm(self) -> float:
        """Water film on the road (mm): as given, else from the rain rate (an assumption): dry without rain,
        0.2 mm ("wet" in the Bosch table) up to light rain (2.5 mm/h), 1 mm ("heavy rain") from heavy
        rain (7.6 mm/h) on, linear between. Melted snow is not counted (a snow-covered road is not modelled)."""
        if self.water_film_mm is not None:
            return self.water_film_mm
        r = self.rain_mm_h
        if r <= 0:
            return 0.0
        w = min(max((r - LIGHT_RAIN_MM_H) / (HEAVY_RAIN_MM_H - LIGHT_RAIN_MM_H), 0.0), 1.0)
        return round(0.2 + 0.8 * w, 12)

    def lens_equilibrium(self) -> float:
        """The lens wetness rain of this rate settles at: ``R / (R + 5 mm/h)`` (an assumption); without rain
        the lens keeps its wetness (drying is not modelled)."""
        r = self.rain_mm_h
        return self.lens_wetness if r <= 0 else max(self.lens_wetness, r / (r + LENS_HALF_MM_H))

    @property
    def is_clear(self) -> bool:
        return self == WeatherState() or self == WeatherState(water_film_mm=0.0)

    def with_(self, **changes: Any) -> WeatherState:
        """A copy with ``changes`` (validated)."""
        return replace(self, **changes)

    def spec(self) -> str:
        """The spec string of this state (``parse_state(s.spec()) == s``)."""
        parts = []
        if not math.isinf(self.mor_m):
            parts.append(f"fog:{self.mor_m:g}m")
        if self.rain_mm_h:
            parts.append(f"rain:{self.rain_mm_h:g}mm/h")
        if self.snow_mm_h:
            parts.append(f"snow:{self.snow_mm_h:g}mm/h")
        if self.illuminance_lux != DAYLIGHT_LUX:
            parts.append(f"dusk:{self.illuminance_lux:g}lux")
        if self.water_film_mm is not None:
            parts.append(f"film:{self.water_film_mm:g}mm")
        if self.lens_wetness:
            parts.append(f"lens:{self.lens_wetness:g}")
        if self.lens_wet_up_s != 60.0:
            parts.append(f"lensup:{self.lens_wet_up_s:g}s")
        return "+".join(parts) or "clear"


CLEAR = WeatherState()

_ITEM = re.compile(r"^\s*([a-z]+)\s*:\s*([-+0-9.eE]+|inf)\s*([a-z/]*)\s*$")


def parse_state(spec: Any) -> WeatherState:
    """A :class:`WeatherState` from a spec string (module doc), a state, or None (clear)."""
    if spec is None:
        return CLEAR
    if isinstance(spec, WeatherState):
        return spec
    if not isinstance(spec, str):
        raise InputError(f"a weather state is a spec string like 'rain:8mm/h+fog:60m', got {spec!r}")
    text = spec.strip()
    if text == "":
        raise InputError("weather state spec is empty; give 'clear' or items like 'rain:8mm/h+fog:60m'")
    if text == "clear":
        return CLEAR
    values: dict[str, float] = {}
    for item in text.split("+"):
        m = _ITEM.match(item)
        if m is None:
            raise InputError(f"weather {item.strip()!r}: expected NAME:VALUE UNIT, e.g. rain:8mm/h, fog:60m, "
                             f"dusk:20lux, film:0.5mm, lens:0.3 (names: {', '.join(ITEMS)})")
        name, number, unit = m.groups()
        if name not in ITEMS:
            raise InputError(f"weather {item.strip()!r}: unknown item {name!r}; valid: {', '.join(ITEMS)}")
        field_name, units = ITEMS[name]
        if unit not in units:
            raise InputError(f"weather {item.strip()!r}: {name} is given in {' or '.join(units) or 'no unit'}, "
                             f"got {unit or 'no unit'!r}")
        if field_name in values:
            raise InputError(f"weather {text!r}: {name} given twice")
        try:
            values[field_name] = float(number)
        except ValueError:
            raise InputError(f"weather {item.strip()!r}: {number!r} is not a number") from None
    try:
        return WeatherState(**values)
    except InputError as exc:
        raise type(exc)(f"weather {text}: {exc}") from None
