"""``weather-gym degrade INPUT OUTPUT``: weather as a post-process on an image, a folder or a video.

The study's offline mode: existing recordings or datasets get the same weather the simulator gets.

Examples:
    weather-gym degrade frame.png frame_wet.png --weather droplets:0.55
    weather-gym degrade images/ images_dusk/ --weather low_light@3 --seed 1
    weather-gym degrade lap.mp4 lap_wet.mp4 --weather droplets:0.55:persistent=true
    weather-gym degrade dataset/images out/images --weather fog:0.5 --depth dataset/depth
    weather-gym degrade run_0412/ run_0412_wet/ --topic /zed/left/image_raw --weather droplets@3

* INPUT: an image (.png .jpg .jpeg .bmp .tif .tiff .webp), a folder (its images, recursively) or a
  video (.mp4 .avi .mov .mkv .m4v .webm). Output names mirror the input names (a folder's tree is
  rebuilt under OUTPUT; an existing folder as OUTPUT of a file receives a file of the same name).
* The input is never written to. An existing output file is an error unless ``--overwrite``; for a
  folder, outputs that already exist are skipped, so an interrupted run resumes where it stopped.
  Files are written to a fresh temporary file first, then renamed (``weather_gym.core._io``). An
  unreadable image in a folder stops the run, naming it, unless ``--skip-unreadable``.
* Randomness: each image gets its own generator from ``--seed`` and its relative path (so the
  result does not depend on the order or on resuming); a video is one episode from ``--seed``.
* Frames that are not 8-bit colour are read as 8-bit RGB, and a note on stderr says so: a grey frame
  is copied into R, G and B, an alpha channel is dropped (not composited), 16 bits per channel become 8
  (a PNG's high byte); the output is 8-bit RGB.
* ``--depth``: metric depth as uint16 PNG in millimetres (the dataset layout), a file for an
  image or a folder mirroring the input folder (same relative names, .png).
* A ROS bag (a rosbag2 folder with metadata.yaml, a .mcap or .db3 file, a ROS 1 .bag) becomes a bag of
  the same kind with the camera ``--topic`` weathered frame by frame (one episode: persistent drops
  stay), motion effects fed from its nav_msgs/Odometry, every other topic copied byte for byte with its
  timestamps and QoS; written to a temporary folder and moved into place when complete (docs/ros.md).

A command line parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['degrade', 'frames/', 'out/', '--weather', 'droplets:0.55,dim:0.3', '--seed', '1'])
    >>> str(args.input), str(args.output), args.weather, args.seed
    ('frames', 'out', 'droplets:0.55,dim:0.3', 1)
"""

from __future__ import annotations

import os
import sys
import zlib
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from weather_gym.cli._presets_arg import add_presets_arg, presets_from_arg
from weather_gym.cli._seed_arg import seed_arg
from weather_gym.core._image_files import (
    CONVERSIONS,
    colour_conversions,
    conversion_note,
    opencv_name,
    read_image_file,
    shown,
)
from weather_gym.core._io import atomic_path, check_output, declare_inputs, write_image
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError, OutputPathError
from weather_gym.core.limits import check_image_size
from weather_gym.lab.calibration.resolve import Scenario
from weather_gym.lab.datasets.coco import read_image
from weather_gym.ros.bags import bag_kind
from weather_gym.ros.degrade import degrade_bag
from weather_gym.viz.video import VideoWriter, check_free_space
from weather_gym.weather import to_spec, weather_source
from weather_gym.weather.option import add_weather_arg, weather_from_arg
from weather_gym.weather.presets import presets_meaning

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
VIDEO_EXTS = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm")
_FOURCC = {".avi": "MJPG", ".mkv": "MJPG"}


