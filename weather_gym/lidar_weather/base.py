"""The contract of a LiDAR weather effect: one knob ``k`` in [0, 1] mapped to a physical parameter.

An effect is a frozen dataclass. ``effect(cloud, rng)`` returns a new
:class:`~weather_gym.core.point_cloud.PointCloud`; the input is never changed.

* ``k = 0`` returns the cloud unchanged (the same arrays, bytes equal).
* Every random value comes from ``rng`` (a ``numpy.random.Generator``): same seed, same points.
  ``apply_batch(clouds, seed)`` gives each cloud a child of ``SeedSequence(seed)`` and equals the loop
  ``[effect(c, rng_i) ...]`` with the same children.
* Each effect names its physical parameter (``PHYSICAL``: fog's extinction, rain's rate, ...), maps
  ``k`` linearly onto it (``k = 1`` is the effect's ``max_*`` field: severity 5 of the published grid)
  and takes the physical value itself too (``Fog(mor=50)``); :data:`SEVERITIES` holds severities 1-5.
* A value outside its range raises :class:`~weather_gym.core.errors.LimitError` naming the parameter, the
  value and the range.

The sensor's detection threshold (rain, snow, wet road): a return is detected while its received
power, ``intensity * T / r**2`` (``T``: the two-way transmission through the weather), stays above
``ref_reflectivity / max_range_m**2``: the sensor sees a ``ref_reflectivity`` target out to
``max_range_m`` in clear air (Goodin et al. 2019, "a return is lost below a minimum received power").
The simulated sensor applies the same threshold in clear air (:mod:`weather_gym.sim.lidar`), so
``k = 0`` loses nothing more.

Example:
    >>> import numpy as np
    >>> from weather_gym.lidar_weather import make
    >>> from weather_gym.core.point_cloud import PointCloud
    >>> pc = PointCloud.from_arrays(xyz=[[20.0, 0, 0]], intensity=[0.5], ring=[0])
    >>> make("fog", k=0.0)(pc, np.random.default_rng(0)) is pc
    True
    >>> make("fog", k=1.5)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.LimitError: fog: k = 1.5 is outside [0, 1]
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.point_cloud import PointCloud

__all__ = ["LidarEffect", "check_rng", "detectable"]


def check_rng(rng: object, who: str) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"{who}: rng must be a numpy.random.Generator (numpy.random.default_rng(seed)), "
                         f"got {type(rng).__name__}")
    return rng


def detectable(intensity: np.ndarray, r: np.ndarray, ref_reflectivity: float, max_range_m: float) -> np.ndarray:
    """Whether returns of ``intensity`` (after the weather) at range ``r`` are above the sensor's
    threshold ``ref_reflectivity / max_range_m**2`` of received power (see the module doc)."""
    return intensity * (max_range_m * max_range_m) >= ref_reflectivity * r * r


@dataclass(frozen=True)
class LidarEffect:
    """Base of the LiDAR weather effects (see the module doc)."""

    name: ClassVar[str] = ""
    PHYSICAL: ClassVar[tuple[str, str]] = ("", "")
    """(name of the physical parameter, its unit)."""
    PARAM_BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {}
    SEVERITIES: ClassVar[tuple[float, ...]] = ()
    """The physical parameter at severities 1-5."""

    k: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"{self.name}: {f.name} must be a finite number, got {v!r}")
        if not 0.0 <= self.k <= 1.0:
            raise LimitError(f"{self.name}: k = {self.k:g} is outside [0, 1]")
        for key, (lo, hi) in self.PARAM_BOUNDS.items():
            v = getattr(self, key)
            if v is not None and not lo <= v <= hi:
                raise LimitError(f"{self.name}: {key} = {v:g} is outside [{lo:g}, {hi:g}]")

    def _set_k_from(self, given: str, value: float, max_value: float, max_name: str) -> None:
        """Set ``k = value / max_value`` from a physical ``value`` given as ``given`` (``LimitError`` beyond
        ``max_value``, the field ``max_name``)."""
        if not 0.0 <= value <= max_value * (1 + 1e-12):
            raise LimitError(f"{self.name}: {given} means {self.PHYSICAL[0]} {value:.4g} {self.PHYSICAL[1]}, outside "
                             f"[0, {max_value:g}] ({max_name}; raise it to go further)")
        value = min(value, max_value)
        object.__setattr__(self, "k", value / max_value)

    @classmethod
    def at_severity(cls, severity: int, **params: float) -> LidarEffect:
        """The effect at severity 1-5 of :attr:`SEVERITIES` (0: clear, ``k = 0``)."""
        if isinstance(severity, bool) or not isinstance(severity, int) or not 0 <= severity <= len(cls.SEVERITIES):
            raise LimitError(f"{cls.name}: severity must be an integer in 0..{len(cls.SEVERITIES)}, got {severity!r}")
        if severity == 0:
            return cls(k=0.0, **params)
        top = cls(**params).max_value
        return cls(k=min(1.0, cls.SEVERITIES[severity - 1] / top), **params)

    @property
    def max_value(self) -> float:
        """The physical parameter at ``k = 1``."""
        return self.physical_at(1.0)

    def physical_at(self, k: float) -> float:
        raise NotImplementedError

    @property
    def physical(self) -> float:
        """The physical parameter at this ``k`` (unit: ``PHYSICAL[1]``)."""
        return self.physical_at(self.k)

    def __call__(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        if not isinstance(cloud, PointCloud):
            raise InputError(f"{self.name}: expected a PointCloud, got {type(cloud).__name__}")
        check_rng(rng, self.name)
        if self.k == 0.0 or len(cloud) == 0:
            return cloud
        return self._apply(cloud, rng)

    def _apply(self, cloud: PointCloud, rng: np.random.Generator) -> PointCloud:
        raise NotImplementedError

    def apply_batch(self, clouds: list[PointCloud], seed: int) -> list[PointCloud]:
        """Each cloud with a child generator of ``SeedSequence(seed)`` (the loop gives the same)."""
        children = np.random.SeedSequence(seed).spawn(len(clouds))
        return [self(c, np.random.default_rng(s)) for c, s in zip(clouds, children)]

    def params(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}

    def describe(self) -> str:
        name, unit = self.PHYSICAL
        return f"{self.name}:k={self.k:.3g} ({name} {self.physical:.3g} {unit})"
