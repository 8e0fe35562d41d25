"""The realistic scene's geometry: an asphalt strip with painted lines along the track, and track-side
clutter (fences, barriers, tyre stacks, banners, tents, poles, people, containers and cone-coloured
distractors that are *not* cones) placed from the track geometry and a layout seed.

Clutter is visual only (no collision) and never labelled: its bodies map to -1 in the world's
segmentation lookup. Every item keeps ``CLEARANCE_M`` beyond the cone lines of *every* part of the
track (checked on each corner of its footprint), so nothing stands in the corridor the car drives.
One layout is one merged mesh (one body, one draw call) with one shared texture atlas; layouts are
numbered ``0 .. CLUTTER_LAYOUTS - 1`` so that PyBullet's path-keyed mesh cache stays bounded.

The geometric ground truth (:mod:`weather_gym.sim.visibility`) ignores clutter: a cone behind a
tent still counts as visible there. The rendered (segmentation) ground truth is pixel exact.

Example:
    >>> import numpy as np
    >>> from weather_gym.tracks import load_track
    >>> from weather_gym.sim.scenery import clutter_layout, corridor_clearance
    >>> track = load_track("small_track")
    >>> items = clutter_layout(track, seed=3)
    >>> len(items) > 50
    True
    >>> corners = np.concatenate([it.footprint for it in items])
    >>> bool(corridor_clearance(track, corners).min() >= 1.5)
    True
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from weather_gym.core.errors import InputError
from weather_gym.sim import scenery_textures as tx

CLUTTER_LAYOUTS = 64
"""Number of distinct clutter layouts per track (``Look.clutter_seed`` in ``[0, CLUTTER_LAYOUTS)``)."""
CLEARANCE_M = 1.5
"""Minimum distance (m) of any clutter footprint corner beyond the cone line (the track's half width)."""
ASPHALT_RUNOFF_M = 6.0
"""Asphalt beyond the cone lines on each side (the realistic ground's strip)."""
ASPHALT_TILE_M = 16.0
RUNOFF_TILE_M = 8.0
STRIP_Z = 0.004


@dataclass(frozen=True)
class Prism:
    """An upright prism: ``footprint`` (k, 2) world x/y counter-clockwise, from ``z0`` to ``z1`` m;
    side faces textured with atlas tile ``side``, the top with ``top``."""

    footprint: np.ndarray
    z0: float
    z1: float
    side: tuple[int, int]
    top: tuple[int, int]
    wrap: bool = False  # cylinders: the tile wraps once around the sides


def _dense(track, step: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centerline points (n, 2), headings, left and right half widths every ``step`` m."""
    length = float(track.length) if track.closed else float(track.s[-1])
    s = np.arange(0.0, length, step)
    x, y, h = track.point_at(s)
    left, right = track.half_widths_at(s)
    return np.stack([np.asarray(x), np.asarray(y)], 1), np.asarray(h), np.asarray(left), np.asarray(right)


def corridor_clearance(track, points: np.ndarray) -> np.ndarray:
    """For each point (n, 2): its distance beyond the cone lines (m) - the distance to the nearest
    centerline sample minus that sample's larger half width; negative = inside the corridor."""
    c, _, left, right = _dense(track, 0.5)
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    half = np.maximum(left, right)
    out = np.empty(len(pts))
    for i in range(0, len(pts), 256):
        d = np.hypot(pts[i:i + 256, None, 0] - c[None, :, 0], pts[i:i + 256, None, 1] - c[None, :, 1])
        out[i:i + 256] = (d - half[None]).min(axis=1)
    return out


def _box(cx: float, cy: float, yaw: float, lx: float, ly: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    corners = np.array([[-lx, -ly], [lx, -ly], [lx, ly], [-lx, ly]]) * 0.5
    return corners @ np.array([[c, s], [-s, c]]) + [cx, cy]


def _cyl(cx: float, cy: float, r: float, k: int = 10) -> np.ndarray:
    a = np.linspace(0, 2 * math.pi, k, endpoint=False)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], 1)


# kind -> (weight, min offset, max offset beyond the cone line, m)
KINDS: dict[str, tuple[float, float, float]] = {
    "fence": (0.16, 4.0, 14.0),
    "barrier": (0.12, 2.5, 10.0),
    "tyres": (0.08, 2.0, 8.0),
    "banner": (0.10, 3.0, 14.0),
    "tent": (0.08, 8.0, 28.0),
    "pole": (0.08, 3.0, 25.0),
    "people": (0.14, 2.5, 22.0),
    "container": (0.06, 12.0, 30.0),
    "distractor": (0.18, CLEARANCE_M + 0.3, 8.0),
}


def _fence(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
           out: list[Prism]) -> None:
    """fence: a run of panels (mesh fence, sometimes with a banner cover)."""
    tile = pick(tx.TILE_FENCE + tx.TILE_BANNER)
    for k in range(int(rng.integers(2, 7))):
        px, py = x + k * 3.5 * math.cos(yaw), y + k * 3.5 * math.sin(yaw)
        out.append(Prism(_box(px, py, yaw, 3.45, 0.05), 0.0, 2.0, tile, (7, 1)))


def _barrier(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
             out: list[Prism]) -> None:
    """barrier: barrier."""
    tile = pick(tx.TILE_BARRIER)
    for k in range(int(rng.integers(2, 8))):
        px, py = x + k * 1.5 * math.cos(yaw), y + k * 1.5 * math.sin(yaw)
        out.append(Prism(_box(px, py, yaw, 1.45, 0.5), 0.0, 0.8, tile, tile))


def _tyres(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
           out: list[Prism]) -> None:
    """tyres: tyres."""
    tile = pick(tx.TILE_TYRES)
    for k in range(int(rng.integers(1, 5))):
        px, py = x + k * 0.62 * math.cos(yaw), y + k * 0.62 * math.sin(yaw)
        out.append(Prism(_cyl(px, py, 0.3), 0.0, 0.22 * int(rng.integers(2, 6)), tile, (7, 0), wrap=True))


def _banner(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
            out: list[Prism]) -> None:
    """banner: banner."""
    tile = pick(tx.TILE_BANNER)
    length = float(rng.uniform(2.0, 6.0))
    z0 = float(rng.choice([0.0, 0.0, 1.5, 3.0]))
    out.append(Prism(_box(x, y, yaw, length, 0.04), z0, z0 + float(rng.uniform(0.6, 1.2)), tile, (7, 3)))
    if z0 > 0:  # on two posts
        for e in (-0.5, 0.5):
            px, py = x + e * length * math.cos(yaw), y + e * length * math.sin(yaw)
            out.append(Prism(_box(px, py, yaw, 0.08, 0.08), 0.0, z0, (7, 2), (7, 2)))


def _tent(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
          out: list[Prism]) -> None:
    """tent: a gazebo: canopy on four legs, sometimes a back wall."""
    tile = pick(tx.TILE_TENT)
    size = float(rng.choice([3.0, 3.0, 4.5, 6.0]))
    h = float(rng.uniform(2.1, 2.5))
    out.append(Prism(_box(x, y, yaw, size, size), h, h + 0.35, tile, tile))
    for ex, ey in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        lx, ly = 0.47 * size * ex, 0.47 * size * ey
        px = x + lx * math.cos(yaw) - ly * math.sin(yaw)
        py = y + lx * math.sin(yaw) + ly * math.cos(yaw)
        out.append(Prism(_box(px, py, yaw, 0.06, 0.06), 0.0, h, (7, 2), (7, 2)))
    if rng.random() < 0.6:
        bx, by = x + nx * 0.48 * size, y + ny * 0.48 * size
        out.append(Prism(_box(bx, by, yaw, size, 0.03), 0.0, h, tile, tile))
    for _ in range(int(rng.integers(0, 3))):  # a table / boxes under it
        out.append(Prism(_box(x + rng.uniform(-1, 1), y + rng.uniform(-1, 1), yaw, 1.2, 0.6), 0.0, 0.75,
                         pick(tx.TILE_SOLID), pick(tx.TILE_SOLID)))


def _pole(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
          out: list[Prism]) -> None:
    """pole: pole."""
    h = float(rng.uniform(3.0, 10.0))
    out.append(Prism(_cyl(x, y, 0.07, 6), 0.0, h, (6, 2), (6, 2), wrap=True))
    if rng.random() < 0.5:
        out.append(Prism(_box(x, y, yaw, 0.6, 0.25), h, h + 0.2, (6, 3), (6, 3)))


def _people(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
            out: list[Prism]) -> None:
    """people: a group of people: legs, torso, head."""
    for _ in range(int(rng.integers(1, 5))):
        px, py = x + rng.uniform(-1.5, 1.5), y + rng.uniform(-1.5, 1.5)
        a = float(rng.uniform(0, 2 * math.pi))
        scale = float(rng.uniform(0.9, 1.08))
        legs = pick(tx.TILE_SOLID[:4] + tx.TILE_SOLID[9:10] + tx.TILE_SOLID[5:6])
        torso = pick(tx.TILE_SOLID + tx.TILE_DISTRACTOR[:4])  # hi-vis jackets in cone colours too
        skin = pick(tx.TILE_SKIN)
        out.append(Prism(_box(px, py, a, 0.32, 0.2), 0.0, 0.85 * scale, legs, legs))
        out.append(Prism(_box(px, py, a, 0.44, 0.24), 0.85 * scale, 1.45 * scale, torso, torso))
        out.append(Prism(_box(px, py, a, 0.19, 0.21), 1.47 * scale, 1.72 * scale, skin, pick(tx.TILE_SOLID[:3])))


def _container(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
               out: list[Prism]) -> None:
    """container: container / trailer / pit box."""
    tile = pick(tx.TILE_BUILDING)
    lx, ly, lz = float(rng.choice([6.0, 12.0])), 2.4, float(rng.choice([2.6, 2.9]))
    out.append(Prism(_box(x, y, yaw, lx, ly), 0.0, lz, tile, (6, 2)))


def _distractor(rng: np.random.Generator, pick: Callable, x: float, y: float, yaw: float, nx: float, ny: float,
                out: list[Prism]) -> None:
    """distractor: cone-coloured things that are not cones (never labelled)."""
    tile = pick(tx.TILE_DISTRACTOR)
    shape = int(rng.integers(4))
    if shape == 0:  # bucket / bin
        r, h = float(rng.uniform(0.14, 0.3)), float(rng.uniform(0.3, 0.9))
        out.append(Prism(_cyl(x, y, r), 0.0, h, tile, tile, wrap=True))
    elif shape == 1:  # bollard / post
        out.append(Prism(_cyl(x, y, float(rng.uniform(0.05, 0.1)), 8), 0.0, float(rng.uniform(0.6, 1.1)),
                         tile, tile, wrap=True))
    elif shape == 2:  # crate / bag / box
        a = float(rng.uniform(0, math.pi))
        out.append(Prism(_box(x, y, a, float(rng.uniform(0.25, 0.7)), float(rng.uniform(0.2, 0.5))), 0.0,
                         float(rng.uniform(0.15, 0.5)), tile, tile))
    else:  # a flag / sign board
        out.append(Prism(_box(x, y, yaw, float(rng.uniform(0.4, 1.2)), 0.03), 0.0, float(rng.uniform(0.4, 1.0)),
                         tile, tile))


_KIND_ITEMS: dict[str, Callable] = {"fence": _fence, "barrier": _barrier, "tyres": _tyres, "banner": _banner,
                                    "tent": _tent, "pole": _pole, "people": _people, "container": _container,
                                    "distractor": _distractor}


def _items(kind: str, rng: np.random.Generator, x: float, y: float, yaw: float, side: int) -> list[Prism]:
    """The prisms of one clutter item of ``kind`` at (x, y), facing the track along ``yaw``."""
    pick = lambda tiles: tiles[int(rng.integers(len(tiles)))]  # noqa: E731
    out: list[Prism] = []
    nx, ny = -math.sin(yaw) * side, math.cos(yaw) * side  # away from the track
    _KIND_ITEMS[kind](rng, pick, x, y, yaw, nx, ny, out)
    return out


def clutter_layout(track, seed: int, density: float = 1.0) -> list[Prism]:
    """The clutter of layout ``seed`` along ``track`` (``density`` scales the number of items)."""
    if not 0 <= int(seed) < CLUTTER_LAYOUTS:
        raise InputError(f"clutter layout must lie in [0, {CLUTTER_LAYOUTS}), got {seed}")
    rng = np.random.default_rng([int(seed), 2024])
    c, h, left, right = _dense(track, 1.0)
    names = list(KINDS)
    weights = np.array([KINDS[k][0] for k in names])
    weights /= weights.sum()
    items: list[Prism] = []
    s = float(rng.uniform(0, 4))
    n = len(c)
    while s < n - 1:
        i = int(s)
        kind = names[int(rng.choice(len(names), p=weights))]
        _, lo, hi = KINDS[kind]
        side = 1 if rng.random() < 0.5 else -1
        half = left[i] if side > 0 else right[i]
        off = half + float(rng.uniform(lo, hi))
        x = c[i, 0] - side * off * math.sin(h[i])
        y = c[i, 1] + side * off * math.cos(h[i])
        yaw = float(h[i] + rng.normal(0, 0.05))
        new = _items(kind, rng, float(x), float(y), yaw, side)
        corners = np.concatenate([p.footprint for p in new])
        if corridor_clearance(track, corners).min() >= CLEARANCE_M:
            items.extend(new)
        s += float(rng.uniform(1.5, 5.0)) / max(density, 1e-3)
    return items


def clutter_obj(items: list[Prism]) -> str:
    """One OBJ mesh of all ``items`` (texture coordinates into the clutter atlas)."""
    v: list[str] = []
    vt: list[str] = []
    vn: list[str] = []
    f: list[str] = []
    nv = nt = nn = 0
    for it in items:
        fp = it.footprint
        k = len(fp)
        u0, v0, u1, v1 = tx.tile_uv(it.side)
        for j in range(k):
            a, b = fp[j], fp[(j + 1) % k]
            dx, dy = b[0] - a[0], b[1] - a[1]
            ln = math.hypot(dx, dy) or 1.0
            vn.append(f"vn {dy / ln:.4f} {-dx / ln:.4f} 0")
            nn += 1
            if it.wrap:
                ua, ub = u0 + (u1 - u0) * j / k, u0 + (u1 - u0) * (j + 1) / k
            else:
                ua, ub = u0, u1
            for (px, py), z in ((a, it.z0), (b, it.z0), (b, it.z1), (a, it.z1)):
                v.append(f"v {px:.3f} {py:.3f} {z:.3f}")
            for uu, vv in ((ua, v0), (ub, v0), (ub, v1), (ua, v1)):
                vt.append(f"vt {uu:.4f} {vv:.4f}")
            # outward normal for a counter-clockwise footprint; faces wound to match
            q = [nv + 1, nv + 2, nv + 3, nv + 4]
            t = [nt + 1, nt + 2, nt + 3, nt + 4]
            f.append(f"f {q[0]}/{t[0]}/{nn} {q[1]}/{t[1]}/{nn} {q[2]}/{t[2]}/{nn}")
            f.append(f"f {q[0]}/{t[0]}/{nn} {q[2]}/{t[2]}/{nn} {q[3]}/{t[3]}/{nn}")
            nv += 4
            nt += 4
        # top cap (fan)
        u0, v0, u1, v1 = tx.tile_uv(it.top)
        vn.append("vn 0 0 1")
        nn += 1
        base = nv + 1
        for px, py in fp:
            v.append(f"v {px:.3f} {py:.3f} {it.z1:.3f}")
        vt.append(f"vt {0.5 * (u0 + u1):.4f} {0.5 * (v0 + v1):.4f}")
        nt += 1
        for j in range(1, k - 1):
            f.append(f"f {base}/{nt}/{nn} {base + j}/{nt}/{nn} {base + j + 1}/{nt}/{nn}")
        nv += k
    return "\n".join(["# weather-gym clutter", *v, *vt, *vn, *f]) + "\n"


def asphalt_strip_obj(track, runoff_m: float = ASPHALT_RUNOFF_M, tile_m: float = ASPHALT_TILE_M,
                      z: float = STRIP_Z) -> str:
    """The asphalt along the track as a triangle strip: from ``runoff_m`` beyond the left cone line
    to ``runoff_m`` beyond the right one; ``u`` runs across (0 left .. 1 right), ``v`` along
    (one texture tile per ``tile_m`` metres)."""
    c, h, left, right = _dense(track, 1.0)
    if track.closed:
        c, h, left, right = (np.concatenate([a, a[:1]]) for a in (c, h, left, right))
    nrm = np.stack([-np.sin(h), np.cos(h)], 1)
    lp = c + nrm * (left + runoff_m)[:, None]
    rp = c - nrm * (right + runoff_m)[:, None]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(c, axis=0).T))]) / tile_m
    lines = ["# weather-gym asphalt strip"]
    for a, b in zip(lp, rp):
        lines.append(f"v {a[0]:.3f} {a[1]:.3f} {z}")
        lines.append(f"v {b[0]:.3f} {b[1]:.3f} {z}")
    for sv in s:
        lines.append(f"vt 0 {sv:.4f}")
        lines.append(f"vt 1 {sv:.4f}")
    lines.append("vn 0 0 1")
    for i in range(len(c) - 1):
        a, b, cc, d = 2 * i + 1, 2 * i + 2, 2 * i + 3, 2 * i + 4  # left_i, right_i, left_i+1, right_i+1
        lines.append(f"f {b}/{b}/1 {d}/{d}/1 {cc}/{cc}/1")
        lines.append(f"f {b}/{b}/1 {cc}/{cc}/1 {a}/{a}/1")
    return "\n".join(lines) + "\n"


def shadow_disc_obj(radius: float, segments: int = 20, z: float = 0.008) -> str:
    """A flat disc just above the asphalt: a cone's soft contact shadow (drawn translucent)."""
    a = np.linspace(0, 2 * math.pi, segments, endpoint=False)
    lines = ["# weather-gym contact shadow", f"v 0 0 {z}"]
    lines += [f"v {radius * math.cos(t):.4f} {radius * math.sin(t):.4f} {z}" for t in a]
    lines.append("vn 0 0 1")
    lines += [f"f 1//1 {i + 2}//1 {(i + 1) % segments + 2}//1" for i in range(segments)]
    return "\n".join(lines) + "\n"
