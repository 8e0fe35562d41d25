"""Lazy re-exports for package ``__init__`` modules, on ``lazy_loader``: names are imported on first use.

A package lists ``name -> defining module`` once; importing the package stays light (PyBullet,
onnxruntime and torch load only when something that needs them is used). ``lazy_loader.attach``
resolves the names of the package's own modules (and caches them on the package; a function named
like its module, ``weather_gym.lab.gap.fit``, stays the function after the module is imported); a name
defined outside the package (``weather_gym.wrappers.RecordVideo`` from ``weather_gym.viz``) is
imported from its module directly.

Example:
    >>> from weather_gym.core._lazy import lazy_exports
    >>> getattr_, dir_ = lazy_exports("json", {"JSONDecoder": "json.decoder"})
    >>> getattr_("JSONDecoder").__name__
    'JSONDecoder'
    >>> getattr_("nothing")
    Traceback (most recent call last):
    ...
    AttributeError: module 'json' has no attribute 'nothing'
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from importlib import import_module
from typing import Any

import lazy_loader

__all__ = ["lazy_exports"]


def lazy_exports(package: str, names: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the module ``package`` that re-exports ``names`` lazily.

    Usage at the end of a package's ``__init__.py``::

        _LAZY = {"ConeDetector": "weather_gym.perception.onnx_detector", ...}
        __all__ = sorted(_LAZY)
        __getattr__, __dir__ = lazy_exports(__name__, _LAZY)
    """
    inside: dict[str, list[str]] = {}
    for name, module in names.items():
        if module.startswith(package + "."):
            inside.setdefault(module.removeprefix(package + "."), []).append(name)
    attached, _, _ = lazy_loader.attach(package, submod_attrs=inside)

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        if names[name].startswith(package + "."):
            return attached(name)
        return getattr(import_module(names[name]), name)

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
