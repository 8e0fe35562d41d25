"""``ConeMemory``: a cone list that remembers confirmed cones the camera no longer sees.

A memoryless driver reads only this frame's cones. In a tight turn, in low light or behind a drop on
the lens, that list is thin: the cones beside the car have left the field of view and the far ones
are missed. ``ConeMemory`` keeps a :class:`~weather_gym.agents.mapper.ConeMapper` running on the
cone lists and the car's odometry, and hands on this frame's detections as they are (those within
``detection_range``) plus every *confirmed* mapped cone that nothing was detected at this frame, seen
within the last ``max_age`` steps and not farther than ``max_behind`` metres behind the car, moved
into the car frame by the odometry. A single false detection never becomes a remembered cone (the
mapper confirms a cone after ``min_hits`` sightings). The observation keeps its space: the same
``(N, 14)`` rows sorted by range and the mask; a remembered row has its class, range, bearing (from
the camera), the colour vote's share as its score, car-frame position, and no box (zeros).

The shipped ``ppo_cones`` driver reads its cone list through a ``ConeMemory`` in training and in
driving (``weather-gym train --cone-memory``; the ``sb3`` agent applies the memory a saved model's
JSON records).

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.cone_memory import ConeMemory
    >>> from weather_gym.perception.cones import FIELD
    >>> memory = ConeMemory()
    >>> cone = np.zeros((4, 14), np.float32); cone[0, 0] = 1; cone[0, FIELD["score"]] = 0.9
    >>> cone[0, FIELD["x_body"]], cone[0, FIELD["y_body"]], cone[0, FIELD["range"]] = 6.6, 1.5, 6.18
    >>> seen = {"cones": cone, "mask": np.array([1, 0, 0, 0], np.int8), "state": np.zeros(5, np.float32)}
    >>> for _ in range(4):                  # seen four times: confirmed
    ...     _ = memory(seen)
    >>> missed = {**seen, "mask": np.zeros(4, np.int8), "state": np.array([0, 0, 1.0, 0, 0], np.float32)}
    >>> out = memory(missed)                # not detected now, 1 m further on: still there, 1 m closer
    >>> out["mask"].tolist(), [round(float(v), 2) for v in out["cones"][0, [FIELD["x_body"], FIELD["y_body"]]]]
    ([1, 0, 0, 0], [5.6, 1.5])
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydantic import InstanceOf
from scipy.spatial import cKDTree

from weather_gym.agents.mapper import ConeMap, ConeMapper, MapperConfig
from weather_gym.core.errors import InputError, check_known
from weather_gym.core.schema import NonNegative, Positive, PositiveInt, check_fields
from weather_gym.perception.cones import FIELD

__all__ = ["ConeMemory", "ConeMemoryConfig"]


@dataclass(frozen=True)
class ConeMemoryConfig:
    """What a :class:`ConeMemory` hands on besides this frame's detections.

    Attributes:
        max_age: a confirmed cone stays in the list this many steps after its last detection
            (30: one second at the default 30 Hz control rate).
        max_behind: cones farther than this (m) behind the car's reference point are left out.
        max_range: cones farther than this (m) from the car are left out.
        duplicate_dist: a remembered cone this close (m) to one of this frame's detections is taken
            to be that cone and left out.
        detection_range: this frame's detections farther than this (m, from the camera) are left out
            (None, the default: none are). The shipped driver, cloned on the surrogate's lists (which
            thin out near 30 m), drives with 30: geometric ground truth (``gt_cones``) lists every
            cone in view, to 70 m.
        mapper: the mapper's tuning (``hfov_deg`` and ``mount_x`` follow the camera when one is given).
    """

    max_age: PositiveInt = 30
    max_behind: NonNegative = 0.0
    max_range: Positive = 20.0
    duplicate_dist: Positive = 1.0
    detection_range: Positive | None = None
    mapper: InstanceOf[MapperConfig] = MapperConfig()

    def __post_init__(self) -> None:
        check_fields(self)

    def to_dict(self) -> dict:
        """Plain fields (JSON), the mapper's as a nested dict: what a model's ``model.json`` records."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ConeMemoryConfig:
        """From :meth:`to_dict`'s dict, or a part of it (the rest default); unknown keys are an error."""
        mapper = d.get("mapper", {}) if isinstance(d, dict) else None
        for name, table, kind in (("cone_memory", d, cls), ("cone_memory.mapper", mapper, MapperConfig)):
            if not isinstance(table, dict):
                raise InputError(f"{name} must be a table of {kind.__name__} fields, got {table!r}")
            check_known(table, {f.name for f in dataclasses.fields(kind)}, what=name)
        return cls(**{**d, "mapper": MapperConfig(**mapper)}) if "mapper" in d else cls(**d)


