"""Dynamic bicycle model with a friction-limited Fiala tyre, integrated at the physics rate.

Pure numpy/math: PyBullet only carries the car's body for collisions and rendering.

Example:
    >>> from weather_gym.sim.car import Car
    >>> car = Car()
    >>> car.reset(0.0, 0.0, 0.0)
    >>> for _ in range(240): car.step(1 / 240, steer=0.0, pedal=1.0)
    >>> 4.0 < car.speed < 7.0   # about 6 m/s after one second at full throttle
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from weather_gym.sim.config import CarConfig

_LOW_SPEED = 1.0  # below this, the kinematic model takes over (dynamic slip angles are singular at v=0)
_BLEND = 2.0  # fully dynamic above _LOW_SPEED + _BLEND


@dataclass
class CarState:
    x: float = 0.0  # centre of gravity, world frame
    y: float = 0.0
    yaw: float = 0.0
    vx: float = 0.0  # body-frame velocity of the CG
    vy: float = 0.0
    yaw_rate: float = 0.0
    steer: float = 0.0  # front wheel angle, rad


def _fiala(alpha: float, c: float, fz: float, mu: float) -> float:
    """Lateral tyre force (N) at slip angle ``alpha`` with cornering stiffness ``c``."""
    if mu <= 0 or fz <= 0:
        return 0.0
    ta = math.tan(alpha)
    lim = 3.0 * mu * fz / c
    if abs(ta) >= lim:
        return -mu * fz * math.copysign(1.0, alpha)
    return -c * ta + (c * c) / (3 * mu * fz) * abs(ta) * ta - (c**3) / (27 * (mu * fz) ** 2) * ta**3


class Car:
    """The car's dynamics. Reference point for poses = centre of the rear axle."""

    def __init__(self, config: CarConfig | None = None, gravity: float = 9.81) -> None:
        self.config = config or CarConfig()
        self.gravity = gravity
        self.state = CarState()
        self._constants: tuple = (None, None)

    # ---- pose of the reference point (rear axle) -------------------------------------------------
    def reset(self, x: float, y: float, yaw: float, speed: float = 0.0) -> None:
        lr = self.config.cg_to_rear
        self.state = CarState(x=x + lr * math.cos(yaw), y=y + lr * math.sin(yaw), yaw=yaw, vx=speed)

    @property
    def pose(self) -> tuple[float, float, float]:
        s, lr = self.state, self.config.cg_to_rear
        return (s.x - lr * math.cos(s.yaw), s.y - lr * math.sin(s.yaw), s.yaw)

    @property
    def speed(self) -> float:
        return math.hypot(self.state.vx, self.state.vy)

    @property
    def velocity_world(self) -> tuple[float, float]:
        s = self.state
        c, si = math.cos(s.yaw), math.sin(s.yaw)
        return (s.vx * c - s.vy * si, s.vx * si + s.vy * c)

    # ---- dynamics --------------------------------------------------------------------------------
    def step(self, dt: float, steer: float, pedal: float, friction: float | None = None) -> None:
        """Advance by ``dt`` seconds. ``steer`` and ``pedal`` are normalised commands in [-1, 1]
        (pedal > 0 throttle, < 0 brake)."""
        cfg, s = self.config, self.state
        k = self._constants
        if k[0] is not cfg or k[1] != self.gravity:
            k = self._constants = self._make_constants()
        _, g, lf, lr, m, wheelbase, m_accel, m_brake, roll, fz_f, fz_r = k
        mu = cfg.friction if friction is None else friction

        target = steer * cfg.max_steer
        max_delta = cfg.steer_rate * dt
        s.steer += min(max(target - s.steer, -max_delta), max_delta)
        delta = s.steer

        vx = max(s.vx, 0.0)
        # longitudinal force: drive on the rear axle (power limited), brakes on both, drag, rolling
        if pedal >= 0:
            f_drive = min(m_accel * pedal, cfg.max_power / max(vx, 1.0))
            f_brake = 0.0
        else:
            f_drive = 0.0
            f_brake = m_brake * (-pedal) if vx > 0 else 0.0
        f_resist = cfg.drag * vx * vx + roll if vx > 0 else 0.0
        # traction / braking limited by friction on each axle
        f_drive = min(f_drive, mu * fz_r)
        f_brake = min(f_brake, mu * m * g)
        fx_r = f_drive - 0.4 * f_brake
        fx_f = -0.6 * f_brake
        # friction circle: what longitudinal force uses is not available laterally
        fy_max_f = math.sqrt(max((mu * fz_f) ** 2 - fx_f**2, 0.0)) / max(mu, 1e-9)
        fy_max_r = math.sqrt(max((mu * fz_r) ** 2 - fx_r**2, 0.0)) / max(mu, 1e-9)

        yaw_rate, vy = s.yaw_rate, s.vy
        if vx > 0.1:
            a_f = math.atan2(vy + lf * yaw_rate, vx) - delta
            a_r = math.atan2(vy - lr * yaw_rate, vx)
        else:
            a_f = a_r = 0.0
        fy_f = _fiala(a_f, cfg.cornering_stiffness_front, fy_max_f, mu)
        fy_r = _fiala(a_r, cfg.cornering_stiffness_rear, fy_max_r, mu)

        cd, sd = math.cos(delta), math.sin(delta)
        ax = (fx_r + fx_f * cd - fy_f * sd - f_resist) / m + vy * yaw_rate
        ay = (fy_r + fy_f * cd + fx_f * sd) / m - vx * yaw_rate
        r_dot = (lf * (fy_f * cd + fx_f * sd) - lr * fy_r) / cfg.yaw_inertia

        vx_new = min(max(vx + ax * dt, 0.0), cfg.max_speed)  # brakes stop the car, they do not reverse it
        vy_dyn = vy + ay * dt
        r_dyn = yaw_rate + r_dot * dt
        # kinematic bicycle at low speed, blended into the dynamic model
        td = math.tan(delta)
        beta = math.atan(lr * td / wheelbase)
        v_kin = vx_new
        r_kin = v_kin * math.cos(beta) * td / wheelbase
        vy_kin = v_kin * math.sin(beta)
        w = min(max((vx_new - _LOW_SPEED) / _BLEND, 0.0), 1.0)
        s.vx = vx_new
        s.vy = w * vy_dyn + (1 - w) * vy_kin
        s.yaw_rate = w * r_dyn + (1 - w) * r_kin

        yaw = s.yaw
        c, si = math.cos(yaw), math.sin(yaw)
        vx, vy = s.vx, s.vy
        s.x += (vx * c - vy * si) * dt
        s.y += (vx * si + vy * c) * dt
        turned = yaw + s.yaw_rate * dt
        s.yaw = math.atan2(math.sin(turned), math.cos(turned))

    def _make_constants(self) -> tuple:
        """The config's products that :meth:`step` needs, computed as it computed them (same floats)."""
        cfg, g = self.config, self.gravity
        lf, lr, m = cfg.cg_to_front, cfg.cg_to_rear, cfg.mass
        return (cfg, g, lf, lr, m, cfg.wheelbase, m * cfg.max_accel, m * cfg.max_brake,
                cfg.rolling_resistance * m * g, m * g * lr / cfg.wheelbase, m * g * lf / cfg.wheelbase)
