"""A naive camera frame, the baseline of ``weather-gym bench sim --naive``: a bare PyBullet scene
rendered with one ``p.getCameraImage`` call (TinyRenderer), nothing before or after it.

Example:
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.sim.baseline import naive_scene
    >>> frame, close = naive_scene(CameraConfig(width=64, height=36))
    >>> frame()[2].shape
    (36, 64, 4)
    >>> close()
"""

from __future__ import annotations

import math
from collections.abc import Callable

from weather_gym.camera.config import CameraConfig
from weather_gym.sim import renderer as _renderer
from weather_gym.sim.bullet import pybullet as p

NAIVE_CYLINDERS = 80
"""Cylinders in the naive scene (small_track has 77 cones)."""


def naive_scene(camera: CameraConfig) -> tuple[Callable[[], tuple], Callable[[], None]]:
    """A naive camera frame: a bare PyBullet client (TinyRenderer) with a grey ground box and
    :data:`NAIVE_CYLINDERS` cone-sized cylinders (0.228 m x 0.325 m) in two gently curving rows 3 m apart,
    seen from the env camera's height, pitch and field of view; one ``p.getCameraImage`` per call.
    Returns ``(frame, close)``.
    """
    lease = _renderer.connect(renderer="tiny")
    c = lease.id
    ground = p.createVisualShape(p.GEOM_BOX, halfExtents=[100.0, 100.0, 0.01], rgbaColor=[0.35, 0.35, 0.35, 1],
                                 physicsClientId=c)
    p.createMultiBody(0, -1, ground, [0.0, 0.0, -0.01], physicsClientId=c)
    colors = ([0.1, 0.2, 0.9, 1], [0.95, 0.85, 0.1, 1])
    shapes = [p.createVisualShape(p.GEOM_CYLINDER, radius=0.114, length=0.325, rgbaColor=rgba, physicsClientId=c)
              for rgba in colors]
    for i in range(NAIVE_CYLINDERS):
        x = 3.0 + 2.5 * (i // 2)
        y = (1.5 if i % 2 else -1.5) + 4.0 * math.sin(x / 25.0)
        p.createMultiBody(0, -1, shapes[i % 2], [x, y, 0.1625], physicsClientId=c)
    pitch = math.radians(camera.pitch_deg)
    eye = [0.0, 0.0, camera.mount_height]
    view = p.computeViewMatrix(eye, [math.cos(pitch), 0.0, camera.mount_height - math.sin(pitch)], [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(camera.vfov_deg, camera.width / camera.height, camera.near, camera.far)

    def frame():
        return p.getCameraImage(camera.width, camera.height, view, proj, renderer=p.ER_TINY_RENDERER,
                                physicsClientId=c)

    return frame, lambda: _renderer.release(lease)
