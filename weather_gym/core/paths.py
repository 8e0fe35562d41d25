"""Locate the data folders (``tracks/``, ``envs/``) in a source checkout or an installed wheel.

Example:
    >>> from weather_gym.core.paths import data_dir
    >>> (data_dir("tracks") / "eufs" / "LICENSE").exists()
    True
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
"""The package folder ``weather_gym/``."""
_PKG = PACKAGE


def data_dir(name: str) -> Path:
    """Return the shipped data folder ``name`` ("tracks" or "envs").

    An installed wheel carries it as ``weather_gym/_data/<name>`` (hatch force-include);
    a source checkout has it at the repository root.
    """
    for candidate in (_PKG / "_data" / name, _PKG.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"data folder {name!r} not found in {_PKG / '_data'} or {_PKG.parent}")


PPO_CONES_MODEL = _PKG / "agents" / "models" / "ppo_cones.zip"
"""The shipped PPO driver of the ``ppo_cones`` agent (trained by ``examples/train_ppo.py``; ``docs/rl.md``)."""
