"""COCO datasets of cone frames: ``load_coco`` (validated), ``CocoWriter``, ``render_dataset``, ``import_dataset`` (KITTI, YOLO, COCO, Supervisely recordings) and ignore masks.

Example:
    >>> from weather_gym.lab.datasets import load_coco
    >>> load_coco("no/such/folder")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.MissingInputError: dataset folder no/such/folder not found
"""

from __future__ import annotations

from weather_gym.core._lazy import lazy_exports

_LAZY = {
    "CocoDataset": "weather_gym.lab.datasets.coco",
    "CocoWriter": "weather_gym.lab.datasets.coco_writer",
    "load_coco": "weather_gym.lab.datasets.coco",
    "read_image": "weather_gym.lab.datasets.coco_files",
    "read_depth_png": "weather_gym.lab.datasets.coco_files",
    "render_dataset": "weather_gym.lab.datasets.render",
    "import_dataset": "weather_gym.lab.datasets.importers",
    "propose_mask": "weather_gym.lab.datasets.masks",
    "read_mask": "weather_gym.lab.datasets.coco_files",
    "write_mask": "weather_gym.lab.datasets.masks",
    "set_dataset_mask": "weather_gym.lab.datasets.masks",
    "ViewRenderer": "weather_gym.lab.datasets.render",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
