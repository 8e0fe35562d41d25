"""Lazy re-exports for package ``__init__`` modules: names are imported on first use.

A package lists ``name -> defining module`` once; importing the package stays light (PyBullet,
onnxruntime and torch load only when something that needs them is used).

Example:
    >>> from weather_gym._lazy import lazy_exports
    >>> getattr_, dir_ = lazy_exports("json", {"JSONDecoder": "json.decoder"})
    >>> getattr_("JSONDecoder").__name__
    'JSONDecoder'
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, names: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the module ``package`` that re-exports ``names`` lazily.

    Usage at the end of a package's ``__init__.py``::

        _LAZY = {"ConeDetector": "weather_gym.perception.onnx_detector", ...}
        __all__ = sorted(_LAZY)
        __getattr__, __dir__ = lazy_exports(__name__, _LAZY)
    """

    def __getattr__(name: str) -> Any:
        if name in names:
            return getattr(import_module(names[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
