"""From one :class:`~weather_gym.conditions.state.WeatherState` to what each part of the car meets.

* :func:`camera_tables`: the camera's effects (``weather_gym.weather``), as weather tables, each k from
  the state's units:

  - ``fog`` k = ``beta * 15 / 3.912`` with ``beta = ln(20) / MOR`` plus rain's visible extinction
    ``0.312 R^0.67`` per km (Halder et al. 2019): the camera fog's ``beta = k * 3.912 / min_visibility_m``
    solved for k (``min_visibility_m`` 15 m). Physical: Koschmieder's law with the state's extinction.
  - ``rain`` (streaks and veil) k = ``R / 50 mm/h``: **an assumption** (the streak effect has no
    physical calibration; k = 1 is the state's top rate).
  - ``droplets`` (refractive lens drops, the calibrated presets' effect) k = the lens wetness, as a
    ``ramp`` from the state's ``lens_wetness`` to the rain's equilibrium ``R / (R + 5 mm/h)`` over
    ``lens_wet_up_s`` (:meth:`~weather_gym.conditions.state.WeatherState.lens_equilibrium`): **an
    assumption** (no measurement of lens wetting in rain was found).
  - ``dim`` (night mode, the calibrated presets' effect) k = ``log2(10000 lux / E) / 12``: the model's
    own scale (the scene gets ``2^(-12 k)`` of the clean frame's light) with the clean frame taken as
    10 000 lux daylight (**an assumption**: the renderer has no photometric scale).
  - snowfall reaches the camera through nothing here (no snow effect on the camera: a documented gap).

* :func:`lidar_weather`: the LiDAR's effects in their own units (``weather_gym.lidar_weather``):
  ``Fog(mor=...)``, ``Rain(rate=...)``, ``Snow(rate=...)``, ``WetRoad(film_mm=...)`` (each effect's top
  value raised where the state goes beyond its severity-5 value).
* :func:`friction`: the tyre-road friction the car's tyre model gets: its dry ``friction`` times
  :func:`~weather_gym.conditions.grip.grip_ratio` of the state's water film at the car's speed.
* :func:`study_severity_states`: the state each calibrated study severity corresponds to under these
  mappings (droplets: the rain rate whose equilibrium wetness is the preset's k; low light: the
  illuminance of its k).

Example:
    >>> from weather_gym.conditions import camera_tables, friction, lidar_weather, parse_state
    >>> s = parse_state("rain:8mm/h+fog:60m+dusk:20lux")
    >>> [t["name"] for t in camera_tables(s)], [t.get("effect") for t in camera_tables(s)][2]
    (['fog', 'rain', 'ramp', 'dim'], 'droplets')
    >>> lidar_weather(s).describe().split("+")[0]
    'fog:k=0.832 (extinction beta 0.0499 1/m)'
    >>> round(friction(s, 1.0, speed_mps=10.0), 3)    # 1 mm of water (heavy rain) at 36 km/h
    0.647
"""

from __future__ import annotations

import math
from typing import Any

from weather_gym.conditions.grip import grip_ratio
from weather_gym.conditions.state import DAYLIGHT_LUX, LENS_HALF_MM_H, WeatherState
from weather_gym.core.errors import InputError
from weather_gym.lidar_weather import FOG_SEVERITIES, RAIN_SEVERITIES, SNOW_SEVERITIES, LidarWeather
from weather_gym.lidar_weather.fog import Fog
from weather_gym.lidar_weather.rain import Rain
from weather_gym.lidar_weather.snow import Snow
from weather_gym.lidar_weather.wet import WetRoad
from weather_gym.weather.fog import KOSCHMIEDER

__all__ = ["CAMERA_FOG_MIN_VISIBILITY_M", "DIM_STOPS", "RAIN_K1_MM_H", "camera_tables", "dim_k", "friction",
           "lidar_weather", "lux_of_dim_k", "rain_extinction", "study_severity_states"]

CAMERA_FOG_MIN_VISIBILITY_M = 15.0
"""The camera fog effect's ``min_visibility_m`` (its default): k = 1 is 15 m of 2 %-contrast visibility."""
RAIN_K1_MM_H = 50.0
"""Rain rate at which the camera's rain streaks reach k = 1 (an assumption)."""
DIM_STOPS = 12.0
"""Stops of light the ``dim`` effect's k spans (its ``stops`` default)."""


