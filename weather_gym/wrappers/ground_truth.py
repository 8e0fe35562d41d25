"""``GroundTruthConeWrapper``: oracle perception, the env's ground truth as a cone-list observation.

It turns ``info["gt"]`` (the cones visible in the camera frame) into the same ``{"cones", "mask",
"state"}`` observation a ``DetectorWrapper`` produces, so the mapper stack can be tested with
perfect perception and evaluation has an oracle baseline. Optional, seeded degradations test an
agent's robustness: relative range noise, bearing noise, missed cones, phantom cones and colour
swaps. The RNG is spawned from the env's own generator at ``reset(seed=...)``: same seed, same cones.

``ObservationWrapper.observation`` cannot see ``info``, so ``reset`` and ``step`` are implemented here.

Example:
    >>> import gymnasium as gym, weather_gym                                  # doctest: +SKIP
    >>> from weather_gym.wrappers import GroundTruthConeWrapper              # doctest: +SKIP
    >>> env = GroundTruthConeWrapper(gym.make("WeatherGym/ConeTrack-v0"), miss_prob=0.2)  # doctest: +SKIP
    >>> obs, info = env.reset(seed=0)                                         # doctest: +SKIP
    >>> sorted(obs), obs["cones"].shape                                       # doctest: +SKIP
    (['cones', 'mask', 'state'], (64, 14))

On an env without camera images (ground truth from geometry, nothing rendered):
    >>> import gymnasium as gym, weather_gym
    >>> env = GroundTruthConeWrapper(gym.make("WeatherGym/ConeTrack-v0", camera_images=False,
    ...                                       ground_truth="geometry"), miss_prob=0.2)
    >>> obs, info = env.reset(seed=0)
    >>> sorted(obs), obs["cones"].shape
    (['cones', 'mask', 'state'], (64, 14))
    >>> env.close()
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import CONE_CLASSES, cone_height
from weather_gym.core.errors import InputError, check_known
from weather_gym.core.schema import NonNegative, NonNegativeInt, Positive, Share, check_fields
from weather_gym.perception.cones import DEFAULT_MAX_CONES, cone_list_space, pack_cones

__all__ = ["GroundTruthConeWrapper", "OracleNoise", "oracle_cones"]

_BLUE, _YELLOW = CONE_CLASSES.index("blue"), CONE_CLASSES.index("yellow")


@dataclass(frozen=True)
class OracleNoise:
    """Degradations of the oracle (all 0 = perfect perception).

    Attributes:
        range_noise: relative std of the range (0.05 = 5 %).
        bearing_noise: std of the bearing, rad.
        miss_prob: probability that a visible cone is not reported.
        false_positives: mean number (Poisson) of phantom cones per frame, blue or yellow, uniformly
            in the field of view between 2 m and ``max_range`` (or 25 m).
        swap_prob: probability that a blue cone is reported yellow or vice versa.
        max_range: cones farther than this (m) are not reported (``None``: all visible cones).
        min_pixels: cones with fewer visible pixels are not reported (occluded or tiny).
    """

    range_noise: NonNegative = 0.0
    bearing_noise: NonNegative = 0.0
    miss_prob: Share = 0.0
    false_positives: NonNegative = 0.0
    swap_prob: Share = 0.0
    max_range: Positive | None = None
    min_pixels: NonNegativeInt = 0

    def __post_init__(self) -> None:
        check_fields(self, who="oracle")

    @property
    def is_perfect(self) -> bool:
        return not (self.range_noise or self.bearing_noise or self.miss_prob or self.false_positives
                    or self.swap_prob)


def oracle_cones(gt: dict, camera: CameraConfig, noise: OracleNoise | None = None,
                 rng: np.random.Generator | None = None, max_cones: int = DEFAULT_MAX_CONES
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(cones, mask)`` from one frame's ground truth, degraded by ``noise`` with ``rng``."""
    noise = noise or OracleNoise()
    if not noise.is_perfect and rng is None:
        raise InputError("oracle_cones: a numpy Generator is needed when noise is enabled")
    rng = cast(np.random.Generator, rng)  # None only with perfect noise, which draws nothing
    if gt is None:
        gt = {}
    n = len(gt.get("classes", ()))
    classes = np.asarray(gt.get("classes", np.zeros(0)), np.int64).reshape(n)
    ranges = np.asarray(gt.get("ranges", np.zeros(0)), np.float64).reshape(n)
    bearings = np.asarray(gt.get("bearings", np.zeros(0)), np.float64).reshape(n)
    boxes = np.asarray(gt.get("boxes", np.zeros((0, 4))), np.float64).reshape(n, 4)
    pixels = np.asarray(gt.get("pixels", np.full(n, np.iinfo(np.int64).max)), np.int64).reshape(n)
    keep = pixels >= max(noise.min_pixels, 0)
    if noise.max_range is not None:
        keep &= ranges <= noise.max_range
    if noise.miss_prob:
        keep &= rng.random(n) >= noise.miss_prob
    classes, ranges, bearings, boxes = classes[keep], ranges[keep], bearings[keep], boxes[keep]
    if noise.range_noise:
        ranges = ranges * np.maximum(1.0 + noise.range_noise * rng.standard_normal(len(ranges)), 0.05)
    if noise.bearing_noise:
        bearings = bearings + noise.bearing_noise * rng.standard_normal(len(bearings))
    if noise.swap_prob:
        swap = (rng.random(len(classes)) < noise.swap_prob) & ((classes == _BLUE) | (classes == _YELLOW))
        classes = np.where(swap, _BLUE + _YELLOW - classes, classes)
    k = int(rng.poisson(noise.false_positives)) if noise.false_positives else 0
    if k:
        half = math.radians(camera.hfov_deg) / 2
        r = rng.uniform(2.0, noise.max_range or 25.0, k)
        b = rng.uniform(-half, half, k)
        c = rng.integers(0, 2, k)  # blue or yellow
        u = camera.cx - camera.fx * np.tan(b)
        h = camera.fy * np.array([cone_height(int(v)) for v in c]) / r
        # the cone's base: the ground point at range r seen from the (pitched) camera
        v_base = camera.cy + camera.fy * np.tan(np.arctan2(camera.mount_height, r) - math.radians(camera.pitch_deg))
        fake = np.c_[u - 0.35 * h, v_base - h, u + 0.35 * h, v_base]
        classes, ranges = np.r_[classes, c], np.r_[ranges, r]
        bearings, boxes = np.r_[bearings, b], np.vstack([boxes, fake])
    return pack_cones(classes=classes, ranges=ranges, bearings=bearings, scores=np.ones(len(classes)),
                      boxes=boxes, camera=camera, max_cones=max_cones)


class GroundTruthConeWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the image observation by the oracle cone list (``cones``, ``mask``, ``state``).

    Args:
        env: a ``ConeTrackEnv`` (possibly wrapped) whose info carries ``gt`` and ``camera``.
        noise: an ``OracleNoise``; or pass its fields as keywords (``miss_prob=0.2``, ...).
        max_cones: rows of the padded cone list.
        keep_image: also pass ``obs["image"]`` through (for videos); agents ignore it.
    """

    def __init__(self, env: gym.Env, noise: OracleNoise | None = None, *, max_cones: int = DEFAULT_MAX_CONES,
                 keep_image: bool = False, **noise_fields: Any) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, noise=noise, max_cones=max_cones, keep_image=keep_image,
                                                 **noise_fields)
        gym.Wrapper.__init__(self, env)
        if noise is not None and noise_fields:
            raise InputError("GroundTruthConeWrapper: pass either noise=OracleNoise(...) or its fields, not both")
        check_known(noise_fields, list(OracleNoise.__dataclass_fields__), what="GroundTruthConeWrapper", kind="option")
        self.noise = noise or OracleNoise(**noise_fields)
        if not (isinstance(max_cones, int) and max_cones >= 1):
            raise InputError(f"GroundTruthConeWrapper: max_cones must be an integer >= 1, got {max_cones!r}")
        inner = env.observation_space
        if not isinstance(inner, spaces.Dict) or "state" not in inner.spaces:
            raise InputError("GroundTruthConeWrapper needs an env whose observation is a Dict with a 'state' entry")
        self.max_cones = max_cones
        self.keep_image = bool(keep_image)
        space = dict(cone_list_space(max_cones).spaces)
        space["state"] = inner["state"]
        if self.keep_image:
            if "image" not in inner.spaces:
                raise InputError("GroundTruthConeWrapper(keep_image=True) needs an env with an 'image' observation")
            space["image"] = inner["image"]
        self.observation_space = spaces.Dict(space)
        self._rng: np.random.Generator | None = None

    def _convert(self, obs: dict, info: dict) -> dict:
        camera = info.get("camera")
        if not isinstance(camera, CameraConfig):
            raise InputError('GroundTruthConeWrapper needs info["camera"] (a CameraConfig) from the env')
        if "gt" not in info:
            raise InputError('GroundTruthConeWrapper needs info["gt"] (the visible cones) from the env')
        cones, mask = oracle_cones(info["gt"], camera, self.noise, self._rng, self.max_cones)
        out = {"cones": cones, "mask": mask, "state": np.asarray(obs["state"], dtype=np.float32)}
        if self.keep_image:
            out["image"] = obs["image"]
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None or self._rng is None:
            # a child of the env's seeded generator: reproducible, and the env's own stream is untouched
            self._rng = self.env.unwrapped.np_random.spawn(1)[0]
        return self._convert(obs, info), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._convert(obs, info), reward, terminated, truncated, info
