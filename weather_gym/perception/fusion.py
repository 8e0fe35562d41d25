"""Camera and LiDAR cone lists fused into one: position from the LiDAR, colour from the camera.

A :class:`FusionRule` takes the two lists (:class:`SensorCones`, car frame) and returns the fused one.
The baseline, :class:`NearestNeighbourFusion`, is deliberately simple:

1. **Gate**: a camera cone and a LiDAR cone may be the same cone when they are at most
   ``gate_m + gate_rel * range`` apart (0.5 m + 10 % of the range: the camera's range from a box grows
   less sure with distance, the LiDAR's does not).
2. **Associate**: pairs inside the gate, nearest first, each cone used once (greedy global nearest
   neighbour).
3. **Fuse**: a pair keeps the LiDAR's position and the camera's colour; its confidence is the noisy-OR
   of both, ``1 - (1 - s_cam)(1 - s_lidar)`` (two independent sensors agreeing).
4. **Unmatched**: a LiDAR cone stays, colour unknown, with the LiDAR's confidence; a camera cone stays
   (its own position and colour) when its score is at least ``camera_only_score`` (0.5): beyond the
   LiDAR's reach or where the weather took its returns.

A team's own rule is any callable ``rule(camera, lidar) -> SensorCones`` (``FusionWrapper(fusion=...)``).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.fusion import NearestNeighbourFusion, SensorCones
    >>> cam = SensorCones.of(x=[5.3, 30.0], y=[1.0, 2.0], classes=[0, 1], scores=[0.8, 0.7])
    >>> lid = SensorCones.of(x=[5.0, 8.0], y=[1.0, -1.0], classes=[-1, -1], scores=[0.9, 0.9])
    >>> f = NearestNeighbourFusion()(cam, lid)
    >>> f.x.tolist(), f.classes.tolist(), np.round(f.scores, 2).tolist()
    ([5.0, 8.0, 30.0], [0, -1, 1], [0.98, 0.9, 0.7])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from weather_gym.core.cone_spec import UNKNOWN_CLASS
from weather_gym.core.errors import InputError

__all__ = ["FusionRule", "NearestNeighbourFusion", "SensorCones"]


@dataclass(frozen=True)
class SensorCones:
    """A cone list in the car frame: ``x``, ``y`` (m), ``classes`` (-1: colour unknown), ``scores``, and
    ``source`` (0 camera, 1 LiDAR, 2 both) per cone."""

    x: np.ndarray
    y: np.ndarray
    classes: np.ndarray
    scores: np.ndarray
    source: np.ndarray

    @classmethod
    def of(cls, *, x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray,
           classes: Sequence[int] | np.ndarray, scores: Sequence[float] | np.ndarray,
           source: int | Sequence[int] = 0) -> SensorCones:
        xa = np.asarray(x, np.float64).reshape(-1)
        n = len(xa)
        arrays = (np.asarray(y, np.float64).reshape(-1), np.asarray(classes, np.int64).reshape(-1),
                  np.asarray(scores, np.float64).reshape(-1))
        if any(len(a) != n for a in arrays):
            raise InputError(f"SensorCones: x, y, classes and scores must have one entry per cone ({n}), got "
                             f"{[len(a) for a in arrays]}")
        src = np.broadcast_to(np.asarray(source, np.int64), (n,)).copy()
        return cls(xa, arrays[0], arrays[1], arrays[2], src)

    def __len__(self) -> int:
        return len(self.x)


class FusionRule(Protocol):
    """A fusion rule: the camera's and the LiDAR's cone lists -> one list."""

    def __call__(self, camera: SensorCones, lidar: SensorCones) -> SensorCones: ...


@dataclass(frozen=True)
class NearestNeighbourFusion:
    """The baseline rule (module doc): gate, greedy nearest neighbour, LiDAR position, camera colour."""

    gate_m: float = 0.5
    gate_rel: float = 0.1
    camera_only_score: float = 0.5

    def __post_init__(self) -> None:
        for name, lo, hi in (("gate_m", 0.0, 10.0), ("gate_rel", 0.0, 1.0), ("camera_only_score", 0.0, 1.0)):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise InputError(f"NearestNeighbourFusion: {name} = {v!r} is outside [{lo:g}, {hi:g}]")

    def __call__(self, camera: SensorCones, lidar: SensorCones) -> SensorCones:
        nc, nl = len(camera), len(lidar)
        pairs: list[tuple[int, int]] = []
        if nc and nl:
            d = np.hypot(camera.x[:, None] - lidar.x[None, :], camera.y[:, None] - lidar.y[None, :])
            gate = self.gate_m + self.gate_rel * np.hypot(lidar.x, lidar.y)[None, :]
            ci, li = np.nonzero(d <= gate)
            order = np.lexsort((li, ci, d[ci, li]))  # nearest first; ties by index (deterministic)
            used_c, used_l = set(), set()
            for c, lo in zip(ci[order].tolist(), li[order].tolist()):
                if c not in used_c and lo not in used_l:
                    used_c.add(c)
                    used_l.add(lo)
                    pairs.append((c, lo))
        pc = np.array([p[0] for p in pairs], np.int64)
        pl = np.array([p[1] for p in pairs], np.int64)
        lone_l = np.setdiff1d(np.arange(nl), pl)
        lone_c = np.setdiff1d(np.arange(nc), pc)
        lone_c = lone_c[camera.scores[lone_c] >= self.camera_only_score]
        x = np.concatenate([lidar.x[pl], lidar.x[lone_l], camera.x[lone_c]])
        y = np.concatenate([lidar.y[pl], lidar.y[lone_l], camera.y[lone_c]])
        classes = np.concatenate([camera.classes[pc], np.full(len(lone_l), UNKNOWN_CLASS, np.int64),
                                  camera.classes[lone_c]])
        scores = np.concatenate([1 - (1 - camera.scores[pc]) * (1 - lidar.scores[pl]), lidar.scores[lone_l],
                                 camera.scores[lone_c]])
        source = np.concatenate([np.full(len(pc), 2), np.full(len(lone_l), 1), np.zeros(len(lone_c))]).astype(np.int64)
        order = np.argsort(np.hypot(x, y), kind="stable")
        return SensorCones(x[order], y[order], classes[order], scores[order], source[order])
