"""The import paths that moved when the folders became the layers, kept as deprecated aliases for one release.

``MOVED`` maps every old public module path to its new home. The old paths still import (with a
``DeprecationWarning``) and name the same module objects, so ``isinstance`` and monkeypatching work
across both spellings: ``weather_gym/_moved/`` holds one small alias file per old name (``errors.py``
for ``weather_gym.errors``, ``perception/train.py`` for ``weather_gym.perception.train``), found
through the package's own ``__path__`` (``moved_path``; nothing is added to ``sys.meta_path``); the
modules of a moved package are aliased when the old package is first imported (loaded on first use,
so an old path costs no more than the new one). The aliases go in weather-gym 0.3.

Example:
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", DeprecationWarning)
    ...     from weather_gym.errors import InputError as Old
    >>> from weather_gym.core.errors import InputError
    >>> Old is InputError
    True
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import sys
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["MOVED", "REMOVED_IN", "alias_module", "deprecated_exports", "moved_path"]

REMOVED_IN = "0.3"
"""The release that drops the old paths."""

MOVED: dict[str, str] = {
    **{f"weather_gym.{m}": f"weather_gym.core.{m}"
       for m in ("errors", "limits", "paths", "registry", "cone_spec", "cone_arrays", "point_cloud")},
    "weather_gym.camera_config": "weather_gym.camera.config",
    "weather_gym.camera_isp": "weather_gym.camera.isp",
    "weather_gym.track_plot": "weather_gym.tracks.plot",
    "weather_gym.perception_modes": "weather_gym.pipeline.modes",
    "weather_gym.datasets": "weather_gym.lab.datasets",
    "weather_gym.evaluation": "weather_gym.lab.evaluation",
    "weather_gym.calibration": "weather_gym.lab.calibration",
    "weather_gym.gap": "weather_gym.lab.gap",
    "weather_gym.bench": "weather_gym.lab.bench",
    "weather_gym.rl": "weather_gym.lab.training.policy",
    # modules that left a package which stays (that package puts its folder in _moved/ on its __path__)
    "weather_gym.agents.episode_driver": "weather_gym.pipeline.episode",
    "weather_gym.perception.train": "weather_gym.lab.training.detector.train",
    "weather_gym.perception.conenet": "weather_gym.lab.training.detector.conenet",
    "weather_gym.perception.plots": "weather_gym.lab.training.detector.plots",
    "weather_gym.surrogate.record": "weather_gym.lab.training.surrogate.record",
    "weather_gym.surrogate.validate": "weather_gym.lab.training.surrogate.validate",
    "weather_gym.sim.egl_shadow_map": "weather_gym.sim.egl.shadow_map",
    "weather_gym.sim.egl_shadow_reuse": "weather_gym.sim.egl.shadow_reuse",
    "weather_gym.sim.egl_gl_table": "weather_gym.sim.egl.gl_table",
    "weather_gym.sim.elf_symbols": "weather_gym.sim.egl.elf_symbols",
}
"""Old module path -> new module path."""


def moved_path(package: str) -> str:
    """The folder of ``package``'s old module paths, for its ``__path__``: ``weather_gym/_moved/<sub>``.

    >>> moved_path("weather_gym.perception").endswith("_moved/perception")
    True
    """
    base = Path(__file__).resolve().parents[1] / "_moved"
    return str(base.joinpath(*package.split(".")[1:]))


def _warn(old: str, new: str, stacklevel: int) -> None:
    warnings.warn(f"{old} moved to {new}; the old path goes in weather-gym {REMOVED_IN}",
                  DeprecationWarning, stacklevel=stacklevel)


def _lazy_module(name: str) -> ModuleType:
    """The module ``name``, from ``sys.modules`` or created to load on first attribute access."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:  # pragma: no cover - listed by iter_modules, so found
        raise ModuleNotFoundError(name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module


def alias_module(old: str) -> ModuleType:
    """Make ``old`` (a key of ``MOVED``) name its new module, and an old package's modules theirs.

    Called by the alias files in ``weather_gym/_moved/``; returns the new module.
    """
    new = MOVED[old]
    _warn(old, new, stacklevel=4)
    module = importlib.import_module(new)
    sys.modules[old] = module
    for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
        sys.modules.setdefault(f"{old}.{info.name}", _lazy_module(f"{new}.{info.name}"))
    return module


def deprecated_exports(package: str, names: Mapping[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for names that left ``package``: ``name -> new module``, with a warning.

    >>> getattr_ = deprecated_exports("weather_gym.agents", {"dumps": "json"})
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     getattr_("dumps").__name__, caught[0].category.__name__
    ('dumps', 'DeprecationWarning')
    """

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        _warn(f"{package}.{name}", f"{names[name]}.{name}", stacklevel=3)
        return getattr(importlib.import_module(names[name]), name)

    return __getattr__
