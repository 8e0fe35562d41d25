"""``ConeDetector``: the shipped ONNX cone detector, run by onnxruntime (no torch at run time).

The model file comes with a JSON sidecar (same name, ``.json``) holding the input size, classes,
stride, default score threshold and training metadata; see ``docs/model_card.md``.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception import ConeDetector
    >>> det = ConeDetector(threads=1)
    >>> d = det(np.zeros((376, 672, 3), np.uint8))       # a frame with no cones
    >>> len(d), d.boxes.shape
    (0, (0, 4))
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import pydantic

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.core.limits import MAX_CAMERA_SIDE, check_image_size
from weather_gym.core.schema import ListAsTuple, PositiveInt, Share, validate_table
from weather_gym.perception.preprocess import decode, letterbox

__all__ = ["ConeDetector", "Detections", "DEFAULT_MODEL", "NATIVE_INPUT", "REFERENCE_CAMERA", "INPUT_MULTIPLE",
           "input_size_for", "native_scale", "load_model_metadata"]

DEFAULT_MODEL = Path(__file__).resolve().parent / "models" / "cone_detector.onnx"

NATIVE_INPUT: tuple[int, int] = (512, 288)
"""The shipped model's native input (W, H): the input it was trained at, for its reference camera."""
REFERENCE_CAMERA: tuple[int, int] = (672, 376)
"""The camera (W, H) whose frames fill the native input (672x376 letterboxed x512/672 into 512x288)."""
INPUT_MULTIPLE = 32
"""Every ConeNet input side is a multiple of this: the backbone halves the image five times (stride 32)."""


def parse_input_size(value: Any, *, what: str, multiple: int = INPUT_MULTIPLE,
                     max_side: int = 3136) -> tuple[int, int]:
    """A pinned ConeNet input ``(W, H)`` / ``"WxH"`` checked: each side a multiple of ``multiple`` from
    ``multiple`` to ``max_side``; InputError naming ``what`` otherwise."""
    if isinstance(value, str):
        w, sep, h = value.lower().partition("x")
        size: Any = (w, h) if sep else None
    else:
        size = value
    try:
        wh = (int(size[0]), int(size[1])) if size is not None and len(size) == 2 else None
        if wh is not None and any(float(v) != n for v, n in zip(size, wh, strict=True)):
            wh = None
    except (TypeError, ValueError):
        wh = None
    if wh is None:
        raise InputError(f"{what}: expected 'follow', 'native', (W, H) or 'WxH' in pixels, e.g. 512x288")
    if any(v < multiple or v > max_side or v % multiple for v in wh):
        raise InputError(f"{what}: each side must be a multiple of {multiple} from {multiple} to {max_side} "
                         "(the network halves the image five times), e.g. 512x288")
    return wh


def native_scale(native: tuple[int, int] = NATIVE_INPUT, reference: tuple[int, int] = REFERENCE_CAMERA) -> float:
    """The scale a reference-camera frame is letterboxed at into the native input (512/672 = 0.762)."""
    return min(native[0] / reference[0], native[1] / reference[1])


def _up(n: float, multiple: int) -> int:
    """``n`` rounded up to a multiple of ``multiple`` (at least one)."""
    return max(1, math.ceil(round(n, 6) / multiple)) * multiple


def input_size_for(camera_width: int, camera_height: int, *, native: tuple[int, int] = NATIVE_INPUT,
                   reference: tuple[int, int] = REFERENCE_CAMERA, multiple: int = INPUT_MULTIPLE) -> tuple[int, int]:
    """The detector input (W, H) for frames of ``camera_width`` x ``camera_height`` (the shipped model by default).

    The input follows the camera at the model's native scale (``native`` / ``reference``: 512/672),
    each side rounded *up* to a multiple of ``multiple`` (32) and at most the native side: a camera
    smaller than the reference gets a proportionally smaller input (never scaled below the native
    scale); the reference camera gets exactly the native 512x288; a larger camera gets the native input
    and is letterboxed down into it, as with a pinned input (following a 1280x720 camera up to 992x576
    measured 4.6x slower and less accurate: docs/model_card.md, "Speed"). The letterbox pads the
    remainder. Pin a larger input with ``ConeDetector(input_size=(W, H))``.

    Example:
        >>> from weather_gym.perception.onnx_detector import input_size_for
        >>> input_size_for(672, 376), input_size_for(336, 188), input_size_for(1280, 720)
        ((512, 288), (256, 160), (512, 288))
    """
    for v, what in ((camera_width, "width"), (camera_height, "height")):
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise InputError(f"camera {what} must be a whole number of pixels, got {v!r}")
    w, h = int(camera_width), int(camera_height)
    check_image_size((h, w), what=f"detector input for a {w}x{h} camera")
    return _follow(w, h, native, reference, multiple)


