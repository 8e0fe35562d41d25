"""One physical weather for every sensor and the tyres: the state, its spec, and what it drives.

:mod:`~weather_gym.conditions.state` holds :class:`WeatherState` (visibility, rain and snowfall rates,
illuminance, water film, lens wetness) and :func:`parse_state` (``"rain:8mm/h+fog:60m"``);
:mod:`~weather_gym.conditions.mapping` turns a state into the camera's effects, the LiDAR's effects and
the tyres' friction; :mod:`~weather_gym.conditions.grip` is the Bosch handbook's wet-road friction table.
No PyBullet here: the env (:mod:`weather_gym.envs`), the wrappers and the pipeline apply it.

Example:
    >>> from weather_gym.conditions import parse_state
    >>> parse_state("clear").is_clear, parse_state("rain:2mm/h").film_mm()
    (True, 0.2)
"""

from __future__ import annotations

from weather_gym.conditions.grip import BOSCH_NEW_TYRE, grip_ratio, table_mu
from weather_gym.conditions.mapping import (
    camera_tables,
    dim_k,
    friction,
    lidar_weather,
    lux_of_dim_k,
    rain_extinction,
    study_severity_states,
)
from weather_gym.conditions.state import CLEAR, DAYLIGHT_LUX, RANGES, WeatherState, parse_state

__all__ = ["BOSCH_NEW_TYRE", "CLEAR", "DAYLIGHT_LUX", "RANGES", "WeatherState", "camera_tables", "dim_k", "friction",
           "grip_ratio", "lidar_weather", "lux_of_dim_k", "parse_state", "rain_extinction", "study_severity_states",
           "table_mu"]
