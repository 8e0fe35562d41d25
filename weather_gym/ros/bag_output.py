"""A bag written whole or not at all: into a temporary folder beside the destination, moved into place
when complete (an error or Ctrl-C leaves nothing). An existing destination is replaced only with
``overwrite`` and only when it is a bag of the same kind (a folder of anything else is never removed).

Example:
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "run.bag"
    >>> with bag_output(out, kind="rosbag1") as inner:
    ...     _ = inner.write_bytes(b"#ROSBAG V2.0")
    >>> out.read_bytes()
    b'#ROSBAG V2.0'
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from weather_gym.core._io import check_not_input
from weather_gym.core.errors import OutputExistsError, OutputPathError
from weather_gym.ros.bags import bag_kind

__all__ = ["bag_output", "check_bag_output"]


def check_bag_output(out: Path, kind: str, overwrite: bool, what: str = "OUT_BAG") -> None:
    """Refuse, before any work, an output that exists (without ``overwrite``), that is not a bag of
    ``kind``, that is a declared input, or whose name does not fit ``kind``."""
    check_not_input(out, what=what)
    if kind == "rosbag1" and out.suffix.lower() != ".bag":
        raise OutputPathError(f"{what} {out}: the bag is a ROS 1 bag: give a .bag file")
    if kind == "rosbag2" and out.suffix.lower() in (".bag", ".mcap", ".db3"):
        raise OutputPathError(f"{what} {out}: a rosbag2 bag is a folder (metadata.yaml and its storage file); give "
                              "a folder name without .bag/.mcap/.db3")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise OutputExistsError(f"{what} {out} already exists; pass --overwrite to replace it")
        if out.is_symlink() or bag_kind(out) != kind:
            raise OutputPathError(f"{what} {out} exists and is not a {kind} bag: it is not replaced; choose "
                                  "another path")


@contextlib.contextmanager
def bag_output(out: str | os.PathLike, *, kind: str, overwrite: bool = False) -> Iterator[Path]:
    """The path to write the bag to (inside a fresh temporary folder beside ``out``; it does not exist
    yet, as bag writers want); on a clean exit it becomes ``out``."""
    out = Path(out)
    check_bag_output(out, kind, overwrite)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    except OSError as exc:
        raise OutputPathError(f"cannot write {out}: {exc.strerror or exc}") from None
    try:
        inner = tmp / out.name
        yield inner
        if not inner.exists():
            raise OutputPathError(f"cannot write {out}: the bag writer wrote nothing")
        check_bag_output(out, kind, overwrite)  # again: something may have appeared meanwhile
        old = tmp / ".replaced"
        if out.exists():
            os.rename(out, old)
        try:
            os.rename(inner, out)
        except OSError as exc:
            if old.exists():
                os.rename(old, out)
            raise OutputPathError(f"cannot write {out}: {exc.strerror or exc}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
