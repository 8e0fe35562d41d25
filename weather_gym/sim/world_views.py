"""What a :class:`~weather_gym.sim.world.World` shows: the car camera's frame (cast shadows and the ego
car's overlay drawn in), the visible cones from geometry (nothing rendered) and a chase view for humans.
A part of ``World`` (it reads the world's bodies, camera and look).

Example (geometry only: nothing is rendered):
    >>> from weather_gym.sim.config import SimConfig
    >>> from weather_gym.sim.world import World
    >>> from weather_gym.tracks import load_track
    >>> world = World(load_track("small_track"), sim=SimConfig(renderer="none"))
    >>> world.reset(world.track.point_at(0.0))
    >>> gt = world.ground_truth()
    >>> sorted(gt.keys())[:3], gt.count > 0
    (['bearings', 'boxes', 'classes'], True)
    >>> world.close()
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.camera_sensor import CameraFrame
from weather_gym.sim.cast_shadows import shadow_strength
from weather_gym.sim.egl.shadow_reuse import planned_frame
from weather_gym.sim.ego import EGO_DEPTH_M, clip_ground_truth, composite, ego_overlay
from weather_gym.sim.renderer import quiet_if_egl, renderer_flag

if TYPE_CHECKING:  # the host's attributes, for type checkers
    from weather_gym.sim.camera_sensor import CameraSensor
    from weather_gym.sim.car import Car
    from weather_gym.sim.cast_shadows import ShadowCaster
    from weather_gym.sim.look import Look


class WorldViews:
    """The camera outputs of a :class:`~weather_gym.sim.world.World` (see the module doc)."""

    if TYPE_CHECKING:  # what World provides
        renderer_name: str
        camera: CameraSensor
        car: Car
        cone_classes: np.ndarray
        _client: int | None
        _look: Look | None
        _applied_look: Look | None
        _warmed_up: bool
        _light: dict[str, Any]
        _caster: ShadowCaster | None
        _cone_lut: np.ndarray
        _cone_xy: np.ndarray
        _cone_tilt: dict[int, tuple[np.ndarray, np.ndarray]]
        _cone_plate: np.ndarray
        _cone_height: np.ndarray
        _car_body_dx: float
        _car_body_z: float
        _car_visual: int

        @property
        def look(self) -> Look: ...
        def _activate(self) -> None: ...
        def _apply_look(self) -> None: ...

    def render(self, segmentation: bool = True) -> CameraFrame:
        """The car camera's frame at the car's current pose; ``segmentation=False`` skips the
        segmentation pass (and its ground truth: take :meth:`ground_truth` instead)."""
        if self.renderer_name == "none":
            raise RuntimeError("this world renders no camera frames (renderer 'none'); "
                               "use ground_truth() for the visible cones")
        self._activate()
        if not self._warmed_up:
            # The renderer's very first frame can differ from every later one of the same scene
            # (far textured quads: seen with the realistic world's asphalt patches), so frame 0 of
            # the first episode would not match frame 0 of the next one with the same seed. One
            # throw-away frame makes every frame a function of the scene alone.
            self._warmed_up = True
            self.camera.render(self.car.pose, self._cone_lut, self._cone_xy, self.cone_classes, self._light,
                               segmentation=True)
        frame = self.camera.render(self.car.pose, self._cone_lut, self._cone_xy, self.cone_classes, self._light,
                                   segmentation=segmentation, hide=self._ego_mask())
        if self._caster is not None and frame.rgb is not None and frame.depth is not None:
            self._cast_shadows(frame)
        overlay = self._ego()
        if overlay is not None and frame.rgb is not None:
            composite(frame.rgb, overlay)
            if frame.depth is not None:
                frame.depth[overlay.mask] = np.float32(EGO_DEPTH_M)
        return frame

    def _cast_shadows(self, frame: CameraFrame) -> None:
        """Darken the ground in the standing cones' shadows (before the ego car's overlay covers it).
        A cone tilted more than 10 degrees (knocked over) casts none."""
        look = self.look
        xy = self._cone_xy
        standing = np.ones(len(xy), dtype=bool)
        if self._cone_tilt:
            xy = xy.copy()
            for i, (origin, rot) in self._cone_tilt.items():
                standing[i] = rot[2, 2] >= math.cos(math.radians(10.0))
                xy[i] = origin[:2]  # the base's centre, not the centre of mass
        eye, heading, pitch = self.camera.mount_pose(self.car.pose)
        assert self._caster is not None
        self._caster.apply(frame.rgb, frame.depth, eye, heading, pitch, xy[standing],  # type: ignore[arg-type]  # both set: see render()
                           self._cone_plate[standing], self._cone_height[standing], self._light["lightDirection"],
                           shadow_strength(look.ambient, look.diffuse))

    def _ego(self):
        """The ego car's overlay for the current look and camera (None: none in view)."""
        if not self.realistic or self._look is None or self._look.ego_seed < 0:
            return None
        cam = self.camera_config
        return ego_overlay(self._look.ego_seed, cam.width, cam.height)

    def _ego_mask(self):
        overlay = self._ego()
        return None if overlay is None else overlay.mask

    def ground_truth(self):
        """The cones the car camera sees now, from geometry (``ConeArrays``; nothing is rendered).
        Occlusion by clutter is not modelled (see :mod:`weather_gym.sim.scenery`); the ego car's
        overlay cuts the boxes (:func:`weather_gym.sim.ego.clip_ground_truth`)."""
        gt = self.camera.geometric_ground_truth(self.car.pose, self._cone_xy, self.cone_classes,
                                                tilted=self._cone_tilt or None)
        overlay = self._ego()
        return gt if overlay is None else clip_ground_truth(gt, overlay)

    def render_chase(self, width: int = 640, height: int = 360, distance: float = 7.0, height_m: float = 3.5) -> np.ndarray:
        """A third-person view from behind and above the car, for humans (videos, ``render()``)."""
        if self._applied_look is not self._look:  # a world without camera frames makes its textures now
            self._apply_look()
        self._activate()
        x, y, yaw = self.car.pose
        eye = [x - distance * math.cos(yaw), y - distance * math.sin(yaw), height_m]
        target = [x + 6 * math.cos(yaw), y + 6 * math.sin(yaw), 0.0]
        view = p.computeViewMatrix(eye, target, [0, 0, 1])
        proj = p.computeProjectionMatrixFOV(60, width / height, 0.1, 150)
        c = self._client
        q = p.getQuaternionFromEuler([0, 0, yaw])
        body = [x + self._car_body_dx * math.cos(yaw), y + self._car_body_dx * math.sin(yaw), self._car_body_z]
        p.resetBasePositionAndOrientation(self._car_visual, body, q, physicsClientId=c)
        try:
            flag = renderer_flag(self.renderer_name)  # "none" renders the chase view with TinyRenderer
            # EGL: the shadow map redrawn only where things moved
            with quiet_if_egl(flag), planned_frame(getattr(self.camera, "shadow_reuse", None), self._light):
                _, _, rgba, _, seg = p.getCameraImage(width, height, view, proj, renderer=flag, physicsClientId=c,
                                                      **self._light)[:5]
        finally:
            p.resetBasePositionAndOrientation(self._car_visual, [0, 0, -10], [0, 0, 0, 1], physicsClientId=c)
        rgb = cv2.cvtColor(np.asarray(rgba, np.uint8).reshape(height, width, 4), cv2.COLOR_RGBA2RGB)
        bg = np.asarray(seg).reshape(height, width) < 0
        rgb[bg] = np.asarray(self.look.sky_top_rgb, np.uint8)
        return rgb
