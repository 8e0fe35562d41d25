"""``ConeTrackEnv``: a Formula Student cone track with a camera car, as a Gymnasium environment.

Observation: ``Dict(image, depth, state)`` (``Dict(state)`` when ``camera_images=False``); action:
``Box(-1, 1, (2,))`` = (steering, throttle/brake). Ground truth (the visible cones, true pose, ...)
is only in ``info``; every ``info`` value is a number, a fixed-shape array or one object, so
Gymnasium's vector envs can stack it. The full reference (reward, termination, every ``info`` key,
arguments, version history) is ``docs/envs.md``.

The PyBullet world is created at the first ``reset()`` (an env that is only inspected - spaces,
spec - starts no physics client and no renderer). Truncation belongs to Gymnasium's ``TimeLimit``
(``gym.make(id, max_episode_steps=...)``); the env itself terminates only on ``END_REASONS``.

Example:
    >>> from weather_gym.envs import ConeTrackEnv, EnvConfig
    >>> env = ConeTrackEnv(EnvConfig(track="small_track"))           # doctest: +SKIP
    >>> obs, info = env.reset(seed=0)                                 # doctest: +SKIP
    >>> obs["image"].shape, obs["state"].shape                        # doctest: +SKIP
    ((376, 672, 3), (5,))
    >>> obs, reward, terminated, truncated, info = env.step([0.0, 0.5])  # doctest: +SKIP
    >>> env.close()                                                   # doctest: +SKIP

Without camera images (no rendering; ground truth from geometry) a reset costs milliseconds:
    >>> env = ConeTrackEnv(EnvConfig(track="small_track", camera_images=False, ground_truth="geometry"))
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["state"].shape, env.action_space.shape
    (['state'], (5,), (2,))
    >>> obs, reward, terminated, truncated, info = env.step([0.0, 0.5])
    >>> terminated, truncated
    (False, False)
    >>> env.close()
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections import deque
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.camera.isp import CameraModel, CameraPipeline
from weather_gym.conditions.grip import grip_ratio
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.errors import InputError, LimitError, StateError, check_known
from weather_gym.core.point_cloud import PointCloud, pack_points
from weather_gym.envs.config import EnvConfig
from weather_gym.sim.look import DEFAULT_LOOK, REALISTIC_LOOK, Look, sample_look
from weather_gym.sim.randomize import sample_realistic
from weather_gym.sim.world import World
from weather_gym.tracks import load_track
from weather_gym.tracks._track import Projection

STATE_FIELDS: tuple[str, ...] = ("speed", "yaw_rate", "odom_x", "odom_y", "odom_yaw")
"""Names of ``obs["state"]``: wheel-speed odometry (m/s), gyro yaw rate (rad/s), odometry pose."""

MAX_FRICTION = 3.0
"""Largest tyre-road friction coefficient a reset accepts (racing slicks on dry tarmac reach about 1.7)."""
RESET_OPTIONS = ("look", "start_pose", "start_s", "start_speed", "friction", "water_film_mm", "camera_model",
                 "camera_frame")
WRAPPER_RESET_OPTIONS = ("weather",)
"""Reset options the weather wrappers above the env take (and remove) before the env sees the rest."""

END_REASONS: tuple[str, ...] = ("laps", "off_track", "stalled", "time_limit")
"""Why an episode ends: ``laps`` (the requested laps driven, or an open event's finish line
crossed), ``off_track`` (left the track, with ``terminate_off_track``), ``stalled`` (less than
``stall_m`` of progress in ``stall_s`` seconds, with ``EnvConfig.stall_s`` > 0), ``time_limit``
(truncated by ``TimeLimit``). The env reports the first three as ``info["end_reason"]`` on the
terminating step."""


def _wrap_angle(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class ConeTrackEnv(gym.Env):
    """A camera car on a cone track. See the module docstring and ``docs/architecture.md``.

    ``reset(options=...)`` accepts: ``look`` (a ``Look``, its dict, or ``"random"``),
    ``start_pose`` (x, y, yaw), ``start_s`` (arc length along the centerline to start at),
    ``start_speed`` (m/s), ``friction`` (tyre-road mu for this episode, e.g. 0.6 for wet),
    ``water_film_mm`` (water on the road: every step the tyres get ``friction`` times the Bosch table's
    wet/dry grip ratio at the car's speed, :mod:`weather_gym.conditions.grip`; :meth:`set_water_film`
    changes it mid-episode),
    ``camera_model`` (this episode's ``CameraModel`` or its dict) and ``camera_frame`` (start the camera's
    noise stream at this frame of the episode: re-renders a recorded frame with its own sensor noise).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None, **overrides: Any) -> None:
        config = config or EnvConfig()
        if overrides:
            config = replace(config, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.config = config
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": config.sim.control_hz}
        self.track = load_track(config.track, seed=config.track_seed)
        sim = config.sim if config.camera_images else replace(config.sim, renderer="none")
        if render_mode == "human":
            if _display_available():
                sim = replace(sim, gui=True)
            else:
                warnings.warn("render_mode='human' opens the PyBullet GUI, which needs a display (DISPLAY is not "
                              "set): running without a window", RuntimeWarning, stacklevel=2)
        self._sim = sim
        self._world: World | None = None
        self._water_film = 0.0
        cam = config.camera
        obs: dict[str, spaces.Space[Any]] = {"state": spaces.Box(-np.inf, np.inf, (len(STATE_FIELDS),), np.float32)}
        if config.camera_images:
            obs = {"image": spaces.Box(0, 255, (cam.height, cam.width, 3), np.uint8),
                   "depth": spaces.Box(0.0, float(cam.far), (cam.height, cam.width), np.float32), **obs}
        if config.lidar is not None:
            n = config.lidar.rays
            obs["points"] = spaces.Box(-np.inf, np.inf, (n, 4), np.float32)
            obs["points_mask"] = spaces.Box(0, 1, (n,), np.int8)
            self._scan_every = max(1, int(round(config.sim.control_hz / config.lidar.rate_hz)))
        self._scan: PointCloud | None = None
        self._scan_new = False
        self._lidar_rng: np.random.Generator | None = None
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._frame_every = max(1, int(round(config.sim.control_hz / cam.fps)))
        self._image: np.ndarray | None = None
        self._depth: np.ndarray | None = None
        self._gt: ConeArrays | None = None
        self._episode_started = False
        self._pipelines: dict[CameraModel, CameraPipeline] = {}
        self._pipeline: CameraPipeline | None = None
        self._pipeline_rng: np.random.Generator | None = None

    # ------------------------------------------------------------------ properties
    @property
    def world(self) -> World:
        """The PyBullet world (created on first use)."""
        if self._world is None:
            self._world = World(self.track, sim=self._sim, car=self.config.car, camera=self.config.camera)
        return self._world

    @property
    def camera_pipeline(self) -> CameraPipeline | None:
        """This episode's prepared camera model (None for the ideal camera): its ``undistort_points`` is
        the lens calibration a perception stack uses to turn pixels into bearings."""
        return self._pipeline

    @property
    def clear_image(self) -> np.ndarray | None:
        """A copy of the camera frame of the last reset/step as the env rendered it, before any wrapper's
        weather (None without camera images or before the first reset): the clear frame of an episode
        recording (``weather-gym lap --bag``)."""
        return None if self._image is None or not self.config.camera_images else self._image.copy()

    @property
    def renderer(self) -> str:
        """The renderer in use: "egl", "tiny" or "none" (``camera_images=False``)."""
        return self.world.renderer_name

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        self._check_open()
        if options is not None and not isinstance(options, Mapping):
            raise InputError(f"reset options must be a dict (keys {list(RESET_OPTIONS)}), got {options!r}")
        super().reset(seed=seed)
        options = dict(options or {})
        check_known(options, RESET_OPTIONS, what="reset", kind="option",
                    hint=f", and {WRAPPER_RESET_OPTIONS[0]!r} on a stack with weather (a WeatherWrapper or "
                         "SurrogatePerceptionWrapper: weather given, or perception 'detector' / 'surrogate')")
        self._episode_started = False  # until this reset has succeeded
        rng = self.np_random
        look = self._resolve_look(options.get("look"), rng)

        track = self.track
        if "start_pose" in options:
            pose = _numbers(options["start_pose"], "start_pose")
            if len(pose) != 3 or not all(math.isfinite(v) for v in pose):
                raise InputError(f"reset option start_pose must be 3 finite numbers (x, y, yaw), got {options['start_pose']!r}")
        elif "start_s" in options:
            start_s = _numbers([options["start_s"]], "start_s")[0]
            if not math.isfinite(start_s):
                raise InputError(f"reset option start_s must be a finite arc length in metres, got {start_s!r}")
            x, y, h = track.point_at(start_s)
            pose = (float(x), float(y), float(h))
        elif track.closed and self.config.random_start > 0 and rng.random() < self.config.random_start:
            x, y, h = track.point_at(rng.uniform(0.0, track.length))
            pose = (float(x), float(y), float(h))
        else:
            pose = tuple(float(v) for v in track.start_pose)
        speed = _numbers([options.get("start_speed", 0.0)], "start_speed")[0]
        v_max = self.config.car.max_speed  # the car's own top speed: faster starts are not physical
        if not (math.isfinite(speed) and 0 <= speed <= v_max):
            raise LimitError(f"reset option start_speed must be 0 to {v_max:g} m/s (the car's max_speed), got {speed!r}")
        friction = options.get("friction", self.config.car.friction)
        if not (isinstance(friction, (int, float)) and not isinstance(friction, bool) and math.isfinite(friction)
                and 0 < friction <= MAX_FRICTION):
            raise LimitError(f"reset option friction must be a tyre-road friction coefficient in (0, {MAX_FRICTION:g}] "
                             f"(ice 0.1, wet 0.6, dry 1.0, slicks ~1.7), got {friction!r}")
        self._friction = float(friction)
        self._water_film = 0.0
        self.set_water_film(options.get("water_film_mm", 0.0))
        model = options.get("camera_model", self.config.camera_model)
        try:
            model = CameraModel.from_dict(model)
        except TypeError as exc:
            raise InputError(f"reset option camera_model: {exc}") from None
        camera_frame = options.get("camera_frame", 0)
        if isinstance(camera_frame, bool) or not isinstance(camera_frame, (int, np.integer)) or camera_frame < 0:
            raise InputError(f"reset option camera_frame must be an integer >= 0 (frames since the episode's "
                             f"seeded reset), got {camera_frame!r}")
        self._set_pipeline(model, rng)
        if self.config.lidar is not None:  # drawn only with a LiDAR: the episodes of envs without one stay as they were
            self._lidar_rng = np.random.default_rng(int(rng.integers(0, 2**63 - 1)))
        if self._pipeline is not None:
            self._pipeline.skip(cast(np.random.Generator, self._pipeline_rng), int(camera_frame))  # set with the pipeline
        world = self.world
        world.set_look(look)
        world.reset(cast(tuple[float, float, float], pose), speed=speed)  # three numbers, checked above

        # odometry errors of this episode
        od = self.config.odometry
        self._odo_scale = 1.0 + od.speed_scale_std * float(rng.standard_normal())
        self._gyro_bias = od.gyro_bias_std * float(rng.standard_normal())
        self._odom = np.array(pose, dtype=np.float64)

        proj = track.project(pose[0], pose[1])
        self._s = float(proj.s)
        self._progress = 0.0
        self._step = 0
        self._time = 0.0
        self._lap_start_time = 0.0
        self._lap_times: list[float] = []
        self._cones_hit: set[int] = set()
        self._off_track = False
        self._off_track_events = 0
        self._finished = False
        stall_steps = round(self.config.stall_s * self.config.sim.control_hz)
        # progress at the last stall_steps + 1 steps (None: no stall rule)
        self._stall_window = deque([0.0], maxlen=max(stall_steps, 1) + 1) if self.config.stall_s > 0 else None
        self._lateral = float(proj.lateral)
        self._update_frame()
        self._update_scan()
        meas = self._measure(0.0)
        self._episode_started = True
        return self._observation(meas), self._info(proj, new_hits=0, end_reason=None)

    def set_water_film(self, film_mm: float) -> None:
        """Water on the road (mm, 0 to 2: the Bosch table's range) from the next step on; 0: dry."""
        if isinstance(film_mm, bool) or not isinstance(film_mm, (int, float)):
            raise InputError(f"water_film_mm must be a number of millimetres, got {film_mm!r}")
        grip_ratio(float(film_mm), 0.0)  # LimitError outside [0, 2] mm, naming the value
        self._water_film = float(film_mm)

    @property
    def water_film_mm(self) -> float:
        """The water film on the road (mm)."""
        return self._water_film

    @property
    def friction_now(self) -> float:
        """The tyre-road friction of the next step: the episode's dry ``friction`` times the grip ratio of
        the water film at the car's speed (:func:`weather_gym.conditions.grip.grip_ratio`)."""
        if self._water_film == 0.0 or self._world is None:
            return self._friction
        return self._friction * grip_ratio(self._water_film, self._world.car.speed)

    def _set_pipeline(self, model: CameraModel, rng: np.random.Generator) -> None:
        """This episode's camera pipeline; its noise comes from a generator seeded from the episode's
        RNG. The seed is drawn with the camera model on or off, so the study's ideal camera
        (``enabled=False``) and a camera model see the same episode (odometry noise, random looks).
        Render-free, a distorting lens still moves the ground-truth boxes (no frame to finish)."""
        noise_seed = int(rng.integers(0, 2**63 - 1))
        if not model.enabled or not (self.config.camera_images or model.distorts):
            self._pipeline = self._pipeline_rng = None
            return
        pipe = self._pipelines.get(model)
        if pipe is None:
            cam = self.config.camera
            if len(self._pipelines) >= 16:
                self._pipelines.pop(next(iter(self._pipelines)))
            pipe = self._pipelines[model] = CameraPipeline(model, cam.width, cam.height, fx=cam.fx, cx=cam.cx, cy=cam.cy)
        self._pipeline = pipe
        self._pipeline_rng = np.random.default_rng(noise_seed)
        if self.config.camera_images:  # render-free, the lens only moves boxes: no noise to draw
            pipe.reseed(self._pipeline_rng)

    def _sample_look(self, rng: np.random.Generator) -> Look:
        """A random look: the plain world's ``sample_look``, or in the realistic scene the look of
        ``weather_gym.sim.randomize.sample_realistic`` (clutter layout, ego car, ...)."""
        if self._sim.scene == "realistic":
            return sample_realistic(rng).look
        return sample_look(rng)

    def _resolve_look(self, look: Any, rng: np.random.Generator) -> Look:
        if look is None:
            if self.config.randomize_look:
                return self._sample_look(rng)
            return REALISTIC_LOOK if self._sim.scene == "realistic" else DEFAULT_LOOK
        if isinstance(look, Look):
            return look
        if look == "random":
            return self._sample_look(rng)
        if isinstance(look, dict):
            return Look.from_dict(look)
        raise InputError(f"reset option look must be a Look, a dict of Look fields or 'random', got {look!r}")

    # ------------------------------------------------------------------ step
    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self._check_open()
        if not self._episode_started:
            raise StateError("call reset() before step()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (2,):
            raise InputError(f"action must have shape (2,) = (steering, throttle/brake), got shape {a.shape}")
        a0, a1 = float(a[0]), float(a[1])  # plain floats: these checks run every step
        if not (math.isfinite(a0) and math.isfinite(a1)):
            raise InputError(f"action must be finite, got {a.tolist()}")
        if abs(a0) > 1.0 + 1e-6 or abs(a1) > 1.0 + 1e-6:
            raise InputError(f"action must lie in [-1, 1] (the action space), got {a.tolist()}")
        steer, pedal = min(max(a0, -1.0), 1.0), min(max(a1, -1.0), 1.0)  # only float rounding is clipped

        assert self._world is not None  # reset() made the world
        touched = self._world.step(steer, pedal, self.friction_now)
        new_hits = len(touched - self._cones_hit)
        self._cones_hit |= touched
        dt = self.config.sim.dt
        self._step += 1
        self._time += dt

        track = self.track
        x, y, _ = self._world.car.pose
        proj = track.project(x, y, s_hint=self._s)
        ds = float(proj.s) - self._s
        if track.closed:
            ds = (ds + track.length / 2) % track.length - track.length / 2
        self._s = float(proj.s)
        self._progress += ds
        self._lateral = float(proj.lateral)

        lap_done = False
        if track.closed:
            while self._progress >= (len(self._lap_times) + 1) * track.length:
                self._lap_times.append(self._time - self._lap_start_time)
                self._lap_start_time = self._time
                lap_done = True
        elif not self._finished and self._s >= track.finish_s:
            self._lap_times.append(self._time - self._lap_start_time)
            self._finished = True
            lap_done = True

        i = int(proj.index)
        limit_left = float(track.half_width_left[i]) + self.config.off_track_margin
        limit_right = float(track.half_width_right[i]) + self.config.off_track_margin
        off = self._lateral > limit_left or self._lateral < -limit_right
        became_off = off and not self._off_track
        self._off_track_events += int(became_off)
        self._off_track = off

        stalled = False
        window = self._stall_window
        if window is not None:
            window.append(self._progress)
            stalled = len(window) == window.maxlen and self._progress - window[0] < self.config.stall_m

        r = self.config.reward
        reward = r.progress * ds + r.cone_hit * new_hits + r.off_track * float(became_off) + r.time

        laps_needed = self.config.laps
        end_reason = None
        if (laps_needed > 0 and len(self._lap_times) >= laps_needed) or (lap_done and not track.closed):
            end_reason = "laps"
        elif off and self.config.terminate_off_track:
            end_reason = "off_track"
        elif stalled:
            end_reason = "stalled"
            reward += r.stall
        terminated = end_reason is not None

        if self._step % self._frame_every == 0:
            self._update_frame()
        self._scan_new = False
        if self.config.lidar is not None and self._step % self._scan_every == 0:
            self._update_scan()
        meas = self._measure(dt)
        return self._observation(meas), float(reward), terminated, False, self._info(proj, new_hits, end_reason)

    # ------------------------------------------------------------------ sensors
    def _measure(self, dt: float) -> tuple[float, float]:
        """Odometry as the car reports it: scaled, noisy wheel speed and biased, noisy gyro."""
        od = self.config.odometry
        rng = self.np_random
        assert self._world is not None  # measured only in an episode
        car = self._world.car
        speed = car.state.vx * self._odo_scale + od.speed_noise_std * float(rng.standard_normal())
        yaw_rate = car.state.yaw_rate + self._gyro_bias + od.gyro_noise_std * float(rng.standard_normal())
        if dt > 0:
            xo, yo, hyo = self._odom
            self._odom = np.array(
                [xo + speed * math.cos(hyo) * dt, yo + speed * math.sin(hyo) * dt, _wrap_angle(hyo + yaw_rate * dt)]
            )
        return speed, yaw_rate

    def _update_frame(self) -> None:
        """Render the camera and/or compute the ground truth, as the config asks."""
        world, cfg = self.world, self.config
        if cfg.camera_images:
            frame = world.render(segmentation=cfg.ground_truth == "segmentation")
            self._image, self._depth, self._gt = frame.rgb, frame.depth, frame.gt
        if cfg.ground_truth == "geometry":
            self._gt = world.ground_truth()
        pipe = self._pipeline
        if pipe is None:
            return
        if cfg.camera_images:
            assert self._pipeline_rng is not None and self._image is not None
            self._image = pipe.apply(self._image, self._pipeline_rng)
            if pipe.model.distorts:  # the lens moves pixels: depth and boxes follow
                self._depth = pipe.remap_nearest(cast(np.ndarray, self._depth), float(cfg.camera.far))  # set with the image
        if pipe.model.distorts and self._gt is not None and self._gt.count:
            self._gt = ConeArrays({**self._gt, "boxes": pipe.distort_boxes(self._gt["boxes"])})

    def _update_scan(self) -> None:
        """Cast the LiDAR's scan (with a LiDAR configured)."""
        lidar = self.config.lidar
        if lidar is None:
            return
        self._scan = self.world.lidar_scan(lidar, self._lidar_rng)
        self._scan_new = True

    def _observation(self, meas: tuple[float, float]) -> dict[str, np.ndarray]:
        state = np.array([meas[0], meas[1], *self._odom], dtype=np.float32)
        out: dict[str, np.ndarray] = {"state": state}
        if self.config.camera_images:
            assert self._image is not None and self._depth is not None
            out = {"image": self._image.copy(), "depth": self._depth.copy(), "state": state}
        if self.config.lidar is not None:
            assert self._scan is not None
            out["points"], out["points_mask"] = pack_points(self._scan, self.config.lidar.rays)
        return out

    def _info(self, proj: Projection, new_hits: int, end_reason: str | None) -> dict[str, Any]:
        world = self.world
        car = world.car
        info: dict[str, Any] = {}
        if self.config.ground_truth != "off":
            info["gt"] = self._gt
        info.update({
            "pose": np.array(car.pose, dtype=np.float64),
            "speed": float(car.speed),
            "yaw_rate": float(car.state.yaw_rate),
            "steer_angle": float(car.state.steer),
            "s": self._s,
            "progress": float(self._progress),
            "lap": len(self._lap_times),
            "lap_time": float(self._time - self._lap_start_time),
            "lap_times": list(self._lap_times),
            "cones_hit": len(self._cones_hit),
            "new_cones_hit": int(new_hits),
            "off_track": bool(self._off_track),
            "off_track_events": int(self._off_track_events),
            "cross_track_error": abs(self._lateral),
            "lateral_offset": self._lateral,
            "time": float(self._time),
            "step": int(self._step),
            "finished": bool(self._finished),
            # SB3's Monitor and EvalCallback read it at an episode's end (also when TimeLimit truncates)
            "is_success": bool(len(self._lap_times) >= max(1, self.config.laps) or self._finished),
            "camera": self.config.camera,
            "track": self.track.name,
            "renderer": world.renderer_name,
        })
        if self.config.lidar is not None:
            info["lidar"] = self._scan
            info["lidar_new"] = self._scan_new
        if end_reason is not None:
            info["end_reason"] = end_reason
        return info

    # ------------------------------------------------------------------ render / close
    @property
    def render_view(self) -> str:
        """What ``render()`` returns in ``rgb_array`` mode: ``"chase"`` or ``"camera"`` (``EnvConfig.render_view``)."""
        return self.config.render_view

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the chase view, or the camera frame (``render_view="camera"``; a
        ``WeatherWrapper`` above returns it weathered); ``human``: None (the GUI window shows the scene)."""
        if self.render_mode == "rgb_array":
            if self.config.render_view == "camera":
                if self._image is None:
                    raise StateError("call reset() before render()")
                return self._image.copy()
            return self.world.render_chase()
        return None  # "human": the PyBullet GUI window shows the scene live

    def close(self) -> None:
        world, self._world = getattr(self, "_world", None), None
        self._episode_started = False
        if world is not None:
            world.close()
        self._closed = True
        super().close()

    def _check_open(self) -> None:
        if getattr(self, "_closed", False):
            raise StateError("this env was closed; make a new one (gymnasium.make) to go on")


def _display_available() -> bool:
    return not sys.platform.startswith("linux") or bool(os.environ.get("DISPLAY"))


def _numbers(values: Any, option: str) -> tuple[float, ...]:
    """``values`` as floats; an :class:`InputError` naming the reset option when they are not numbers."""
    try:
        return tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise InputError(f"reset option {option} must be numbers, got {values!r}") from None