def register(sub) -> None:
    p = sub.add_parser("degrade", help="apply weather to an image, a folder of images or a video",
                       description=__doc__.split("\n\n")[1])
    p.add_argument("input", type=Path, help="image file, folder of images, or video file")
    p.add_argument("output", type=Path, help="output file or folder (names mirror the input)")
    add_weather_arg(p, help="the weather to apply (required)")
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed (default %(default)s)")
    add_presets_arg(p)
    p.add_argument("--reference", type=Path, default=None, metavar="DIR",
                   help="with --presets resolved: a clear COCO recording of the scenario these images come from "
                        "(same camera and scene), on which the presets are resolved for the shipped detector")
    p.add_argument("--depth", type=Path, help="depth PNG (uint16 mm) or folder of them mirroring INPUT")
    add_overwrite_arg(p)
    ros = p.add_argument_group("ROS bags (docs/ros.md)")
    ros.add_argument("--topic", default=None, help="the camera topic to weather (default: the bag's only image topic)")
    ros.add_argument("--odometry", default=None, metavar="TOPIC",
                     help="nav_msgs/Odometry topic giving speed and yaw rate to the motion effects (default: the "
                          "bag's only one, if any; '' for none)")
    ros.add_argument("--jpeg-quality", type=int, default=95, metavar="Q",
                     help="JPEG quality of re-encoded CompressedImage frames (default %(default)s)")
    p.add_argument("--skip-unreadable", action="store_true",
                   help="in a folder, skip images that cannot be read (listed at the end) instead of stopping")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _same(a: Path, b: Path) -> bool:
    return a.resolve() == b.resolve()


def _target(src: Path, output: Path) -> Path:
    return output / src.name if output.is_dir() else output


def _read_rgb(path: Path):
    return read_image(path)


def _read_depth(path: Path, shape):
    raw = read_image_file(path, cv2.IMREAD_UNCHANGED) if path.is_file() else None
    if raw is None or raw.ndim != 2:
        raise FileFormatError(f"{path}: expected a single-channel uint16 depth PNG in millimetres")
    if raw.shape != tuple(shape[:2]):
        raise InputError(f"{path}: depth is {raw.shape[1]}x{raw.shape[0]}, the image {shape[1]}x{shape[0]}")
    return raw.astype(np.float32) / np.float32(1000.0)




def _image_seed(seed: int, rel: Path):
    return np.random.SeedSequence(seed, spawn_key=(zlib.crc32(os.fsencode(rel.as_posix())),))


def _one_image(weather, src: Path, dst: Path, depth: Path | None, seed: int, rel: Path,
               overwrite: bool) -> tuple[str, ...]:
    """Degrade one image; returns the conversions reading it as 8-bit RGB made (``colour_conversions``)."""
    img = _read_rgb(src)
    check_image_size(img.shape, what=str(src))
    d = _read_depth(depth, img.shape) if depth is not None else None
    write_image(dst, weather.start(_image_seed(seed, rel))(img, depth=d), overwrite=overwrite)
    return colour_conversions(src)


def _folder(weather, args) -> int:
    src_root, out_root = args.input, args.output
    if _same(src_root, out_root) or out_root.resolve().is_relative_to(src_root.resolve()):
        raise InputError(f"{out_root}: the output folder must not be the input folder or inside it")
    if out_root.exists() and not out_root.is_dir():
        raise OutputPathError(f"{out_root}: exists and is not a folder")
    files = sorted(p for p in src_root.rglob("*") if p.is_file() and p.suffix.lower() in IMAGE_EXTS)
    if not files:
        raise MissingInputError(f"{src_root}: no images ({', '.join(IMAGE_EXTS)}) found")
    done = skipped = 0
    unreadable: list[str] = []
    converted: Counter = Counter()
    n_converted = 0
    for src in tqdm(files, desc="degrade", unit="img", disable=args.quiet):
        rel = src.relative_to(src_root)
        dst = out_root / rel
        if dst.exists() and not args.overwrite:
            skipped += 1
            continue
        depth = None
        if args.depth is not None:
            depth = args.depth / rel.with_suffix(".png")
            if not depth.is_file():
                raise MissingInputError(f"{depth}: no depth map for {src}")
        try:
            conv = _one_image(weather, src, dst, depth, args.seed, rel, args.overwrite)
            converted.update(conv)
            n_converted += bool(conv)
        except FileFormatError as exc:
            if not args.skip_unreadable:
                raise FileFormatError(f"{exc} (pass --skip-unreadable to skip such images; {done} written so far, "
                                      "a rerun resumes)") from None
            unreadable.append(str(rel))
            continue
        done += 1
    print(f"wrote {done} image(s) to {out_root}" + (f", skipped {skipped} that already existed" if skipped else ""))
    if converted:
        print(conversion_note({k: converted[k] for k in CONVERSIONS}, f"{n_converted} image(s)")
              + "; their outputs are 8-bit RGB", file=sys.stderr)
    if unreadable:
        shown = ", ".join(unreadable[:10]) + (f" and {len(unreadable) - 10} more" if len(unreadable) > 10 else "")
        print(f"skipped {len(unreadable)} unreadable image(s): {shown}")
    return 0


