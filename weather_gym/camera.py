"""Pinhole camera parameters shared by the simulator, the detector and the agents (no PyBullet here).

Example:
    >>> from weather_gym.camera import CameraConfig
    >>> cam = CameraConfig()            # ZED-like 672x376, 90 deg horizontal field of view
    >>> round(cam.fx, 1), cam.bearing(cam.cx)
    (336.0, 0.0)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from weather_gym.errors import InputError, LimitError
from weather_gym.limits import MAX_CAMERA_SIDE


@dataclass(frozen=True)
class CameraConfig:
    """A camera mounted on the car.

    Attributes:
        width, height: resolution in pixels (default 672x376, the ZED's VGA mode used in the study).
        hfov_deg: horizontal field of view in degrees.
        mount_x: forward offset of the lens from the car's reference point (rear axle), metres.
        mount_height: lens height above the ground, metres.
        pitch_deg: downward tilt of the optical axis, degrees (positive looks down).
        fps: frame rate of the sensor (the env's control rate must divide the physics rate).
        near, far: clipping planes in metres; depth beyond ``far`` reads as ``far``.
        exposure_s: nominal exposure time (used by motion blur / low-light models).
    """

    width: int = 672
    height: int = 376
    hfov_deg: float = 90.0
    mount_x: float = 0.6
    mount_height: float = 1.0
    pitch_deg: float = 4.0
    fps: float = 30.0
    near: float = 0.1
    far: float = 80.0
    exposure_s: float = 0.004

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                raise InputError(f"camera {name} must be a positive integer, got {v!r}")
            if v > MAX_CAMERA_SIDE:
                raise LimitError(f"camera {name} = {v} px is too large; at most {MAX_CAMERA_SIDE} px are rendered")
        checks = {
            "hfov_deg": 1.0 <= self.hfov_deg <= 170.0,
            "fps": self.fps > 0,
            "near": 0 < self.near < self.far,
            "far": math.isfinite(self.far),
            "mount_height": math.isfinite(self.mount_height) and self.mount_height > 0,
            "pitch_deg": -89.0 < self.pitch_deg < 89.0,
            "mount_x": math.isfinite(self.mount_x),
            "exposure_s": self.exposure_s > 0,
        }
        for name, ok in checks.items():
            if not ok:
                raise InputError(f"camera {name} has an invalid value {getattr(self, name)!r}")

    @property
    def fx(self) -> float:
        return self.width / (2.0 * math.tan(math.radians(self.hfov_deg) / 2.0))

    @property
    def fy(self) -> float:
        return self.fx  # square pixels

    @property
    def cx(self) -> float:
        return self.width / 2.0

    @property
    def cy(self) -> float:
        return self.height / 2.0

    @property
    def vfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan(self.height / (2.0 * self.fy)))

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    def bearing(self, u: float | np.ndarray) -> float | np.ndarray:
        """Horizontal angle (rad, positive to the left) of image column ``u``."""
        return np.arctan2(self.cx - np.asarray(u, dtype=np.float64), self.fx) if np.ndim(u) else math.atan2(
            self.cx - float(u), self.fx
        )

    def range_from_height(self, box_height_px: float | np.ndarray, object_height_m: float | np.ndarray):
        """Distance along the optical axis of an upright object of known height from its box height."""
        h = np.maximum(np.asarray(box_height_px, dtype=np.float64), 1e-6)
        return self.fy * np.asarray(object_height_m, dtype=np.float64) / h

    def to_dict(self) -> dict:
        return asdict(self)

    def scaled(self, width: int, height: int) -> CameraConfig:
        """The same camera at another resolution (same field of view)."""
        d = self.to_dict()
        d.update(width=int(width), height=int(height))
        return CameraConfig(**d)
