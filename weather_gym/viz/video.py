"""Writing what people look at: MP4 videos (OpenCV ``mp4v``) and PNG strips of frames.

Nothing a user wrote is overwritten unless they say so (``overwrite=True``).

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

import math
import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

__all__ = ["check_output_path", "VideoWriter", "FrameSampler", "save_strip"]


def check_output_path(path: str | os.PathLike, *, overwrite: bool = False, suffixes: Sequence[str] = ()) -> Path:
    """``path`` as a Path, after checking its suffix, that its folder exists and that it is not
    about to overwrite a file (unless ``overwrite``)."""
    p = Path(path)
    if suffixes and p.suffix.lower() not in suffixes:
        raise ValueError(f"{p}: expected a file ending in {' or '.join(suffixes)}")
    if p.exists() and not overwrite:
        raise FileExistsError(f"{p} already exists; pass --overwrite to replace it")
    if not p.parent.is_dir():
        raise FileNotFoundError(f"folder {p.parent} does not exist (for {p})")
    return p


class VideoWriter:
    """An MP4 file written frame by frame (RGB uint8, all frames the size of the first)."""

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, *, overwrite: bool = False) -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise ValueError(f"video fps must be a finite number > 0, got {fps!r}")
        self.path = check_output_path(path, overwrite=overwrite, suffixes=(".mp4",))
        self.fps = float(fps)
        self._writer: cv2.VideoWriter | None = None
        self._size: tuple[int, int] | None = None
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        f = np.asarray(frame)
        if f.dtype != np.uint8 or f.ndim != 3 or f.shape[2] != 3:
            raise ValueError(f"video frames must be RGB uint8 (H, W, 3), got {f.dtype} {f.shape}")
        size = (f.shape[1], f.shape[0])
        if self._writer is None:
            self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, size)
            if not self._writer.isOpened():
                raise OSError(f"OpenCV could not open {self.path} for writing (mp4v codec)")
            self._size = size
        elif size != self._size:
            raise ValueError(f"video frame size changed from {self._size} to {size}")
        self._writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class FrameSampler:
    """Keeps about ``n`` frames spread evenly over a run of unknown length, in bounded memory.

    Every ``stride``-th frame is kept; when more than ``2 n`` are held, every other one is dropped
    and the stride doubles. ``frames()`` returns ``n`` of them, evenly spaced.
    """

    def __init__(self, n: int) -> None:
        if not (isinstance(n, int) and n >= 1):
            raise ValueError(f"number of strip frames must be an integer >= 1, got {n!r}")
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
        raise ValueError("save_strip: no frames to write")
    h, w = frames[0].shape[:2]
    cols = columns or min(len(frames), 4)
    rows = math.ceil(len(frames) / cols)
    grid = np.full((rows * h + (rows - 1) * 2, cols * w + (cols - 1) * 2, 3), 255, np.uint8)
    for k, f in enumerate(frames):
        if f.shape[:2] != (h, w):
            raise ValueError(f"save_strip: frame {k} is {f.shape[:2]}, expected {(h, w)}")
        r, c = divmod(k, cols)
        grid[r * (h + 2) : r * (h + 2) + h, c * (w + 2) : c * (w + 2) + w] = f
    if not cv2.imwrite(str(p), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR)):
        raise OSError(f"could not write {p}")
    return p
