"""Hidden effects written independently of the weather library, in shapes its families do not have.

The gap workflow is proven on truths outside its own effect families: other tone curves (gamma,
S-curve), sensor noise with a gain and read noise (Poisson-Gaussian, drawn per pixel), other blur
kernels (disc, box, anisotropic Gaussian), other radial fall-offs (cos^4, a polynomial), JPEG by
OpenCV's encoder. Each is a plain function ``f(img, rng) -> img`` on 8-bit RGB; :func:`hide` copies
a COCO folder with one of them applied to every frame (PNG, the annotations unchanged, poses
stripped on request). Used by ``tests/lab/gap/test_gap_hidden.py`` and ``benchmarks/gap_hidden.py``.

Example:
    >>> import numpy as np
    >>> out = CASES["tone_gamma"](np.full((4, 4, 3), 128, np.uint8), np.random.default_rng(0))
    >>> int(out[0, 0, 0]) < 128
    True
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

Hidden = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def _lin(img: np.ndarray) -> np.ndarray:
    v = img.astype(np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _enc(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.clip(np.rint(255.0 * v), 0, 255).astype(np.uint8)


def tone_gamma(img: np.ndarray, rng: np.random.Generator, gamma: float = 1.8) -> np.ndarray:
    """A strong gamma on the code values (darker mid-tones, black and white fixed)."""
    lut = np.clip(np.rint(255.0 * (np.arange(256) / 255.0) ** gamma), 0, 255).astype(np.uint8)
    return cv2.LUT(img, lut)


def tone_scurve(img: np.ndarray, rng: np.random.Generator, gain: float = 9.0) -> np.ndarray:
    """A logistic S-curve (contrastier than any blend with smoothstep), rescaled to keep 0 and 255."""
    v = np.arange(256) / 255.0
    s = 1.0 / (1.0 + np.exp(-gain * (v - 0.5)))
    s = (s - s[0]) / (s[-1] - s[0])
    return cv2.LUT(img, np.clip(np.rint(255.0 * s), 0, 255).astype(np.uint8))


def sensor_noise(img: np.ndarray, rng: np.random.Generator, electrons: float = 120.0, read_e: float = 6.0,
                 gain: float = 1.0) -> np.ndarray:
    """Shot noise (Poisson, ``electrons`` at full scale) plus Gaussian read noise in linear light."""
    x = _lin(img)
    e = rng.poisson(x * electrons).astype(np.float64) + rng.normal(0.0, read_e, x.shape)
    return _enc(gain * e / electrons)


def _conv(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    kernel = kernel / kernel.sum()
    return cv2.filter2D(img, -1, kernel.astype(np.float32), borderType=cv2.BORDER_REFLECT)


def disc_blur(img: np.ndarray, rng: np.random.Generator, radius_frac: float = 0.006) -> np.ndarray:
    """Defocus with a hard-edged disc kernel (radius a fraction of the width)."""
    r = max(radius_frac * img.shape[1], 1.0)
    n = int(np.ceil(r))
    y, x = np.mgrid[-n:n + 1, -n:n + 1]
    return _conv(img, (np.hypot(x, y) <= r).astype(np.float64))


def box_motion(img: np.ndarray, rng: np.random.Generator, length_frac: float = 0.02,
               angle_deg: float = 15.0) -> np.ndarray:
    """A straight motion streak (a line kernel drawn at ``angle_deg``), box-weighted."""
    length = max(length_frac * img.shape[1], 2.0)
    n = int(np.ceil(length / 2)) + 1
    k = np.zeros((2 * n + 1, 2 * n + 1), np.float64)
    a = np.deg2rad(angle_deg)
    for t in np.linspace(-length / 2, length / 2, int(4 * length) + 1):
        k[int(round(n - t * np.sin(a))), int(round(n + t * np.cos(a)))] += 1.0
    return _conv(img, k)


def aniso_blur(img: np.ndarray, rng: np.random.Generator, sx_frac: float = 0.006, sy_frac: float = 0.0015) -> np.ndarray:
    """An anisotropic Gaussian (astigmatism): wider across than up."""
    sx, sy = sx_frac * img.shape[1], sy_frac * img.shape[1]
    return cv2.GaussianBlur(img, (0, 0), sigmaX=sx, sigmaY=sy, borderType=cv2.BORDER_REFLECT)


def _radial(img: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    return np.hypot(x + 0.5 - w / 2, y + 0.5 - h / 2) / (0.5 * np.hypot(w, h))


def falloff_cos4(img: np.ndarray, rng: np.random.Generator, half_fov_deg: float = 45.0) -> np.ndarray:
    """The cos^4 law of a wide lens: linear light times cos(theta)^4, theta reaching ``half_fov_deg`` at the corner."""
    r = _radial(img)
    theta = np.arctan(r * np.tan(np.deg2rad(half_fov_deg)))
    return _enc(_lin(img) * (np.cos(theta) ** 4)[..., None])


def falloff_poly(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A polynomial fall-off on the code values: 1 - 0.25 r^2 - 0.35 r^4."""
    r = _radial(img)
    g = np.clip(1.0 - 0.25 * r ** 2 - 0.35 * r ** 4, 0.0, 1.0)
    return np.clip(np.rint(img * g[..., None]), 0, 255).astype(np.uint8)


