"""What an import reads from a source folder, whatever its format: frames with their label boxes, and
the helpers every reader shares (finding images and their label files, checking boxes, a frame's size).

Example:
    >>> from weather_gym.lab.datasets.import_frames import check_box, is_image
    >>> is_image(Path("frame_0001.JPG")), check_box(1, 2, 11, 22, "demo.txt:1")
    (True, (1, 2, 11, 22))
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
from PIL import Image

from weather_gym.core._confine import confined_file, walk_files
from weather_gym.core._image_files import read_image_file
from weather_gym.core.errors import FileFormatError, LimitError, MissingInputError
from weather_gym.core.limits import MAX_IMAGE_PIXELS, check_image_size

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp")


@dataclass
class LabelBox:
    cls: str
    box: tuple[float, float, float, float]  # xyxy pixels
    where: str
    range: float = math.nan
    bearing: float = math.nan
    crowd: bool = False
    location: tuple[float, float, float] | None = None
    size3d: tuple[float, float] | None = None  # KITTI (h, w) in metres


@dataclass
class SourceFrame:
    image: Path  # the resolved file (confined to the source folder)
    rel: str  # where it goes under OUT/images/
    source_file: str = ""  # the path under the source folder, as found there
    boxes: list[LabelBox] = field(default_factory=list)
    only3d: list[tuple[str, tuple[float, float, float], tuple[float, float, float], str]] = field(default_factory=list)
    intrinsics: dict[str, float] | None = None
    size: tuple[int, int] = (0, 0)
    stated_size: tuple[int, int] | None = None  # (w, h) the labels state (COCO, Supervisely)
    label: Path | None = None  # the label file, for the resume identity


@dataclass
class SourceRead:
    """What a reader found: frames, counts of rows left out, label files without an image, the layout."""

    frames: list[SourceFrame]
    stats: Counter = field(default_factory=Counter)
    unmatched: list[str] = field(default_factory=list)
    layout: str = ""


def find_dir(src: Path, names: Sequence[str], what: str, required: bool = True) -> Path | None:
    for n in names:
        if (src / n).is_dir():
            return src / n
    if required:
        raise MissingInputError(f"{src}: no {what} folder (looked for {', '.join(n + '/' for n in names)})")
    return None


def is_image(p: Path) -> bool:
    return p.suffix.lower() in IMAGE_EXTS


def images_under(folder: Path, root: Path) -> list[Path]:
    files = [p for p in walk_files(folder, root) if is_image(p)]
    if not files:
        raise MissingInputError(f"{folder}: no images ({', '.join(IMAGE_EXTS)})")
    return files


def rel_path(path: Path, base: Path) -> str:
    return path.relative_to(base).as_posix()


def check_box(x1: float, y1: float, x2: float, y2: float, where: str) -> tuple[float, float, float, float]:
    if not all(math.isfinite(v) for v in (x1, y1, x2, y2)):
        raise FileFormatError(f"{where}: box ({x1}, {y1}, {x2}, {y2}) is not finite")
    if x2 <= x1 or y2 <= y1:
        raise FileFormatError(f"{where}: box ({x1:g}, {y1:g}, {x2:g}, {y2:g}) is empty or inverted (expected x1 < x2, y1 < y2)")
    return (x1, y1, x2, y2)


def parse_floats(parts: Sequence[str], where: str, what: str) -> list[float]:
    try:
        return [float(v) for v in parts]
    except ValueError:
        raise FileFormatError(f"{where}: expected numbers for {what}, got {' '.join(parts)!r}") from None


def source_frame(img: Path, rel: str, src: Path) -> SourceFrame:
    """A frame for the image ``img`` found under ``src``: resolved inside it (a link out is refused)."""
    return SourceFrame(confined_file(img, src), rel, rel_path(img, src))


def labelled_frames(images: Path, labels: Path, src: Path, fmt: str, *, unmatched: list[str]) -> Iterator[tuple[Path, SourceFrame]]:
    """Each image under ``images`` with its label file (mirrored under ``labels``, ``.txt``) and a new frame;
    label files without an image are added to ``unmatched``."""
    imgs = images_under(images, src)
    stems = {p.relative_to(images).with_suffix("") for p in imgs}
    unmatched += [rel_path(p, src) for p in walk_files(labels, src)
                  if p.suffix == ".txt" and p.relative_to(labels).with_suffix("") not in stems]
    check_one_image_per_label(imgs, [(labels / img.relative_to(images)).with_suffix(".txt") for img in imgs])
    for img in imgs:
        lab = (labels / img.relative_to(images)).with_suffix(".txt")
        if not lab.is_file():
            raise MissingInputError(f"{img}: its {fmt} label file {lab} is missing (every image needs one; an "
                                    "empty file means no cones)")
        fr = source_frame(img, rel_path(img, images), src)
        fr.label = lab
        yield lab, fr


def check_one_image_per_label(images: Sequence[Path], labels: Sequence[Path]) -> None:
    """Refuse two images that would take their boxes from one label file (``a.jpg`` and ``a.png`` beside
    ``a.txt``): a label file describes one image, so one of them would get boxes that are not its own."""
    seen: dict[Path, Path] = {}
    for img, lab in zip(images, labels, strict=True):
        if lab in seen:
            raise FileFormatError(f"{seen[lab]} and {img} share the label file {lab}, which describes one image; "
                                  "give each image its own label file (same name, .txt) or remove one")
        seen[lab] = img


_GREY_MODES = frozenset({"1", "L", "LA", "I", "I;16", "I;16B", "I;16L", "F"})
"""Pillow modes of single-channel frames (refused: the detector and the effects take colour frames)."""


def image_size(fr: SourceFrame, src: Path) -> tuple[int, int]:
    """(width, height) of a frame as every reader decodes it (an EXIF rotation applied, as labelling tools
    show it): the header is read first and the size bound checked (:func:`~weather_gym.core.limits.check_image_size`)
    before the frame is decoded."""
    where = fr.image if not fr.source_file else src / fr.source_file
    mode = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(fr.image) as im:
                (w, h), mode = im.size, im.mode
                if im.getexif().get(0x0112) in (5, 6, 7, 8):  # EXIF orientation: turned by 90 degrees
                    w, h = h, w
    except Image.DecompressionBombError:
        raise LimitError(f"{where}: image is larger than {MAX_IMAGE_PIXELS / 1e6:.0f} MP (the most supported)") from None
    except (OSError, SyntaxError, ValueError):
        w = h = None  # not a format Pillow reads: OpenCV decides below
    if w is not None:
        check_image_size((h, w), what=str(where))
    if mode is None:  # Pillow could not tell the channels: OpenCV's undecorated decode does
        raw = read_image_file(fr.image, cv2.IMREAD_UNCHANGED)
        channels = None if raw is None or raw.size == 0 else (1 if raw.ndim == 2 else raw.shape[2])
    else:
        channels = 1 if mode in _GREY_MODES else 3
    if channels is not None and channels not in (3, 4):
        raise FileFormatError(f"image file {where} has {channels} channel(s); expected colour (RGB) frames")
    img = read_image_file(fr.image, cv2.IMREAD_COLOR)  # as weather_gym.lab.datasets.coco.read_image decodes it
    if img is None or img.size == 0:
        raise FileFormatError(f"image file {where} could not be decoded as an image")
    check_image_size(img.shape, what=str(where))
    return int(img.shape[1]), int(img.shape[0])
