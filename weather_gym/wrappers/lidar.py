"""``LidarConeWrapper``: the LiDAR's scan, through its weather, to the cone list a cone-list agent reads.

On an env with a LiDAR (``EnvConfig.lidar``): each new scan (``info["lidar_new"]``) goes through the
LiDAR weather (:mod:`weather_gym.lidar_weather`, seeded from the env's generator) and the cone
extraction (:mod:`weather_gym.perception.lidar_cones`); the observation becomes the same
``{"cones", "mask", "state"}`` a camera perception gives, each cone's colour one-hot read from its
stripe near the car, all zero (unknown) where it could not be read. Between scans (10 Hz against 30 Hz control) the last scan's cones are moved into the car's
present frame by the odometry (``obs["state"]``), as a stack compensates its own motion.

``info["detections"]`` (a ``ConeArrays``: ``x_body``, ``y_body``, ``ranges``, ``bearings``, ``classes``,
``scores``) and ``info["lidar_gt"]`` (the cones the clear scan hit with at least ``min_gt_points``
returns, true positions in the car frame) come on the steps of a new scan, for
:class:`~weather_gym.perception.lidar_scoring.LidarScoring`. ``reset(options={"lidar_weather": SPEC})``
changes the weather for that episode; ``keep_points=True`` keeps the weathered ``points`` in the
observation.

Example:
    >>> import gymnasium as gym, weather_gym
    >>> from weather_gym.sim.lidar_config import LidarConfig
    >>> from weather_gym.wrappers.lidar import LidarConeWrapper
    >>> env = LidarConeWrapper(gym.make("WeatherGym/ConeTrack-v0", camera_images=False, ground_truth="geometry",
    ...                                 lidar=LidarConfig()), lidar_weather="fog:mor=60")
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["cones"].shape, int(obs["mask"].sum()) > 0
    (['cones', 'mask', 'state'], (64, 14), True)
    >>> env.close()
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.cone_spec import UNKNOWN_CLASS
from weather_gym.core.errors import InputError
from weather_gym.core.point_cloud import pack_points
from weather_gym.lidar_weather import parse_lidar_weather
from weather_gym.perception.cones import CONE_FIELDS, DEFAULT_MAX_CONES, FIELD, cone_list_space
from weather_gym.perception.lidar_cones import LidarConeConfig, cones_from_points

__all__ = ["LidarConeWrapper"]


class LidarConeWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """LiDAR scan -> LiDAR weather -> cones (see the module doc).

    Args:
        env: an env with a LiDAR (``EnvConfig.lidar`` set).
        lidar_weather: a LiDAR weather spec (``"fog:mor=60+rain@2"``; None: clear).
        max_cones: rows of the padded cone list.
        cone_config: the cone extraction's tuning (``LidarConeConfig``).
        keep_points: also pass the weathered ``points`` / ``points_mask`` through.
        min_gt_points: returns a cone needs in the clear scan to count as visible in ``info["lidar_gt"]``.
    """

    def __init__(self, env: gym.Env, lidar_weather: Any = None, *, max_cones: int = DEFAULT_MAX_CONES,
                 cone_config: LidarConeConfig | None = None, keep_points: bool = False, min_gt_points: int = 2) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, lidar_weather=lidar_weather, max_cones=max_cones,
                                                 cone_config=cone_config, keep_points=keep_points,
                                                 min_gt_points=min_gt_points)
        gym.Wrapper.__init__(self, env)
        lidar = getattr(getattr(env.unwrapped, "config", None), "lidar", None)
        if lidar is None:
            raise InputError("LidarConeWrapper needs an env with a LiDAR: EnvConfig(lidar=LidarConfig()) "
                             "(perception 'lidar' sets it)")
        if not (isinstance(max_cones, int) and max_cones >= 1):
            raise InputError(f"LidarConeWrapper: max_cones must be an integer >= 1, got {max_cones!r}")
        self.lidar = lidar
        self.weather = parse_lidar_weather(lidar_weather)
        self._default_weather = self.weather
        self.cone_config = cone_config or LidarConeConfig()
        self.max_cones = max_cones
        self.keep_points = bool(keep_points)
        self.min_gt_points = int(min_gt_points)
        space = dict(cone_list_space(max_cones).spaces)
        inner = env.observation_space
        assert isinstance(inner, spaces.Dict)  # the env's Dict (the LiDAR adds points to it)
        space["state"] = inner["state"]
        if self.keep_points:
            space["points"] = inner["points"]
            space["points_mask"] = inner["points_mask"]
        self.observation_space = spaces.Dict(space)
        self._rng: np.random.Generator | None = None
        self._cones: ConeArrays | None = None
        self._scan_pose = np.zeros(3)
        self._points: tuple[np.ndarray, np.ndarray] | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        options = dict(options or {})
        self.weather = parse_lidar_weather(options.pop("lidar_weather")) if "lidar_weather" in options \
            else self._default_weather
        obs, info = self.env.reset(seed=seed, options=options or None)
        if seed is not None or self._rng is None:
            self._rng = self.env.unwrapped.np_random.spawn(1)[0]
        return self._convert(obs, info)

    def step(self, action: Any) -> tuple[dict, Any, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        out, info = self._convert(obs, info)
        return out, reward, terminated, truncated, info

    def _convert(self, obs: dict, info: dict) -> tuple[dict, dict]:
        info = dict(info)
        state = np.asarray(obs["state"], dtype=np.float32)
        if info.get("lidar_new") or self._cones is None:
            clear = info["lidar"]
            assert self._rng is not None  # made by reset()
            cloud = self.weather(clear, self._rng)
            self._cones = cones_from_points(cloud, self.lidar, self.cone_config)
            self._scan_pose = state[2:5].astype(np.float64)
            info["detections"] = self._cones
            info["lidar_gt"] = self._truth(clear, info)
            info["lidar_weather"] = self.weather.describe()
            if self.keep_points:
                self._points = pack_points(cloud, self.lidar.rays)
        xb, yb = self._moved(state[2:5].astype(np.float64))
        out = {"cones": self._pack(xb, yb), "mask": self._mask(len(xb)), "state": state}
        if self.keep_points and self._points is not None:
            out["points"], out["points_mask"] = self._points
        return out, info

    def _moved(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The last scan's cones in the car frame at odometry ``pose``."""
        c = self._cones
        assert c is not None  # a scan was taken by reset()
        x, y = np.asarray(c["x_body"], float), np.asarray(c["y_body"], float)
        x0, y0, h0 = self._scan_pose
        x1, y1, h1 = pose
        if (x0, y0, h0) == (x1, y1, h1):
            return x, y
        gx, gy = x0 + math.cos(h0) * x - math.sin(h0) * y, y0 + math.sin(h0) * x + math.cos(h0) * y
        dx, dy = gx - x1, gy - y1
        return math.cos(h1) * dx + math.sin(h1) * dy, -math.sin(h1) * dx + math.cos(h1) * dy

    def _pack(self, xb: np.ndarray, yb: np.ndarray) -> np.ndarray:
        lid = self.lidar
        rx, ry = xb - lid.mount_x, yb - lid.mount_y
        r = np.hypot(rx, ry)
        order = np.argsort(r, kind="stable")[:self.max_cones]
        k = len(order)
        out = np.zeros((self.max_cones, len(CONE_FIELDS)), np.float32)
        out[:k, FIELD["range"]] = r[order]
        out[:k, FIELD["bearing"]] = np.arctan2(ry, rx)[order]
        out[:k, FIELD["score"]] = 1.0
        out[:k, FIELD["x_body"]] = xb[order]
        out[:k, FIELD["y_body"]] = yb[order]
        assert self._cones is not None  # packed after a scan
        cls = np.asarray(self._cones["classes"], np.int64)[order]
        known = np.flatnonzero(cls >= 0)  # colour read from the stripes; the rest stay all zero (unknown)
        out[known, cls[known]] = 1.0
        return out

    def _mask(self, n: int) -> np.ndarray:
        m = np.zeros(self.max_cones, np.int8)
        m[:min(n, self.max_cones)] = 1
        return m

    def _truth(self, clear: Any, info: dict) -> ConeArrays:
        """The cones the clear scan hit with at least ``min_gt_points`` returns (true positions, car frame)."""
        ids, counts = np.unique(clear.cone[clear.cone >= 0], return_counts=True)
        ids = ids[counts >= self.min_gt_points]
        xy = np.asarray(self.env.unwrapped.world.cone_xy, np.float64)[ids]  # type: ignore[attr-defined]  # a ConeTrackEnv (checked in __init__)
        x, y, yaw = (float(v) for v in info["pose"])
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = xy[:, 0] - x, xy[:, 1] - y
        xb, yb = c * dx + s * dy, -s * dx + c * dy
        lid = self.lidar
        return ConeArrays(x_body=xb, y_body=yb, ranges=np.hypot(xb - lid.mount_x, yb - lid.mount_y),
                          cone_ids=ids.astype(np.int64), classes=np.full(len(ids), UNKNOWN_CLASS, np.int64))

