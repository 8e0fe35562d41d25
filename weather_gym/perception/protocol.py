"""The detector interface: the ``Detector`` protocol and ``DetectorBase``, shared by every adapter.

``weather_gym.perception.detector_spec`` re-exports both (with the spec parser ``load_detector``).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.onnx_detector import Detections
    >>> from weather_gym.perception.protocol import DetectorBase
    >>> class Empty(DetectorBase):
    ...     def detect_batch(self, images, score_threshold=None):
    ...         return [Detections(np.zeros((0, 4), np.float32), np.zeros(0, np.float32), np.zeros(0, np.int64))
    ...                 for _ in images]
    >>> len(Empty()(np.zeros((8, 8, 3), np.uint8)))
    0
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from weather_gym.perception.onnx_detector import Detections, check_frame


@runtime_checkable
class Detector(Protocol):
    """``detector(frame) -> Detections`` for an RGB uint8 frame ``(H, W, 3)``."""

    def __call__(self, frame: np.ndarray) -> Detections: ...


class DetectorBase:
    """What every detector offers; a subclass implements :meth:`detect_batch`.

    Attributes: ``score_threshold`` (operating threshold), ``input_size`` (W, H) of the network or
    None, ``resize`` (``letterbox``/``stretch``), ``name``.
    """

    score_threshold: float = 0.3
    input_size: tuple[int, int] | None = None
    resize: str = "letterbox"
    name: str = "detector"

    def detect_batch(self, images: Sequence[np.ndarray] | np.ndarray,
                     score_threshold: float | None = None) -> list[Detections]:
        raise NotImplementedError

    def detect(self, image: np.ndarray, score_threshold: float | None = None) -> Detections:
        """Detections of one frame ``(H, W, 3)``."""
        return self.detect_batch([check_frame(image, "image")], score_threshold)[0]

    def __call__(self, images, score_threshold: float | None = None):
        """One frame -> ``Detections``; a batch (4-D array or list) -> ``list[Detections]``."""
        if isinstance(images, np.ndarray) and images.ndim == 3:
            return self.detect(images, score_threshold)
        return self.detect_batch(images, score_threshold)
