"""Image files by any name the file system gives: OpenCV decodes bytes Python read, never a path.

``cv2.imread`` / ``cv2.imwrite`` take a path that OpenCV must turn into UTF-8: a name that is not
UTF-8 (``b'caf\\xe9.png'`` from a Latin-1 or Windows recording, which Python holds as
``'caf\\udce9.png'``) crashed the process with a segmentation fault. Here Python reads the file
(``np.fromfile``: any name the system accepts) and OpenCV decodes the bytes (``cv2.imdecode``); writes
go through ``cv2.imencode`` and :func:`weather_gym.core._io.atomic_write`. Video files, which OpenCV and
FFmpeg open by name, are checked first by :func:`opencv_name`: a name they cannot take is an
:class:`~weather_gym.core.errors.InputError` naming the file, not a signal. :func:`shown` prints a path that
is not UTF-8 the way ``ls`` would show it (``caf\\xe9.png``), so that printing it cannot fail either.

Every read of a user's image file in the package goes through :func:`read_image_file`.

**Frames that are not 8-bit colour.** The package works on 8-bit RGB frames, and OpenCV's colour
decode (``cv2.IMREAD_COLOR``) converts every other frame to one: a grey frame is copied into R, G and B;
an alpha channel is dropped (not composited onto a background); 16 bits per channel become 8 (a
PNG's high byte, a TIFF scaled by 1/257). :func:`colour_conversions` says which of these reading a file makes (from its header), so
that the commands that read a user's frames say so in a note (``degrade``, ``dataset import``) instead
of flattening them without a word.

Example:
    >>> import os, tempfile, pathlib, numpy as np, cv2
    >>> p = pathlib.Path(tempfile.mkdtemp()) / os.fsdecode(b"caf\\xe9.png")
    >>> _ = p.write_bytes(cv2.imencode(".png", np.zeros((2, 3, 3), np.uint8))[1].tobytes())
    >>> read_image_file(p).shape, shown(p.name)
    ((2, 3, 3), 'caf\\\\xe9.png')
    >>> opencv_name(p, what="video")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: video .../caf\\xe9.png: OpenCV cannot open a file whose name is not UTF-8; rename it
"""

from __future__ import annotations

import os

import cv2
import numpy as np
from PIL import Image

from weather_gym.core.errors import InputError

__all__ = ["CONVERSIONS", "colour_conversions", "conversion_note", "read_image_file", "opencv_name", "shown"]

CONVERSIONS = {"grey": "grey copied into R, G and B", "alpha": "alpha channel dropped (not composited)",
               "16-bit": "16 bits per channel reduced to 8"}
"""What reading a frame as 8-bit RGB may change -> how (``cv2.IMREAD_COLOR``'s conversion)."""

_PNG = b"\x89PNG\r\n\x1a\n"
_PIL_GREY = frozenset({"1", "L", "LA", "La", "I", "I;16", "I;16B", "I;16L", "I;16N", "F"})
_PIL_ALPHA = frozenset({"RGBA", "RGBa", "LA", "La", "PA"})
_PIL_DEEP = frozenset({"I", "I;16", "I;16B", "I;16L", "I;16N", "F"})


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


def colour_conversions(path: str | os.PathLike) -> tuple[str, ...]:
    """The conversions (keys of :data:`CONVERSIONS`, in that order) reading ``path`` as 8-bit RGB makes;
    ``()`` for an 8-bit colour frame, or when the header cannot be read (the decode then reports).

    A PNG's header is read directly (bit depth and colour type); another format's through Pillow.
    """
    try:
        with open(os.fspath(path), "rb") as f:
            head = f.read(33)
    except (OSError, ValueError):
        return ()
    found: set[str] = set()
    if head[:8] == _PNG and head[12:16] == b"IHDR" and len(head) >= 26:
        depth, colour = head[24], head[25]
        if colour in (0, 4):
            found.add("grey")
        if colour in (4, 6):
            found.add("alpha")
        if depth == 16:
            found.add("16-bit")
    else:
        try:
            with Image.open(os.fspath(path)) as im:
                mode, info = im.mode, im.info
        except Exception:  # noqa: BLE001 - not a format Pillow reads: OpenCV decides
            return ()
        if mode in _PIL_GREY:
            found.add("grey")
        if mode in _PIL_ALPHA or (mode == "P" and "transparency" in info):
            found.add("alpha")
        if mode in _PIL_DEEP:
            found.add("16-bit")
    return tuple(k for k in CONVERSIONS if k in found)


def conversion_note(counts: dict[str, int] | tuple[str, ...], what: str) -> str:
    """One line saying what reading ``what`` as 8-bit RGB converted: the conversions of one file (a tuple),
    or how many files each conversion touched (a dict).

    Example:
        >>> conversion_note(("alpha", "16-bit"), "a.png")
        'note: a.png read as 8-bit RGB: alpha channel dropped (not composited), 16 bits per channel reduced to 8'
        >>> conversion_note({"alpha": 2}, "3 images")
        'note: 3 images read as 8-bit RGB: alpha channel dropped (not composited) in 2'
    """
    if isinstance(counts, tuple):
        parts = [CONVERSIONS[k] for k in counts]
    else:
        parts = [f"{CONVERSIONS[k]} in {n}" for k, n in counts.items() if n]
    return f"note: {what} read as 8-bit RGB: " + ", ".join(parts)


def opencv_name(path: str | os.PathLike, *, what: str = "file") -> str:
    """``path`` as the string OpenCV or FFmpeg opens by name; :class:`InputError` naming it when the name
    is not UTF-8 (which they cannot take)."""
    name = os.fsdecode(path)
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{what} {shown(name)}: OpenCV cannot open a file whose name is not UTF-8; rename it") from None
    return name
