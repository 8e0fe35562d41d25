"""Writing what people look at: MP4 videos (H.264) and PNG strips of frames.

Videos are H.264 (``yuv420p``, ``+faststart``: browsers and notebooks play them) through PyAV
(``av``, a runtime dependency). Without PyAV, or when its FFmpeg has no H.264 encoder, the writer
falls back to OpenCV's MPEG-4 Part 2 (``mp4v``) with a warning. Frames go to a hidden temporary
file beside the target, renamed into place by ``close()``: an interrupted run never leaves a
half-written video under the real name (the temporary file is made and moved by
``weather_gym.core._io``: an unpredictable name, ``O_EXCL``, fsync, one rename). Nothing a user wrote is
overwritten unless they say so (``overwrite=True``).

Example:
    >>> import numpy as np, tempfile, pathlib
    >>> from weather_gym.viz.video import VideoWriter, save_strip
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with VideoWriter(d / "lap.mp4", fps=30) as video:
    ...     for k in range(5): video.write(np.full((48, 64, 3), 40 * k, np.uint8))
    >>> video.frames, video.codec, (d / "lap.mp4").stat().st_size > 0
    (5, 'h264', True)
    >>> save_strip([np.zeros((48, 64, 3), np.uint8)] * 4, d / "strip.png").name
    'strip.png'
"""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

from weather_gym.core._image_files import opencv_name
from weather_gym.core._io import atomic_path, check_output, write_failure, write_image
from weather_gym.core.errors import InputError, MissingDependencyError, OutputPathError

__all__ = ["check_output_path", "h264_available", "VideoWriter", "FrameSampler", "save_strip"]

H264_OPTIONS = {"crf": "23", "preset": "veryfast", "movflags": "+faststart"}
"""libx264 settings: visually clean at a few hundred kB per lap, fast enough to write while driving."""


def check_output_path(path: str | os.PathLike, *, overwrite: bool = False, suffixes: Sequence[str] = ()) -> Path:
    """``path`` as a Path, after :func:`weather_gym.core._io.check_output` (suffix, no overwrite unless asked)."""
    return check_output(path, overwrite=overwrite, suffixes=suffixes)


def h264_available() -> bool:
    """True when PyAV is installed and its FFmpeg can encode H.264 (libx264)."""
    try:
        import av
    except ImportError:
        return False
    return "libx264" in av.codecs_available


class _AvStream:
    """H.264 in MP4 through PyAV."""

    codec = "h264"

    def __init__(self, path: Path, fps: float, size: tuple[int, int]) -> None:
        self._container = av.open(opencv_name(path, what="video"), mode="w", format="mp4", options={"movflags": H264_OPTIONS["movflags"]})
        rate = Fraction(fps).limit_denominator(1001)
        self._stream = self._container.add_stream("libx264", rate=rate)
        # yuv420p needs even sizes: odd frames get one replicated edge row/column
        self._pad = (size[1] % 2, size[0] % 2)
        self._stream.width, self._stream.height = size[0] + self._pad[1], size[1] + self._pad[0]
        self._stream.pix_fmt = "yuv420p"
        self._stream.options = {k: v for k, v in H264_OPTIONS.items() if k != "movflags"}
        self._av = av

    def write(self, rgb: np.ndarray) -> None:
        if any(self._pad):
            rgb = np.pad(rgb, ((0, self._pad[0]), (0, self._pad[1]), (0, 0)), mode="edge")
        frame = self._av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
        for packet in self._stream.encode(frame):
            self._container.mux(packet)

    def close(self) -> None:
        try:
            for packet in self._stream.encode():  # flush the encoder
                self._container.mux(packet)
        except BaseException:
            self.abandon()
            raise
        container, self._container = self._container, None  # type: ignore[assignment]  # None once closed
        container.close()

    def abandon(self) -> None:
        """Give the file up after a failed write: no encoder flush and no second try at the trailer
        (FFmpeg's close after a write error on a full disk is where it crashed); errors are ignored."""
        container, self._container = self._container, None  # type: ignore[assignment]  # None once given up
        if container is not None:
            with contextlib.suppress(Exception):
                container.close()


class _Mp4vStream:
    """MPEG-4 Part 2 through OpenCV (the fallback: most browsers will not play it)."""

    codec = "mp4v"

    def __init__(self, path: Path, fps: float, size: tuple[int, int]) -> None:
        self._writer = cv2.VideoWriter(opencv_name(path, what="video"), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)  # type: ignore[attr-defined]  # not in cv2's stubs
        if not self._writer.isOpened():
            raise OutputPathError(f"OpenCV could not open {path} for writing (mp4v codec)")

    def write(self, rgb: np.ndarray) -> None:
        self._writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))

    def close(self) -> None:
        self._writer.release()

    def abandon(self) -> None:
        with contextlib.suppress(Exception):
            self._writer.release()


