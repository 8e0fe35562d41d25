"""Weather on LiDAR scans, in physical units: fog by visibility, rain and snow by rate, a wet road.

Every effect follows the contract of :mod:`weather_gym.lidar_weather.base` (one knob ``k``, ``k = 0``
the identity, seeded, typed errors) and works on a :class:`~weather_gym.core.point_cloud.PointCloud`; no
PyBullet here. Effects: ``fog`` (:mod:`~weather_gym.lidar_weather.fog`, Bijelic et al. 2020), ``rain``
(:mod:`~weather_gym.lidar_weather.rain`, Goodin et al. 2019), ``snow``
(:mod:`~weather_gym.lidar_weather.snow`) and ``wet`` (:mod:`~weather_gym.lidar_weather.wet`).

A spec string names one or more effects joined by ``+``; each is ``NAME:K`` (the knob), ``NAME@S``
(severity 1-5) or ``NAME:PARAM=VALUE,...`` (physical values: ``fog:mor=60``, ``rain:rate=5``,
``snow:rate=1``, ``wet:film_mm=0.2``); ``clear`` is none.

Example:
    >>> import numpy as np
    >>> from weather_gym.lidar_weather import parse_lidar_weather
    >>> w = parse_lidar_weather("fog:mor=100+rain@2+wet@3")
    >>> [e.name for e in w.effects], round(w.effects[1].physical, 2)
    (['fog', 'rain', 'wet'], 0.73)
    >>> parse_lidar_weather("clear").effects
    ()
    >>> parse_lidar_weather("hail:0.5")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: unknown LiDAR weather effect 'hail'; valid names: fog, rain, snow, wet
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError, check_known
from weather_gym.core.point_cloud import PointCloud
from weather_gym.core.registry import Registry
from weather_gym.lidar_weather.base import LidarEffect, check_rng
from weather_gym.lidar_weather.fog import FOG_SEVERITIES, Fog, mor_of
from weather_gym.lidar_weather.rain import RAIN_SEVERITIES, Rain
from weather_gym.lidar_weather.snow import SNOW_SEVERITIES, Snow
from weather_gym.lidar_weather.wet import WET_SEVERITIES, WetRoad

__all__ = ["FOG_SEVERITIES", "LIDAR_EFFECTS", "RAIN_SEVERITIES", "SNOW_SEVERITIES", "WET_SEVERITIES", "Fog",
           "LidarEffect", "LidarWeather", "Rain", "Snow", "WetRoad", "make", "mor_of", "parse_lidar_weather"]

LIDAR_EFFECTS: Registry[type[LidarEffect]] = Registry("LiDAR weather effect")
for _cls in (Fog, Rain, Snow, WetRoad):
    LIDAR_EFFECTS.register(_cls.name, _cls)


def make(name: str, k: float = 0.0, **params: Any) -> LidarEffect:
    """The effect ``name`` at knob ``k`` (or with its physical parameter among ``params``)."""
    cls = LIDAR_EFFECTS.get(name)
    check_known(params, [f for f in cls.__dataclass_fields__ if f != "k"], what=f"LiDAR {name}", kind="parameter")
    return cls(k=k, **params)


@dataclass(frozen=True)
class LidarWeather:
    """Effects applied in order, each with its own child of the scan's generator."""

    effects: tuple[LidarEffect, ...] = ()

    def __call__(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        check_rng(rng, "LiDAR weather")
        if not self.effects:
            return cloud
        for effect, child in zip(self.effects, rng.spawn(len(self.effects))):
            cloud = effect(cloud, child)
        return cloud

    def describe(self) -> str:
        return "+".join(e.describe() for e in self.effects) or "clear"

    @property
    def is_clear(self) -> bool:
        return all(e.k == 0 for e in self.effects)


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"LiDAR weather {what}: expected a number, got {text!r}") from None


def parse_lidar_weather(spec: Any) -> LidarWeather:
    """A :class:`LidarWeather` from a spec string (see the module doc), an effect, a list of effects or None."""
    if spec is None:
        return LidarWeather()
    if isinstance(spec, LidarWeather):
        return spec
    if isinstance(spec, LidarEffect):
        return LidarWeather((spec,))
    if isinstance(spec, (list, tuple)) and all(isinstance(e, LidarEffect) for e in spec):
        return LidarWeather(tuple(spec))
    if not isinstance(spec, str):
        raise InputError(f"LiDAR weather must be a spec string like 'fog:mor=60+rain@2', got {spec!r}")
    text = spec.strip()
    if text in ("", "clear"):
        return LidarWeather()
    effects = []
    for item in text.split("+"):
        item = item.strip()
        if "@" in item:
            name, sev = item.split("@", 1)
            cls = LIDAR_EFFECTS.get(name.strip())
            s = _number(sev, f"severity of {name!r}")
            if s != int(s):
                raise InputError(f"LiDAR weather {item!r}: the severity must be an integer 0..5, got {sev!r}")
            effects.append(cls.at_severity(int(s)))
            continue
        name, _, rest = item.partition(":")
        if not rest:
            raise InputError(f"LiDAR weather {item!r}: give NAME:K, NAME@SEVERITY or NAME:PARAM=VALUE")
        if "=" not in rest:
            effects.append(make(name.strip(), k=_number(rest, f"k of {name!r}")))
            continue
        params = {}
        for pair in rest.split(","):
            key, eq, value = pair.partition("=")
            if not eq:
                raise InputError(f"LiDAR weather {item!r}: expected PARAM=VALUE, got {pair!r}")
            params[key.strip()] = _number(value, f"{name}.{key.strip()}")
        effects.append(make(name.strip(), **params))
    return LidarWeather(tuple(effects))
