"""A camera's image pipeline as a finishing stage after rendering (separate from weather): lens
distortion and slight defocus, vignetting, exposure with highlight clipping, white balance, a tone
curve, sensor noise, and chroma subsampling / JPEG compression.

``CameraModel`` holds the parameters (frozen; the scenario TOML's ``[camera_model]`` table). Its
defaults are a realistic camera (``CameraModel() == CameraModel.realistic()``): a table or dict changes
only the fields it names. ``enabled=False`` (``CameraModel.ideal()``, the study's "ideal" camera, the
envs' default) leaves frames untouched.
:class:`CameraPipeline` applies it to one camera size: per-channel look-up tables, a precomputed
remap and vignetting gain, and a noise bank drawn from the episode's RNG, so a frame costs a few
milliseconds at 672x376 and the same seed gives the same bytes. Lens distortion moves pixels, so
ground-truth boxes go through :meth:`CameraPipeline.distort_boxes` (and segmentation / depth through
:meth:`CameraPipeline.remap_nearest`).

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.isp import CameraModel, CameraPipeline
    >>> img = np.full((40, 60, 3), 128, np.uint8)
    >>> off = CameraPipeline(CameraModel(enabled=False), 60, 40)
    >>> bool((off.apply(img, np.random.default_rng(0)) == img).all())
    True
    >>> a = CameraPipeline(CameraModel(), 60, 40).apply(img, np.random.default_rng(1))
    >>> b = CameraPipeline(CameraModel(), 60, 40).apply(img, np.random.default_rng(1))
    >>> bool((a == b).all()), bool((a != img).any())
    (True, True)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Annotated

import cv2
import numpy as np
from pydantic import Field

from weather_gym.core.errors import InputError, check_known
from weather_gym.core.schema import ListAsTuple, check_fields

__all__ = ["CameraModel", "CameraPipeline"]

#: a white-balance gain of one channel
Gain = Annotated[float, Field(ge=0.2, le=5.0)]


@dataclass(frozen=True)
class CameraModel:
    """Parameters of the finishing stage; the defaults are a realistic camera (``realistic()``).

    Attributes:
        enabled: False = the ideal camera (frames pass unchanged; every other field is ignored).
        exposure_ev: exposure in stops relative to the renderer's (+1 = twice the light); highlights
            above full scale clip, as on a sensor.
        white_balance: per-channel gains (R, G, B) of a white balance that is not quite right.
        contrast: slope of the filmic tone curve at mid-grey (1 = the renderer's sRGB curve).
        vignetting: light fall-off at the image corners (0.3 = 30 % darker there, cos^4-like).
        k1, k2: radial lens distortion (Brown model on coordinates normalised by fx); k1 < 0 = barrel.
            A barrel-distorted frame is zoomed in just enough to stay filled (``CameraPipeline.zoom``).
        defocus_px: Gaussian blur sigma in pixels (slight defocus / lens softness).
        read_noise: sensor read noise, standard deviation in 8-bit levels.
        shot_noise: photon noise: standard deviation at full scale in levels, growing as sqrt(signal).
        chroma_subsampling: 4:2:0 colour (chroma at half resolution) as video codecs and JPEG store it.
        jpeg_quality: JPEG compression at this quality (1-100); 0 = no JPEG.
    """

    enabled: bool = True
    exposure_ev: Annotated[float, Field(ge=-6.0, le=6.0)] = 0.6
    white_balance: Annotated[tuple[Gain, Gain, Gain], ListAsTuple] = (1.0, 1.0, 1.04)  # R, G, B
    contrast: Annotated[float, Field(ge=0.3, le=3.0)] = 1.15
    vignetting: Annotated[float, Field(ge=0.0, le=0.9)] = 0.25
    k1: Annotated[float, Field(ge=-0.5, le=0.5)] = -0.06
    k2: Annotated[float, Field(ge=-0.5, le=0.5)] = 0.0
    defocus_px: Annotated[float, Field(ge=0.0, le=5.0)] = 0.6
    read_noise: Annotated[float, Field(ge=0.0, le=30.0)] = 2.0
    shot_noise: Annotated[float, Field(ge=0.0, le=10.0)] = 3.0
    chroma_subsampling: bool = True
    jpeg_quality: Annotated[int, Field(ge=0, le=100)] = 90  # 0 = off

    def __post_init__(self) -> None:
        check_fields(self, who="camera_model")

    @classmethod
    def realistic(cls) -> CameraModel:
        """``CameraModel()``: a plausible machine-vision camera, a little
        over-exposed (bright skies clip), mild barrel distortion and vignetting, slight softness,
        visible noise, 4:2:0 colour and JPEG at 90."""
        return cls(enabled=True, exposure_ev=0.6, white_balance=(1.0, 1.0, 1.04), contrast=1.15, vignetting=0.25,
                   k1=-0.06, k2=0.0, defocus_px=0.6, read_noise=2.0, shot_noise=3.0, chroma_subsampling=True,
                   jpeg_quality=90)

    @classmethod
    def ideal(cls) -> CameraModel:
        """The study's ideal camera: off, and every stage neutral (``.with_(enabled=True, k1=-0.1)`` is
        then a camera with that one stage)."""
        return cls(enabled=False, exposure_ev=0.0, white_balance=(1.0, 1.0, 1.0), contrast=1.0, vignetting=0.0,
                   k1=0.0, k2=0.0, defocus_px=0.0, read_noise=0.0, shot_noise=0.0, chroma_subsampling=False,
                   jpeg_quality=0)

    @property
    def distorts(self) -> bool:
        """True when the lens moves pixels (boxes, segmentation and depth must follow)."""
        return self.enabled and (self.k1 != 0.0 or self.k2 != 0.0)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> CameraModel:
        """From a dict (a TOML table, a dataset record); unknown keys are an error naming them."""
        if isinstance(d, CameraModel):
            return d
        if not isinstance(d, dict):
            raise InputError(f"camera_model must be a table of CameraModel fields, got {d!r}")
        check_known(d, {f.name for f in fields(cls)}, what="camera_model")
        d = dict(d)
        if "white_balance" in d and isinstance(d["white_balance"], list):
            d["white_balance"] = tuple(d["white_balance"])
        return cls(**d)

    def with_(self, **changes) -> CameraModel:
        return replace(self, **changes)


def _srgb_to_linear(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(v: np.ndarray) -> np.ndarray:
    v = np.clip(v, 0, 1)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)


def _edge_points() -> np.ndarray:
    """(4, 64): xyxy boxes times it give 8 points along each of the 4 edges (32 x, then 32 y)."""
    t = np.linspace(0, 1, 8)
    m = np.zeros((4, 64))
    m[0, 0:16], m[2, 0:16] = np.tile(1 - t, 2), np.tile(t, 2)  # top and bottom edges: x along the box
    m[1, 32:40], m[3, 40:48] = 1.0, 1.0  # their y: y0, then y1
    m[0, 16:24], m[2, 24:32] = 1.0, 1.0  # left and right edges: x0, then x1
    m[1, 48:64], m[3, 48:64] = np.tile(1 - t, 2), np.tile(t, 2)  # their y along the box
    return m


_EDGE_POINTS = _edge_points()


class CameraPipeline:
    """A :class:`CameraModel` prepared for one image size (``width`` x ``height``; ``fx`` for the
    distortion's normalisation, default the 90-degree camera's ``width / 2``)."""

    def __init__(self, model: CameraModel, width: int, height: int, fx: float | None = None,
                 cx: float | None = None, cy: float | None = None) -> None:
        self.model = model
        self.width, self.height = int(width), int(height)
        self.fx = float(fx) if fx is not None else self.width / 2.0
        self.cx = float(cx) if cx is not None else self.width / 2.0
        self.cy = float(cy) if cy is not None else self.height / 2.0
        if not model.enabled:
            return
        m = model
        # exposure + white balance + clipping + tone curve: one 256-entry table per channel
        lin = _srgb_to_linear(np.arange(256) / 255.0)
        luts = []
        for gain in m.white_balance:
            x = np.clip(lin * gain * 2.0 ** m.exposure_ev, 0, 1)  # the sensor clips at full scale
            y = _linear_to_srgb(x)
            # filmic contrast about mid-grey (an S-curve that keeps 0 and 1 fixed)
            y = 1.0 / (1.0 + ((1.0 - y + 1e-6) / (y + 1e-6)) ** m.contrast)
            luts.append(np.clip(np.round(y * 255), 0, 255).astype(np.uint8))
        self._lut = np.stack(luts, axis=1)[:, None, :]  # (256, 1, 3) for cv2.LUT
        # vignetting as an 8-bit gain map (multiplied with scale 1/255)
        yy, xx = np.mgrid[0:self.height, 0:self.width].astype(np.float32)
        r2 = ((xx + 0.5 - self.cx) ** 2 + (yy + 0.5 - self.cy) ** 2) / (self.cx ** 2 + self.cy ** 2)
        vig = 1.0 - m.vignetting * r2 ** 1.5
        self._vig = np.repeat(np.clip(np.round(vig * 255), 0, 255).astype(np.uint8)[..., None], 3, axis=2)
        self._vig_on = m.vignetting > 0
        # distortion: for every output (distorted) pixel the undistorted source pixel
        self._map = None
        self.zoom = 1.0
        if m.distorts:
            K = np.array([[self.fx, 0, self.cx], [0, self.fx, self.cy], [0, 0, 1]], np.float64)
            dist = np.array([m.k1, m.k2, 0, 0], np.float64)
            self._K, self._dist = K, dist
            # zoom in just enough that every output pixel has a rendered source pixel (barrel
            # distortion would otherwise pull in content from outside the rendered frame)
            border = np.concatenate([np.stack([np.linspace(0, self.width, 17), np.full(17, e)], 1)
                                     for e in (0.0, self.height)] + [
                                     np.stack([np.full(17, e), np.linspace(0, self.height, 17)], 1)
                                     for e in (0.0, self.width)])

            def inside(z: float) -> bool:
                src = self._source(border, K, dist, z)
                return bool((src[:, 0] >= -0.5).all() and (src[:, 0] <= self.width + 0.5).all()
                            and (src[:, 1] >= -0.5).all() and (src[:, 1] <= self.height + 0.5).all())

            lo, hi = 1.0, 2.0
            if not inside(lo):
                for _ in range(30):
                    mid = 0.5 * (lo + hi)
                    lo, hi = (lo, mid) if inside(mid) else (mid, hi)
                self.zoom = hi
            pts = np.stack([xx + 0.5, yy + 0.5], -1).reshape(-1, 2)
            und = self._source(pts, K, dist, self.zoom).reshape(self.height, self.width, 2) - 0.5
            self._map = (und[..., 0].astype(np.float32), und[..., 1].astype(np.float32))
        # noise: sigma per output level (read + shot), in 1/8 levels (a uint8 table for cv2.LUT)
        levels = np.arange(256) / 255.0
        sigma = np.sqrt(m.read_noise ** 2 + (m.shot_noise ** 2) * levels)
        self._sigma8 = np.clip(np.round(sigma * 8), 0, 255).astype(np.uint8)
        self._noise_on = m.read_noise > 0 or m.shot_noise > 0
        self._bank: np.ndarray | None = None

    def _source(self, pts: np.ndarray, K: np.ndarray, dist: np.ndarray, zoom: float) -> np.ndarray:
        """Rendered (undistorted) pixel positions of output pixel positions ``pts`` (n, 2)."""
        Kd = K.copy()
        Kd[0, 0] = Kd[1, 1] = self.fx * zoom
        out = cv2.undistortPoints(np.asarray(pts, np.float64).reshape(-1, 1, 2), Kd, dist, P=K)
        return out.reshape(-1, 2)

    # ------------------------------------------------------------------ frames
    def reseed(self, rng: np.random.Generator) -> None:
        """Draw this episode's noise bank from ``rng`` (standard normal noise, int8 in 1/32 sigma):
        frames take shifted windows of it at offsets drawn from the same generator - cheap, and the
        same seed gives the same frames. :meth:`apply` draws it on first use."""
        if self.model.enabled and self._noise_on:
            bank = rng.standard_normal((self.height + 64, self.width + 64, 3), dtype=np.float32) * 32
            self._bank = np.clip(np.round(bank), -127, 127).astype(np.int8)

    def skip(self, rng: np.random.Generator, frames: int) -> None:
        """Draw from ``rng`` what :meth:`apply` draws for ``frames`` frames, so the next frame gets the
        noise frame number ``frames`` of the episode had (a recorded frame re-rendered exactly)."""
        if self.model.enabled and self._noise_on:
            for _ in range(frames):
                rng.integers(0, 64, 2)

    def apply(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The finished frame (a new uint8 array; ``rgb`` itself when the model is off). Draws from
        ``rng`` only for the noise."""
        m = self.model
        if not m.enabled:
            return rgb
        if rgb.shape != (self.height, self.width, 3):
            raise InputError(f"camera model prepared for {self.width}x{self.height}, got an image of shape {rgb.shape}")
        img = rgb
        if self._map is not None:
            img = cv2.remap(img, self._map[0], self._map[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if m.defocus_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), m.defocus_px)
        if self._vig_on:
            img = cv2.multiply(img, self._vig, scale=1 / 255.0)
        img = cv2.LUT(np.ascontiguousarray(img), self._lut)
        if self._noise_on:
            if self._bank is None:
                self.reseed(rng)
            bank = self._bank
            assert bank is not None  # reseed() made it
            oy, ox = (int(v) for v in rng.integers(0, 64, 2))
            n = bank[oy:oy + self.height, ox:ox + self.width]
            noise = np.multiply(cv2.LUT(img, self._sigma8), n, dtype=np.int16)  # sigma*8 * z*32
            np.right_shift(noise, 8, out=noise)  # / 256 = sigma * z
            img = cv2.add(img, noise, dtype=cv2.CV_8U)  # saturated to 0..255
        if m.jpeg_quality > 0:
            params = [cv2.IMWRITE_JPEG_QUALITY, int(m.jpeg_quality),
                      cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
                      cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420 if m.chroma_subsampling else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
            ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), params)
            if not ok:
                raise RuntimeError("JPEG encoding failed")
            img = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)  # type: ignore[arg-type]  # just encoded: never None
        elif m.chroma_subsampling:
            y, cr, cb = cv2.split(cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb))
            half, full = (max(1, self.width // 2), max(1, self.height // 2)), (self.width, self.height)
            cr, cb = (cv2.resize(cv2.resize(c, half, interpolation=cv2.INTER_AREA), full,
                                 interpolation=cv2.INTER_LINEAR) for c in (cr, cb))
            img = cv2.cvtColor(cv2.merge([y, cr, cb]), cv2.COLOR_YCrCb2RGB)
        return img

    def remap_nearest(self, a: np.ndarray, border) -> np.ndarray:
        """Move a per-pixel map (segmentation, depth) with the lens distortion (nearest pixel)."""
        if self._map is None or not self.model.enabled:
            return a
        return cv2.remap(a, self._map[0], self._map[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=border)

    def distort_points(self, uv: np.ndarray) -> np.ndarray:
        """Where undistorted pixel coordinates (n, 2) land in the distorted image."""
        uv = np.asarray(uv, np.float64)
        if not self.model.distorts:
            return uv
        return np.stack(self._distort_xy(uv[:, 0], uv[:, 1]), 1)

    def _distort_xy(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lens on pixel coordinates given as two arrays of any (equal) shape."""
        x = (u - self.cx) / self.fx
        y = (v - self.cy) / self.fx
        r2 = x * x + y * y
        f = (1 + self.model.k1 * r2 + self.model.k2 * r2 * r2) * self.zoom
        return x * f * self.fx + self.cx, y * f * self.fx + self.cy

    def undistort_points(self, uv: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`distort_points`: where pixel coordinates (n, 2) of the distorted image
        were in the undistorted (pinhole) image - what a calibrated perception stack computes before it
        turns a pixel into a bearing."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        if not self.model.distorts or len(uv) == 0:
            return uv
        return self._source(uv, self._K, self._dist, self.zoom)

    def distort_boxes(self, boxes: np.ndarray) -> np.ndarray:
        """Boxes (n, 4) xyxy in pixel edges after the distortion: the bounds of 8 points per edge
        (radial distortion bends straight edges; the extremes lie on the edges), clipped to the image."""
        boxes = np.asarray(boxes, np.float32)
        if not self.model.distorts or len(boxes) == 0:
            return boxes
        # 8 points along each edge, as one matrix product: (n, 4) xyxy @ (4, 64) -> 32 x and 32 y
        pts = boxes.astype(np.float64) @ _EDGE_POINTS
        x, y = self._distort_xy(pts[:, :32], pts[:, 32:])
        out = np.empty((len(boxes), 4), np.float32)  # the bounds, rounded to float32 as they are written
        np.minimum.reduce(x, 1, out=out[:, 0])
        np.minimum.reduce(y, 1, out=out[:, 1])
        np.maximum.reduce(x, 1, out=out[:, 2])
        np.maximum.reduce(y, 1, out=out[:, 3])
        np.maximum(out, 0, out=out)  # clipped to the image
        return np.minimum(out, np.array([self.width, self.height] * 2, np.float32), out=out)
