"""The car's camera as a sensor: RGB, metric depth, segmentation and per-cone ground truth.

Ground truth comes from the rendered segmentation (pixel exact) or, without rendering anything,
from geometry (:mod:`weather_gym.sim.visibility`); ``render(segmentation=False)`` skips the
segmentation pass (the sky is then found from the depth buffer).

Example (needs PyBullet; see ``World.render``):
    >>> from weather_gym.sim.camera_sensor import depth_from_zbuffer
    >>> import numpy as np
    >>> float(depth_from_zbuffer(np.array([1.0], np.float32), near=0.1, far=80.0)[0])
    80.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.egl import shadow_map as egl_shadow_map
from weather_gym.sim.egl.shadow_reuse import ShadowMapReuse, planned_frame
from weather_gym.sim.look import Look
from weather_gym.sim.renderer import quiet_if_egl
from weather_gym.sim.visibility import empty_ground_truth, visible_cones


@dataclass
class CameraFrame:
    """One frame: ``rgb`` (H,W,3) uint8, ``depth`` (H,W) float32 metres, ``segmentation`` (H,W)
    int32 cone index or -1 (None when not rendered), and ``gt`` (``ConeArrays`` of the visible
    cones, None when not computed)."""

    rgb: np.ndarray | None
    depth: np.ndarray | None
    segmentation: np.ndarray | None
    gt: ConeArrays | None


def depth_from_zbuffer(zbuf: np.ndarray, near: float, far: float) -> np.ndarray:
    """Convert OpenGL's non-linear depth buffer (0..1) to metric z-depth in metres."""
    z = np.asarray(zbuf, dtype=np.float32)
    depth = np.multiply(z, np.float32(far - near))  # the same float32 operations, in one buffer
    np.subtract(np.float32(far), depth, out=depth)
    np.divide(np.float32(far * near), depth, out=depth)
    return np.minimum(depth, np.float32(far), out=depth)  # float32 rounding at z=1 overshoots far by ~1e-3


def empty_gt() -> ConeArrays:
    return empty_ground_truth()


