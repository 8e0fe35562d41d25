"""Training-time image augmentation that makes a detector trained on rendered frames survive a real camera.

Two stages, both seeded by the ``numpy`` Generator passed in (no global RNG) and both numpy/OpenCV
only (no torch):

* :func:`paste_distractors` - procedural clutter pasted into a training frame and **never labelled**:
  banners and boards (some in cone colours, some striped), poles, fence meshes, noisy texture
  patches, blobs and barrels in cone colours, and a dark/white "bodywork" band rising from the
  bottom edge. Shapes are kept off the labelled cones (and their ignore boxes), so every pixel of
  them is a hard negative: this is what teaches the detector that a yellow banner above the horizon
  or a red/white nose at the bottom is not a cone.
* :func:`camera_look` - what a real camera does to the scene: white balance, exposure from under- to
  blown-out with highlight clipping (pale, washed-out cones), a tone curve, desaturation, defocus or
  motion blur, sensor noise and JPEG compression.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.augment import camera_look, paste_distractors
    >>> img = np.full((96, 128, 3), 110, np.uint8)
    >>> boxes = np.array([[50.0, 40.0, 60.0, 60.0]])
    >>> out = paste_distractors(img, boxes, np.random.default_rng(0))
    >>> bool((out[40:60, 50:60] == 110).all())  # the labelled cone is left untouched
    True
    >>> camera_look(out, np.random.default_rng(1)).shape
    (96, 128, 3)
"""

from __future__ import annotations

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_BODY_RGB, CONE_STRIPE_RGB

__all__ = ["paste_distractors", "camera_look"]

_CONE_COLOURS = [tuple(int(255 * v) for v in c) for c in CONE_BODY_RGB.values()]
_STRIPE_COLOURS = [tuple(int(255 * v) for v in c) for c in CONE_STRIPE_RGB.values()]


def _colour(rng: np.random.Generator) -> tuple[int, int, int]:
    """Half the time a cone colour (slightly shifted), otherwise any colour."""
    if rng.random() < 0.5:
        base = np.array(_CONE_COLOURS[int(rng.integers(len(_CONE_COLOURS)))], float)
        c = base * rng.uniform(0.7, 1.25) + rng.normal(0, 12, 3)
    else:
        c = rng.uniform(0, 255, 3)
    return tuple(int(v) for v in np.clip(c, 0, 255))  # type: ignore[return-value]  # three channels