class ConeMemory:
    """Cone list in, cone list with the recently seen confirmed cones out (see the module doc).

    Args:
        config: a :class:`ConeMemoryConfig` (defaults tuned for FS tracks at 30 Hz).
        camera: the camera behind the cone lists (its field of view and mount for the mapper and for
            the remembered cones' range and bearing); the default camera when omitted.
    """

    def __init__(self, config: ConeMemoryConfig | None = None, camera=None) -> None:
        self.config = config or ConeMemoryConfig()
        mapper = self.config.mapper
        if camera is not None:
            mapper = dataclasses.replace(mapper, hfov_deg=camera.hfov_deg, mount_x=camera.mount_x)
        self.mount_x = mapper.mount_x
        self.mapper = ConeMapper(mapper)

    def reset(self) -> None:
        """Forget every cone (a new episode)."""
        self.mapper.reset()

    def __call__(self, obs: dict) -> dict:
        """The observation with remembered cones added to ``cones`` and ``mask`` (a new dict)."""
        cfg = self.config
        cone_map = self.mapper.update_from_obs(obs)
        cones = np.asarray(obs["cones"], dtype=np.float32)
        mask = np.asarray(obs["mask"]).astype(bool)
        if cfg.detection_range is not None:
            mask &= cones[:, FIELD["range"]] <= cfg.detection_range
        now = cones[mask]
        merged = np.concatenate([now, self._remembered(cone_map, obs["state"], now)])
        order = np.argsort(merged[:, FIELD["range"]], kind="stable")[:cones.shape[0]]
        out = np.zeros_like(cones)
        out[:len(order)] = merged[order]
        out_mask = np.zeros(cones.shape[0], np.int8)
        out_mask[:len(order)] = 1
        return {**obs, "cones": out, "mask": out_mask}

    def _remembered(self, cone_map: ConeMap, state: np.ndarray, now: np.ndarray) -> np.ndarray:
        """Cone-list rows of the confirmed cones to add (see the module doc); ``now``: this frame's rows."""
        cfg = self.config
        rows = np.zeros((0, now.shape[1]), np.float32)
        keep = cone_map.confirmed & (cone_map.age >= 1) & (cone_map.age <= cfg.max_age)
        if not keep.any():
            return rows
        x, y, yaw = (float(v) for v in np.asarray(state, dtype=np.float64).reshape(-1)[2:5])
        c, s = np.cos(yaw), np.sin(yaw)
        d = cone_map.xy[keep] - (x, y)
        xb, yb = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        near = (xb >= -cfg.max_behind) & (np.hypot(xb, yb) <= cfg.max_range)
        if near.any() and len(now):
            dist, _ = cKDTree(now[:, [FIELD["x_body"], FIELD["y_body"]]]).query(np.c_[xb, yb], k=1)
            near &= dist > cfg.duplicate_dist
        if not near.any():
            return rows
        xb, yb = xb[near], yb[near]
        prob = cone_map.class_prob[keep][near]
        rows = np.zeros((len(xb), now.shape[1]), np.float32)
        rows[np.arange(len(xb)), prob.argmax(axis=1)] = 1.0
        cx = xb - self.mount_x
        rows[:, FIELD["range"]] = np.hypot(cx, yb)
        rows[:, FIELD["bearing"]] = np.arctan2(yb, cx)
        rows[:, FIELD["score"]] = prob.max(axis=1)
        rows[:, FIELD["x_body"]], rows[:, FIELD["y_body"]] = xb, yb
        return rows
