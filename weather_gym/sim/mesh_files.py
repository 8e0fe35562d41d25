"""Mesh files for PyBullet, named by their content, in one folder per process.

PyBullet loads meshes and their textures from files and keeps what it loaded in a process-wide
cache keyed by the file's path, which it never empties (not even when the client disconnects). A
folder per world would therefore leak every mesh and texture of every world ever built (a 2048x2048
ground texture is 12 MB). Naming each file by the hash of its content makes the same content load
from the same path, so PyBullet's cache holds each distinct mesh once, and a different content can
never be served stale from it.

Example:
    >>> from weather_gym.sim.mesh_files import mesh_file
    >>> from weather_gym.sim.meshes import box_obj
    >>> a = mesh_file("car", box_obj(1.0, 0.5, 0.3))
    >>> a == mesh_file("car", box_obj(1.0, 0.5, 0.3)) and a.exists()
    True
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import tempfile
from pathlib import Path

import cv2
import numpy as np

from weather_gym.core._io import atomic_write

__all__ = ["mesh_file", "mesh_dir"]

_dir: Path | None = None
_owner_pid: int | None = None


def mesh_dir() -> Path:
    """This process's mesh folder (created on first use, removed when the process that made it exits)."""
    global _dir, _owner_pid
    if _dir is None or not _dir.is_dir():
        _dir = Path(tempfile.mkdtemp(prefix="weather_gym_meshes_"))
        _owner_pid = os.getpid()
    return _dir


@atexit.register
def _remove_mesh_dir() -> None:
    if _dir is not None and _owner_pid == os.getpid():  # a forked child never removes its parent's folder
        shutil.rmtree(_dir, ignore_errors=True)


def _write_atomic(path: Path, data: bytes) -> None:
    atomic_write(path, data, overwrite=True)  # content-named: a file already there holds the same bytes


def mesh_file(stem: str, obj_text: str, texture_rgb: np.ndarray | None = None) -> Path:
    """Path of an OBJ file with ``obj_text`` (and, if given, an MTL + PNG texture), named by content.

    ``stem`` is only a readable prefix; two calls with the same content return the same path and
    write nothing the second time.
    """
    h = hashlib.sha1(obj_text.encode())
    png = None
    if texture_rgb is not None:
        tex = np.ascontiguousarray(texture_rgb, dtype=np.uint8)
        ok, buf = cv2.imencode(".png", cv2.cvtColor(tex, cv2.COLOR_RGB2BGR))
        if not ok:
            raise RuntimeError(f"could not encode the texture of mesh {stem!r} as PNG")
        png = buf.tobytes()
        h.update(png)
    name = f"{stem}_{h.hexdigest()[:20]}"
    folder = mesh_dir()
    obj = folder / f"{name}.obj"
    if obj.exists():
        return obj
    if png is None:
        _write_atomic(obj, obj_text.encode())
        return obj
    # the texture is named by its own content: meshes with the same texture share one file (and one
    # entry in PyBullet's texture cache)
    tex_name = f"tex_{hashlib.sha1(png).hexdigest()[:20]}.png"
    if not (folder / tex_name).exists():
        _write_atomic(folder / tex_name, png)
    _write_atomic(folder / f"{name}.mtl",
                  f"newmtl mat\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd {tex_name}\n".encode())
    _write_atomic(obj, f"mtllib {name}.mtl\nusemtl mat\n{obj_text}".encode())
    return obj