def _free(mask: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> bool:
    return not mask[max(0, y0) : max(0, y1), max(0, x0) : max(0, x1)].any()


def _texture(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Low-frequency coloured noise (foliage, crowds, buildings seen from far)."""
    gh, gw = max(2, h // int(rng.integers(3, 12))), max(2, w // int(rng.integers(3, 12)))
    small = rng.uniform(0, 255, (gh, gw, 3)).astype(np.float32)
    small = small * rng.uniform(0.3, 1.0) + np.array(_colour(rng), np.float32) * 0.5
    return np.clip(cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR), 0, 255).astype(np.uint8)


def _draw_shape(layer: np.ndarray, kind: str, rng: np.random.Generator, box: tuple[int, int, int, int],
                clipped: tuple[int, int, int, int]) -> None:
    """Draw one clutter shape of ``kind`` into ``layer`` in place (``box`` unclipped, ``clipped`` inside it)."""
    x0, y0, x1, y1 = box
    cx0, cy0, cx1, cy1 = clipped
    bw, bh = x1 - x0, y1 - y0
    if kind == "board":
        layer[cy0:cy1, cx0:cx1] = _colour(rng)
        if rng.random() < 0.5:  # stripes or lettering-like bars
            n = int(rng.integers(1, 5))
            col = _STRIPE_COLOURS[int(rng.integers(len(_STRIPE_COLOURS)))]
            for k in range(n):
                ys = cy0 + int((k + 0.5) * (cy1 - cy0) / n)
                cv2.line(layer, (cx0, ys), (cx1 - 1, ys), col, max(1, (cy1 - cy0) // (3 * n)))
    elif kind == "pole":
        layer[cy0:cy1, cx0:cx1] = _colour(rng) if rng.random() < 0.4 else tuple(int(v) for v in rng.uniform(150, 255, 3))
    elif kind == "fence":
        col = tuple(int(v) for v in rng.uniform(40, 220, 3))
        step = int(rng.integers(3, 9))
        for xx in range(cx0, cx1, step):
            cv2.line(layer, (xx, cy0), (min(cx1 - 1, xx + step), cy1 - 1), col, 1)
            cv2.line(layer, (min(cx1 - 1, xx + step), cy0), (xx, cy1 - 1), col, 1)
    elif kind == "texture":
        layer[cy0:cy1, cx0:cx1] = _texture(rng, cy1 - cy0, cx1 - cx0)
    elif kind == "blob":
        cv2.ellipse(layer, ((x0 + x1) // 2, (y0 + y1) // 2), (bw // 2, bh // 2), 0, 0, 360, _colour(rng), -1)
    elif kind == "barrel":
        body = _colour(rng)
        cv2.rectangle(layer, (cx0, cy0), (cx1 - 1, cy1 - 1), body, -1)
        if rng.random() < 0.6:
            col = _STRIPE_COLOURS[int(rng.integers(len(_STRIPE_COLOURS)))]
            ys = (cy0 + cy1) // 2
            cv2.line(layer, (cx0, ys), (cx1 - 1, ys), col, max(1, (cy1 - cy0) // 6))
    else:  # random erasing: grey or noise
        if rng.random() < 0.5:
            layer[cy0:cy1, cx0:cx1] = int(rng.integers(0, 256))
        else:
            layer[cy0:cy1, cx0:cx1] = rng.integers(0, 256, (cy1 - cy0, cx1 - cx0, 3), dtype=np.uint8)


def paste_distractors(image: np.ndarray, boxes: np.ndarray, rng: np.random.Generator, *, max_shapes: int = 8,
                      ego_band: float = 0.3) -> np.ndarray:
    """Return a copy of ``image`` (H, W, 3 uint8) with up to ``max_shapes`` unlabelled clutter shapes
    and, with probability ``ego_band``, a bodywork band at the bottom; no pixel inside ``boxes``
    (xyxy, grown by 2 px) is changed."""
    out = image.copy()
    h, w = out.shape[:2]
    keep = np.zeros((h, w), bool)
    for b in np.asarray(boxes, float).reshape(-1, 4):
        x0, y0 = int(np.floor(b[0])) - 2, int(np.floor(b[1])) - 2
        x1, y1 = int(np.ceil(b[2])) + 2, int(np.ceil(b[3])) + 2
        keep[max(0, y0) : max(0, y1), max(0, x0) : max(0, x1)] = True
    layer = out  # shapes are drawn only where _free says no cone is (they may overlap each other)
    for _ in range(int(rng.integers(1, max_shapes + 1))):
        kind = rng.choice(["board", "pole", "fence", "texture", "blob", "barrel", "erase"],
                          p=[0.22, 0.16, 0.1, 0.16, 0.14, 0.1, 0.12])
        bw = int(rng.uniform(0.02, 0.35) * w) if kind != "pole" else int(rng.integers(2, max(3, w // 40)))
        bh = int(rng.uniform(0.02, 0.25) * h) if kind != "pole" else int(rng.uniform(0.15, 0.7) * h)
        if kind in ("blob", "barrel"):
            bh = int(rng.uniform(0.02, 0.15) * h)
            bw = int(bh * rng.uniform(0.5, 2.0))
        bw, bh = max(bw, 2), max(bh, 2)
        x0 = int(rng.integers(-bw // 2, w))
        y0 = int(rng.integers(-bh // 2, h))
        x1, y1 = x0 + bw, y0 + bh
        if not _free(keep, x0, y0, x1, y1):
            continue
        cx0, cy0, cx1, cy1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
        if cx1 <= cx0 or cy1 <= cy0:
            continue
        _draw_shape(layer, str(kind), rng, (x0, y0, x1, y1), (cx0, cy0, cx1, cy1))
    if rng.random() < ego_band:
        # bodywork from the bottom edge: a polygon in dark carbon, white or red paint, not over a cone
        top = int(h * rng.uniform(0.65, 0.95))
        pts = np.array([[0, h], [int(w * rng.uniform(0, 0.3)), top], [int(w * rng.uniform(0.7, 1.0)), top], [w, h]],
                       np.int32)
        band = np.zeros((h, w), np.uint8)
        cv2.fillPoly(band, [pts], 1)
        band = band.astype(bool) & ~keep  # type: ignore[assignment]  # now a bool mask
        col = [(25, 25, 28), (235, 235, 235), (200, 30, 35)][int(rng.integers(3))]
        shade = np.clip(np.array(col, float) + rng.normal(0, 10, (h, w, 1)), 0, 255).astype(np.uint8)
        out[band] = shade[band]
    return out


def camera_look(image: np.ndarray, rng: np.random.Generator, *, strength: float = 1.0,
                degrade: bool = False) -> np.ndarray:
    """A random real-camera rendition of ``image`` (H, W, 3 uint8 RGB) on a clear day: white balance,
    exposure from normal to blown-out (highlights clipped), tone curve, saturation, mild sensor noise,
    JPEG. ``degrade`` adds what the weather effects also do - under-exposure, defocus or motion blur,
    strong noise - which makes a detector robust to them too (and hides the drop the simulator's weather
    is meant to show). ``strength`` scales the ranges (0 = identity)."""
    if strength <= 0:
        return image
    s = float(strength)
    lin = (image.astype(np.float32) / 255.0) ** 2.2
    lin *= (1.0 + rng.uniform(-0.15, 0.15, 3) * s).astype(np.float32)  # white balance
    ev = rng.uniform(-1.0 if degrade else 0.0, 1.6) * s  # exposure (+: blown-out, clipped below)
    lin *= np.float32(2.0 ** ev)
    gamma = 1 / 2.2 * (1.0 + rng.uniform(-0.2, 0.2) * s)
    img = np.clip(lin, 0, 1) ** np.float32(gamma)
    c = rng.uniform(-0.3, 0.3) * s  # S-curve (>0) or flattening (<0) contrast
    img = img + np.float32(c) * img * (1 - img) * (2 * img - 1) * 2
    sat = 1.0 + rng.uniform(-0.6, 0.25) * s
    grey = img.mean(axis=2, keepdims=True)
    img = np.clip(grey + (img - grey) * np.float32(sat), 0, 1)
    out = (img * 255 + 0.5).astype(np.uint8)
    r = rng.random() if degrade else 1.0
    if r < 0.3 * s:
        sigma = rng.uniform(0.4, 1.6)
        out = cv2.GaussianBlur(out, (0, 0), sigma)
    elif r < 0.4 * s:
        k = int(rng.integers(3, 7))
        kernel = np.zeros((k, k), np.float32)
        kernel[k // 2, :] = 1.0 / k
        out = cv2.filter2D(out, -1, kernel)
    if rng.random() < 0.5 * s:
        sd = rng.uniform(1, 8 if degrade else 3)
        out = np.clip(out.astype(np.float32) + rng.normal(0, sd, out.shape).astype(np.float32), 0, 255).astype(np.uint8)
    if rng.random() < 0.4 * s:
        ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 95))])
        if ok:
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]  # type: ignore[index]  # just encoded: never None
    return np.ascontiguousarray(out)