MIN_FREE_BYTES = 4 << 20
"""A video is not started on a file system with less free space than this (a clear error, not a
failure in the encoder)."""


def check_free_space(folder: str | os.PathLike, what: str, need: int = MIN_FREE_BYTES) -> None:
    """Refuse (:class:`OutputPathError`) to start writing ``what`` into ``folder`` with under ``need`` bytes free."""
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):  # no statvfs (Windows) or the folder is not there yet: the write will tell
        return
    free = st.f_bavail * st.f_frsize
    if free < need:
        raise OutputPathError(f"cannot write {what}: no space left on the device of {folder} "
                              f"({free / 1e6:.1f} MB free, a video needs at least {need / 1e6:.0f} MB)")


class VideoWriter:
    """An MP4 file written frame by frame (RGB uint8, all frames the size of the first).

    ``codec``: ``"h264"`` (PyAV) or ``"mp4v"`` (the OpenCV fallback, with a warning); ``"auto"``
    (default) picks H.264 when it is available. The file appears under ``path`` on ``close()``.
    """

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, *, overwrite: bool = False,
                 codec: str = "auto") -> None:
        if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
            raise InputError(f"video fps must be a finite number > 0, got {fps!r}")
        if codec not in ("auto", "h264", "mp4v"):
            raise InputError(f"video codec must be 'auto', 'h264' or 'mp4v', got {codec!r}")
        self.path = check_output_path(path, overwrite=overwrite, suffixes=(".mp4",))
        self.overwrite = overwrite
        self.fps = float(fps)
        if codec == "auto":
            codec = "h264" if h264_available() else "mp4v"
            if codec == "mp4v":
                warnings.warn("PyAV with an H.264 encoder is not installed (pip install av): writing "
                              f"{self.path} as MPEG-4 Part 2, which browsers may not play", RuntimeWarning,
                              stacklevel=2)
        elif codec == "h264" and not h264_available():
            raise MissingDependencyError("H.264 video needs PyAV with libx264: pip install av")
        self.codec = codec
        self._output: contextlib.AbstractContextManager[Path] | None = None
        self._stream: _AvStream | _Mp4vStream | None = None
        self._size: tuple[int, int] | None = None
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        f = np.asarray(frame)
        if f.dtype != np.uint8 or f.ndim != 3 or f.shape[2] != 3:
            raise InputError(f"video frames must be RGB uint8 (H, W, 3), got {f.dtype} {f.shape}")
        size = (f.shape[1], f.shape[0])
        if self._stream is None:
            cls = _AvStream if self.codec == "h264" else _Mp4vStream
            check_free_space(self.path.parent if self.path.parent.exists() else Path("."), str(self.path))
            self._output = atomic_path(self.path, overwrite=self.overwrite)
            tmp = self._output.__enter__()
            try:
                self._stream = cls(tmp, self.fps, size)
            except BaseException as exc:
                output, self._output = self._output, None
                output.__exit__(type(exc), exc, exc.__traceback__)
                raise write_failure(self.path, exc) from None
            self._size = size
        elif size != self._size:
            raise InputError(f"video frame size changed from {self._size} to {size}")
        try:
            self._stream.write(f)
        except BaseException as exc:  # a full disk: give the file up now, with a typed error
            self._drop()
            raise write_failure(self.path, exc) from None
        self.frames += 1

    def _drop(self) -> None:
        """Abandon the stream and remove its temporary file (``path`` is left as it was)."""
        stream, self._stream = self._stream, None
        output, self._output = self._output, None
        if stream is not None:
            stream.abandon()
        if output is not None:
            output.__exit__(_Discarded, _Discarded(), None)

    def close(self) -> None:
        """Finish the file and move it to ``path`` (nothing is written when no frame was)."""
        if self._stream is not None:
            stream, self._stream = self._stream, None
            output, self._output = self._output, None
            assert output is not None  # opened with the stream
            try:
                stream.close()
            except BaseException as exc:
                output.__exit__(_Discarded, _Discarded(), None)  # the temporary file is removed
                raise write_failure(self.path, exc) from None
            output.__exit__(None, None, None)

    def abort(self) -> None:
        """Drop the partial file; ``path`` is left as it was."""
        self._drop()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()  # a run that stopped early still leaves a playable video of what it recorded


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
