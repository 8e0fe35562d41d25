"""Skidpad mission: the figure-eight path from the rules, fitted to the mapped cones.

At the skidpad junction both circles' cones surround the car, so no cone-by-cone planner can tell
which way to go: teams drive the rule-defined figure eight (FS rules: inner circles 15.25 m across,
outer 21.25 m, centres 18.25 m apart; two laps clockwise on the right circle, two counter-clockwise
on the left, then straight out) and fit it to the cones they see. This planner does the same:

* the two circle centres are fitted (``scipy.optimize.least_squares``, robust loss) to the recently
  mapped blue and yellow cones with the known ring radii: on the right circle the yellow cones are
  the inner ring, on the left circle the blue ones; a cone belongs to the circle whose ring it fits
  best (to start with, the side of the car's starting axis it is on);
* the fits are refreshed every step (smoothed), so the path follows the odometry drift;
* the path, in the map frame: the approach along the starting axis to the junction (the midpoint of
  the centres), 2 x right circle, 2 x left circle, and the exit straight on; its arc length
  parameterisation hardly changes when the centres move, so the controller keeps its progress.
  (``MapperPurePursuit`` leaves the exit lane to its centre-line planner.)

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.skidpad import SkidpadPlanner, skidpad_cones
    >>> xy, classes = skidpad_cones(junction=(0.0, 0.0), heading=np.pi / 2)
    >>> planner = SkidpadPlanner(start_pose=(0.0, -15.0, np.pi / 2))
    >>> path = planner.plan(xy, classes)
    >>> np.round(planner.centres, 2).tolist()        # right circle, left circle
    [[9.12, 0.0], [-9.12, 0.0]]
    >>> round(planner.lengths["circles"], 1)          # 4 laps of radius 9.125 m
    229.5
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field
from scipy.optimize import least_squares

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.core.schema import Positive, PositiveInt, check_fields

__all__ = ["SkidpadConfig", "SkidpadPlanner", "skidpad_cones"]

BLUE, YELLOW = CONE_CLASSES.index("blue"), CONE_CLASSES.index("yellow")


@dataclass(frozen=True)
class SkidpadConfig:
    """FS skidpad geometry and fitting.

    Attributes:
        inner_radius, outer_radius: cone ring radii (m).
        centre_distance: distance between the circle centres (m); the driving line's radius is half.
        laps_per_circle: laps on each circle.
        exit_length: straight driven after the junction at the end (m).
        min_cones: cones a circle's fit needs.
        smoothing: weight of a new fit in the running centre estimate (0..1].
        step: path point spacing (m).
    """

    inner_radius: Positive = 7.625
    outer_radius: Positive = 10.625
    centre_distance: Positive = 18.25
    laps_per_circle: PositiveInt = 2
    exit_length: Positive = 25.0
    min_cones: PositiveInt = 4
    smoothing: Annotated[float, Field(gt=0, le=1)] = 0.2
    step: Positive = 0.25

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.inner_radius < self.outer_radius:
            raise InputError(f"SkidpadConfig: need 0 < inner_radius < outer_radius, got {self.inner_radius}, "
                             f"{self.outer_radius}")


def skidpad_cones(junction: Sequence[float] = (0.0, 0.0), heading: float = math.pi / 2,
                  config: SkidpadConfig | None = None, spacing: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Blue and yellow cones of an ideal skidpad (for tests and examples)."""
    cfg = config or SkidpadConfig()
    a = np.array([math.cos(heading), math.sin(heading)])
    n = np.array([-a[1], a[0]])  # left
    j = np.asarray(junction, dtype=np.float64)
    xy, cls = [], []
    for sgn, inner_cls, outer_cls in ((-1, YELLOW, BLUE), (1, BLUE, YELLOW)):
        c = j + sgn * n * cfg.centre_distance / 2
        for r, k in ((cfg.inner_radius, inner_cls), (cfg.outer_radius, outer_cls)):
            m = int(2 * math.pi * r / spacing)
            t = np.linspace(0, 2 * math.pi, m, endpoint=False)
            pts = c + r * np.c_[np.cos(t), np.sin(t)]
            keep = np.hypot(*(pts - j).T) > 2.5  # the junction stays open
            xy.append(pts[keep])
            cls.append(np.full(int(keep.sum()), k))
    return np.vstack(xy), np.concatenate(cls)