class _Cv2Video:
    """Non-MP4 outputs (.avi, .mkv, ...) through OpenCV, to a temporary file moved into place on close."""

    def __init__(self, dst: Path, fps: float, size: tuple[int, int], overwrite: bool) -> None:
        check_free_space(dst.parent if dst.parent.exists() else Path("."), str(dst))  # OpenCV fails silently
        self._cv2 = cv2
        self._dst = dst
        self._frames = 0
        self._output = atomic_path(dst, overwrite=overwrite)
        tmp = self._tmp = self._output.__enter__()
        fourcc = cv2.VideoWriter_fourcc(*_FOURCC.get(dst.suffix.lower(), "mp4v"))  # type: ignore[attr-defined]  # not in cv2's stubs
        self.writer = cv2.VideoWriter(opencv_name(tmp, what="OUTPUT video"), fourcc, fps, size)
        if not self.writer.isOpened():
            self.abort()
            raise OutputPathError(f"{dst}: OpenCV cannot write a {dst.suffix} video here")

    def write(self, rgb) -> None:
        self.writer.write(self._cv2.cvtColor(rgb, self._cv2.COLOR_RGB2BGR))
        self._frames += 1

    def close(self) -> None:
        self.writer.release()
        cap = self._cv2.VideoCapture(opencv_name(self._tmp, what="OUTPUT video"))  # OpenCV's writer drops failed writes without a word
        try:
            n = int(cap.get(self._cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
        finally:
            cap.release()
        if n != self._frames:
            self._output.__exit__(InputError, InputError("incomplete"), None)
            raise OutputPathError(f"cannot write {self._dst}: the video holds {n} of {self._frames} frames "
                                  "(disk full or a file size limit?)")
        self._output.__exit__(None, None, None)

    def abort(self) -> None:
        self.writer.release()
        self._output.__exit__(InputError, InputError("aborted"), None)


def _video(weather, src: Path, dst: Path, args) -> int:
    opencv_name(dst, what="OUTPUT video")  # before anything is opened or written
    cap = cv2.VideoCapture(opencv_name(src, what="video"))
    try:
        if not cap.isOpened():
            raise FileFormatError(f"{src}: OpenCV cannot open this video")
        fps = cap.get(cv2.CAP_PROP_FPS)
        fps = fps if 0 < fps < 1000 else 30.0
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        check_image_size((h, w, 3), what=f"video {src}")
        total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        if dst.suffix.lower() == ".mp4":  # H.264 (PyAV), falling back to mp4v with a warning
            writer: VideoWriter | _Cv2Video = VideoWriter(dst, fps=fps, overwrite=args.overwrite)
        else:
            writer = _Cv2Video(dst, fps, (w, h), args.overwrite)
        run = weather.start(args.seed)  # the video is one episode
        n = 0
        try:
            with tqdm(total=total, desc="degrade", unit="frame", disable=args.quiet) as bar:
                while True:
                    ok, bgr = cap.read()
                    if not ok:
                        break
                    writer.write(run(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)))
                    n += 1
                    bar.update(1)
        except BaseException:
            writer.abort()
            raise
        if n == 0:
            writer.abort()
            raise FileFormatError(f"{src}: no frames could be read")
        writer.close()
    finally:
        cap.release()
    print(f"wrote {n} frame(s) to {dst}")
    return 0


def _bag(weather, args) -> int:
    if args.depth is not None:
        raise InputError("--depth is not supported for ROS bags")
    r = degrade_bag(args.input, args.output, weather=weather, topic=args.topic, odometry=args.odometry,
                    seed=args.seed, jpeg_quality=args.jpeg_quality, overwrite=args.overwrite, progress=not args.quiet)
    span = "" if r.first_ns is None or r.last_ns is None else f", {(r.last_ns - r.first_ns) / 1e9:.3f} s"
    print(f"wrote {r.out} ({r.kind}, {r.storage}): {r.frames} frame(s) of {r.topic} weathered{span}; "
          f"{sum(r.copied.values())} other message(s) copied unchanged"
          + (f" ({', '.join(f'{t} {n}' for t, n in sorted(r.copied.items()))})" if r.copied else ""))
    print(f"motion effects: speed and yaw rate from {r.odometry}" if r.odometry else
          "motion effects: no odometry topic, their documented defaults")
    for t, why in r.left_out.items():
        print(f"left out {t}: {why}")
    return 0


def _presets(args):
    """``--presets`` of degrade: resolved on ``--reference DIR`` (the default with one), else the pool or a file."""
    choice = args.presets
    if choice is None and args.reference is not None and presets_meaning() == "resolved":
        choice = "resolved"  # the default: resolved on the clear recording given; without one (no scenario), the pool
    if args.reference is not None and choice != "resolved":
        raise InputError("--reference is the clear recording presets are resolved on; it goes with --presets resolved "
                         "(the default unless WEATHER_GYM_PRESETS says otherwise)")
    if choice == "resolved" and args.reference is None:
        raise InputError("--presets resolved needs --reference DIR: a clear COCO recording of the scenario to resolve on")
    presets = presets_from_arg(choice, None if args.reference is None else
                               (lambda: Scenario(dataset=str(args.reference))), progress=not args.quiet)
    return presets


def _run(args) -> int:
    if args.weather is None:
        raise InputError("give the weather with --weather SPEC (e.g. droplets:0.55, low_light@2 or "
                         "droplets:0.55,dim:0.3)")
    presets = _presets(args)
    weather = weather_from_arg(args.weather, presets=presets)
    source = weather_source(args.weather, presets)
    if source != "given" and weather is not None:
        ks = ", ".join(f"{t['name']}={t['k']:.3f}" for t in to_spec(weather) if "k" in t)
        print(f"weather {args.weather}: k {ks} ({source}" + (f": {presets})" if presets is not None and source != "pool" else ")"))
    src = args.input
    declare_inputs(src, args.depth)
    if not src.exists():
        raise MissingInputError(f"{src}: no such file or folder")
    if bag_kind(src) is not None:
        return _bag(weather, args)
    ros_flags = [f for f, v in (("--topic", args.topic), ("--odometry", args.odometry)) if v is not None]
    if ros_flags:
        raise InputError(f"{', '.join(ros_flags)} go with a ROS bag; {src} is not one (a rosbag2 folder with "
                         "metadata.yaml, a .mcap, .db3 or .bag file)")
    if src.is_dir():
        if args.depth is not None and not args.depth.is_dir():
            raise InputError(f"--depth {args.depth}: must be a folder when INPUT is a folder")
        return _folder(weather, args)
    ext = src.suffix.lower()
    if ext not in IMAGE_EXTS + VIDEO_EXTS:
        raise InputError(f"{src}: unknown kind of file; expected an image ({', '.join(IMAGE_EXTS)}), "
                         f"a video ({', '.join(VIDEO_EXTS)}) or a folder")
    dst = _target(src, args.output)
    if _same(src, dst):
        raise InputError(f"{dst}: the output would overwrite the input")
    kind = VIDEO_EXTS if ext in VIDEO_EXTS else IMAGE_EXTS
    check_output(dst, overwrite=args.overwrite, suffixes=kind, what="OUTPUT")
    if ext in VIDEO_EXTS:
        if args.depth is not None:
            raise InputError("--depth is not supported for videos")
        return _video(weather, src, dst, args)
    converted = _one_image(weather, src, dst, args.depth, args.seed, Path(src.name), args.overwrite)
    print(f"wrote {dst}")
    if converted:
        print(conversion_note(converted, shown(src)) + "; the output is 8-bit RGB", file=sys.stderr)
    return 0
