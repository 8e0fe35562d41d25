"""Procedural textures of the realistic scene: striped FS cones, asphalt and run-off tiles, the clutter
atlas, and a skyline (buildings, trees, poles) painted into the sky panorama.

Every function is a deterministic function of its arguments (seeds included), and each produces one of
a *finite* set of images for the values :func:`weather_gym.sim.randomize.sample_realistic` draws:
PyBullet keeps every texture it loaded for the life of the process, keyed by file path, so the
realistic world draws from palettes instead of making a new texture per episode.

Example:
    >>> from weather_gym.sim.scenery_textures import realistic_cone_texture, stripe_rows
    >>> tex = realistic_cone_texture("orange")
    >>> tex.shape, len(stripe_rows("orange")), len(stripe_rows("blue"))
    ((128, 8, 3), 2, 1)
"""

from __future__ import annotations

import cv2
import numpy as np

from weather_gym.core.errors import InputError

# FS cones (FSG handbook): blue with a white stripe, yellow with a black stripe, small orange with two
# white stripes, big orange with two white stripes. (v_from, v_to) fractions of the frustum height.
REALISTIC_STRIPES: dict[str, tuple[tuple[float, float], ...]] = {
    "blue": ((0.40, 0.62),),
    "yellow": ((0.40, 0.62),),
    "orange": ((0.30, 0.42), (0.54, 0.66)),
    "big_orange": ((0.28, 0.40), (0.52, 0.64)),
}
STRIPE_RGB: dict[str, tuple[float, float, float]] = {
    "blue": (236.0, 238.0, 240.0),
    "yellow": (22.0, 22.0, 24.0),
    "orange": (236.0, 238.0, 240.0),
    "big_orange": (236.0, 238.0, 240.0),
}
# matte plastic a bit less saturated than the plain world's primaries
BODY_RGB: dict[str, tuple[float, float, float]] = {
    "blue": (18.0, 62.0, 190.0),
    "yellow": (246.0, 200.0, 22.0),
    "orange": (250.0, 108.0, 18.0),
    "big_orange": (250.0, 108.0, 18.0),
}

TILE_PX = 128
ATLAS_TILES = 8  # the clutter atlas is ATLAS_TILES x ATLAS_TILES tiles of TILE_PX
ATLAS_PX = TILE_PX * ATLAS_TILES


def stripe_rows(cls: str, rows: int = 128) -> list[tuple[int, int]]:
    """Row ranges [r0, r1) of ``realistic_cone_texture(cls)`` that are stripe (row 0 = cone top)."""
    out = []
    for lo, hi in REALISTIC_STRIPES[cls]:
        out.append((int(round((1 - hi) * rows)), int(round((1 - lo) * rows))))
    return out


def realistic_cone_texture(cls: str, rows: int = 128, cols: int = 8) -> np.ndarray:
    """Vertical strip (rows x cols x RGB) for the cone mesh: body colour, the class's stripes, a little
    dirt towards the base and a slightly darker top (row 0 = top of the cone)."""
    if cls not in BODY_RGB:
        raise InputError(f"unknown cone class {cls!r}; expected one of {sorted(BODY_RGB)}")
    rng = np.random.default_rng(sum(map(ord, cls)))
    tex = np.empty((rows, cols, 3), np.float32)
    tex[:] = BODY_RGB[cls]
    for r0, r1 in stripe_rows(cls, rows):
        tex[r0:r1] = STRIPE_RGB[cls]
        if r1 - r0 > 2:  # soft stripe edges (the sleeve's edge catches light)
            tex[r0] = 0.5 * (tex[r0] + np.array(BODY_RGB[cls]))
            tex[r1 - 1] = 0.5 * (tex[r1 - 1] + np.array(BODY_RGB[cls]))
    v = 1.0 - (np.arange(rows) + 0.5) / rows
    dirt = np.clip((0.18 - v) / 0.18, 0, 1)[:, None, None] * 0.25  # scuffed, dusty base
    tex = tex * (1 - dirt) + np.array([95.0, 90.0, 85.0]) * dirt  # type: ignore[assignment]  # float64 from here on
    tex *= 1 + 0.03 * rng.standard_normal((rows, cols, 1)).astype(np.float32)
    return np.clip(tex, 0, 255).astype(np.uint8)