class CameraSensor:
    """Renders what a camera mounted on the car sees; holds the per-episode sky and mount jitter."""

    def __init__(self, config: CameraConfig, client: int, renderer: int, shadows: bool | None = None) -> None:
        self.config = config
        self.client = client
        self.renderer = renderer
        self.shadows = shadows  # None: the renderer's own (EGL: its shadow map; TinyRenderer: none)
        # EGL draws its shadow map unless switched off around each frame (weather_gym.sim.egl.shadow_map)
        self._without_shadow_map = renderer == p.ER_BULLET_HARDWARE_OPENGL and shadows is False
        if self._without_shadow_map and (reason := egl_shadow_map.unavailable_reason()) is not None:
            raise RuntimeError(f"SimConfig.shadows=False cannot be honoured with the EGL renderer here: {reason}; "
                               "leave shadows unset (the plugin's shadow map) or use renderer='tiny'")
        # EGL frames with the plugin's shadow map redraw only the part of it that changed (same bytes)
        with_map = renderer == p.ER_BULLET_HARDWARE_OPENGL and not self._without_shadow_map
        self.shadow_reuse = ShadowMapReuse(client) if with_map else None
        c = config
        if c.centred:
            self._proj = p.computeProjectionMatrixFOV(c.vfov_deg, c.width / c.height, c.near, c.far)
        else:  # measured intrinsics: an off-centre frustum with the principal point where the camera has it
            n = c.near
            self._proj = p.computeProjectionMatrix(-c.cx * n / c.fx, (c.width - c.cx) * n / c.fx,
                                                   -(c.height - c.cy) * n / c.fy, c.cy * n / c.fy, n, c.far)
        self.look: Look | None = None
        self._sky_rows: np.ndarray | None = None
        self._pano: np.ndarray | None = None
        self._col_angles = np.arctan2(c.cx - (np.arange(c.width) + 0.5), c.fx)  # rad, positive left

    def set_look(self, look: Look, panorama: np.ndarray, max_elevation_deg: float = 60.0) -> None:
        """Per-episode appearance: mount jitter and the sky panorama (rows = elevation)."""
        self.look = look
        self._pano = panorama
        if self.shadow_reuse is not None:  # the world changed shapes or colours with the look
            self.shadow_reuse.invalidate()
        c = self.config
        pitch = math.radians(c.pitch_deg + look.camera_pitch_offset_deg)
        v = np.arange(c.height) + 0.5
        elev = -pitch + np.arctan2(c.cy - v, c.fy)  # elevation of each image row, rad
        h = panorama.shape[0]
        rows = (math.radians(max_elevation_deg) - elev) / math.radians(max_elevation_deg + 10.0) * (h - 1)
        self._sky_rows = np.clip(np.round(rows), 0, h - 1).astype(np.intp)

    def mount_pose(self, car_pose: tuple[float, float, float]) -> tuple[np.ndarray, float, float]:
        """Camera position (3,), heading yaw and downward pitch (rad) for the car's reference pose."""
        x, y, yaw = car_pose
        look = self.look
        dz = look.camera_height_offset if look else 0.0
        dyaw = math.radians(look.camera_yaw_offset_deg) if look else 0.0
        dpitch = math.radians(look.camera_pitch_offset_deg) if look else 0.0
        c = self.config
        eye = np.array([x + c.mount_x * math.cos(yaw), y + c.mount_x * math.sin(yaw), c.mount_height + dz])
        return eye, yaw + dyaw, math.radians(c.pitch_deg) + dpitch

    def render(
        self,
        car_pose: tuple[float, float, float],
        cone_lut: np.ndarray,
        cone_xy: np.ndarray,
        cone_classes: np.ndarray,
        light: dict,
        *,
        segmentation: bool = True,
        hide: np.ndarray | None = None,
    ) -> CameraFrame:
        """Render the frame; with ``segmentation`` also the cone segmentation and its ground truth
        (pixels where ``hide`` (H, W bool) is set are never cones: the ego car covers them)."""
        c = self.config
        eye, heading, pitch = self.mount_pose(car_pose)
        fwd = np.array([math.cos(heading) * math.cos(pitch), math.sin(heading) * math.cos(pitch), -math.sin(pitch)])
        view = p.computeViewMatrix(eye.tolist(), (eye + fwd).tolist(), [0, 0, 1])
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        shadow_map = (egl_shadow_map.shadow_map_off() if self._without_shadow_map
                      else planned_frame(self.shadow_reuse, light))
        with quiet_if_egl(self.renderer), shadow_map:
            _, _, rgba, zbuf, seg = p.getCameraImage(
                c.width,
                c.height,
                view,
                self._proj,
                renderer=self.renderer,
                shadow=int(bool(self.shadows)),
                flags=flags,
                physicsClientId=self.client,
                **light,
            )[:5]
        rgba = np.asarray(rgba, dtype=np.uint8).reshape(c.height, c.width, 4)
        rgb = cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)
        zbuf = np.asarray(zbuf, dtype=np.float32).reshape(c.height, c.width)
        depth = depth_from_zbuffer(zbuf, c.near, c.far)
        if not segmentation:
            self._composite_sky(rgb, zbuf >= np.float32(1.0), heading)  # nothing drawn: the far plane
            return CameraFrame(rgb=rgb, depth=depth, segmentation=None, gt=None)
        seg = np.asarray(seg, dtype=np.int32).reshape(c.height, c.width)
        self._composite_sky(rgb, seg < 0, heading)
        # body id -> cone index; ids outside the table clip onto its last entry, which is -1
        # (clipped indices, then plain indexing: several times faster than np.take(mode="clip"))
        index = seg + 1
        np.clip(index, 0, cone_lut.shape[0] - 1, out=index)
        cone_seg = cone_lut[index]
        if hide is not None:
            cone_seg[hide] = -1
        gt = self._ground_truth(cone_seg, eye, heading, cone_xy, cone_classes)
        return CameraFrame(rgb=rgb, depth=depth, segmentation=cone_seg, gt=gt)

    def geometric_ground_truth(self, car_pose: tuple[float, float, float], cone_xy: np.ndarray,
                               cone_classes: np.ndarray, tilted=None) -> ConeArrays:
        """The visible cones from geometry alone (no rendering); see :mod:`weather_gym.sim.visibility`."""
        eye, heading, pitch = self.mount_pose(car_pose)
        return visible_cones(self.config, eye, heading, pitch, cone_xy, cone_classes, tilted=tilted)

    def _composite_sky(self, rgb: np.ndarray, background: np.ndarray, heading: float) -> None:
        """Fill pixels where no geometry was drawn with the sky panorama seen at ``heading``."""
        if self._pano is None:
            return
        rows_with_sky = np.flatnonzero(background.any(axis=1))
        if rows_with_sky.size == 0:
            return
        last = int(rows_with_sky[-1]) + 1
        cols = np.round((heading + self._col_angles) / (2 * math.pi) * self._pano.shape[1]).astype(np.intp)
        cols %= self._pano.shape[1]
        # the image's columns first (the panorama is wider than the image), then its rows; a masked
        # copy in OpenCV (``rgb[:last]`` is a contiguous view, written in place)
        sky = self._pano.take(cols, axis=1).take(self._sky_rows[:last], axis=0)  # type: ignore[index]  # set with the panorama
        cv2.copyTo(sky, background[:last].view(np.uint8), rgb[:last])

    @staticmethod
    def _ground_truth(cone_seg, eye, heading, cone_xy, cone_classes) -> ConeArrays:
        n = cone_xy.shape[0]
        rows = np.flatnonzero((cone_seg >= 0).any(axis=1))
        if rows.size == 0:
            return empty_gt()
        top = int(rows[0])  # only the band of rows with cone pixels is labelled and searched
        labels = cone_seg[top:int(rows[-1]) + 1] + 1
        counts = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        visible = np.flatnonzero(counts)
        slices = ndimage.find_objects(labels, max_label=n)
        boxes = np.array(
            [[slices[i][1].start, slices[i][0].start + top, slices[i][1].stop, slices[i][0].stop + top]
             for i in visible],
            dtype=np.float32,
        )
        d = cone_xy[visible] - eye[:2]
        ranges = np.hypot(d[:, 0], d[:, 1])
        bearings = np.arctan2(d[:, 1], d[:, 0]) - heading
        bearings = (bearings + np.pi) % (2 * np.pi) - np.pi
        return ConeArrays(
            boxes=boxes,
            classes=cone_classes[visible].astype(np.int64),
            cone_ids=visible.astype(np.int64),
            ranges=ranges.astype(np.float32),
            bearings=bearings.astype(np.float32),
            pixels=counts[visible].astype(np.int64),
        )
