"""Saving a matplotlib figure the way every output is written (``weather_gym.core._io``): atomically,
never over an existing file without ``overwrite``, no timestamp in the PNG. Only plotting code
imports this module (``import weather_gym`` does not load matplotlib).

Example:
    >>> import tempfile, pathlib
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> import matplotlib.pyplot as plt
    >>> fig, ax = plt.subplots()
    >>> save_figure(fig, pathlib.Path(tempfile.mkdtemp()) / "plot.png").suffix
    '.png'
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt

from weather_gym.core._io import atomic_file

__all__ = ["save_figure"]


def save_figure(fig: Any, path: str | os.PathLike, *, overwrite: bool = False, close: bool = True,
                **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure safely (format from the suffix, no timestamp metadata); close it."""
    p = Path(path)
    savefig_kwargs.setdefault("metadata", {"Software": None} if p.suffix.lower() == ".png" else None)
    try:
        with atomic_file(p, "wb", overwrite=overwrite) as f:
            fig.savefig(f, format=(p.suffix[1:].lower() or "png"), **savefig_kwargs)
    finally:
        if close:
            plt.close(fig)
    return p
