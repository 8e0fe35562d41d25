"""Dynamic bicycle model with a friction-limited Fiala tyre, integrated at the physics rate.

Compiled (numba), no PyBullet: PyBullet only carries the car's body for collisions and rendering.

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

import numba
import numpy as np

from weather_gym.core._jit_cache import jit_cache
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


@numba.njit(cache=jit_cache(__file__), nogil=True, inline="always")
def _fiala(alpha: float, c: float, fz: float, mu: float, two: float, three: float) -> float:  # pragma: no cover
    """Lateral tyre force (N) at slip angle ``alpha`` with cornering stiffness ``c``."""
    if mu <= 0 or fz <= 0:
        return 0.0
    ta = math.tan(alpha)
    lim = 3.0 * mu * fz / c
    if abs(ta) >= lim:
        return -mu * fz * math.copysign(1.0, alpha)
    # libm's pow, as CPython's float ** int: exponents known only at run time (see _advance)
    return -c * ta + (c * c) / (3 * mu * fz) * abs(ta) * ta - math.pow(c, three) / (27 * math.pow(mu * fz, two)) * math.pow(ta, three)


# constants (Car._make_constants): index of each in the array the kernel reads
_G, _LF, _LR, _M, _WB, _M_ACCEL, _M_BRAKE, _ROLL, _FZ_F, _FZ_R, _MAX_STEER, _STEER_RATE, _MAX_POWER, _DRAG, \
    _C_F, _C_R, _YAW_INERTIA, _MAX_SPEED, _TWO, _THREE = range(20)


@numba.njit(cache=jit_cache(__file__), nogil=True)
def _advance(st, k, n: int, dt: float, steer: float, pedal: float, mu: float) -> None:  # pragma: no cover (compiled)
    """``n`` steps of ``dt`` seconds of the state ``st`` = (x, y, yaw, vx, vy, yaw_rate, steer), in place."""
    g, lf, lr, m, wheelbase = k[_G], k[_LF], k[_LR], k[_M], k[_WB]
    # The exponents 2 and 3 come from the array, not as literals: LLVM turns pow(x, 2.0) into x * x,
    # and glibc's pow (what CPython's x ** 2 calls) is not always that in the last bit.
    two, three = k[_TWO], k[_THREE]
    for _ in range(n):
        target = steer * k[_MAX_STEER]
        max_delta = k[_STEER_RATE] * dt
        st[6] += min(max(target - st[6], -max_delta), max_delta)
        delta = st[6]

        vx = max(st[3], 0.0)
        # longitudinal force: drive on the rear axle (power limited), brakes on both, drag, rolling
        if pedal >= 0:
            f_drive = min(k[_M_ACCEL] * pedal, k[_MAX_POWER] / max(vx, 1.0))
            f_brake = 0.0
        else:
            f_drive = 0.0
            f_brake = k[_M_BRAKE] * (-pedal) if vx > 0 else 0.0
        f_resist = k[_DRAG] * vx * vx + k[_ROLL] if vx > 0 else 0.0
        # traction / braking limited by friction on each axle
        f_drive = min(f_drive, mu * k[_FZ_R])
        f_brake = min(f_brake, mu * m * g)
        fx_r = f_drive - 0.4 * f_brake
        fx_f = -0.6 * f_brake
        # friction circle: what longitudinal force uses is not available laterally
        fy_max_f = math.sqrt(max(math.pow(mu * k[_FZ_F], two) - math.pow(fx_f, two), 0.0)) / max(mu, 1e-9)
        fy_max_r = math.sqrt(max(math.pow(mu * k[_FZ_R], two) - math.pow(fx_r, two), 0.0)) / max(mu, 1e-9)

        yaw_rate, vy = st[5], st[4]
        if vx > 0.1:
            a_f = math.atan2(vy + lf * yaw_rate, vx) - delta
            a_r = math.atan2(vy - lr * yaw_rate, vx)
        else:
            a_f = a_r = 0.0
        fy_f = _fiala(a_f, k[_C_F], fy_max_f, mu, two, three)
        fy_r = _fiala(a_r, k[_C_R], fy_max_r, mu, two, three)

        cd, sd = math.cos(delta), math.sin(delta)
        ax = (fx_r + fx_f * cd - fy_f * sd - f_resist) / m + vy * yaw_rate
        ay = (fy_r + fy_f * cd + fx_f * sd) / m - vx * yaw_rate
        r_dot = (lf * (fy_f * cd + fx_f * sd) - lr * fy_r) / k[_YAW_INERTIA]

        vx_new = min(max(vx + ax * dt, 0.0), k[_MAX_SPEED])  # brakes stop the car, they do not reverse it
        vy_dyn = vy + ay * dt
        r_dyn = yaw_rate + r_dot * dt
        # kinematic bicycle at low speed, blended into the dynamic model
        td = math.tan(delta)
        beta = math.atan(lr * td / wheelbase)
        v_kin = vx_new
        r_kin = v_kin * math.cos(beta) * td / wheelbase
        vy_kin = v_kin * math.sin(beta)
        w = min(max((vx_new - _LOW_SPEED) / _BLEND, 0.0), 1.0)
        st[3] = vx_new
        st[4] = w * vy_dyn + (1 - w) * vy_kin
        st[5] = w * r_dyn + (1 - w) * r_kin

        yaw = st[2]
        c, si = math.cos(yaw), math.sin(yaw)
        vx, vy = st[3], st[4]
        st[0] += (vx * c - vy * si) * dt
        st[1] += (vx * si + vy * c) * dt
        turned = yaw + st[5] * dt
        st[2] = math.atan2(math.sin(turned), math.cos(turned))


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
    def step(self, dt: float, steer: float, pedal: float, friction: float | None = None, n: int = 1) -> None:
        """Advance by ``n`` steps of ``dt`` seconds (one compiled call). ``steer`` and ``pedal`` are
        normalised commands in [-1, 1] (pedal > 0 throttle, < 0 brake)."""
        cfg, s = self.config, self.state
        k = self._constants
        if k[0] is not cfg or k[1] != self.gravity:
            k = self._constants = (cfg, self.gravity, self._make_constants())
        mu = cfg.friction if friction is None else friction
        st = np.array([s.x, s.y, s.yaw, s.vx, s.vy, s.yaw_rate, s.steer])
        _advance(st, k[2], int(n), float(dt), float(steer), float(pedal), float(mu))
        s.x, s.y, s.yaw, s.vx, s.vy, s.yaw_rate, s.steer = st.tolist()

    def _make_constants(self) -> np.ndarray:
        """The config's numbers that :func:`_advance` reads (indices ``_G`` ...), products computed as
        the model always computed them (same floats)."""
        cfg, g = self.config, self.gravity
        lf, lr, m = cfg.cg_to_front, cfg.cg_to_rear, cfg.mass
        return np.array([g, lf, lr, m, cfg.wheelbase, m * cfg.max_accel, m * cfg.max_brake,
                         cfg.rolling_resistance * m * g, m * g * lr / cfg.wheelbase, m * g * lf / cfg.wheelbase,
                         cfg.max_steer, cfg.steer_rate, cfg.max_power, cfg.drag, cfg.cornering_stiffness_front,
                         cfg.cornering_stiffness_rear, cfg.yaw_inertia, cfg.max_speed, 2.0, 3.0], dtype=np.float64)
