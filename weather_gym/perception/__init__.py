"""Perception: the ONNX cone detector, detections -> cones, and pycocotools scoring.

Runtime needs onnxruntime only; ``model.py`` and ``train.py`` need the ``train`` extra (torch).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception import ConeDetector, detections_to_cones, evaluate
    >>> from weather_gym.camera.config import CameraConfig
    >>> det = ConeDetector()
    >>> cones = detections_to_cones(det(np.zeros((376, 672, 3), np.uint8)), CameraConfig())
    >>> cones["ranges"].shape
    (0,)
"""

from __future__ import annotations

from weather_gym.core._lazy import lazy_exports
from weather_gym.core.moved import moved_path

_LAZY = {
    "ConeDetector": "weather_gym.perception.onnx_detector",
    "Detector": "weather_gym.perception.detector_spec",
    "DetectorSpec": "weather_gym.perception.detector_spec",
    "load_detector": "weather_gym.perception.detector_spec",
    "as_detector": "weather_gym.perception.detector_spec",
    "YoloDetector": "weather_gym.perception.yolo",
    "SmallRule": "weather_gym.perception.labels",
    "Detections": "weather_gym.perception.onnx_detector",
    "DEFAULT_MODEL": "weather_gym.perception.onnx_detector",
    "detections_to_cones": "weather_gym.perception.ranging",
    "cones_to_observation": "weather_gym.perception.ranging",
    "evaluate": "weather_gym.perception.scoring",
    "score_dataset": "weather_gym.perception.scoring",
    "score_detections": "weather_gym.perception.scoring",
    "EvalResult": "weather_gym.perception.scoring",
    "MIN_BOX_HEIGHT_PX": "weather_gym.perception.labels",
    "CONE_FIELDS": "weather_gym.perception.cones",
    "pack_cones": "weather_gym.perception.cones",
    "unpack_cones": "weather_gym.perception.cones",
    "cone_list_space": "weather_gym.perception.cones",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
__path__.append(moved_path(__name__))  # the old module paths, deprecated (weather_gym.core.moved)
