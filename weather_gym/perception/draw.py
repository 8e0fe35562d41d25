"""Draw detections on a frame (for people: README pictures, ``weather-gym detector predict``).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.draw import draw_detections
    >>> img = np.zeros((40, 60, 3), np.uint8)
    >>> out = draw_detections(img, {"boxes": np.array([[5, 5, 20, 30.]]), "scores": np.array([0.8]),
    ...                              "classes": np.array([0])})
    >>> out.shape, bool(out.any()), bool(img.any())
    ((40, 60, 3), True, False)
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES

BOX_RGB = {"blue": (40, 120, 255), "yellow": (255, 230, 0), "orange": (255, 120, 0), "big_orange": (255, 0, 160)}


def draw_detections(image: np.ndarray, detections: Any, *, labels: bool = True, thickness: int = 1) -> np.ndarray:
    """A copy of ``image`` (RGB uint8) with each detection's box and ``class score`` drawn."""
    d = detections.to_dict() if hasattr(detections, "to_dict") and not isinstance(detections, dict) else detections
    out = np.ascontiguousarray(image).copy()
    for (x1, y1, x2, y2), s, c in zip(np.asarray(d["boxes"]).reshape(-1, 4), np.asarray(d["scores"]).reshape(-1),
                                      np.asarray(d["classes"]).reshape(-1), strict=True):
        name = CONE_CLASSES[int(c)]
        col = BOX_RGB[name]
        p1, p2 = (int(round(x1)), int(round(y1))), (int(round(x2)), int(round(y2)))
        cv2.rectangle(out, p1, p2, col, thickness)
        if labels:
            cv2.putText(out, f"{s:.2f}", (p1[0], max(8, p1[1] - 2)), cv2.FONT_HERSHEY_SIMPLEX, 0.3, col, 1, cv2.LINE_AA)
    return out