def _follow(w: int, h: int, native: tuple[int, int], reference: tuple[int, int], multiple: int) -> tuple[int, int]:
    """:func:`input_size_for` without the size check (any frame the detector accepts)."""
    scale = native_scale(native, reference)
    return min(native[0], _up(w * scale, multiple)), min(native[1], _up(h * scale, multiple))


@dataclass
class Detections:
    """Detections of one frame, in original image pixels: ``boxes`` (K, 4) xyxy float32,
    ``scores`` (K,) float32, ``classes`` (K,) int64 (index into ``CONE_CLASSES``), best first."""

    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))
    scores: np.ndarray = field(default_factory=lambda: np.zeros((0,), np.float32))
    classes: np.ndarray = field(default_factory=lambda: np.zeros((0,), np.int64))

    def __len__(self) -> int:
        return int(self.scores.shape[0])

    def above(self, score_threshold: float) -> Detections:
        """The detections scoring at least ``score_threshold``."""
        k = self.scores >= score_threshold
        return Detections(self.boxes[k], self.scores[k], self.classes[k])

    def to_dict(self) -> dict[str, np.ndarray]:
        return {"boxes": self.boxes, "scores": self.scores, "classes": self.classes}


def check_frame(image: Any, where: str) -> np.ndarray:
    """``image`` when it is an RGB uint8 ``(H, W, 3)`` array; InputError naming ``where`` otherwise."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        got = f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        raise InputError(f"{where}: expected an RGB uint8 image of shape (H, W, 3), got {got}")
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise InputError(f"{where}: image is empty (shape {image.shape})")
    return image


Side = Annotated[tuple[PositiveInt, PositiveInt], ListAsTuple]


class DetectorSidecar(pydantic.BaseModel):
    """The keys of a detector's JSON sidecar that the runtime reads, declared (any other key, the model's
    provenance, is free); a bad one is a ``FileFormatError`` naming the file, the key, the value and what
    was expected."""

    model_config = pydantic.ConfigDict(strict=True, extra="allow", allow_inf_nan=False)

    classes: Annotated[tuple[Annotated[str, pydantic.Field(min_length=1)], ...], ListAsTuple,
                       pydantic.Field(min_length=1)] = CONE_CLASSES
    stride: PositiveInt = 4
    score_threshold: Share = 0.3
    input_size: Side | None = None
    reference_camera: Side = REFERENCE_CAMERA
    input_multiple: PositiveInt = INPUT_MULTIPLE


def load_model_metadata(model_path: str | os.PathLike) -> dict[str, Any]:
    """The sidecar JSON of ``model_path`` (``{}`` when there is none), checked against
    :class:`DetectorSidecar`; returned as written."""
    side = Path(model_path).with_suffix(".json")
    if not side.is_file():
        return {}
    try:
        with open(side) as f:
            meta = json.load(f)
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"model metadata {side} is not valid JSON: {exc}") from None
    if not isinstance(meta, dict):
        raise FileFormatError(f"model metadata {side} must be a JSON object")
    validate_table(DetectorSidecar, meta, who=f"model metadata {side}", error=FileFormatError)
    return meta


def rebuild_detector(cls: type, kwargs: dict[str, Any]) -> Any:
    """``cls(**kwargs)``: how an ONNX detector is unpickled and deep-copied (``gym.make`` deep-copies its
    keyword arguments; a vector env pickles them): from its constructor arguments, with its own session."""
    return cls(**kwargs)


class ConeDetector:
    """Run the cone detector on RGB uint8 frames.

    Args:
        model: path to an ONNX file (default: the model shipped in the package).
        score_threshold: minimum score of a reported detection (default: the model's, from its sidecar).
        threads: onnxruntime intra-op threads (1 = one CPU core).
        max_detections: at most this many detections per frame, best first.
        nms_iou: IoU of the class-agnostic box NMS after the heatmap peak filter (None = off).
        input_size: the network input. ``None`` / ``"follow"`` (default for a model whose input height
            and width are symbolic, as the shipped one's): it follows each frame's size,
            :meth:`input_size_for` (672x376 -> 512x288, 336x188 -> 256x160, never above the native
            input: 1280x720 -> 512x288), so a small camera is proportionally faster. ``"native"``:
            always the model's native input (512x288, every frame letterboxed into it). ``(W, H)`` or
            ``"WxH"``: always that size; each side a multiple of ``INPUT_MULTIPLE`` (32) from 32 to
            3136 (a 4096-px camera at the native scale).

    Call with one frame ``(H, W, 3)`` -> ``Detections``, or a batch ``(N, H, W, 3)`` / list of
    frames -> ``list[Detections]``. Boxes are in the original frame's pixels. It follows the
    :class:`~weather_gym.perception.detector_spec.Detector` protocol (``resize`` is always ``letterbox``).
    ``input_size`` is the pinned input, or when following the input at the reference camera (the
    native one); ``follow`` says which.
    """

    resize = "letterbox"

    def __init__(
        self,
        model: str | os.PathLike | None = None,
        *,
        score_threshold: float | None = None,
        threads: int = 1,
        max_detections: int = 100,
        nms_iou: float | None = 0.7,
        input_size: tuple[int, int] | str | None = None,
    ) -> None:
        import onnxruntime as ort

        path = Path(model) if model is not None else DEFAULT_MODEL
        if not path.is_file():
            hint = "" if model is not None else " (the package was installed without its model; reinstall weather-gym)"
            raise MissingInputError(f"detector model {path} not found{hint}")
        if not isinstance(threads, int) or threads < 1:
            raise InputError(f"threads must be a positive integer, got {threads!r}")
        if max_detections < 1:
            raise InputError(f"max_detections must be >= 1, got {max_detections}")
        self.path = path
        self.meta = load_model_metadata(path)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types for bad files
            raise InputError(f"detector model {path} could not be loaded by onnxruntime "
                             f"(corrupt or not an ONNX model): {exc}") from None
        self.classes: tuple[str, ...] = tuple(self.meta.get("classes", CONE_CLASSES))
        self.stride = int(self.meta.get("stride", 4))
        inp = self.session.get_inputs()
        outs = self.session.get_outputs()
        if len(inp) != 1 or len(outs) != 1:
            raise InputError(f"detector model {path} must have one input and one output, "
                             f"got {len(inp)} inputs and {len(outs)} outputs")
        shape = inp[0].shape
        if len(shape) != 4 or shape[1] != 3:
            raise InputError(f"detector model {path} has input shape {shape}; expected (batch, 3, H, W)")
        self.input_name = inp[0].name
        self._set_input(path, shape, input_size)
        oshape = outs[0].shape
        nc = len(self.classes)
        if len(oshape) != 4 or oshape[1] != nc + 4:
            raise InputError(f"detector model {path} has output shape {oshape}; expected (batch, {nc + 4}, H/{self.stride}, "
                             f"W/{self.stride}) for {nc} classes")
        self.batch_fixed = shape[0] if isinstance(shape[0], int) else None
        thr = score_threshold if score_threshold is not None else float(self.meta.get("score_threshold", 0.3))
        if not 0.0 <= thr <= 1.0:
            raise InputError(f"score_threshold must be in [0, 1], got {thr}")
        self.score_threshold = float(thr)
        self.max_detections = int(max_detections)
        self.nms_iou = nms_iou
        self.threads = threads
        self.name = f"conenet:{path.name}"
        self._init_kwargs = {"model": str(path), "score_threshold": score_threshold, "threads": threads,
                             "max_detections": max_detections, "nms_iou": nms_iou, "input_size": input_size}

    def _set_input(self, path: Path, shape: list, input_size: tuple[int, int] | str | None) -> None:
        """The native input, the reference camera and the follow / pinned choice (checked)."""
        fixed = (int(shape[3]), int(shape[2])) if all(isinstance(v, int) for v in shape[2:]) else None
        want = self.meta.get("input_size")
        if fixed is not None and want is not None and tuple(want) != fixed:
            raise InputError(f"detector model {path} has input {fixed[0]}x{fixed[1]} but its "
                             f"metadata {path.with_suffix('.json')} says {want[0]}x{want[1]}")
        if fixed is None and want is None:
            raise InputError(f"detector model {path} has a symbolic input size {shape} and no input_size in its "
                             f"metadata {path.with_suffix('.json')}; add it (the native input, e.g. [512, 288])")
        self.native_size: tuple[int, int] = fixed or (int(want[0]), int(want[1]))  # type: ignore[index]  # one is set: checked above
        self.reference_camera: tuple[int, int] = tuple(int(v) for v in self.meta.get("reference_camera",  # type: ignore[assignment]  # a (w, h) pair
                                                                                      REFERENCE_CAMERA))
        self.input_multiple = int(self.meta.get("input_multiple", INPUT_MULTIPLE))
        m, of = (self.stride, "stride") if fixed else (self.input_multiple, "input_multiple")
        if self.native_size[0] % m or self.native_size[1] % m:
            raise InputError(f"detector model {path}: input size {self.native_size} is not a multiple of {of} {m}")
        what = f"detector input_size {input_size!r}"
        if input_size is None or input_size == "follow":
            self.follow = fixed is None
            if input_size == "follow" and fixed is not None:
                raise InputError(f"{what}: detector model {path} has a fixed input {fixed[0]}x{fixed[1]}; it "
                                 "cannot follow the camera (export it with a symbolic height and width)")
            self.input_size: tuple[int, int] = self.native_size
            return
        self.follow = False
        if input_size == "native":
            self.input_size = self.native_size
            return
        size = parse_input_size(input_size, what=what, multiple=self.input_multiple, max_side=self._max_side())
        if fixed is not None and size != fixed:
            raise InputError(f"{what}: detector model {path} has a fixed input {fixed[0]}x{fixed[1]}")
        self.input_size = size

    def _max_side(self) -> int:
        """The largest pinned input side: the native-scale input of the largest camera (3136 for 4096 px)."""
        return _up(MAX_CAMERA_SIDE * native_scale(self.native_size, self.reference_camera), self.input_multiple)

    def input_size_for(self, width: int, height: int) -> tuple[int, int]:
        """The network input (W, H) a ``width`` x ``height`` frame is letterboxed into: the pinned size,
        or when following the camera, :func:`input_size_for` at this model's native scale."""
        if not self.follow:
            return self.input_size
        return _follow(int(width), int(height), self.native_size, self.reference_camera, self.input_multiple)

    def __reduce__(self) -> tuple:
        """Copied and pickled as its constructor arguments (an onnxruntime session cannot be pickled)."""
        return rebuild_detector, (type(self), self._init_kwargs)

    def __repr__(self) -> str:
        inp = "follow" if self.follow else f"{self.input_size[0]}x{self.input_size[1]}"
        return (f"ConeDetector({str(self.path)!r}, input={inp}, "
                f"score_threshold={self.score_threshold}, threads={self.threads})")

    # ------------------------------------------------------------------ inference
    def _check(self, image: Any, where: str) -> np.ndarray:
        return check_frame(image, where)

    def raw(self, images: list[np.ndarray]) -> tuple[np.ndarray | list[np.ndarray], list]:
        """Letterbox ``images`` and run the graph; returns (output, letterboxes). Frames that get the same
        input size (:meth:`input_size_for`) run as one batch; the output is ``(N, C+4, h, w)`` when all
        do, else a list of each frame's ``(C+4, h, w)``."""
        sizes = [self.input_size_for(im.shape[1], im.shape[0]) for im in images]
        outs: list[np.ndarray] = [None] * len(images)  # type: ignore[list-item]  # every slot is filled below
        lbs: list = [None] * len(images)
        for size in dict.fromkeys(sizes):
            idx = [i for i, s in enumerate(sizes) if s == size]
            w, h = size
            batch = np.empty((len(idx), 3, h, w), np.float32)
            for j, i in enumerate(idx):
                x, lbs[i] = letterbox(images[i], size)
                batch[j] = x.transpose(2, 0, 1)
            if self.batch_fixed is not None and self.batch_fixed != len(idx):
                out = np.concatenate([self.session.run(None, {self.input_name: batch[j : j + 1]})[0]
                                      for j in range(len(idx))])
            else:
                out = self.session.run(None, {self.input_name: batch})[0]
            if len(idx) == len(images):
                return out, lbs
            for j, i in enumerate(idx):
                outs[i] = out[j]
        return outs, lbs

    def detect_batch(self, images: list[np.ndarray] | np.ndarray, score_threshold: float | None = None) -> list[Detections]:
        """Detections for each frame of a batch (list of frames or an (N, H, W, 3) array)."""
        if isinstance(images, np.ndarray):
            if images.ndim != 4:
                raise InputError(f"a batch must be (N, H, W, 3), got shape {images.shape}")
            images = list(images)
        frames = [self._check(im, f"frame {i}") for i, im in enumerate(images)]
        if not frames:
            return []
        out, lbs = self.raw(frames)
        thr = self.score_threshold if score_threshold is None else float(score_threshold)
        decoded = decode(out, len(self.classes), self.stride, thr, self.max_detections, self.nms_iou)  # type: ignore[arg-type]  # a list of frames' outputs too
        result = []
        for (boxes, scores, classes), lb in zip(decoded, lbs, strict=True):
            b = lb.to_original(boxes).astype(np.float32)
            keep = (b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1])  # boxes wholly in the padding vanish
            result.append(Detections(b[keep], scores[keep], classes[keep]))
        return result

    def detect(self, image: np.ndarray, score_threshold: float | None = None) -> Detections:
        """Detections of one frame ``(H, W, 3)``."""
        return self.detect_batch([self._check(image, "image")], score_threshold)[0]

    def __call__(self, images, score_threshold: float | None = None):
        """One frame -> ``Detections``; a batch (4-D array or list) -> ``list[Detections]``."""
        if isinstance(images, np.ndarray) and images.ndim == 3:
            return self.detect(images, score_threshold)
        return self.detect_batch(images, score_threshold)