def _noise(rng: np.random.Generator, shape: tuple[int, int], scale: int) -> np.ndarray:
    """Smooth value noise in about [-1, 1], features ``scale`` px wide, tileable (wraps both ways)."""
    h, w = shape
    gh, gw = max(2, h // scale), max(2, w // scale)
    small = rng.uniform(-1, 1, (gh, gw)).astype(np.float32)
    big = cv2.resize(np.tile(small, (3, 3)), (3 * w, 3 * h), interpolation=cv2.INTER_CUBIC)
    return big[h:2 * h, w:2 * w]


def asphalt_tile(rgb, seed: int, size: int = 1024, lines: bool = True) -> np.ndarray:
    """Asphalt seen from above (square, tiles seamlessly along v): grain, white speckle (the aggregate),
    darker repair patches, cracks, tyre marks and - with ``lines`` - painted lines along both edges
    and a worn dashed line. Columns run across the road (u), rows along it (v)."""
    rng = np.random.default_rng([seed, 7])
    base = np.array(rgb, np.float32)
    n = 0.07 * _noise(rng, (size, size), 96) + 0.05 * _noise(rng, (size, size), 16)
    grain = rng.standard_normal((size, size)).astype(np.float32)
    img = base * (1 + n + 0.10 * grain)[..., None]
    # light aggregate speckle (what makes real asphalt look grey-white at a distance)
    speck = rng.random((size, size)) < 0.05
    img[speck] = np.minimum(img[speck] * 1.0 + 70.0, 255)
    dark = rng.random((size, size)) < 0.04
    img[dark] *= 0.6
    # repair patches: darker, smoother rectangles
    for _ in range(int(rng.integers(1, 4))):
        w, h = int(rng.integers(size // 10, size // 4)), int(rng.integers(size // 10, size // 3))
        x, y = int(rng.integers(0, size - w)), int(rng.integers(0, size - h))
        img[y:y + h, x:x + w] *= float(rng.uniform(0.72, 0.88))
    # cracks and tyre marks
    for _ in range(int(rng.integers(3, 8))):
        pts = np.cumsum(rng.normal(0, size / 40, (12, 2)), axis=0) + rng.uniform(0, size, 2)
        cv2.polylines(img, [pts.astype(np.int32)], False, (base * 0.45).tolist(), 2, cv2.LINE_AA)
    for _ in range(int(rng.integers(1, 4))):
        x = float(rng.uniform(0.1, 0.9) * size)  # type: ignore[assignment]  # the name reused for a float
        amp, ph = float(rng.uniform(5, 60)), float(rng.uniform(0, 6.28))
        ys = np.arange(0, size + 1, 16, dtype=np.float32)
        xs = x + amp * np.sin(ys / size * 2 * np.pi + ph)
        mark = np.zeros((size, size), np.float32)
        cv2.polylines(mark, [np.stack([xs, ys], 1).astype(np.int32)], False, 1.0, int(rng.integers(12, 30)))
        mark = cv2.GaussianBlur(mark, (0, 0), 6)  # type: ignore[assignment]  # cv2's stubs drop the float32 dtype
        img *= (1 - 0.25 * mark)[..., None]
    if lines:
        paint = np.array([228.0, 228.0, 222.0])
        for c0 in (int(0.03 * size), int(0.95 * size)):
            img[:, c0:c0 + max(2, size // 90)] = paint
        c0 = int(rng.uniform(0.15, 0.85) * size)
        for r in range(0, size, size // 4):
            img[r:r + size // 8, c0:c0 + max(2, size // 110)] = paint * 0.9
        wear = _noise(rng, (size, size), 8) > 0.35  # worn paint shows the asphalt
        img[wear] = np.minimum(img[wear], base * 1.1)
    return np.clip(img, 0, 255).astype(np.uint8)


def runoff_tile(rgb, seed: int, size: int = 512) -> np.ndarray:
    """Run-off beyond the asphalt (tileable): grass (a green ``rgb``) or gravel / paved lot (grey)."""
    rng = np.random.default_rng([seed, 11])
    base = np.array(rgb, np.float32)
    green = base[1] > base[0] * 1.1
    n = 0.15 * _noise(rng, (size, size), 64) + 0.08 * _noise(rng, (size, size), 12)
    fine = rng.standard_normal((size, size)).astype(np.float32) * (0.14 if green else 0.2)
    img = base * (1 + n + fine)[..., None]
    if not green:  # gravel: coarse light and dark stones
        for frac, gain in ((0.04, 1.5), (0.04, 0.6)):
            m = rng.random((size, size)) < frac
            img[m] *= gain
        img = cv2.GaussianBlur(img, (3, 3), 0)  # type: ignore[assignment]  # cv2's stubs drop the float32 dtype
    return np.clip(img, 0, 255).astype(np.uint8)


# ------------------------------------------------------------------------------------------ clutter atlas
SOLID_COLOURS: tuple[tuple[float, float, float], ...] = (
    (30, 30, 32), (70, 72, 76), (150, 150, 150), (225, 225, 222), (190, 30, 28), (28, 60, 150),
    (40, 110, 50), (235, 200, 40), (240, 110, 20), (24, 40, 90), (120, 80, 50), (210, 190, 160),
    (60, 140, 190), (160, 40, 120), (200, 200, 60), (235, 235, 235),
)
"""Plain colours (atlas row 7 and half of row 6): people's clothes, poles, tent frames, skin tones."""

# atlas tile indices: (row, col)
TILE_BANNER = [(0, c) for c in range(8)]  # advertising banners / fence covers
TILE_BARRIER = [(1, 0), (1, 1), (1, 2), (1, 3)]  # red/white, concrete, white, yellow/black
TILE_TYRES = [(1, 4), (1, 5)]
TILE_FENCE = [(1, 6), (1, 7)]
TILE_TENT = [(2, c) for c in range(8)]
TILE_DISTRACTOR = [(3, c) for c in range(8)]  # cone-coloured things that are not cones
TILE_BUILDING = [(4, c) for c in range(8)]  # containers, trailers, pit garages
TILE_SKIN = [(5, c) for c in range(4)]
TILE_SOLID = [(6, c) for c in range(8)] + [(7, c) for c in range(8)]


def _banner(rng, t: int) -> np.ndarray:
    bg = rng.choice([(230, 230, 230), (30, 40, 110), (200, 30, 30), (20, 20, 20), (240, 200, 30), (20, 120, 60)])
    img = np.empty((t, t, 3), np.float32)
    img[:] = bg
    for _ in range(int(rng.integers(2, 6))):  # letters / logos as blocks and circles
        col = tuple(float(c) for c in rng.integers(0, 255, 3))
        x, y = int(rng.integers(0, t - 20)), int(rng.integers(20, t - 30))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(10, 60)), y + int(rng.integers(6, 20))), col, -1)
        else:
            cv2.circle(img, (x + 10, y + 8), int(rng.integers(4, 14)), col, -1, cv2.LINE_AA)
    img[: t // 10] *= 0.8
    return img


def clutter_atlas(seed: int = 0) -> np.ndarray:
    """The clutter texture atlas (ATLAS_PX square, RGB); rows of tiles as listed by the TILE_* tables."""
    rng = np.random.default_rng([seed, 13])
    t = TILE_PX
    atlas = np.zeros((ATLAS_PX, ATLAS_PX, 3), np.float32)

    def put(rc, img):
        r, c = rc
        atlas[r * t:(r + 1) * t, c * t:(c + 1) * t] = img

    for rc in TILE_BANNER:
        put(rc, _banner(rng, t))
    stripes = np.arange(t)[None, :] // 16 % 2
    put(TILE_BARRIER[0], np.where(stripes[..., None] == 1, (200, 30, 30), (235, 235, 235)) * np.ones((t, 1, 1)))
    put(TILE_BARRIER[1], np.full((t, t, 3), 165.0) * (1 + 0.08 * rng.standard_normal((t, t, 1))))
    put(TILE_BARRIER[2], np.full((t, t, 3), 225.0) * (1 + 0.04 * rng.standard_normal((t, t, 1))))
    put(TILE_BARRIER[3], np.where(((np.arange(t)[None, :] + np.arange(t)[:, None]) // 20 % 2)[..., None] == 1,
                                  (240, 200, 30), (25, 25, 25)).astype(np.float32))
    for i, rc in enumerate(TILE_TYRES):
        rows = np.arange(t)[:, None] % 32
        g = np.where(rows < 3, 55.0, 28.0 + 6 * i) * np.ones((1, t))
        put(rc, np.repeat(g[..., None], 3, axis=2) * (1 + 0.1 * rng.standard_normal((t, t, 1))))
    for i, rc in enumerate(TILE_FENCE):  # mesh fence seen against a pale background
        img = np.full((t, t, 3), (150.0, 155.0, 150.0) if i == 0 else (60.0, 90.0, 60.0))
        for k in range(0, t, 8):
            img[k:k + 1] = 200 if i == 0 else 90
            img[:, k:k + 1] = 200 if i == 0 else 90
        img[:, :4] = img[:, -4:] = 120
        put(rc, img)
    for rc in TILE_TENT:
        col = rng.choice([(235, 235, 235), (30, 60, 160), (200, 30, 30), (40, 120, 60), (240, 240, 240),
                          (20, 20, 20), (240, 190, 30), (235, 235, 235)])
        img = np.empty((t, t, 3), np.float32)
        img[:] = col
        img[: t // 5] = (235, 235, 235) if sum(col) < 600 else (30, 60, 160)  # valance band
        put(rc, img * (1 + 0.03 * rng.standard_normal((t, t, 1))))
    # distractors: things in cone colours that are not FS cones (buckets, bins, bags, jackets, bollards)
    cone_cols = [BODY_RGB["blue"], BODY_RGB["yellow"], BODY_RGB["orange"], (250.0, 140.0, 30.0)]
    for i, rc in enumerate(TILE_DISTRACTOR):
        col = np.array(cone_cols[i % 4], np.float32)
        img = np.empty((t, t, 3), np.float32)
        img[:] = col
        if i >= 4:  # bands like a cone's stripe, at other heights / widths
            band = int(rng.integers(10, 40))
            y0 = int(rng.integers(10, t - band - 10))
            img[y0:y0 + band] = (235, 235, 235) if i % 4 != 1 else (25, 25, 25)
        put(rc, img * (1 + 0.04 * rng.standard_normal((t, t, 1))))
    for rc in TILE_BUILDING:  # container / trailer / garage walls: ribbed panels, a door
        col = np.array(rng.choice([(190, 190, 185), (120, 40, 35), (40, 70, 120), (230, 230, 225),
                                   (90, 110, 90), (200, 160, 60)]), np.float32)
        img = np.empty((t, t, 3), np.float32)
        img[:] = col
        img[:, ::6] *= 0.8
        if rng.random() < 0.6:
            x = int(rng.integers(10, t - 40))
            img[t // 3:, x:x + 30] = col * 0.4
        put(rc, img)
    skins = [(225, 185, 160), (190, 140, 110), (140, 95, 70), (90, 60, 45)]
    for rc, s in zip(TILE_SKIN, skins):
        put(rc, np.full((t, t, 3), s, np.float32))
    for rc, s in zip(TILE_SOLID, SOLID_COLOURS):  # type: ignore[assignment]  # s: float RGBs here
        put(rc, np.full((t, t, 3), s, np.float32) * (1 + 0.03 * rng.standard_normal((t, t, 1))))
    return np.clip(atlas, 0, 255).astype(np.uint8)


def tile_uv(rc: tuple[int, int], inset: float = 0.02) -> tuple[float, float, float, float]:
    """(u0, v0, u1, v1) of atlas tile ``rc`` (OBJ texture coordinates: v = 0 at the image's bottom)."""
    r, c = rc
    n = ATLAS_TILES
    e = inset / n
    return (c / n + e, 1 - (r + 1) / n + e, (c + 1) / n - e, 1 - r / n - e)


# ------------------------------------------------------------------------------------------ skyline
def add_skyline(pano: np.ndarray, seed: int, max_elevation_deg: float = 60.0, min_elevation_deg: float = -10.0,
                ground_rgb=(120.0, 120.0, 118.0)) -> np.ndarray:
    """Paint a horizon of buildings, pit garages, grandstands, trees and light poles into a sky
    panorama (rows = elevation from ``max_elevation_deg`` down to ``min_elevation_deg``, columns =
    360 deg of azimuth, wrapping). Returns a new array."""
    h, w = pano.shape[:2]
    rng = np.random.default_rng([seed, 17])
    img = pano.astype(np.float32).copy()
    rows_per_deg = (h - 1) / (max_elevation_deg - min_elevation_deg)

    def row(elev: float) -> int:
        return int(round((max_elevation_deg - elev) * rows_per_deg))

    horizon = row(0.0)
    # the far ground below the horizon: the paved paddock / grass, hazy
    img[horizon:] = np.array(ground_rgb, np.float32) * 0.9 + img[horizon:] * 0.1
    base = row(-0.4)
    x = 0
    while x < w:
        kind = rng.choice(["building", "trees", "gap", "stand", "trees", "building"])
        width = int(rng.integers(w // 120, w // 30))
        if kind == "gap":
            x += width
            continue
        top_elev = {"building": rng.uniform(1.0, 6.0), "trees": rng.uniform(1.5, 5.0),
                    "stand": rng.uniform(1.5, 3.5)}[kind]
        top = row(float(top_elev))
        cols = np.arange(x, x + width) % w
        if kind == "building":
            col = np.array(rng.choice([(235, 235, 232), (200, 200, 196), (170, 160, 150), (220, 215, 200),
                                       (90, 100, 120), (60, 70, 110)]), np.float32)
            block = np.empty((base - top, width, 3), np.float32)
            block[:] = col
            # windows / garage doors as bands
            for r in range(2, base - top - 2, max(3, (base - top) // 4)):
                block[r:r + max(1, (base - top) // 10), ::4] = col * 0.45
            if rng.random() < 0.5:  # coloured fascia (pit garages: blue/orange bands)
                band = max(1, (base - top) // 5)
                block[:band] = rng.choice([(30, 70, 170), (230, 120, 30), (200, 30, 30), (30, 30, 30)])
            img[top:base, cols] = block
        elif kind == "stand":
            for r in range(top, base):
                frac = (r - top) / max(1, base - top)
                img[r, cols] = np.array([150, 150, 160]) * (0.6 + 0.4 * frac) + rng.normal(0, 15, (width, 3))
        else:  # trees: a lumpy dark-green canopy
            prof = top + (np.abs(_noise(rng, (1, width), max(2, width // 6))[0]) * (base - top) * 0.6).astype(int)
            green = np.array(rng.choice([(50, 75, 45), (65, 90, 55), (40, 60, 40)]), np.float32)
            for j, c in enumerate(cols):
                n = base - prof[j]
                img[prof[j]:base, c] = green * (1 + 0.15 * rng.standard_normal((n, 1)))
        x += width
    # light poles / masts
    for _ in range(int(rng.integers(6, 16))):
        c = int(rng.integers(0, w))
        top = row(float(rng.uniform(5, 14)))
        img[top:base, c:c + 2] = (110, 110, 115)
        img[top:top + 3, max(0, c - 3):c + 5] = (200, 200, 200)
    # a soft edge so the skyline does not alias against the sky
    img[row(15.0):base + 2] = cv2.GaussianBlur(img[row(15.0):base + 2], (3, 3), 0)
    return np.clip(img, 0, 255).astype(np.uint8)