def jpeg(img: np.ndarray, rng: np.random.Generator, quality: int = 12) -> np.ndarray:
    """Re-encoding by OpenCV's JPEG encoder at ``quality``."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def low_light(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A dark scene: a disc blur (slow lens, long exposure) then strong shot and read noise."""
    return sensor_noise(disc_blur(img, rng, 0.005), rng, electrons=60.0, read_e=4.0)


def none(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Nothing hidden (the negative control): the frame as it is."""
    return img.copy()


#: case -> hidden function
CASES: dict[str, Hidden] = {"none": none,
    "tone_gamma": tone_gamma, "tone_scurve": tone_scurve, "sensor_noise": sensor_noise, "disc_blur": disc_blur,
    "box_motion": box_motion, "aniso_blur": aniso_blur, "falloff_cos4": falloff_cos4, "falloff_poly": falloff_poly,
    "jpeg": jpeg, "low_light": low_light,
}
#: the family a case belongs to: the names the workflow may give it first (a measured member of the
#: family is named by its kind)
FAMILY: dict[str, tuple[str, ...]] = {"none": (),
    "tone_gamma": ("exposure", "tone_curve"), "tone_scurve": ("exposure", "tone_curve"),
    "sensor_noise": ("noise", "noise_level"), "disc_blur": ("blur", "blur_kernel"),
    "box_motion": ("motion_blur", "blur_kernel"), "aniso_blur": ("blur", "motion_blur", "blur_kernel"),
    "falloff_cos4": ("vignette", "radial_gain"), "falloff_poly": ("vignette", "radial_gain"), "jpeg": ("jpeg",),
    "low_light": ("noise", "noise_level", "blur", "blur_kernel"),
}


def hide(src: str | Path, dst: str | Path, case: str, *, seed: int = 4242, strip_poses: bool = False) -> Path:
    """Copy the COCO folder ``src`` to ``dst`` with hidden effect ``case`` applied to every frame."""
    src, dst = Path(src), Path(dst)
    data = json.loads((src / "annotations.json").read_text())
    fn = CASES[case]
    for i, rec in enumerate(data["images"]):
        img = cv2.cvtColor(cv2.imread(str(src / rec["file_name"]), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        out = fn(img, np.random.default_rng([seed, i]))
        name = str(Path(rec["file_name"]).with_suffix(".png"))
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(dst / name), cv2.cvtColor(out, cv2.COLOR_RGB2BGR))
        rec["file_name"] = name
        for key in ("depth_file", "ignore_mask"):
            if rec.get(key):
                (dst / rec[key]).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src / rec[key], dst / rec[key])
        if strip_poses:
            for key in ("pose", "look", "seed", "episode", "step"):
                rec.pop(key, None)
    mask = (data.get("info") or {}).get("ignore_mask")
    if mask:
        shutil.copyfile(src / mask, dst / mask)
    (dst / "annotations.json").write_text(json.dumps(data))
    return dst
