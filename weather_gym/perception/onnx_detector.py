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
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.cone_spec import CONE_CLASSES
from weather_gym.errors import InputError, MissingInputError
from weather_gym.perception.preprocess import decode, letterbox

__all__ = ["ConeDetector", "Detections", "DEFAULT_MODEL", "load_model_metadata"]

DEFAULT_MODEL = Path(__file__).resolve().parent / "models" / "cone_detector.onnx"


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


def load_model_metadata(model_path: str | os.PathLike) -> dict[str, Any]:
    """The sidecar JSON of ``model_path`` (``{}`` when there is none)."""
    side = Path(model_path).with_suffix(".json")
    if not side.is_file():
        return {}
    try:
        with open(side) as f:
            meta = json.load(f)
    except json.JSONDecodeError as exc:
        raise InputError(f"model metadata {side} is not valid JSON: {exc}") from None
    if not isinstance(meta, dict):
        raise InputError(f"model metadata {side} must be a JSON object")
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

    Call with one frame ``(H, W, 3)`` -> ``Detections``, or a batch ``(N, H, W, 3)`` / list of
    frames -> ``list[Detections]``. Boxes are in the original frame's pixels. It follows the
    :class:`~weather_gym.perception.detector_spec.Detector` protocol (``resize`` is always ``letterbox``).
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
        if len(shape) != 4 or shape[1] != 3 or not all(isinstance(v, int) for v in shape[2:]):
            raise InputError(f"detector model {path} has input shape {shape}; expected (batch, 3, H, W) with fixed H, W")
        self.input_name = inp[0].name
        self.input_size: tuple[int, int] = (int(shape[3]), int(shape[2]))  # (W, H)
        want = self.meta.get("input_size")
        if want is not None and tuple(want) != self.input_size:
            raise InputError(f"detector model {path} has input {self.input_size[0]}x{self.input_size[1]} but its "
                             f"metadata {path.with_suffix('.json')} says {want[0]}x{want[1]}")
        if self.input_size[0] % self.stride or self.input_size[1] % self.stride:
            raise InputError(f"detector model {path}: input size {self.input_size} is not a multiple of stride {self.stride}")
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
                             "max_detections": max_detections, "nms_iou": nms_iou}

    def __reduce__(self) -> tuple:
        """Copied and pickled as its constructor arguments (an onnxruntime session cannot be pickled)."""
        return rebuild_detector, (type(self), self._init_kwargs)

    def __repr__(self) -> str:
        return (f"ConeDetector({str(self.path)!r}, input={self.input_size[0]}x{self.input_size[1]}, "
                f"score_threshold={self.score_threshold}, threads={self.threads})")

    # ------------------------------------------------------------------ inference
    def _check(self, image: Any, where: str) -> np.ndarray:
        return check_frame(image, where)

    def raw(self, images: list[np.ndarray]) -> tuple[np.ndarray, list]:
        """Letterbox ``images`` and run the graph; returns (output, letterboxes)."""
        w, h = self.input_size
        batch = np.empty((len(images), 3, h, w), np.float32)
        lbs = []
        for i, im in enumerate(images):
            x, lb = letterbox(im, self.input_size)
            batch[i] = x.transpose(2, 0, 1)
            lbs.append(lb)
        if self.batch_fixed is not None and self.batch_fixed != len(images):
            outs = [self.session.run(None, {self.input_name: batch[i : i + 1]})[0] for i in range(len(images))]
            return np.concatenate(outs), lbs
        return self.session.run(None, {self.input_name: batch})[0], lbs

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
        decoded = decode(out, len(self.classes), self.stride, thr, self.max_detections, self.nms_iou)
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
