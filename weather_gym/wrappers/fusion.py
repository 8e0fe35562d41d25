"""``FusionWrapper``: the camera's and the LiDAR's cone lists fused into the one the agent reads.

It stands on a camera cone stack (``DetectorWrapper`` on a ``WeatherWrapper``, on an env with a LiDAR:
``EnvConfig.lidar``) and runs the LiDAR path itself (it is a
:class:`~weather_gym.wrappers.lidar.LidarConeWrapper`: scan -> LiDAR weather -> cones, moved by the
odometry between scans). Every step the detector's cones (``obs["cones"]`` below) and the LiDAR's are
fused by a rule (:mod:`weather_gym.perception.fusion`; the baseline :class:`NearestNeighbourFusion`:
LiDAR position, camera colour, noisy-OR confidence) into ``{"cones", "mask", "state"}``.

``info["detections"]`` stays the detector's (boxes: the per-frame mAP is scored as for ``detector``);
``info["lidar_detections"]`` holds the LiDAR's cones of a new scan; ``info["fusion_sources"]`` counts the
fused cones seen by both sensors, the LiDAR only and the camera only.

Example:
    >>> from weather_gym.pipeline import make_env
    >>> env = make_env("WeatherGym/ConeTrack-v0", perception="fused", max_episode_steps=5,
    ...                camera={"width": 160, "height": 96})
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["cones"].shape, sorted(info["fusion_sources"])
    (['cones', 'mask', 'state'], (64, 14), ['both', 'camera', 'lidar'])
    >>> env.close()
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import CONE_FIELDS, DEFAULT_MAX_CONES, FIELD, unpack_cones
from weather_gym.perception.fusion import FusionRule, NearestNeighbourFusion, SensorCones
from weather_gym.perception.lidar_cones import LidarConeConfig
from weather_gym.wrappers.lidar import LidarConeWrapper

__all__ = ["FusionWrapper"]


class FusionWrapper(LidarConeWrapper):
    """Camera cones (from the stack below) + LiDAR cones (its own) -> one fused list (see the module doc).

    Args:
        env: a cone-list stack with camera cones (``DetectorWrapper``) over an env with a LiDAR.
        lidar_weather: the LiDAR weather spec (None: clear).
        fusion: a fusion rule ``(camera, lidar) -> SensorCones`` (default :class:`NearestNeighbourFusion`).
        max_cones, cone_config, min_gt_points: as :class:`LidarConeWrapper`.
    """

    def __init__(self, env: gym.Env, lidar_weather: Any = None, *, fusion: FusionRule | None = None,
                 max_cones: int = DEFAULT_MAX_CONES, cone_config: LidarConeConfig | None = None,
                 min_gt_points: int = 2) -> None:
        space = env.observation_space
        if not isinstance(space, gym.spaces.Dict) or "cones" not in space.spaces:
            raise InputError("FusionWrapper needs a camera cone list below it (DetectorWrapper: perception 'fused' "
                             "builds it)")
        super().__init__(env, lidar_weather, max_cones=max_cones, cone_config=cone_config, min_gt_points=min_gt_points)
        self._saved_kwargs = {"lidar_weather": lidar_weather, "fusion": fusion, "max_cones": max_cones,
                              "cone_config": cone_config, "min_gt_points": min_gt_points}
        if fusion is not None and not callable(fusion):
            raise InputError(f"FusionWrapper: fusion must be a callable (camera, lidar) -> SensorCones, got {fusion!r}")
        self.fusion: FusionRule = fusion if fusion is not None else NearestNeighbourFusion()
        self._camera_mount_x = float(self.env.unwrapped.config.camera.mount_x)  # type: ignore[attr-defined]  # a ConeTrackEnv (checked by LidarConeWrapper)

    def _convert(self, obs: dict, info: dict) -> tuple[dict, dict]:
        cam = unpack_cones(obs["cones"], obs["mask"])
        camera_dets = info.get("detections")
        out, info = super()._convert(obs, info)
        if "lidar_weather" in info:  # a new scan: the LiDAR's cones, and the detector's back under detections
            info["lidar_detections"] = info["detections"]
        if camera_dets is not None:
            info["detections"] = camera_dets
        else:
            info.pop("detections", None)
        lid = unpack_cones(out["cones"], out["mask"])
        fused = self.fusion(
            SensorCones.of(x=cam["x_body"], y=cam["y_body"], classes=cam["classes"], scores=cam["score"], source=0),
            SensorCones.of(x=lid["x_body"], y=lid["y_body"], classes=lid["classes"], scores=lid["score"], source=1))
        if not isinstance(fused, SensorCones):
            raise InputError(f"FusionWrapper: the fusion rule returned {type(fused).__name__}, expected SensorCones")
        out["cones"], out["mask"] = self._pack_fused(fused)
        info["fusion_sources"] = {name: int((fused.source == i).sum())
                                  for i, name in enumerate(("camera", "lidar", "both"))}
        return out, info

    def _pack_fused(self, f: SensorCones) -> tuple[np.ndarray, np.ndarray]:
        rx = f.x - self._camera_mount_x
        r = np.hypot(rx, f.y)
        order = np.argsort(r, kind="stable")[:self.max_cones]
        k = len(order)
        out = np.zeros((self.max_cones, len(CONE_FIELDS)), np.float32)
        c = f.classes[order]
        known = (c >= 0) & (c < len(CONE_CLASSES))
        out[np.flatnonzero(known), c[known]] = 1.0
        out[:k, FIELD["range"]] = r[order]
        out[:k, FIELD["bearing"]] = np.arctan2(f.y, rx)[order]
        out[:k, FIELD["score"]] = f.scores[order]
        out[:k, FIELD["x_body"]] = f.x[order]
        out[:k, FIELD["y_body"]] = f.y[order]
        return out, self._mask(k)
