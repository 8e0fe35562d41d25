"""YOLO-family ONNX exports as weather-gym detectors (onnxruntime only).

:class:`YoloDetector` runs a YOLOv5 / YOLOv8 / YOLOv11 export and maps its classes to cone classes.
The output layout is recognised from the shapes of one probe run at load time (or forced with
``layout``):

==========  ============================================================================
``v5``      one output ``(B, N, 5+nc)``: ``cx cy w h objectness class scores`` (raw, NMS here)
``v8``      one output ``(B, 4+nc, N)``: ``cx cy w h class scores`` (raw; also v11)
``nms``     NMS in the graph: ``(B, K, 6)`` rows ``x1 y1 x2 y2 score class`` (ultralytics
            ``nms=True``, YOLOv10), ``(K, 7)`` rows ``batch x1 y1 x2 y2 class score``, or the
            four outputs ``num_dets, boxes (B, K, 4), scores (B, K), classes (B, K)``
==========  ============================================================================

Boxes are in network-input pixels (normalised ones are recognised); the frame goes in letterboxed
(``resize="letterbox"``, grey 114 padding, centred, as ultralytics does) or stretched
(``"stretch"``), as RGB scaled to [0, 1]. Raw outputs get a score threshold and a per-class
non-maximum suppression (IoU ``nms_iou``). Any fixed input size works; an export with a dynamic
input needs ``input_size`` (or carries ``imgsz`` in its metadata).

**Class map** ``classes``: ``"0=blue,1=yellow,2=orange,3=big_orange,4=ignore"`` by output index,
or by the export's class names (``blue_cone=blue,...``); ``ignore`` drops that class's detections;
``*=ignore`` drops every class not named. Without one, the export's own class names (ultralytics
stores them) are mapped with the import default (``blue_cone=blue, yellow_cone=yellow, ...``). Every
output class must be mapped.

Example:
    >>> from weather_gym.perception.yolo import resolve_class_map
    >>> resolve_class_map("0=blue,1=yellow,*=ignore", 3, None, "model.onnx").tolist()
    [0, 1, -1]
"""

from __future__ import annotations

import ast
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError
from weather_gym.perception.labels import DEFAULT_CLASSES, IGNORE, parse_class_map
from weather_gym.perception.onnx_detector import Detections, check_frame, rebuild_detector
from weather_gym.perception.preprocess import letterbox
from weather_gym.perception.protocol import DetectorBase

__all__ = ["YoloDetector", "resolve_class_map", "LAYOUTS"]

LAYOUTS = ("auto", "v5", "v8", "nms")
_PAD = 114


def resolve_class_map(classes: str | Mapping[str, str] | None, nc: int | None, names: Sequence[str] | None,
                      where: str) -> np.ndarray:
    """Output class index -> cone class id (-1: dropped) for ``nc`` output classes (see module doc)."""

    if classes is None:
        if not names:
            raise InputError(f"detector {where}: the export names no classes; give a class map "
                             "(--detector-classes 0=blue,1=yellow,2=orange,3=big_orange)")
        classes = DEFAULT_CLASSES
    cmap = parse_class_map(classes)
    n = nc if nc is not None else max([int(k) for k in cmap if k.isdigit()] + [len(names or []) - 1]) + 1
    out = np.full(n, -1, np.int64)
    missing = []
    for i in range(n):
        keys = [str(i)] + ([names[i]] if names and i < len(names) else [])
        target = next((cmap[k] for k in keys if k in cmap), cmap.get("*"))
        if target is None:
            missing.append(keys[-1] if len(keys) > 1 else keys[0])
        elif target != IGNORE:
            out[i] = CONE_CLASSES.index(target)
    if missing:
        raise InputError(f"detector {where}: output class(es) {', '.join(missing)} are not in the class map "
                         f"({', '.join(f'{k}={v}' for k, v in cmap.items())}); map every class to a cone class or "
                         "to 'ignore' ('*=ignore' drops every class not named)")
    bad = [k for k in cmap if k.isdigit() and int(k) >= n]
    if bad:
        raise InputError(f"detector {where}: class map names output index {bad[0]} but the export has {n} classes")
    return out


def _metadata(session: Any) -> dict[str, Any]:
    meta = dict(session.get_modelmeta().custom_metadata_map or {})
    out: dict[str, Any] = {}
    for key in ("names", "imgsz"):
        if key in meta:
            try:
                out[key] = ast.literal_eval(meta[key])
            except (ValueError, SyntaxError):
                pass
    names = out.get("names")
    if isinstance(names, dict):
        out["names"] = [str(names[k]) for k in sorted(names, key=int)]
    elif isinstance(names, list | tuple):
        out["names"] = [str(n) for n in names]
    else:
        out.pop("names", None)
    return out


