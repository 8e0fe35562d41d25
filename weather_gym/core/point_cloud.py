"""``PointCloud``: one LiDAR scan's returns as typed arrays (the sensor, its weather and perception share it).

One row per return, in the sensor's frame (x forward, y left, z up, metres; origin at the sensor):
``xyz`` (N, 3) float32, ``intensity`` (N,) float32 in [0, 1] (reflectivity x cos(incidence), after
any attenuation), ``reflectivity`` (N,) float32 (the surface's, before the incidence angle and the
weather: what the fog model's detection threshold reads), ``ring`` (N,) int16 (the beam, 0 = lowest),
``cone`` (N,) int32 (ground truth: the index of the cone the beam hit, -1 for anything else) and
``label`` (N,) uint8 (ground truth: what made the return, :data:`LABELS`). Arrays are read-only; the
weather makes new clouds.

Example:
    >>> import numpy as np
    >>> from weather_gym.core.point_cloud import PointCloud, LABELS
    >>> pc = PointCloud.from_arrays(xyz=np.array([[3.0, 4.0, 0.0]]), intensity=[0.5], ring=[2])
    >>> len(pc), float(pc.ranges[0]), LABELS[int(pc.label[0])]
    (1, 5.0, 'ground')
    >>> len(pc.select(pc.ranges > 10))
    0
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError

__all__ = ["LABELS", "PointCloud", "label_id", "pack_points"]

LABELS: tuple[str, ...] = ("ground", "cone", "car", "other", "fog", "rain", "snow")
"""What made a return: the road (``ground``), a cone, the ego car, other scenery, or the weather
(backscatter and drops: ``fog``, ``rain``, ``snow``). ``label`` holds the index in this tuple."""

_DTYPES = {"xyz": np.float32, "intensity": np.float32, "reflectivity": np.float32, "ring": np.int16,
           "cone": np.int32, "label": np.uint8}


def label_id(name: str) -> int:
    """Index of ``name`` in :data:`LABELS` (``InputError`` listing them)."""
    try:
        return LABELS.index(name)
    except ValueError:
        raise InputError(f"unknown point label {name!r}; valid: {', '.join(LABELS)}") from None


@dataclass(frozen=True, eq=False)
class PointCloud:
    """One scan's returns (see the module doc). Build with :meth:`from_arrays` (checked)."""

    xyz: np.ndarray
    intensity: np.ndarray
    reflectivity: np.ndarray
    ring: np.ndarray
    cone: np.ndarray
    label: np.ndarray

    @classmethod
    def from_arrays(cls, *, xyz: Any, intensity: Any, ring: Any, reflectivity: Any = None, cone: Any = None,
                    label: Any = None) -> PointCloud:
        """A checked cloud; ``reflectivity`` defaults to ``intensity``, ``cone`` to -1, ``label`` to ground."""
        xyz = np.asarray(xyz, dtype=np.float32)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"PointCloud.xyz must have shape (N, 3), got {xyz.shape}")
        n = xyz.shape[0]
        arrays = {"xyz": xyz, "intensity": intensity, "ring": ring,
                  "reflectivity": intensity if reflectivity is None else reflectivity,
                  "cone": np.full(n, -1) if cone is None else cone, "label": np.zeros(n) if label is None else label}
        out = {}
        for name, a in arrays.items():
            a = np.asarray(a, dtype=_DTYPES[name])
            if a.shape[0] != n or (name != "xyz" and a.ndim != 1):
                raise InputError(f"PointCloud.{name} must have shape ({n},), got {a.shape}")
            out[name] = a
        if n and not np.isfinite(out["xyz"]).all():
            raise InputError("PointCloud.xyz must be finite")
        return cls.trusted(**out)

    @classmethod
    def trusted(cls, **arrays: np.ndarray) -> PointCloud:
        """Wrap arrays of the right dtypes and one length (not checked), read-only."""
        for a in arrays.values():
            a.flags.writeable = False
        return cls(**arrays)

    @classmethod
    def empty(cls) -> PointCloud:
        return cls.from_arrays(xyz=np.zeros((0, 3)), intensity=np.zeros(0), ring=np.zeros(0))

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def ranges(self) -> np.ndarray:
        """(N,) distance of each return from the sensor (m), float32."""
        out: np.ndarray = np.sqrt(np.einsum("ij,ij->i", self.xyz, self.xyz))
        return out

    def select(self, rows: np.ndarray) -> PointCloud:
        """The returns ``rows`` (an index or boolean array)."""
        return PointCloud.trusted(**{f.name: np.ascontiguousarray(getattr(self, f.name)[rows]) for f in fields(self)})

    def replace(self, **arrays: np.ndarray) -> PointCloud:
        """A new cloud with some arrays replaced (same length and dtypes expected)."""
        cur = {f.name: getattr(self, f.name) for f in fields(self)}
        cur.update({k: np.asarray(v, dtype=_DTYPES[k]) for k, v in arrays.items()})
        return PointCloud.trusted(**cur)

    def concat(self, other: PointCloud) -> PointCloud:
        """This cloud's returns followed by ``other``'s."""
        return PointCloud.trusted(**{f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                                     for f in fields(self)})

    def equals(self, other: PointCloud) -> bool:
        """Same returns, same bytes."""
        return all(np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))

    def __eq__(self, other: object) -> bool:  # compares the arrays (Gymnasium's env checker compares infos)
        if not isinstance(other, PointCloud):
            return NotImplemented
        return self.equals(other)

    __hash__ = None  # type: ignore[assignment]  # holds arrays: not hashable


def pack_points(cloud: PointCloud, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """``(points, mask)``: ``(max_points, 4)`` float32 rows x, y, z, intensity padded with zeros, and the
    ``(max_points,)`` int8 mask of valid rows (the nearest returns kept when there are more)."""
    n = len(cloud)
    rows = np.arange(n) if n <= max_points else np.sort(np.argsort(cloud.ranges, kind="stable")[:max_points])
    k = len(rows)
    points = np.zeros((max_points, 4), np.float32)
    mask = np.zeros(max_points, np.int8)
    points[:k, :3] = cloud.xyz[rows]
    points[:k, 3] = cloud.intensity[rows]
    mask[:k] = 1
    return points, mask
