"""Procedural textures: cone colour bands, asphalt/kerb/grass ground painted from the track, sky panorama.

All deterministic functions of their inputs (seeds come from the ``Look``).

Example:
    >>> from weather_gym.sim.textures import cone_texture
    >>> cone_texture("blue").shape
    (64, 4, 3)
"""

from __future__ import annotations

import cv2
import numpy as np

from weather_gym.core.cone_spec import CONE_BODY_RGB, CONE_STRIPE_RGB

# stripe bands as (v_from, v_to) fractions of the cone height (0 = bottom)
STRIPES = {
    "blue": ((0.42, 0.62),),
    "yellow": ((0.42, 0.62),),
    "orange": ((0.42, 0.62),),
    "big_orange": ((0.30, 0.42), (0.56, 0.68)),
}


def cone_texture(cls: str, shade: tuple[float, float, float] = (1.0, 1.0, 1.0), rows: int = 64) -> np.ndarray:
    """Vertical colour strip (rows x 4 x RGB) for a cone mesh: row 0 is the TOP of the cone (image order)."""
    body = np.array(CONE_BODY_RGB[cls]) * 255 * np.array(shade)
    stripe = np.array(CONE_STRIPE_RGB[cls]) * 255
    tex = np.empty((rows, 4, 3), np.float64)
    tex[:] = body
    v = 1.0 - (np.arange(rows) + 0.5) / rows  # texture v of each row
    for lo, hi in STRIPES[cls]:
        tex[(v >= lo) & (v < hi)] = stripe
    return np.clip(tex, 0, 255).astype(np.uint8)


def _noise(rng: np.random.Generator, shape: tuple[int, int], scale: int) -> np.ndarray:
    """Smooth value noise in [-1, 1] with features about ``scale`` pixels wide."""
    small = rng.uniform(-1, 1, (max(2, shape[0] // scale + 2), max(2, shape[1] // scale + 2))).astype(np.float32)
    return cv2.resize(small, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)


def _periodic_noise(rng: np.random.Generator, height: int, width: int, scale: int) -> np.ndarray:
    """Smooth noise that wraps around horizontally (for a 360-degree panorama)."""
    cells = max(2, width // scale)
    small = rng.uniform(-1, 1, (max(2, height // scale + 2), cells)).astype(np.float32)
    tiled = cv2.resize(np.tile(small, (1, 3)), (3 * width, height), interpolation=cv2.INTER_CUBIC)
    return tiled[:, width : 2 * width]


def ground_texture(
    centerline: np.ndarray,
    half_width_left: np.ndarray,
    half_width_right: np.ndarray,
    closed: bool,
    extent: tuple[float, float, float, float],
    look,
    size: int = 2048,
) -> np.ndarray:
    """RGB texture (size x size) of the ground over ``extent`` = (x0, y0, x1, y1) metres.

    Asphalt along the centerline out to the cone lines plus a run-off margin, a light kerb line at
    the asphalt edge, grass elsewhere. Image row 0 is y1 (top), column 0 is x0.
    """
    x0, y0, x1, y1 = extent
    px_per_m = size / max(x1 - x0, y1 - y0)
    rng = np.random.default_rng(look.ground_seed)

    def to_px(xy: np.ndarray) -> np.ndarray:
        u = (xy[:, 0] - x0) * px_per_m
        v = (y1 - xy[:, 1]) * px_per_m
        return np.round(np.stack([u, v], axis=1) * 4).astype(np.int32)  # 2 bits sub-pixel

    width_m = float(np.median(half_width_left + half_width_right))
    asphalt_m = width_m + 2 * 1.6  # run-off beyond the cones
    pts = to_px(np.asarray(centerline, dtype=np.float64))
    road = np.zeros((size, size), np.uint8)
    kerb = np.zeros((size, size), np.uint8)
    thick_kerb = max(1, int(round((asphalt_m + 0.6) * px_per_m)))
    thick_road = max(1, int(round(asphalt_m * px_per_m)))
    cv2.polylines(kerb, [pts], closed, 255, thick_kerb, cv2.LINE_AA, shift=2)
    cv2.polylines(road, [pts], closed, 255, thick_road, cv2.LINE_AA, shift=2)
    road_f = road.astype(np.float32)[..., None] / 255.0
    kerb_f = kerb.astype(np.float32)[..., None] / 255.0

    grass = np.array(look.grass_rgb, np.float32) * (
        1 + 0.18 * _noise(rng, (size, size), 24)[..., None] + 0.10 * rng.standard_normal((size, size, 1)).astype(np.float32)
    )
    asphalt = np.array(look.asphalt_rgb, np.float32) * (
        1 + 0.06 * _noise(rng, (size, size), 64)[..., None] + 0.07 * rng.standard_normal((size, size, 1)).astype(np.float32)
    )
    kerb_rgb = np.array(look.kerb_rgb, np.float32)
    img = grass * (1 - kerb_f) + kerb_rgb * kerb_f
    img = img * (1 - road_f) + asphalt * road_f
    return np.clip(img, 0, 255).astype(np.uint8)


def sky_panorama(look, width: int = 2048, height: int = 256, max_elevation_deg: float = 60.0) -> np.ndarray:
    """Sky panorama (height x width RGB): columns span 360 deg of azimuth, rows elevation
    from ``max_elevation_deg`` (row 0) down to -10 deg (last row, distant ground haze)."""
    rng = np.random.default_rng(look.sky_seed)
    elev = np.linspace(max_elevation_deg, -10.0, height, dtype=np.float32)[:, None, None]
    t = np.clip(elev / max_elevation_deg, 0, 1) ** 0.6
    top = np.array(look.sky_top_rgb, np.float32)
    hor = np.array(look.sky_horizon_rgb, np.float32)
    sky = hor * (1 - t) + top * t
    sky = np.broadcast_to(sky, (height, width, 3)).copy()
    # clouds: thresholded smooth noise, wrapped horizontally so the panorama is seamless
    f = width // 2048 if width % 2048 == 0 and width >= 2048 else 1  # a finer panorama: same clouds, more pixels
    n = _periodic_noise(rng, height, width, 48 * f) + 0.5 * _periodic_noise(rng, height, width, 16 * f)
    thresh = 1.0 - 2.0 * look.cloud_cover
    cloud = np.clip((n - thresh) * 2.0, 0, 1)[..., None] * (elev > 0.5)
    cloud_rgb = np.array([235, 237, 240], np.float32)
    sky = sky * (1 - 0.85 * cloud) + cloud_rgb * 0.85 * cloud
    ground = np.array(look.grass_rgb, np.float32) * 0.85 + hor * 0.15
    below = np.clip(-elev / 1.0, 0, 1)  # 1 deg blend into the far ground
    sky = sky * (1 - below) + ground * below
    return np.clip(sky, 0, 255).astype(np.uint8)
