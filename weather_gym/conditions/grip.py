"""Tyre-road grip from the water film on the road and the car's speed (Bosch Automotive Handbook).

The table (:data:`BOSCH_NEW_TYRE`) is the handbook's tyre-road static friction for a new tyre on tarmac
in good condition, at 50 and 90 km/h (as reproduced in /work/shared/references; check a copy of the
handbook before quoting): dry 0.85 / 0.80, wet (about 0.2 mm of water) 0.65 / 0.60, heavy rain (about
1 mm) 0.55 / 0.30, puddles (about 2 mm) 0.50 / 0.05.

:func:`grip_ratio` interpolates the table linearly in the film and in the speed and divides by the dry
value at that speed: the share of its dry grip a tyre keeps. The car's own tyre model
(:mod:`weather_gym.sim.car`, a Fiala tyre with friction coefficient ``CarConfig.friction``) gets
``friction * grip_ratio(film, speed)``: the handbook's road tyre sets how much is lost, the car's
slicks keep their own dry level (EUFS's Formula Student tyre loses 18 % wet; the table's 0.2 mm: 24 %).

**Limits** (documented, not hidden): below 50 km/h the 50 km/h column is used (the table has no lower
speed; grip at low speed is at least that); above 90 km/h the 90 km/h column; films above 2 mm are
refused (:data:`MAX_FILM_MM`); no aquaplaning model (at 90 km/h in puddles the table's 0.05 is the
only sign of it), no tyre temperature, wear (the worn-tyre column is not used) or texture depth.

Example:
    >>> from weather_gym.conditions.grip import grip_ratio, table_mu
    >>> table_mu(0.0, 50 / 3.6), table_mu(0.2, 50 / 3.6), table_mu(2.0, 90 / 3.6)
    (0.85, 0.65, 0.05)
    >>> round(grip_ratio(0.2, 10.0), 3)       # a wet road at 36 km/h: the 50 km/h column
    0.765
    >>> grip_ratio(3.0, 10.0)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.LimitError: water film 3 mm is outside [0, 2] mm (the Bosch table's range: dry to puddles)
"""

from __future__ import annotations

import math

import numpy as np

from weather_gym.core.errors import InputError, LimitError

__all__ = ["BOSCH_FILMS_MM", "BOSCH_NEW_TYRE", "BOSCH_SPEEDS_KMH", "MAX_FILM_MM", "grip_ratio", "table_mu"]

BOSCH_FILMS_MM: tuple[float, ...] = (0.0, 0.2, 1.0, 2.0)
"""Water film of the table's rows: dry, wet, heavy rain, puddles (mm)."""
BOSCH_SPEEDS_KMH: tuple[float, ...] = (50.0, 90.0)
"""Speeds of the table's columns (km/h)."""
BOSCH_NEW_TYRE: tuple[tuple[float, float], ...] = ((0.85, 0.80), (0.65, 0.60), (0.55, 0.30), (0.50, 0.05))
"""Static friction of a new tyre, row per film of :data:`BOSCH_FILMS_MM`, column per speed."""
MAX_FILM_MM = BOSCH_FILMS_MM[-1]

_TABLE = np.asarray(BOSCH_NEW_TYRE, np.float64)


def _check(film_mm: float, speed_mps: float) -> tuple[float, float]:
    for name, v in (("water film", film_mm), ("speed", speed_mps)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise InputError(f"{name} must be a finite number, got {v!r}")
    if not 0.0 <= film_mm <= MAX_FILM_MM:
        raise LimitError(f"water film {film_mm:g} mm is outside [0, {MAX_FILM_MM:g}] mm (the Bosch table's range: "
                         "dry to puddles)")
    if speed_mps < 0:
        raise LimitError(f"speed {speed_mps:g} m/s is below 0")
    return float(film_mm), float(speed_mps)


def table_mu(film_mm: float, speed_mps: float) -> float:
    """The table's friction at ``film_mm`` of water and ``speed_mps`` (linear in both; see the module doc)."""
    film, v = _check(film_mm, speed_mps)
    kmh = min(max(v * 3.6, BOSCH_SPEEDS_KMH[0]), BOSCH_SPEEDS_KMH[-1])
    w = (kmh - BOSCH_SPEEDS_KMH[0]) / (BOSCH_SPEEDS_KMH[1] - BOSCH_SPEEDS_KMH[0])
    col = _TABLE[:, 0] * (1 - w) + _TABLE[:, 1] * w
    return round(float(np.interp(film, BOSCH_FILMS_MM, col)), 12)


def grip_ratio(film_mm: float, speed_mps: float) -> float:
    """The share of its dry grip a tyre keeps on ``film_mm`` of water at ``speed_mps`` (1 when dry)."""
    return table_mu(film_mm, speed_mps) / table_mu(0.0, speed_mps)
