"""Atomic file writes: a reader (or a run killed half-way) sees the old file or the new one, never half.

Example:
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "out.json"
    >>> atomic_write_json(p, {"k": 0.5}).read_text()
    '{"k": 0.5}'
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["atomic_write", "atomic_write_json"]


def atomic_write(path: str | os.PathLike, data: str | bytes, *,
                 check: Callable[[Path], None] | None = None) -> Path:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``.

    ``check(tmp_path)`` may validate the written file first; if it raises, ``path`` is left as it
    was. The file gets the usual permissions (umask), like a plain ``open(path, "w")``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data, encoding="utf-8")
        if check is not None:
            check(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_json(path: str | os.PathLike, obj: Any, *, indent: int | None = None,
                      sort_keys: bool = False) -> Path:
    """``obj`` as JSON (a final newline when indented), written with :func:`atomic_write`."""
    text = json.dumps(obj, indent=indent, sort_keys=sort_keys)
    return atomic_write(path, text + "\n" if indent is not None else text)
