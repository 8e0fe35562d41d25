"""Frozen configuration of the simulator: physics and control rates, the car, its odometry.

No PyBullet import here, so any layer may read these.

Example:
    >>> from weather_gym.sim.config import SimConfig, CarConfig
    >>> SimConfig(physics_hz=240, control_hz=30).substeps
    8
    >>> CarConfig(friction=0.6).friction
    0.6
    >>> SimConfig().scene, SimConfig(scene="realistic").scene
    ('plain', 'realistic')
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Annotated

from pydantic import Field

from weather_gym.core.errors import InputError
from weather_gym.core.schema import NonNegative, OneOf, Positive, check_fields

RENDERERS = ("auto", "egl", "tiny", "none")
SCENES = ("plain", "realistic")
"""``SimConfig.scene``: the plain world (the default: flat textured ground, clouds, plain-striped cones;
the world the calibration, the presets, the agents and the surrogate are made in) or the realistic one
(FS cone stripes, contact and cast shadows, asphalt with patches and painted lines, run-off, track-side clutter
and distractors, a skyline, the ego car's nose in view: ``weather_gym.sim.scenery``,
``weather_gym.sim.ego``; ``WeatherGym/ConeTrackRealistic-v0``). The realistic world is not the default
because its clutter gives the shipped detector false positives that the mapping agent cannot yet
handle: ``mapper_pure_pursuit`` leaves the track in clear weather there (docs/world.md)."""


@dataclass(frozen=True)
class SimConfig:
    """Rates and world settings.

    Attributes:
        physics_hz: fixed physics rate (car dynamics and PyBullet contacts).
        control_hz: env step rate (actions and camera frames); must divide ``physics_hz``.
        renderer: ``"auto"`` (EGL when it loads, else TinyRenderer), ``"egl"``, ``"tiny"`` or ``"none"``
            (no camera rendering at all: physics only; ground truth from geometry).
        gui: open the PyBullet GUI (needs a display) instead of DIRECT mode.
        cone_mass: kg per small cone (big cones weigh 1.5x).
        shadows: PyBullet's shadow map in the camera's frames (the chase view for humans draws the
            renderer's own way). None (the default): the renderer's own way, which the shipped
            calibration, presets and detector are made with: PyBullet's EGL plugin draws its shadow map
            on every frame, TinyRenderer none. True: shadows with either renderer (TinyRenderer's cost
            about twice the frame). False: none with either; with EGL the frame is about 15 ms faster
            (the shadow-map pass; ``weather-gym bench sim --naive``) and its cones lose the plugin's
            shading, so the calibration's numbers do not hold for it as they stand
            (:mod:`weather_gym.sim.egl.shadow_map`).
        scene: ``"plain"`` (default) or ``"realistic"`` (see ``SCENES``).
        cast_shadows: the realistic scene's cones cast shadows away from the sun, drawn into each
            frame after rendering (:mod:`weather_gym.sim.cast_shadows`); the plain scene has none.
    """

    physics_hz: Positive = 240.0
    control_hz: Positive = 30.0
    renderer: Annotated[str, OneOf(RENDERERS)] = "auto"
    gui: bool = False
    cone_mass: Positive = 0.6
    shadows: bool | None = None
    gravity: Positive = 9.81
    scene: Annotated[str, OneOf(SCENES)] = "plain"
    cast_shadows: bool = True

    def __post_init__(self) -> None:
        check_fields(self)  # each field against its annotation; then the rates against each other
        ratio = self.physics_hz / self.control_hz
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
            raise InputError(
                f"SimConfig.physics_hz ({self.physics_hz}) must be an integer multiple of control_hz ({self.control_hz})"
            )

    @property
    def substeps(self) -> int:
        return int(round(self.physics_hz / self.control_hz))

    @property
    def dt(self) -> float:
        return 1.0 / self.control_hz


REAR_OVERHANG_M = 0.45
"""How far (m) the car's body reaches behind the rear axle (the pose's reference point)."""


@dataclass(frozen=True)
class CarConfig:
    """A Formula Student car as a dynamic bicycle model with a friction-limited (Fiala) tyre.

    The reference point is the centre of the rear axle. ``friction`` is the tyre-road friction
    coefficient mu (dry asphalt ~1.0, wet ~0.6).
    """

    mass: Positive = 230.0
    yaw_inertia: Positive = 110.0
    wheelbase: Positive = 1.55
    cg_to_rear: Positive = 0.80
    width: Positive = 1.2
    length: Positive = 2.6
    body_height: Positive = 0.55
    max_steer: Annotated[float, Field(gt=0, lt=math.pi / 2)] = 0.45  # below pi/2 rad
    steer_rate: Positive = 4.0
    max_accel: Positive = 6.0
    max_brake: Positive = 10.0
    max_power: Positive = 40_000.0
    max_speed: Positive = 25.0
    cornering_stiffness_front: Positive = 18_000.0
    cornering_stiffness_rear: Positive = 22_000.0
    drag: NonNegative = 0.55  # 0.5 * rho * Cd * A, N / (m/s)^2
    rolling_resistance: NonNegative = 0.015
    friction: Positive = 1.0

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.cg_to_rear < self.wheelbase:
            raise InputError(f"CarConfig.cg_to_rear must lie inside the wheelbase (0, {self.wheelbase}), got {self.cg_to_rear}")

    @property
    def cg_to_front(self) -> float:
        return self.wheelbase - self.cg_to_rear

    @property
    def body_center_x(self) -> float:
        """How far (m) the body's centre sits ahead of the rear axle (``REAR_OVERHANG_M`` behind it)."""
        return self.length / 2 - REAR_OVERHANG_M


@dataclass(frozen=True)
class OdometryConfig:
    """Noise of the car's own odometry (wheel-speed scale error and noise, gyro bias and noise).

    Per-episode errors are drawn from the env's RNG at reset. Set all to 0 for perfect odometry.
    """

    speed_scale_std: NonNegative = 0.005
    speed_noise_std: NonNegative = 0.02
    gyro_bias_std: NonNegative = 0.002
    gyro_noise_std: NonNegative = 0.005

    def __post_init__(self) -> None:
        check_fields(self)


def config_to_dict(cfg) -> dict:
    return asdict(cfg)