def _ort_errors() -> tuple[type[Exception], ...]:
    """The exception types onnxruntime raises for a model it cannot load or run (a bad file, not a bug)."""
    from onnxruntime.capi import onnxruntime_pybind11_state as state

    names = ("Fail", "InvalidArgument", "InvalidGraph", "InvalidProtobuf", "NoSuchFile", "NoModel", "NotImplemented",
             "RuntimeException", "EPFail", "EngineError", "NotFound")
    return tuple(t for t in (getattr(state, n, None) for n in names) if isinstance(t, type))


class YoloDetector(DetectorBase):
    """A YOLO-family ONNX export (see module doc).

    Args:
        model: the ONNX file.
        layout: ``auto`` (recognised from the outputs), ``v5``, ``v8`` or ``nms``.
        classes: class map (see module doc).
        resize: ``letterbox`` (default) or ``stretch``.
        input_size: ``(W, H)`` for an export with a dynamic input.
        score_threshold: operating threshold (default 0.25, ultralytics' default).
        nms_iou: IoU of the per-class NMS of raw outputs (default 0.6).
        max_detections: at most this many detections per frame, best first.
        threads: onnxruntime intra-op threads.
    """

    input_size: tuple[int, int]  # always set by __init__

    def __init__(self, model: str | os.PathLike, *, layout: str = "auto", classes: str | Mapping | None = None,
                 resize: str = "letterbox", input_size: tuple[int, int] | None = None,
                 score_threshold: float | None = None, nms_iou: float = 0.6, max_detections: int = 300,
                 threads: int = 1) -> None:
        import onnxruntime as ort

        path = Path(model)
        if not path.is_file():
            raise MissingInputError(f"detector model {path} not found")
        if layout not in LAYOUTS:
            raise InputError(f"YOLO layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
        if resize not in ("letterbox", "stretch"):
            raise InputError(f"resize must be 'letterbox' or 'stretch', got {resize!r}")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = int(threads)
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        except (*_ort_errors(), OSError) as exc:  # type: ignore[misc]  # a tuple of exception types
            raise FileFormatError(f"detector model {path} could not be loaded by onnxruntime (corrupt or not an ONNX "
                             f"model): {exc}") from None
        self.path, self.resize, self.threads = path, resize, int(threads)
        self.name = f"yolo:{path.name}"
        self._init_kwargs = {"model": str(path), "layout": layout, "classes": classes, "resize": resize,
                             "input_size": input_size, "score_threshold": score_threshold, "nms_iou": nms_iou,
                             "max_detections": max_detections, "threads": threads}
        self.nms_iou, self.max_detections = float(nms_iou), int(max_detections)
        self.score_threshold = 0.25 if score_threshold is None else float(score_threshold)
        if not 0.0 <= self.score_threshold <= 1.0:
            raise InputError(f"score_threshold must be in [0, 1], got {self.score_threshold}")
        inputs = self.session.get_inputs()
        if len(inputs) != 1 or len(inputs[0].shape) != 4:
            raise FileFormatError(f"detector model {path} must have one image input (batch, 3, H, W), got "
                             f"{[(i.name, i.shape) for i in inputs]}")
        shape = inputs[0].shape
        if shape[1] not in (3, "3") and isinstance(shape[1], int):
            raise FileFormatError(f"detector model {path} has input shape {shape}; expected (batch, 3, H, W)")
        meta = _metadata(self.session)
        self.input_name = inputs[0].name
        self.input_dtype = np.float16 if "float16" in inputs[0].type else np.float32
        if isinstance(shape[2], int) and isinstance(shape[3], int):
            fixed = (int(shape[3]), int(shape[2]))
            if input_size is not None and tuple(input_size) != fixed:
                raise InputError(f"detector model {path} has a fixed {fixed[0]}x{fixed[1]} input, not "
                                 f"{input_size[0]}x{input_size[1]}")
            self.input_size = fixed
        elif input_size is not None:
            self.input_size = (int(input_size[0]), int(input_size[1]))
        elif "imgsz" in meta:
            sz = meta["imgsz"]
            sz = [sz, sz] if isinstance(sz, int) else list(sz)
            self.input_size = (int(sz[-1]), int(sz[0]))
        else:
            raise InputError(f"detector model {path} has a dynamic input size {shape}; give one "
                             "(input_size=(W, H), --detector-input 640x640)")
        self.batch_fixed = shape[0] if isinstance(shape[0], int) else None
        self.names = meta.get("names")
        self.layout, self.nc = self._recognise(layout, classes)
        self.class_map = resolve_class_map(classes, self.nc, self.names, str(path))

    def __repr__(self) -> str:
        return (f"YoloDetector({str(self.path)!r}, layout={self.layout}, input={self.input_size[0]}x{self.input_size[1]}, "
                f"resize={self.resize}, score_threshold={self.score_threshold})")

    # ------------------------------------------------------------------ layout
    def _run(self, batch: np.ndarray) -> list[np.ndarray]:
        n = batch.shape[0]
        if n > 1 and (self.batch_fixed is not None and self.batch_fixed != n):
            return self._run_each(batch)
        outs = self.session.run(None, {self.input_name: batch})
        if n > 1 and getattr(self, "_nms_form", None) != "seven" and outs[0].shape[0] != n:
            self.batch_fixed = 1  # an export that keeps batch 1 whatever it is given: one frame at a time
            return self._run_each(batch)
        return outs

    def _run_each(self, batch: np.ndarray) -> list[np.ndarray]:
        outs = [self.session.run(None, {self.input_name: batch[i:i + 1]}) for i in range(batch.shape[0])]
        if getattr(self, "_nms_form", None) == "seven":  # rows carry their batch index
            for i, o in enumerate(outs):
                o[0] = o[0].copy()
                o[0][:, 0] = i
        return [np.concatenate([o[j] for o in outs]) for j in range(len(outs[0]))]

    def _recognise(self, layout: str, classes: Any) -> tuple[str, int | None]:
        w, h = self.input_size
        try:
            outs = self._run(np.zeros((1, 3, h, w), self.input_dtype))
        except _ort_errors() as exc:  # onnxruntime's own errors: the model; anything else is a bug
            raise FileFormatError(f"detector model {self.path} failed on a {w}x{h} input: {exc}") from None
        shapes = [tuple(o.shape) for o in outs]
        nc_hint = len(self.names) if self.names else _map_size(classes)
        expected = ("(1, N, 5+nc) YOLOv5, (1, 4+nc, N) YOLOv8/v11, (1, K, 6) [x1 y1 x2 y2 score class] or "
                    "(K, 7) [batch x1 y1 x2 y2 class score] with NMS in the graph, or the four outputs num_dets, "
                    "boxes, scores, classes")
        fail = FileFormatError(f"detector model {self.path}: outputs {shapes} match no YOLO layout"
                          f"{f' for {nc_hint} class(es)' if nc_hint else ''}; expected {expected}")
        if len(outs) == 4 and [len(s) for s in shapes][1:] == [3, 2, 2]:
            if layout not in ("auto", "nms"):
                raise fail
            self._nms_form = "four"
            return "nms", None
        if len(outs) != 1:
            raise fail
        s = shapes[0]
        if len(s) == 2 and s[1] == 7:
            if layout not in ("auto", "nms"):
                raise fail
            self._nms_form = "seven"
            return "nms", None
        if len(s) != 3:
            raise fail
        a, c = s[1], s[2]
        fits = {
            "v8": a > 4 and c > a and (nc_hint is None or a == 4 + nc_hint),
            "v5": c > 5 and a > c and (nc_hint is None or c == 5 + nc_hint),
            "nms": c == 6 and a <= 1000,
        }
        if layout != "auto":
            ok = {"v8": a > 4, "v5": c > 5, "nms": c == 6}[layout]
            if not ok:
                raise fail
            chosen = layout
        else:
            cands = [k for k, v in fits.items() if v]
            if len(cands) > 1 and "nms" in cands:  # (1, K, 6): NMS output unless there are many rows
                cands = ["v5"] if a > 1000 else ["nms"]
            if len(cands) != 1:
                raise fail
            chosen = cands[0]
        self._nms_form = "six"
        nc = {"v8": a - 4, "v5": c - 5, "nms": None}[chosen]
        if nc is not None and nc_hint is not None and nc != nc_hint and self.names:
            raise FileFormatError(f"detector model {self.path}: output {s} has {nc} classes but its metadata names "
                             f"{len(self.names)}")
        return chosen, nc

    # ------------------------------------------------------------------ inference
    def _prepare(self, images: list[np.ndarray]) -> tuple[np.ndarray, list[tuple[float, float, float, float]]]:
        w, h = self.input_size
        batch = np.empty((len(images), 3, h, w), np.float32)
        maps = []  # (sx, sy, px, py): input = original * s + p
        for i, im in enumerate(images):
            ih, iw = im.shape[:2]
            if self.resize == "stretch":
                x = cv2.resize(im, (w, h), interpolation=cv2.INTER_LINEAR) if (iw, ih) != (w, h) else im
                maps.append((w / iw, h / ih, 0.0, 0.0))
            else:
                x, lb = letterbox(im, (w, h))
                maps.append((lb.scale, lb.scale, float(lb.pad[0]), float(lb.pad[1])))
            batch[i] = x.transpose(2, 0, 1)
        batch *= np.float32(1.0 / 255.0)
        return batch.astype(self.input_dtype, copy=False), maps

    def _decode(self, outs: list[np.ndarray], i: int, thr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.layout in ("v5", "v8"):
            p = outs[0][i].astype(np.float32)
            if self.layout == "v8":
                p = p.T
                xywh, cls_scores = p[:, :4], p[:, 4:]
            else:
                xywh, cls_scores = p[:, :4], p[:, 5:] * p[:, 4:5]
            cls = np.argmax(cls_scores, axis=1)
            scores = cls_scores[np.arange(len(cls)), cls]
            keep = scores >= thr
            xywh, cls, scores = xywh[keep], cls[keep], scores[keep]
            boxes = np.c_[xywh[:, :2] - xywh[:, 2:] / 2, xywh[:, :2] + xywh[:, 2:] / 2]
            if len(scores) > 1:
                k = cv2.dnn.NMSBoxesBatched(np.c_[boxes[:, :2], xywh[:, 2:]].tolist(), scores.tolist(),
                                            cls.tolist(), 0.0, self.nms_iou)
                k = np.asarray(k, np.int64).reshape(-1)  # type: ignore[assignment]  # the kept indices as an array
                boxes, scores, cls = boxes[k], scores[k], cls[k]
            return boxes, scores, cls
        if self._nms_form == "four":
            n = int(np.asarray(outs[0][i]).reshape(-1)[0])
            boxes, scores, cls = outs[1][i][:n], outs[2][i][:n], outs[3][i][:n]
        elif self._nms_form == "seven":
            rows = outs[0][outs[0][:, 0].astype(np.int64) == i]
            boxes, cls, scores = rows[:, 1:5], rows[:, 5], rows[:, 6]
        else:
            rows = outs[0][i]
            boxes, scores, cls = rows[:, :4], rows[:, 4], rows[:, 5]
        boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
        if boxes.size and float(np.abs(boxes).max()) <= 1.0:  # normalised coordinates
            boxes = boxes * np.array([*self.input_size, *self.input_size], np.float64)
        scores = np.asarray(scores, np.float64).reshape(-1)
        keep = scores >= thr
        return boxes[keep], scores[keep], np.asarray(cls).reshape(-1)[keep].astype(np.int64)

    def __reduce__(self) -> tuple:
        """Copied and pickled as its constructor arguments (an onnxruntime session cannot be pickled)."""
        return rebuild_detector, (type(self), self._init_kwargs)

    def detect_batch(self, images: Sequence[np.ndarray] | np.ndarray,
                     score_threshold: float | None = None) -> list[Detections]:
        """Detections for each frame of a batch (list of frames or an (N, H, W, 3) array)."""
        if isinstance(images, np.ndarray):
            if images.ndim != 4:
                raise InputError(f"a batch must be (N, H, W, 3), got shape {images.shape}")
            images = list(images)
        frames = [check_frame(im, f"frame {i}") for i, im in enumerate(images)]
        if not frames:
            return []
        batch, maps = self._prepare(frames)
        outs = self._run(batch)
        thr = self.score_threshold if score_threshold is None else float(score_threshold)
        result = []
        for i, (im, (sx, sy, px, py)) in enumerate(zip(frames, maps)):
            boxes, scores, cls = self._decode(outs, i, thr)
            if len(cls) and (cls.min() < 0 or cls.max() >= len(self.class_map)):
                raise InputError(f"detector {self.path} reported class {int(cls.max())}, outside the "
                                 f"{len(self.class_map)} classes of its class map")
            target = self.class_map[cls] if len(cls) else np.zeros(0, np.int64)
            ok = target >= 0
            boxes, scores, target = boxes[ok], scores[ok], target[ok]
            b = boxes.copy()
            b[:, [0, 2]] = ((b[:, [0, 2]] - px) / sx).clip(0, im.shape[1])
            b[:, [1, 3]] = ((b[:, [1, 3]] - py) / sy).clip(0, im.shape[0])
            valid = (b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1])
            order = np.argsort(-scores[valid], kind="stable")[:self.max_detections]
            result.append(Detections(b[valid][order].astype(np.float32), scores[valid][order].astype(np.float32),
                                     target[valid][order].astype(np.int64)))
        return result


def _map_size(classes: Any) -> int | None:
    """Number of output classes a by-index class map implies (None when it names classes or has ``*``)."""
    if classes is None:
        return None

    cmap = parse_class_map(classes)
    if "*" in cmap or not all(k.isdigit() for k in cmap):
        return None
    return max(int(k) for k in cmap) + 1
