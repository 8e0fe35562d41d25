"""Configuration of ``ConeTrackEnv`` (frozen dataclasses; scenario TOML files map onto them).

Example:
    >>> from weather_gym.envs.config import EnvConfig
    >>> cfg = EnvConfig(track="peanut", laps=2)
    >>> cfg.camera.width, cfg.sim.control_hz
    (672, 30.0)
    >>> EnvConfig(camera_images=False, ground_truth="geometry").ground_truth   # render-free
    'geometry'
"""

from __future__ import annotations

import typing
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field, InstanceOf

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core.errors import InputError
from weather_gym.core.schema import NonNegative, NonNegativeInt, Share, check_fields
from weather_gym.sim.config import CarConfig, OdometryConfig, SimConfig
from weather_gym.sim.lidar_config import LidarConfig

GroundTruth = Literal["segmentation", "geometry", "off"]
GROUND_TRUTH_MODES: tuple[str, ...] = typing.get_args(GroundTruth)
"""Where ``info["gt"]`` comes from: the rendered segmentation (pixel exact), geometry (no rendering;
:mod:`weather_gym.sim.visibility`), or nowhere (no ``info["gt"]``)."""

RenderView = Literal["chase", "camera"]
RENDER_VIEWS: tuple[str, ...] = typing.get_args(RenderView)
"""Views ``ConeTrackEnv.render()`` can return (``EnvConfig.render_view``)."""


@dataclass(frozen=True)
class RewardConfig:
    """Reward = progress * metres gained along the centerline + cone_hit per new cone touched
    + off_track on leaving the track + stall on the step an episode ends for stalling
    (``EnvConfig.stall_s``) + time per step."""

    progress: float = 1.0
    cone_hit: float = -2.0
    off_track: float = -10.0
    time: float = 0.0
    stall: float = -10.0

    def __post_init__(self) -> None:
        check_fields(self)


def _lidar(value: Any) -> Any:
    """``EnvConfig.lidar`` given as a dict of ``LidarConfig``'s fields (a scenario file's table) -> a ``LidarConfig``."""
    if isinstance(value, dict):
        try:
            return LidarConfig(**value)
        except TypeError as exc:
            raise InputError(f"EnvConfig.lidar: {exc}") from None
    return value


@dataclass(frozen=True)
class EnvConfig:
    """Everything a ``ConeTrackEnv`` is built from.

    Attributes:
        track: registered track name, ``"random:SEED"``, ``"reverse:SPEC"`` (driven the other way round),
            ``"mirror:SPEC"`` (reflected) or a path to a cone CSV file.
        track_seed: seed for generated tracks when ``track`` is ``"random"``.
        laps: the episode terminates after this many laps (or when an open event is finished);
            0 = never terminate on laps.
        terminate_off_track: end the episode when the car leaves the track.
        off_track_margin: metres beyond the cone line the car's reference point may go before it
            counts as off track (0.6 m = all four wheels out for a 1.2 m wide car).
        stall_s: terminate the episode (``end_reason`` ``"stalled"``, reward ``RewardConfig.stall``)
            when the car has gained less than ``stall_m`` along the centre line in the last ``stall_s``
            seconds (from the reset on, so a car that never leaves its start stalls too); 0 = never
            (the default): a standing car then costs nothing and runs to the time limit.
        stall_m: metres of progress the car must make in every ``stall_s`` window.
        random_start: the share of resets (without a ``start_pose`` or ``start_s`` option, on a closed
            track) that start at a uniformly drawn arc length instead of the start line, drawn from the
            episode's RNG; 0 = always the start line. For training: 0.75 still starts a quarter of the
            episodes where an evaluation starts (the start line's big orange cones beside a standing car).
        randomize_look: draw a random appearance from the episode's RNG at every reset.
        camera_images: render the camera (``obs["image"]``, ``obs["depth"]``); False = render nothing
            (the observation is ``state`` only; pair with ``ground_truth="geometry"``).
        ground_truth: ``info["gt"]`` from the rendered ``"segmentation"``, from ``"geometry"`` (the
            segmentation pass is then skipped), or ``"off"``.
        render_view: what ``render()`` returns with ``render_mode="rgb_array"``: ``"chase"`` (a
            camera behind the car, for people) or ``"camera"`` (the car's camera frame; through a
            ``WeatherWrapper`` it is the weathered frame the agent sees, so Gymnasium's and our
            ``RecordVideo`` record the weather).
        camera_model: the camera's image pipeline applied to every frame before anything else sees it
            (``weather_gym.camera.isp``; by default ``CameraModel.realistic()``: exposure, tone curve,
            white balance, vignetting, distortion, defocus, sensor noise, 4:2:0 and JPEG, as a real camera
            delivers frames; ``CameraModel.ideal()`` switches it off = the study's ideal camera, as
            ``WeatherGym/ConeTrackPlain-v0`` does). Weather wrappers act on the finished frame.

        lidar: a LiDAR on the car (``LidarConfig``; None, the default: none). With one, the observation
            gains ``points`` ``(lidar.rays, 4)`` float32 (x, y, z in the sensor frame, intensity; padded
            with zeros) and ``points_mask`` ``(lidar.rays,)`` int8, a new scan every ``control_hz /
            lidar.rate_hz`` steps, and ``info["lidar"]`` holds the scan as a ``PointCloud`` (with the
            ground truth of which cone each return hit) and ``info["lidar_new"]`` whether it is new.

    The episode's time limit is not here: Gymnasium's ``TimeLimit`` owns truncation
    (``gym.make(id, max_episode_steps=...)``; each scenario registers its default).
    """

    track: Annotated[str, Field(min_length=1)] = "small_track"
    track_seed: int | None = None
    laps: NonNegativeInt = 1
    terminate_off_track: bool = True
    off_track_margin: NonNegative = 0.6
    stall_s: NonNegative = 0.0
    stall_m: NonNegative = 1.0
    random_start: Share = 0.0
    randomize_look: bool = False
    camera_images: bool = True
    ground_truth: GroundTruth = "segmentation"
    render_view: RenderView = "chase"
    sim: InstanceOf[SimConfig] = field(default_factory=SimConfig)
    car: InstanceOf[CarConfig] = field(default_factory=CarConfig)
    camera: InstanceOf[CameraConfig] = field(default_factory=CameraConfig)
    odometry: InstanceOf[OdometryConfig] = field(default_factory=OdometryConfig)
    reward: InstanceOf[RewardConfig] = field(default_factory=RewardConfig)
    camera_model: InstanceOf[CameraModel] = field(default_factory=CameraModel.realistic)
    lidar: Annotated[InstanceOf[LidarConfig] | None, BeforeValidator(_lidar)] = None

    def __post_init__(self) -> None:
        check_fields(self)  # each field against its annotation; then the relations between fields
        if not self.camera_images and self.ground_truth == "segmentation":
            raise InputError('EnvConfig.ground_truth="segmentation" needs rendered frames; with camera_images=False '
                             'take ground_truth="geometry" (or "off")')
        if self.camera_images and self.sim.renderer == "none":
            raise InputError('EnvConfig: sim.renderer="none" renders no camera frames; set camera_images=False '
                             '(or pick renderer "auto", "egl" or "tiny")')
        if self.render_view == "camera" and not self.camera_images:
            raise InputError('EnvConfig: render_view="camera" needs camera_images=True (nothing is rendered otherwise)')
