"""Writing what people look at: MP4 videos (OpenCV ``mp4v``) and PNG strips of frames.

Nothing a user wrote is overwritten unless they say so (``overwrite=True``). A video is written to
a temporary file beside its path and moved there by ``close()``; an interrupted run (an exception,
Ctrl-C, SIGTERM through the CLI) leaves no file, not a truncated one (``weather_gym._io``).

Example:
    >>> import numpy as np, tempfile, pathlib
    >>> from weather_gym.viz.video import VideoWriter, save_strip
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with VideoWriter(d / "lap.mp4", fps=30) as video:
    ...     for k in range(5): video.write(np.full((48, 64, 3), 40 * k, np.uint8))
    >>> video.frames, (d / "lap.mp4").stat().st_size > 0
    (5, True)
    >>> save_strip([np.zeros((48, 64, 3), np.uint8)] * 4, d / "strip.png").name
    'strip.png'
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from weather_gym._io import atomic_path, check_output, write_image
from weather_gym.errors import InputError, OutputPathError

__all__ = ["check_output_path", "VideoWriter", "FrameSampler", "save_strip"]


def check_output_path(path: str | os.PathLike, *, overwrite: bool = False, suffixes: Sequence[str] = ()) -> Path:
    """``path`` as a Path, after :func:`weather_gym._io.check_output` (suffix, no overwrite unless asked)."""
    return check_output(path, overwrite=overwrite, suffixes=suffixes)


class VideoWriter:
    """An MP4 file written frame by frame (RGB uint8, all frames the size of the first)."""

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, *, overwrite: bool = False) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise InputError(f"video fps must be a finite number > 0, got {fps!r}")
        self.path = check_output_path(path, overwrite=overwrite, suffixes=(".mp4",))
        self.overwrite = overwrite
        self.fps = float(fps)
        self._writer: cv2.VideoWriter | None = None
        self._output: contextlib.AbstractContextManager[Path] | None = None
        self._size: tuple[int, int] | None = None
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        f = np.asarray(frame)
        if f.dtype != np.uint8 or f.ndim != 3 or f.shape[2] != 3:
            raise InputError(f"video frames must be RGB uint8 (H, W, 3), got {f.dtype} {f.shape}")
        size = (f.shape[1], f.shape[0])
        if self._writer is None:
            self._output = atomic_path(self.path, overwrite=self.overwrite)
            tmp = self._output.__enter__()
            self._writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, size)
            if not self._writer.isOpened():
                self.abort()
                raise OutputPathError(f"OpenCV could not open {self.path} for writing (mp4v codec)")
            self._size = size
        elif size != self._size:
            raise InputError(f"video frame size changed from {self._size} to {size}")
        self._writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        """Finish the video and move it to ``path`` (nothing is written when no frame was)."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
            output, self._output = self._output, None
            output.__exit__(None, None, None)

    def abort(self) -> None:
        """Stop and discard the video: ``path`` is left as it was."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._output is not None:
            output, self._output = self._output, None
            output.__exit__(_Discarded, _Discarded(), None)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class _Discarded(Exception):
    """Thrown into the temporary output of an aborted video so that it is removed."""


class FrameSampler:
    """Keeps about ``n`` frames spread evenly over a run of unknown length, in bounded memory.

    Every ``stride``-th frame is kept; when more than ``2 n`` are held, every other one is dropped
    and the stride doubles. ``frames()`` returns ``n`` of them, evenly spaced.
    """

    def __init__(self, n: int) -> None:
        if not (isinstance(n, int) and n >= 1):
            raise InputError(f"number of strip frames must be an integer >= 1, got {n!r}")
        self.n = n
        self.stride = 1
        self._count = 0
        self._kept: list[np.ndarray] = []

    def offer(self, frame: np.ndarray) -> None:
        if self._count % self.stride == 0:
            self._kept.append(np.asarray(frame).copy())
            if len(self._kept) > 2 * self.n:
                self._kept = self._kept[::2]
                self.stride *= 2
        self._count += 1

    def frames(self) -> list[np.ndarray]:
        if len(self._kept) <= self.n:
            return list(self._kept)
        idx = np.round(np.linspace(0, len(self._kept) - 1, self.n)).astype(int)
        return [self._kept[i] for i in idx]


def save_strip(frames: Sequence[np.ndarray], path: str | os.PathLike, *, columns: int | None = None,
               overwrite: bool = False) -> Path:
    """Write the frames (RGB uint8, one size) as a PNG grid (``columns`` wide, default up to 4)."""
    p = check_output_path(path, overwrite=overwrite, suffixes=(".png",))
    if not len(frames):
        raise InputError("save_strip: no frames to write")
    h, w = frames[0].shape[:2]
    cols = columns or min(len(frames), 4)
    rows = math.ceil(len(frames) / cols)
    grid = np.full((rows * h + (rows - 1) * 2, cols * w + (cols - 1) * 2, 3), 255, np.uint8)
    for k, f in enumerate(frames):
        if f.shape[:2] != (h, w):
            raise InputError(f"save_strip: frame {k} is {f.shape[:2]}, expected {(h, w)}")
        r, c = divmod(k, cols)
        grid[r * (h + 2) : r * (h + 2) + h, c * (w + 2) : c * (w + 2) + w] = f
    return write_image(p, grid, overwrite=overwrite)
