"""Any detector, one protocol: ``frame -> Detections``; :func:`load_detector` picks one from a spec.

A :class:`Detector` is anything called with an RGB uint8 frame ``(H, W, 3)`` that returns
:class:`~weather_gym.perception.onnx_detector.Detections` (boxes xyxy in the frame's pixels, scores,
classes as indices into ``CONE_CLASSES``). :func:`as_detector` gives any such callable what the rest
of weather-gym uses (``detect_batch``, ``score_threshold``, ``input_size`` for the too-small rule).

Specs (the CLI's ``--detector``, :func:`load_detector`):

=======================  ====================================================================
``None`` / ``conenet``   the ONNX cone detector shipped in the package (``ConeDetector``)
``conenet:PATH``         another ConeNet export (or a bare ``PATH.onnx``)
``yolov8:PATH``          a YOLOv8 / v11 ONNX export: output ``(1, 4+nc, N)`` (or NMS in the graph)
``yolov5:PATH``          a YOLOv5 ONNX export: output ``(1, N, 5+nc)`` (or NMS in the graph)
``yolo:PATH``            a YOLO-family export, layout recognised from its outputs
a ``Detector`` object    used as it is
=======================  ====================================================================

YOLO options: ``classes`` (``"0=blue,1=yellow,2=orange,3=big_orange,4=ignore"``, by output index or
class name; default: the export's class names mapped like a dataset import), ``resize``
(``letterbox``, the default, or ``stretch``), ``input_size`` (for exports with a dynamic input),
``score_threshold``, ``nms_iou``. See :mod:`weather_gym.perception.yolo`.

ConeNet option: ``input_size`` -- by default the shipped model's input follows the camera
(:func:`~weather_gym.perception.onnx_detector.input_size_for`: 672x376 -> 512x288, 336x188 -> 256x160,
never above 512x288); ``"native"`` pins it at the model's native 512x288 (every frame letterboxed
into it), ``(W, H)`` / ``"WxH"`` at that size (sides multiples of 32, up to 3136).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.detector_spec import load_detector, as_detector
    >>> det = load_detector("conenet")                  # the shipped model
    >>> det.input_size, det.resize, det.follow, det.input_size_for(336, 188)
    ((512, 288), 'letterbox', True, (256, 160))
    >>> from weather_gym.perception import Detections
    >>> mine = as_detector(lambda frame: Detections())  # your own function frame -> Detections
    >>> len(mine(np.zeros((40, 60, 3), np.uint8))), mine.score_threshold
    (0, 0.3)
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError, MissingInputError
from weather_gym.core.limits import check_image_size, parse_size
from weather_gym.perception.onnx_detector import (
    DEFAULT_MODEL,
    ConeDetector,
    Detections,
    check_frame,
    parse_input_size,
)
from weather_gym.perception.protocol import Detector, DetectorBase
from weather_gym.perception.yolo import YoloDetector

__all__ = ["Detector", "DetectorBase", "CallableDetector", "DetectorSpec", "KINDS", "as_detector", "load_detector",
           "parse_detector_spec", "detector_id"]

KINDS = ("conenet", "yolov8", "yolov5", "yolo")
_ALIASES = {"shipped": "conenet", "cone": "conenet", "yolov11": "yolov8", "yolo11": "yolov8", "yolov10": "yolov8"}


class CallableDetector(DetectorBase):
    """A plain function ``frame -> Detections`` (or dict of arrays) as a full detector."""

    def __init__(self, fn: Callable[[np.ndarray], Any], *, score_threshold: float = 0.3,
                 input_size: tuple[int, int] | None = None, name: str | None = None) -> None:
        self.fn = fn
        self.score_threshold = float(score_threshold)
        self.input_size = input_size
        self.name = name or getattr(fn, "__name__", type(fn).__name__)  # type: ignore[assignment]  # a str either way

    def detect_batch(self, images, score_threshold: float | None = None) -> list[Detections]:
        thr = self.score_threshold if score_threshold is None else float(score_threshold)
        out = []
        for i, im in enumerate(list(images)):
            d = self.fn(check_frame(im, f"frame {i}"))
            if isinstance(d, Mapping):
                d = Detections(np.asarray(d["boxes"], np.float32).reshape(-1, 4),
                               np.asarray(d["scores"], np.float32).reshape(-1),
                               np.asarray(d["classes"], np.int64).reshape(-1))
            if not isinstance(d, Detections):
                raise InputError(f"detector {self.name} returned {type(d).__name__}; expected Detections "
                                 "(boxes, scores, classes)")
            out.append(d.above(thr))
        return out


def as_detector(obj: Any) -> Any:
    """``obj`` with ``detect_batch`` / ``score_threshold`` / ``input_size``: detectors pass through,
    a plain callable ``frame -> Detections`` is wrapped in :class:`CallableDetector`."""
    if hasattr(obj, "detect_batch") and hasattr(obj, "score_threshold"):
        return obj
    if callable(obj):
        return CallableDetector(obj)
    raise InputError(f"expected a detector (a callable frame -> Detections), got {type(obj).__name__}")


@dataclass(frozen=True)
class DetectorSpec:
    """A detector by description (picklable: sweep cells and gap runs carry it to worker processes)."""

    kind: str = "conenet"
    path: str | None = None
    classes: str | None = None
    resize: str | None = None
    input_size: tuple[int, int] | str | None = None
    score_threshold: float | None = None

    def __str__(self) -> str:
        s = self.kind if self.path is None else f"{self.kind}:{self.path}"
        opts = [f"{k}={v}" for k, v in (("classes", self.classes), ("resize", self.resize),
                                         ("input", self.input_size if self.input_size is None or isinstance(self.input_size, str)
                                          else "x".join(map(str, self.input_size))),
                                         ("threshold", self.score_threshold)) if v is not None]
        return s + (f" ({', '.join(opts)})" if opts else "")

    def load(self, threads: int = 1) -> Any:
        if self.kind == "conenet":
            if self.classes is not None or self.resize not in (None, "letterbox"):
                raise InputError(f"detector {self}: classes and resize are options of YOLO detectors; "
                                 "the ConeNet detector has its own (from its sidecar JSON)")
            return ConeDetector(self.path, threads=threads, score_threshold=self.score_threshold,
                                input_size=self.input_size)

        layout = {"yolov8": "v8", "yolov5": "v5", "yolo": "auto"}[self.kind]
        return YoloDetector(self.path, layout=layout, classes=self.classes, resize=self.resize or "letterbox",  # type: ignore[arg-type]  # a YOLO spec has a path
                            input_size=self.input_size, score_threshold=self.score_threshold, threads=threads)  # type: ignore[arg-type]  # and a (w, h) input or None


def parse_detector_spec(spec: str | os.PathLike | DetectorSpec | None, *, classes: str | Mapping | None = None,
                        resize: str | None = None, input_size: tuple[int, int] | str | None = None,
                        score_threshold: float | None = None) -> DetectorSpec:
    """A :class:`DetectorSpec` from ``"kind:PATH"``, a bare ONNX path, or None (the shipped model)."""
    if isinstance(spec, DetectorSpec):
        if (classes, resize, input_size, score_threshold) == (None, None, None, None):
            return spec

        if isinstance(classes, Mapping):
            classes = ",".join(f"{k}={v}" for k, v in classes.items())
        changes: dict[str, Any] = {k: v for k, v in (("classes", classes), ("resize", resize), ("score_threshold", score_threshold))
                   if v is not None}
        if input_size is not None:
            changes["input_size"] = _input_option(spec.kind, input_size)
        return replace(spec, **changes)
    if isinstance(classes, Mapping):
        classes = ",".join(f"{k}={v}" for k, v in classes.items())
    if resize not in (None, "letterbox", "stretch"):
        raise InputError(f"detector resize must be 'letterbox' or 'stretch', got {resize!r}")
    if score_threshold is not None and not 0.0 <= float(score_threshold) <= 1.0:
        raise InputError(f"detector score threshold must be in [0, 1], got {score_threshold}")
    kind, path = ("conenet", None) if spec is None else _kind_and_path(os.fspath(spec))
    if path is not None and not Path(path).is_file():
        raise MissingInputError(f"detector model {path} not found")
    input_size = _input_option(kind, input_size)
    return DetectorSpec(kind, path, classes, resize, input_size,
                        None if score_threshold is None else float(score_threshold))


def _kind_and_path(text: str) -> tuple[str, str | None]:
    """The detector kind and ONNX path named by a spec string (``kind:PATH``, a kind, or a path)."""
    kind, path = "conenet", None
    head, sep, tail = text.partition(":")
    head_l = _ALIASES.get(head.lower(), head.lower())
    if sep and head_l in KINDS:
        kind, path = head_l, tail
        if not path:
            raise InputError(f"detector {text!r}: give the ONNX file after the colon, e.g. {head_l}:model.onnx")
    elif sep and not Path(text).is_file():
        raise InputError(f"detector {text!r}: unknown kind {head!r}; expected conenet, conenet:PATH, yolov8:PATH, "
                         "yolov5:PATH, yolo:PATH or a path to a ConeNet .onnx file")
    elif not sep and head_l in KINDS:
        if head_l != "conenet":
            raise InputError(f"detector {text!r}: a YOLO detector needs its ONNX file, e.g. {head_l}:model.onnx")
    elif text.lower().endswith(".onnx") or Path(text).is_file():
        path = text
    else:
        raise InputError(f"detector {text!r}: expected conenet, conenet:PATH, yolov8:PATH, yolov5:PATH, yolo:PATH "
                         "or a path to a ConeNet .onnx file")
    return kind, path


def _input_option(kind: str, value: tuple[int, int] | str | None) -> tuple[int, int] | str | None:
    """The ``input_size`` option checked: (W, H), ``"native"`` (ConeNet only) or None (ConeNet: follow the camera)."""
    if value is None or (kind == "conenet" and value == "follow"):
        return None
    if isinstance(value, str) and value.lower() in ("follow", "native"):
        if kind != "conenet":
            raise InputError(f"detector input size {value!r} (--detector-input): 'follow' and 'native' are options "
                             "of the ConeNet detector; give a YOLO export's input as WxH, e.g. 640x640")
        return None if value.lower() == "follow" else "native"
    if isinstance(value, str):
        size = _parse_size(value)
    else:
        try:
            size = (int(value[0]), int(value[1]))
        except (TypeError, ValueError, IndexError):
            raise InputError(f"detector input size {value!r} (--detector-input): expected WxH in pixels, "
                             "e.g. 640x640") from None
        _check_input_size(size)
    if kind == "conenet":
        size = parse_input_size(size, what=f"detector input size {size[0]}x{size[1]} (--detector-input)")
    return size


def _parse_size(text: str) -> tuple[int, int]:
    size = parse_size(text, what="detector input size (--detector-input)", example="640x640")
    _check_input_size(size)
    return size


def _check_input_size(size: tuple[int, int]) -> None:
    """The one frame-size bound (``weather_gym.core.limits``) for a YOLO export's input (W, H)."""
    check_image_size((size[1], size[0]), what=f"detector input size {size[0]}x{size[1]} (--detector-input)")


def load_detector(spec: Any = None, *, classes: str | Mapping | None = None, resize: str | None = None,
                  input_size: tuple[int, int] | str | None = None, score_threshold: float | None = None,
                  threads: int = 1) -> Any:
    """A ready detector from a spec (see module doc), a ``DetectorSpec``, or a detector / callable (as is)."""
    if spec is not None and not isinstance(spec, str | os.PathLike | DetectorSpec):
        if classes is not None or resize is not None or input_size is not None:
            raise InputError("classes / resize / input size are options of a detector spec, not of a detector object")
        return as_detector(spec)
    return parse_detector_spec(spec, classes=classes, resize=resize, input_size=input_size,
                               score_threshold=score_threshold).load(threads=threads)


def detector_id(spec: Any) -> str:
    """12 hex digits identifying a detector spec: its model file's SHA-256 and its options."""

    s = parse_detector_spec(spec)
    h = hashlib.sha256()
    with open(s.path or DEFAULT_MODEL, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    if s.kind != "conenet" or s.score_threshold is not None or s.input_size is not None:
        h.update(repr((s.kind, s.classes, s.resize, s.input_size, s.score_threshold)).encode())
    return h.hexdigest()[:12]
