"""Letterboxing and output decoding shared by the ONNX runtime and the training loop (numpy + OpenCV).

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.preprocess import letterbox, Letterbox
    >>> img = np.zeros((376, 672, 3), np.uint8)
    >>> x, lb = letterbox(img, (512, 288))
    >>> x.shape, round(lb.scale, 4), lb.pad
    ((288, 512, 3), 0.7619, (0, 1))
    >>> lb.to_original(np.array([[0, 1, 512, 287.]])).round(1).tolist()
    [[0.0, 0.0, 672.0, 375.4]]
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PAD_VALUE = 114


@dataclass(frozen=True)
class Letterbox:
    """How an original image was placed into the network input: ``input = original * scale + pad``."""

    scale: float
    pad: tuple[int, int]  # (x, y) offset of the resized image inside the input
    original_size: tuple[int, int]  # (width, height)

    def to_original(self, boxes: np.ndarray) -> np.ndarray:
        """Map xyxy boxes from input pixels back to original pixels, clipped to the image."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4).copy()
        b[:, [0, 2]] = (b[:, [0, 2]] - self.pad[0]) / self.scale
        b[:, [1, 3]] = (b[:, [1, 3]] - self.pad[1]) / self.scale
        w, h = self.original_size
        b[:, [0, 2]] = b[:, [0, 2]].clip(0, w)
        b[:, [1, 3]] = b[:, [1, 3]].clip(0, h)
        return b


def _fitted(width: int, height: int, scale: float) -> tuple[int, int]:
    """The scaled size, at least one pixel each way (a 1 x 5000 strip still has a row)."""
    return max(1, int(round(width * scale))), max(1, int(round(height * scale)))


def letterbox_params(width: int, height: int, input_size: tuple[int, int]) -> Letterbox:
    """Scale to fit ``input_size`` (W, H) keeping the aspect ratio, centred."""
    iw, ih = input_size
    scale = min(iw / width, ih / height)
    nw, nh = _fitted(width, height, scale)
    return Letterbox(scale=scale, pad=((iw - nw) // 2, (ih - nh) // 2), original_size=(int(width), int(height)))


def letterbox(image: np.ndarray, input_size: tuple[int, int]) -> tuple[np.ndarray, Letterbox]:
    """Resize (bilinear) and pad ``image`` (H, W, 3 uint8) into ``input_size`` (W, H)."""
    h, w = image.shape[:2]
    lb = letterbox_params(w, h, input_size)
    iw, ih = input_size
    nw, nh = _fitted(w, h, lb.scale)
    if (nw, nh) == (iw, ih):
        return (image if (w, h) == (iw, ih) else cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR)), lb
    out = np.full((ih, iw, 3), PAD_VALUE, dtype=np.uint8)
    resized = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR) if (nw, nh) != (w, h) else image
    out[lb.pad[1] : lb.pad[1] + nh, lb.pad[0] : lb.pad[0] + nw] = resized
    return out, lb


def nms(boxes: np.ndarray, scores: np.ndarray, iou: float) -> np.ndarray:
    """Indices kept by greedy non-maximum suppression (OpenCV's ``NMSBoxes``), best first."""
    if len(boxes) == 0:
        return np.zeros(0, np.int64)
    xywh = np.c_[boxes[:, :2], boxes[:, 2:] - boxes[:, :2]]
    keep = cv2.dnn.NMSBoxes(xywh.tolist(), scores.astype(float).tolist(), 0.0, float(iou))
    return np.asarray(keep, dtype=np.int64).reshape(-1)


def decode(
    out: np.ndarray,
    num_classes: int,
    stride: int,
    score_threshold: float,
    max_detections: int = 100,
    nms_iou: float | None = 0.7,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Decode the exported graph's output ``(B, C+4, h, w)`` into per-image (boxes xyxy in input
    pixels, scores, classes), best first. The graph already keeps only 3x3 heatmap peaks; a
    class-agnostic box NMS at ``nms_iou`` then removes a cone reported under two classes."""
    results = []
    c = num_classes
    for o in out:
        heat = o[:c]
        cls, ys, xs = np.nonzero(heat >= score_threshold)
        scores = heat[cls, ys, xs]
        if scores.size > max_detections * 4:
            top = np.argpartition(-scores, max_detections * 4)[: max_detections * 4]
            cls, ys, xs, scores = cls[top], ys[top], xs[top], scores[top]
        w = o[c, ys, xs]
        h = o[c + 1, ys, xs]
        cx = (xs + o[c + 2, ys, xs]) * stride
        cy = (ys + o[c + 3, ys, xs]) * stride
        boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1).astype(np.float64)
        order = np.argsort(-scores, kind="stable")
        boxes, scores, cls = boxes[order], scores[order], cls[order]
        if nms_iou is not None and len(scores) > 1:
            keep = nms(boxes, scores, nms_iou)
            keep.sort()
            boxes, scores, cls = boxes[keep], scores[keep], cls[keep]
        results.append((boxes[:max_detections], scores[:max_detections].astype(np.float32),
                        cls[:max_detections].astype(np.int64)))
    return results
