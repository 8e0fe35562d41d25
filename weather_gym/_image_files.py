"""Image files by any name the file system gives: OpenCV decodes bytes Python read, never a path.

``cv2.imread`` / ``cv2.imwrite`` take a path that OpenCV must turn into UTF-8: a name that is not
UTF-8 (``b'caf\\xe9.png'`` from a Latin-1 or Windows recording, which Python holds as
``'caf\\udce9.png'``) crashed the process with a segmentation fault. Here Python reads the file
(``np.fromfile``: any name the system accepts) and OpenCV decodes the bytes (``cv2.imdecode``); writes
go through ``cv2.imencode`` and :func:`weather_gym._io.atomic_write`. Video files, which OpenCV and
FFmpeg open by name, are checked first by :func:`opencv_name`: a name they cannot take is an
:class:`~weather_gym.errors.InputError` naming the file, not a signal. :func:`shown` prints a path that
is not UTF-8 the way ``ls`` would show it (``caf\\xe9.png``), so that printing it cannot fail either.

Every read of a user's image file in the package goes through :func:`read_image_file`.

Example:
    >>> import os, tempfile, pathlib, numpy as np, cv2
    >>> p = pathlib.Path(tempfile.mkdtemp()) / os.fsdecode(b"caf\\xe9.png")
    >>> _ = p.write_bytes(cv2.imencode(".png", np.zeros((2, 3, 3), np.uint8))[1].tobytes())
    >>> read_image_file(p).shape, shown(p.name)
    ((2, 3, 3), 'caf\\\\xe9.png')
    >>> opencv_name(p, what="video")
    Traceback (most recent call last):
    ...
    weather_gym.errors.InputError: video .../caf\\xe9.png: OpenCV cannot open a file whose name is not UTF-8; rename it
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from weather_gym.errors import InputError

__all__ = ["read_image_file", "opencv_name", "shown"]


def shown(path: str | os.PathLike) -> str:
    """``path`` as text that prints anywhere: a byte that is not UTF-8 shown as ``\\xNN``."""
    return os.fsencode(path).decode("utf-8", "backslashreplace")


def read_image_file(path: str | os.PathLike, flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
    """``cv2.imread(path, flags)`` for any file name: None where the file cannot be read or decoded.

    Python reads the bytes (a missing file, a folder or no permission: None, as ``cv2.imread``);
    ``cv2.imdecode`` decodes them with the same decoders and ``flags``.
    """
    try:
        data = np.fromfile(os.fspath(path), dtype=np.uint8)
    except (OSError, ValueError):
        return None
    if data.size == 0:
        return None
    try:
        img = cv2.imdecode(data, flags)
    except cv2.error:
        return None
    return None if img is None or img.size == 0 else img


def opencv_name(path: str | os.PathLike, *, what: str = "file") -> str:
    """``path`` as the string OpenCV or FFmpeg opens by name; :class:`InputError` naming it when the name
    is not UTF-8 (which they cannot take)."""
    name = os.fsdecode(path)
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{what} {shown(name)}: OpenCV cannot open a file whose name is not UTF-8; rename it") from None
    return name
