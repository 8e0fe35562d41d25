"""``ConeShield``: a safety filter that keeps a driver's steering off the cones it can see.

A learned driver can cut a turn it has never driven: on a road narrower than any it trained on, the
shipped ``ppo_cones`` touched the inside cone of a tight turn and then the outside one on the exit.
``ConeShield`` sits between the policy and the car (the *shielding* of safe reinforcement learning:
Alshiekh et al., "Safe Reinforcement Learning via Shielding", AAAI 2018; here with a short-horizon
model check, as in predictive safety filters, Wabersich and Zeilinger, Automatica 2021). Each step
it rolls the car forward for ``horizon`` seconds with a kinematic bicycle model (the car's wheelbase,
steering limit and steering rate, the speed and yaw rate the car's own sensors report in
``obs["state"]``), once with the policy's steering held and once for each of ``candidates`` steering
values spread over the action range, and measures the gap between the car's body (a rectangle) and
the base of every cone in the observation's list. The policy's action passes unchanged while its
rollout keeps ``margin`` metres from every cone (or, for a cone already closer than that, does not
come any closer). Otherwise the shield steers with the steering value nearest the policy's that
does, at most ``max_change`` away from it (a short look ahead can call a swerve the wrong way safe,
which leaves the road a second later), and keeps the policy's pedal; when none within
``max_change`` does, it takes the one of those that comes least close and brakes (``brake``),
unless the car is crawling (``crawl_speed``). It reads only the cone list and the state, never
ground truth.

The shipped ``ppo_cones`` driver drives with it (its JSON records ``cone_shield``; the ``sb3`` agent
applies what a saved model's JSON records, or ``cone_shield=``).

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.cone_shield import ConeShield
    >>> from weather_gym.perception.cones import FIELD
    >>> shield = ConeShield()
    >>> cones = np.zeros((4, 14), np.float32)
    >>> cones[0, FIELD["x_body"]], cones[0, FIELD["y_body"]] = 6.0, 0.3   # a cone ahead
    >>> obs = {"cones": cones, "mask": np.array([1, 0, 0, 0], np.int8),
    ...        "state": np.array([8.0, 0, 0, 0, 0], np.float32)}        # at 8 m/s
    >>> shield.reset()
    >>> steer, pedal = shield(obs, np.array([0.0, 0.5], np.float32))
    >>> round(float(steer), 2), float(pedal)              # steers right of it, keeps the pedal
    (-0.15, 0.5)
    >>> shield.interventions
    1
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from weather_gym.core.errors import InputError, check_known
from weather_gym.core.schema import NonNegative, Positive, check_fields
from weather_gym.perception.cones import FIELD
from weather_gym.sim.config import CarConfig

__all__ = ["ConeShield", "ConeShieldConfig"]

_X, _Y = FIELD["x_body"], FIELD["y_body"]


@dataclass(frozen=True)
class ConeShieldConfig:
    """How a :class:`ConeShield` checks and mends an action.

    Attributes:
        horizon: seconds of driving each steering value is rolled forward for.
        step: the rollout's time step (s).
        margin: the gap (m) kept between the car's body and a cone's base.
        candidates: steering values tried, evenly spread over [-1, 1] (odd: straight ahead is one).
        cone_radius: a cone's base radius (m; the small FS cone's base is 0.228 m wide).
        max_change: the most the shield moves the policy's steering (in action units, of 2 from full
            left to full right): a turn is mended, not swapped for one the other way.
        brake: the pedal (in [-1, 0]) when no steering value within ``max_change`` keeps the margin
            and the car is faster than ``crawl_speed``.
        crawl_speed: at this speed (m/s) or slower the shield leaves the pedal to the driver (a car
            stopped among cones it cannot steer clear of would otherwise wait there for good).
        min_speed: the speed (m/s) a rollout assumes at least, so a car at rest still looks ahead.
    """

    horizon: Positive = 0.5
    step: Positive = 0.05
    margin: NonNegative = 0.15
    candidates: Annotated[int, Field(ge=3)] = 41
    cone_radius: NonNegative = 0.114
    max_change: Annotated[float, Field(gt=0.0, le=2.0)] = 0.3
    brake: Annotated[float, Field(ge=-1.0, le=0.0)] = -0.3
    crawl_speed: NonNegative = 2.0
    min_speed: Positive = 1.0

    def __post_init__(self) -> None:
        check_fields(self)
        if self.candidates % 2 == 0:
            raise InputError(f"ConeShieldConfig.candidates must be odd (straight ahead among them), got {self.candidates}")

    def to_dict(self) -> dict:
        """Plain fields (JSON): what a model's ``model.json`` records."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ConeShieldConfig:
        """From :meth:`to_dict`'s dict, or a part of it (the rest default); unknown keys are an error."""
        if not isinstance(d, dict):
            raise InputError(f"cone_shield must be a table of ConeShieldConfig fields, got {d!r}")
        check_known(d, {f.name for f in dataclasses.fields(cls)}, what="cone_shield")
        return cls(**d)


