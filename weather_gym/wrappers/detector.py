"""``DetectorWrapper``: camera image in, fixed-size cone list out (what a real perception stack reports).

Order: ``env -> WeatherWrapper -> DetectorWrapper``, so the detector sees the weathered image.
The observation becomes ``Dict(cones=(N, 14) float32, mask=(N,) int8, state=...)`` (state passed
through; see ``weather_gym.perception.cones.CONE_FIELDS``), which stable-baselines3 accepts. Range
comes from the depth observation when the env has one (``use_depth=True``; the study used stereo
depth) or else from the box height and the known cone height.

``info["detections"]`` holds the raw detections as one ``ConeArrays`` object (``boxes`` xyxy in
original pixels, ``scores``, ``classes``, ``ranges``, ``bearings``; an object, so vector envs keep
one per env). ``wrapper.latency_ms`` is the inference time of the last step (letterbox, ONNX run
and decoding); ``info["detector_latency_ms"]`` has it only with ``latency_in_info=True`` (wall-clock
times differ between identical runs). With ``keep_image=True`` the (weathered) image stays in the
observation.

Example:
    >>> import gymnasium as gym, numpy as np
    >>> from weather_gym.wrappers import DetectorWrapper
    >>> class Camera(gym.Env):
    ...     observation_space = gym.spaces.Dict({"image": gym.spaces.Box(0, 255, (376, 672, 3), np.uint8)})
    ...     action_space = gym.spaces.Discrete(1)
    ...     def reset(self, *, seed=None, options=None):
    ...         super().reset(seed=seed); return {"image": np.zeros((376, 672, 3), np.uint8)}, {}
    ...     def step(self, action):
    ...         return {"image": np.zeros((376, 672, 3), np.uint8)}, 0.0, False, False, {}
    >>> env = DetectorWrapper(Camera(), max_cones=8)
    >>> obs, info = env.reset(seed=0)
    >>> obs["cones"].shape, int(obs["mask"].sum()), len(info["detections"]["scores"])
    ((8, 14), 0, 0)
"""

from __future__ import annotations

import os
import time
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.errors import InputError
from weather_gym.perception.cones import DEFAULT_MAX_CONES, cone_list_space
from weather_gym.perception.detector_spec import DetectorSpec, as_detector, load_detector
from weather_gym.perception.ranging import (
    DEPTH_QUANTILE,
    Undistort,
    check_depth_quantile,
    cones_to_observation,
    detections_to_cones,
)
from weather_gym.wrappers._recorded import recorded, unrecorded

__all__ = ["DetectorWrapper"]


