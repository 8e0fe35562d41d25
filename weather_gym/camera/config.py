"""Pinhole camera parameters shared by the simulator, the detector and the agents (no PyBullet here).

Example:
    >>> from weather_gym.camera.config import CameraConfig
    >>> cam = CameraConfig()            # ZED-like 672x376, 90 deg horizontal field of view
    >>> round(cam.fx, 1), cam.bearing(cam.cx)
    (336.0, 0.0)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.limits import MAX_CAMERA_SIDE
from weather_gym.core.schema import Positive, PositiveInt, check_fields


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
        fy_px: vertical focal length in pixels when it differs from ``fx`` (None: square pixels).
        cx_px, cy_px: principal point in pixels when it is off-centre (None: the image centre).

    A measured camera (``fx, fy, cx, cy`` from a calibration) is :meth:`from_intrinsics`; ``fx``
    always follows from ``hfov_deg`` and ``width``.
    """

    width: PositiveInt = 672
    height: PositiveInt = 376
    hfov_deg: Annotated[float, Field(ge=1.0, le=170.0)] = 90.0
    mount_x: float = 0.6
    mount_height: Positive = 1.0
    pitch_deg: Annotated[float, Field(gt=-89.0, lt=89.0)] = 4.0
    fps: Positive = 30.0
    near: Positive = 0.1
    far: Positive = 80.0
    exposure_s: Positive = 0.004
    fy_px: Positive | None = None
    cx_px: float | None = None
    cy_px: float | None = None

    def __post_init__(self) -> None:
        check_fields(self)  # each field against its annotation; then the size limit and near < far
        for name in ("width", "height"):
            v = getattr(self, name)
            if v > MAX_CAMERA_SIDE:
                raise LimitError(f"camera {name} = {v} px is too large; at most {MAX_CAMERA_SIDE} px are rendered")
        if not self.near < self.far:
            raise InputError(f"CameraConfig.near must be below far ({self.far}), got {self.near!r}")

    @classmethod
    def from_intrinsics(cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                        **kwargs) -> CameraConfig:
        """A camera from measured intrinsics (pixels, at ``width`` x ``height``).

        Example:
            >>> cam = CameraConfig.from_intrinsics(1024, 768, 900.9, 900.1, 506.4, 358.0)
            >>> round(cam.fx, 1), cam.fy, cam.cx, cam.cy, round(cam.hfov_deg, 2)
            (900.9, 900.1, 506.4, 358.0, 59.22)
        """
        for name, v in (("fx", fx), ("fy", fy)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"camera intrinsics: {name} must be a positive number of pixels, got {v!r}")
        for name, v, size in (("cx", cx, width), ("cy", cy, height)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= size):
                raise InputError(f"camera intrinsics: {name} must lie in [0, {size}] pixels, got {v!r}")
        hfov = math.degrees(2.0 * math.atan(width / (2.0 * float(fx))))
        return cls(width=int(width), height=int(height), hfov_deg=hfov,
                   fy_px=None if abs(fy - fx) < 1e-9 else float(fy),
                   cx_px=None if abs(cx - width / 2.0) < 1e-9 else float(cx),
                   cy_px=None if abs(cy - height / 2.0) < 1e-9 else float(cy), **kwargs)

    @property
    def fx(self) -> float:
        return self.width / (2.0 * math.tan(math.radians(self.hfov_deg) / 2.0))

    @property
    def fy(self) -> float:
        return self.fx if self.fy_px is None else float(self.fy_px)  # square pixels unless measured otherwise

    @property
    def cx(self) -> float:
        return self.width / 2.0 if self.cx_px is None else float(self.cx_px)

    @property
    def cy(self) -> float:
        return self.height / 2.0 if self.cy_px is None else float(self.cy_px)

    @property
    def centred(self) -> bool:
        """Square pixels and the principal point at the image centre (the simulator's default camera)."""
        return self.fy_px is None and self.cx_px is None and self.cy_px is None

    @property
    def intrinsics(self) -> dict[str, float]:
        """``{"fx", "fy", "cx", "cy"}`` in pixels."""
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy}

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
        """The fields as a dict (the measured-intrinsics fields only when set)."""
        d = asdict(self)
        for key in ("fy_px", "cx_px", "cy_px"):
            if d[key] is None:
                del d[key]
        return d

    def scaled(self, width: int, height: int) -> CameraConfig:
        """The same camera at another resolution (same field of view; a measured principal point and
        vertical focal length scale with the image)."""
        d = asdict(self)
        sx, sy = int(width) / self.width, int(height) / self.height
        d.update(width=int(width), height=int(height))
        for key, f in (("fy_px", sy), ("cx_px", sx), ("cy_px", sy)):
            if d[key] is not None:
                d[key] = d[key] * f
        return CameraConfig(**d)