class ConeShield:
    """Action in, the action kept off the cones out (see the module doc).

    Args:
        config: a :class:`ConeShieldConfig`.
        car: the car's geometry and steering (``CarConfig`` defaults: the env's car).

    ``interventions`` counts the steps of the episode whose action it changed.
    """

    def __init__(self, config: ConeShieldConfig | None = None, car: CarConfig | None = None) -> None:
        self.config = cfg = config or ConeShieldConfig()
        self.car = car = car or CarConfig()
        self._targets = np.linspace(-1.0, 1.0, cfg.candidates)
        self._n_steps = max(1, math.ceil(cfg.horizon / cfg.step - 1e-9))
        self._half = (car.length / 2, car.width / 2)
        self._body_dx = car.body_center_x
        self.interventions = 0

    def reset(self) -> None:
        """A new episode: the intervention count starts again."""
        self.interventions = 0

    def __call__(self, obs: dict, action: np.ndarray) -> np.ndarray:
        """``action`` (steering, pedal) as it is, or mended (a new float32 array)."""
        action = np.asarray(action, dtype=np.float32).reshape(-1)
        cfg, car = self.config, self.car
        mask = np.asarray(obs["mask"]).astype(bool)
        cones = np.asarray(obs["cones"], dtype=np.float64)[mask][:, [_X, _Y]]
        state = np.asarray(obs["state"], dtype=np.float64).reshape(-1)
        speed = max(float(state[0]), cfg.min_speed)
        reach = speed * cfg.horizon + car.length + cfg.margin + cfg.cone_radius
        cones = cones[np.hypot(cones[:, 0], cones[:, 1]) <= reach]
        if not len(cones):
            return action
        targets = np.append(float(np.clip(action[0], -1.0, 1.0)), self._targets)
        gaps = self._gaps(targets, cones, speed, float(state[1]))  # (candidate, time, cone)
        now = self._gap_now(cones)
        need = np.minimum(cfg.margin, now - 1e-6)
        shortfall = (need[None, :] - gaps.min(axis=1)).max(axis=1)  # > 0: comes too close to a cone
        if shortfall[0] <= 0:
            return action
        self.interventions += 1
        near = np.abs(self._targets - action[0]) <= cfg.max_change + 1e-9
        safe = near & (shortfall[1:] <= 0)
        if safe.any():
            pick = np.flatnonzero(safe)[np.argmin(np.abs(self._targets[safe] - action[0]))]
            return np.array([self._targets[pick], action[1]], np.float32)
        pick = np.flatnonzero(near)[np.argmin(shortfall[1:][near])]
        pedal = float(action[1]) if float(state[0]) <= cfg.crawl_speed else min(float(action[1]), cfg.brake)
        return np.array([self._targets[pick], pedal], np.float32)

    def _gaps(self, targets: np.ndarray, cones: np.ndarray, speed: float, yaw_rate: float) -> np.ndarray:
        """Gap (m) between body and each cone's base along each steering target's rollout."""
        cfg, car = self.config, self.car
        dt, wb = cfg.step, car.wheelbase
        now = min(max(math.atan(yaw_rate * wb / speed), -car.max_steer), car.max_steer)  # from the yaw rate
        delta = np.full(len(targets), now)
        goal = targets * car.max_steer
        x = np.zeros(len(targets))
        y = np.zeros(len(targets))
        yaw = np.zeros(len(targets))
        poses = np.empty((self._n_steps, 3, len(targets)))
        for k in range(self._n_steps):
            delta += np.clip(goal - delta, -car.steer_rate * dt, car.steer_rate * dt)
            yaw = yaw + speed * np.tan(delta) / wb * dt
            x = x + speed * np.cos(yaw) * dt
            y = y + speed * np.sin(yaw) * dt
            poses[k] = x, y, yaw
        px, py, pyaw = (poses[:, i].T[:, :, None] for i in range(3))  # (candidate, time, 1)
        dx, dy = cones[:, 0] - px, cones[:, 1] - py
        c, s = np.cos(pyaw), np.sin(pyaw)
        return self._box_gap(dx * c + dy * s - self._body_dx, -dx * s + dy * c)

    def _gap_now(self, cones: np.ndarray) -> np.ndarray:
        """Gap (m) between the body where it is now and each cone's base."""
        return self._box_gap(cones[:, 0] - self._body_dx, cones[:, 1])

    def _box_gap(self, along: np.ndarray, across: np.ndarray) -> np.ndarray:
        """Signed distance from points in the body frame to the body's rectangle, less a cone's base."""
        hl, hw = self._half
        ox, oy = np.abs(along) - hl, np.abs(across) - hw
        outside = np.hypot(np.maximum(ox, 0.0), np.maximum(oy, 0.0))
        return outside + np.minimum(np.maximum(ox, oy), 0.0) - self.config.cone_radius
