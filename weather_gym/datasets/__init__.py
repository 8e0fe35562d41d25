"""COCO datasets of rendered cone frames: ``load_coco`` (validated), ``CocoWriter``, ``render_dataset``.

Example:
    >>> from weather_gym.datasets import load_coco
    >>> load_coco("no/such/folder")
    Traceback (most recent call last):
    ...
    FileNotFoundError: dataset folder no/such/folder not found
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_LAZY = {
    "CocoDataset": "weather_gym.datasets.coco",
    "CocoWriter": "weather_gym.datasets.coco",
    "load_coco": "weather_gym.datasets.coco",
    "read_image": "weather_gym.datasets.coco",
    "read_depth_png": "weather_gym.datasets.coco",
    "render_dataset": "weather_gym.datasets.render",
    "ViewRenderer": "weather_gym.datasets.render",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'weather_gym.datasets' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