def rain_extinction(rate_mm_h: float) -> float:
    """Visible extinction by rain (1/m): ``0.312 R^0.67`` per km (Halder et al. 2019)."""
    return 0.312 * float(rate_mm_h) ** 0.67 / 1000.0 if rate_mm_h > 0 else 0.0


def dim_k(lux: float) -> float:
    """The ``dim`` k of an illuminance: ``log2(10000 / lux) / 12``."""
    return max(0.0, math.log2(DAYLIGHT_LUX / lux) / DIM_STOPS)


def lux_of_dim_k(k: float) -> float:
    """The illuminance a ``dim`` k stands for (the inverse of :func:`dim_k`)."""
    return float(DAYLIGHT_LUX * 2.0 ** (-DIM_STOPS * k))


def camera_tables(state: WeatherState, control_hz: float = 30.0) -> list[dict[str, Any]]:
    """The camera's weather (a list of weather tables for ``parse_weather``) of ``state``; ``[]`` when
    nothing reaches the camera. ``control_hz``: frames per second (the lens ramp's steps)."""
    out: list[dict[str, Any]] = []
    beta = state.beta + rain_extinction(state.rain_mm_h)
    if beta > 0:
        out.append({"name": "fog", "k": round(beta * CAMERA_FOG_MIN_VISIBILITY_M / KOSCHMIEDER, 6)})
    if state.rain_mm_h > 0:
        out.append({"name": "rain", "k": round(state.rain_mm_h / RAIN_K1_MM_H, 6)})
    lens_end = state.lens_equilibrium()
    if lens_end > 0:
        steps = max(1, int(round(state.lens_wet_up_s * control_hz)))
        out.append({"name": "ramp", "effect": "droplets", "k_start": round(state.lens_wetness, 6),
                    "k_end": round(lens_end, 6), "steps": steps, "mode": "refractive"})
    k_dim = dim_k(state.illuminance_lux)
    if k_dim > 0:
        out.append({"name": "dim", "k": round(k_dim, 6), "mode": "night"})
    return out


def lidar_weather(state: WeatherState) -> LidarWeather:
    """The LiDAR's weather of ``state`` (fog by MOR, rain and snow by rate, the road's water film)."""
    effects: list[Any] = []
    if state.beta > 0:
        effects.append(Fog(mor=state.mor_m, max_beta=max(FOG_SEVERITIES[-1], state.beta)))
    if state.rain_mm_h > 0:
        effects.append(Rain(rate=state.rain_mm_h, max_rate=max(RAIN_SEVERITIES[-1], state.rain_mm_h)))
    if state.snow_mm_h > 0:
        effects.append(Snow(rate=state.snow_mm_h, max_rate=max(SNOW_SEVERITIES[-1], state.snow_mm_h)))
    film = state.film_mm()
    if film > 0:
        effects.append(WetRoad(film_mm=film, max_film_mm=max(1.0, film)))
    return LidarWeather(tuple(effects))


def friction(state: WeatherState, dry_friction: float, speed_mps: float) -> float:
    """Tyre-road friction on the state's water film at ``speed_mps``: ``dry_friction * grip_ratio``."""
    if not (isinstance(dry_friction, (int, float)) and math.isfinite(dry_friction) and dry_friction > 0):
        raise InputError(f"dry friction must be a number > 0, got {dry_friction!r}")
    return dry_friction * grip_ratio(state.film_mm(), speed_mps)


def study_severity_states(presets: dict[str, dict[int, float]]) -> dict[str, dict[int, dict[str, float]]]:
    """The physical state each calibrated severity's k corresponds to under these mappings.

    ``presets``: ``{"droplets": {severity: k}, "low_light": {severity: k}}`` (the calibrated presets).
    droplets -> the rain rate whose equilibrium lens wetness is k; low_light -> the illuminance of k.

    Example:
        >>> study_severity_states({"low_light": {3: 0.89}})["low_light"][3]["illuminance_lux"]
        6.1
    """
    out: dict[str, dict[int, dict[str, float]]] = {}
    for sev, k in presets.get("droplets", {}).items():
        rate = LENS_HALF_MM_H * k / (1 - k) if k < 1 else math.inf
        out.setdefault("droplets", {})[sev] = {"lens_wetness": k, "rain_mm_h": round(rate, 2)}
    for sev, k in presets.get("low_light", {}).items():
        out.setdefault("low_light", {})[sev] = {"dim_k": k, "illuminance_lux": round(lux_of_dim_k(k), 1)}
    return out
