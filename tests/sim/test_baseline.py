"""The naive baseline scene of ``weather-gym bench sim --naive``."""

from __future__ import annotations

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.sim.baseline import naive_scene


def test_naive_scene_renders_the_cylinders():
    frame, close = naive_scene(CameraConfig(width=96, height=54))
    try:
        _, _, rgba, depth, _ = frame()[:5]
    finally:
        close()
    rgba = np.asarray(rgba).reshape(54, 96, 4)
    assert np.asarray(depth).size == 96 * 54
    blue = (rgba[..., 2] > 2 * rgba[..., 0].astype(int) + 20)  # the blue row of cylinders is in view
    assert blue.any()
