"""Rendering for people: lap videos, detection overlays, a top-down map inset, PNG strips.

Called from the CLI and examples, never from the physics step. OpenCV only (no PyBullet).

Example:
    >>> import numpy as np
    >>> from weather_gym.viz import TopDownView, compose_frame
    >>> view = TopDownView((-10, 10, -5, 5), size=120)
    >>> inset = view.draw(cones_xy=np.array([[0.0, 2.0]]), classes=np.array([0]), pose=(0, 0, 0))
    >>> frame = compose_frame(np.zeros((188, 336, 3), np.uint8), inset, ["lap 1"])
    >>> frame.shape
    (188, 336, 3)
"""

from weather_gym.viz.overlay import TopDownView, compose_frame, cone_list_boxes, draw_boxes
from weather_gym.viz.video import FrameSampler, VideoWriter, check_output_path, save_strip

__all__ = ["TopDownView", "cone_list_boxes", "compose_frame", "draw_boxes", "FrameSampler", "VideoWriter",
           "check_output_path", "save_strip"]