class DetectorWrapper(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Replace the image observation by the detector's cone list; see the module doc.

    Args:
        env: an env whose observation is an RGB image Box or a Dict with one under ``image_key``.
        detector: any :class:`~weather_gym.perception.detector_spec.Detector` (a callable
            ``frame -> Detections``), a detector spec (``"yolov8:model.onnx"``, ``"conenet:PATH"``,
            a ConeNet ``.onnx`` path; see ``weather_gym.perception.load_detector``), or None (the
            shipped model).
        max_cones: rows of the cone list (nearest cones kept).
        camera: the camera model for bearing/range (default: the env's ``config.camera``, else the
            default camera scaled to the image size).
        use_depth: take range from the ``depth_key`` observation when present.
        depth_quantile: the quantile of the depths inside a box that gives its range (0.5, the median;
            0.25 ranges far cones in small boxes far better: docs/perception.md, "Far cones and the depth
            quantile").
        keep_image: keep the image in the observation (for viewing; most policies do not need it).
        score_threshold, threads, detector_classes, detector_resize, detector_input: passed to a
            detector the wrapper creates from a spec (``detector_classes``: a YOLO class map, e.g.
            ``"0=blue,1=yellow"``; ``detector_resize``: letterbox / stretch; ``detector_input``: ``"640x640"``).
        latency_in_info: also put ``detector_latency_ms`` into ``info``.
    """

    def __init__(
        self,
        env: gym.Env,
        detector: Any = None,
        *,
        max_cones: int = DEFAULT_MAX_CONES,
        camera: CameraConfig | None = None,
        image_key: str = "image",
        depth_key: str = "depth",
        use_depth: bool = True,
        depth_quantile: float = DEPTH_QUANTILE,
        keep_image: bool = False,
        score_threshold: float | None = None,
        threads: int = 1,
        detector_classes: str | None = None,
        detector_resize: str | None = None,
        detector_input: str | tuple[int, int] | None = None,
        latency_in_info: bool = False,
    ) -> None:
        detector = unrecorded(detector)  # rebuilt from env.spec
        gym.utils.RecordConstructorArgs.__init__(
            self, _disable_deepcopy=True, detector=recorded(detector, (str, os.PathLike, DetectorSpec)),
            max_cones=max_cones, camera=camera,
            image_key=image_key, depth_key=depth_key, use_depth=use_depth, depth_quantile=depth_quantile,
            keep_image=keep_image, score_threshold=score_threshold, threads=threads,
            detector_classes=detector_classes, detector_resize=detector_resize, detector_input=detector_input,
            latency_in_info=latency_in_info)
        gym.ObservationWrapper.__init__(self, env)
        self.latency_in_info = bool(latency_in_info)
        self.depth_quantile = check_depth_quantile(depth_quantile)

        if not isinstance(max_cones, int) or max_cones < 1:
            raise InputError(f"DetectorWrapper: max_cones must be a positive integer, got {max_cones!r}")
        space = env.observation_space
        if isinstance(space, spaces.Dict):
            if image_key not in space.spaces:
                raise InputError(f"DetectorWrapper: observation Dict has no image key {image_key!r} "
                                 f"(keys: {', '.join(space.spaces)}); pass image_key=...")
            image_space = space[image_key]
            self._is_dict = True
        else:
            image_space = space
            self._is_dict = False
        if not (isinstance(image_space, spaces.Box) and image_space.dtype == np.uint8 and len(image_space.shape) == 3
                and image_space.shape[2] == 3):
            raise InputError(f"DetectorWrapper: the image observation must be Box(0, 255, (H, W, 3), uint8), got {image_space}")
        h, w = image_space.shape[:2]
        if camera is None:
            cfg = getattr(getattr(env, "unwrapped", env), "config", None)
            camera = getattr(cfg, "camera", None) if cfg is not None else None
            if not isinstance(camera, CameraConfig):
                camera = CameraConfig().scaled(w, h)
        if (camera.width, camera.height) != (w, h):
            raise InputError(f"DetectorWrapper: camera is {camera.width}x{camera.height} but the image observation is {w}x{h}")
        self.camera = camera
        if detector is None or isinstance(detector, (str, os.PathLike, DetectorSpec)):
            detector = load_detector(detector, classes=detector_classes, score_threshold=score_threshold,
                                     resize=detector_resize, input_size=detector_input, threads=threads)
        self.detector = as_detector(detector)
        self.image_key = image_key
        self.depth_key = depth_key if (use_depth and isinstance(space, spaces.Dict) and depth_key in space.spaces) else None
        self.max_cones = max_cones
        self.keep_image = keep_image
        out = dict(cone_list_space(max_cones).spaces)
        if isinstance(space, spaces.Dict):
            for k, v in space.spaces.items():
                if k not in (image_key, depth_key) or (k == image_key and keep_image):
                    out[k] = v
        elif keep_image:
            out[image_key] = image_space
        self.observation_space = spaces.Dict(out)
        self._last_detections: ConeArrays | None = None
        self._last_latency = 0.0

    @property
    def latency_ms(self) -> float:
        """Milliseconds the detector took on the last frame (letterbox, ONNX run, decoding)."""
        return self._last_latency

    def observation(self, observation: Any) -> dict[str, np.ndarray]:
        image = observation[self.image_key] if self._is_dict else observation
        t0 = time.perf_counter()
        det = self.detector(np.asarray(image))
        self._last_latency = 1000.0 * (time.perf_counter() - t0)
        depth = observation[self.depth_key] if self.depth_key is not None else None
        cones = detections_to_cones(det, self.camera, depth, self._undistort(), self.depth_quantile)
        packed, mask = cones_to_observation(cones, self.camera, self.max_cones)
        self._last_detections = ConeArrays({**det.to_dict(), "ranges": cones["ranges"].astype(np.float32),
                                            "bearings": cones["bearings"].astype(np.float32)})
        out: dict[str, np.ndarray] = {"cones": packed, "mask": mask}
        for k in cast(spaces.Dict, self.observation_space).spaces:
            if k not in out:
                out[k] = observation[k] if self._is_dict else image
        return out

    def _undistort(self) -> Undistort | None:
        """The lens's inverse when the env's camera model distorts (a calibrated camera: bearings and
        ranges are computed in the pinhole image), else None."""
        pipe = getattr(getattr(self.env, "unwrapped", None), "camera_pipeline", None)
        return pipe.undistort_points if pipe is not None and pipe.model.distorts else None

    def _add_info(self, info: dict) -> dict:
        info = dict(info)
        info["detections"] = self._last_detections
        if self.latency_in_info:
            info["detector_latency_ms"] = self._last_latency
        return info

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        return self.observation(obs), self._add_info(info)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self.observation(obs), reward, terminated, truncated, self._add_info(info)