class SkidpadPlanner:
    """Fits the figure eight to mapped cones; ``plan`` returns the whole path (map frame)."""

    def __init__(self, start_pose: Sequence[float] | np.ndarray, config: SkidpadConfig | None = None) -> None:
        self.config = config or SkidpadConfig()
        x, y, yaw = (float(v) for v in start_pose)
        self.start = np.array([x, y])
        self.axis = np.array([math.cos(yaw), math.sin(yaw)])
        self.centres: np.ndarray | None = None  # (2, 2): right, left
        self.lengths: dict[str, float] = {}

    def _fit(self, pts: np.ndarray, radii: np.ndarray, guess: np.ndarray) -> np.ndarray | None:
        if len(pts) < self.config.min_cones:
            return None
        res = least_squares(lambda c: np.hypot(*(pts - c).T) - radii, guess, loss="soft_l1", f_scale=0.3)
        return res.x if res.success else None

    def update(self, cones_xy: np.ndarray, classes: np.ndarray) -> None:
        """Refit the circle centres to the cones (map frame)."""
        cfg = self.config
        xy = np.asarray(cones_xy, dtype=np.float64).reshape(-1, 2)
        cls = np.asarray(classes, dtype=np.int64).reshape(-1)
        ring = (cls == BLUE) | (cls == YELLOW)
        xy, cls = xy[ring], cls[ring]
        left_n = np.array([-self.axis[1], self.axis[0]])
        if self.centres is None:
            lateral = (xy - self.start) @ left_n
            right_side, left_side = lateral < -1.0, lateral > 1.0
            ahead = self.start + self.axis * 15.0
            guesses = (ahead - left_n * cfg.centre_distance / 2, ahead + left_n * cfg.centre_distance / 2)
        else:
            d = np.hypot(*(xy[:, None, :] - self.centres[None, :, :]).transpose(2, 0, 1))
            right_side, left_side = d[:, 0] < d[:, 1], d[:, 1] <= d[:, 0]
            guesses = (self.centres[0], self.centres[1])
        fits: list[np.ndarray | None] = [None, None]
        for _ in range(3):  # fit, give each cone to the circle whose ring it fits best, refit
            for k, (side, inner, guess) in enumerate(((right_side, YELLOW, guesses[0]), (left_side, BLUE, guesses[1]))):
                radii = np.where(cls[side] == inner, cfg.inner_radius, cfg.outer_radius)
                fits[k] = self._fit(xy[side], radii, np.asarray(guess, dtype=np.float64))
            if fits[0] is None or fits[1] is None:
                break
            guesses = (fits[0], fits[1])
            misfit = []
            for c, inner in ((fits[0], YELLOW), (fits[1], BLUE)):
                ring = np.where(cls == inner, cfg.inner_radius, cfg.outer_radius)
                misfit.append(np.abs(np.hypot(*(xy - c).T) - ring))
            right_side, left_side = misfit[0] < misfit[1], misfit[1] <= misfit[0]
        if self.centres is None:
            if fits[0] is None or fits[1] is None:
                return
            self.centres = np.array(fits)
            return
        for k, f in enumerate(fits):
            if f is not None:
                self.centres[k] = (1 - cfg.smoothing) * self.centres[k] + cfg.smoothing * f

    def plan(self, cones_xy: np.ndarray, classes: np.ndarray) -> np.ndarray:
        """Refit, then the figure-eight path (``(M, 2)``); before any fit, the straight ahead."""
        self.update(cones_xy, classes)
        return self.path()

    def path(self) -> np.ndarray:
        cfg = self.config
        step = cfg.step
        if self.centres is None:
            s = np.arange(-3.0, 20.0 + step / 2, step)
            self.lengths = {"approach": 23.0, "circles": 0.0, "exit": 0.0}
            return self.start + s[:, None] * self.axis
        c_r, c_l = self.centres
        junction = (c_r + c_l) / 2
        radius = float(np.hypot(*(c_l - c_r))) / 2
        # approach: from 3 m behind the start along the axis to the junction (fixed number of points
        # per unit of the *nominal* approach, so the parameterisation hardly moves between refits)
        approach_len = max(float((junction - self.start) @ self.axis) + 3.0, 1.0)
        n_app = max(int(round(approach_len / step)), 2)
        t = np.linspace(0.0, 1.0, n_app, endpoint=False)
        begin = self.start - 3.0 * self.axis
        approach = begin + t[:, None] * (junction - begin)
        n_circ = int(round(cfg.laps_per_circle * 2 * math.pi * radius / step))
        phase = np.linspace(0.0, cfg.laps_per_circle * 2 * math.pi, n_circ, endpoint=False)
        th_r = math.atan2(*(junction - c_r)[::-1])
        th_l = math.atan2(*(junction - c_l)[::-1])
        right = c_r + radius * np.c_[np.cos(th_r - phase), np.sin(th_r - phase)]  # clockwise
        left = c_l + radius * np.c_[np.cos(th_l + phase), np.sin(th_l + phase)]  # counter-clockwise
        out_dir = (junction - begin) / max(float(np.hypot(*(junction - begin))), 1e-9)
        s_exit = np.arange(0.0, cfg.exit_length + step / 2, step)
        exit_ = junction + s_exit[:, None] * out_dir
        self.lengths = {"approach": n_app * step, "circles": 2 * n_circ * step, "exit": float(cfg.exit_length)}
        return np.vstack([approach, right, left, exit_])
