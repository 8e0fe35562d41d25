"""Polyline geometry behind :mod:`weather_gym.tracks` (private: no stable API).

Everything here works on plain numpy arrays: ``(N, 2)`` float64 polylines, ``closed`` flags.
The cone-to-centerline reconstruction follows the usual Formula Student approach: a Delaunay
triangulation of the boundary cones, whose blue-yellow edges cross the track; their midpoints,
chained through the triangles they share, give the centerline in order without any guess
about the track's shape (works for peanut and B-shaped layouts where angular sorting fails).

Example:
    >>> import numpy as np
    >>> square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    >>> float(polyline_length(square, closed=True))
    16.0
"""

from __future__ import annotations

from typing import cast

import numpy as np
import shapely
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial import Delaunay, QhullError

STEP_M = 0.5
"""Centerline point spacing."""


# ---------------------------------------------------------------------------------------------
# basic polyline helpers


def segments(points: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Segment start points and vectors (closed: includes the last -> first segment)."""
    end = np.roll(points, -1, axis=0) if closed else points[1:]
    start = points if closed else points[:-1]
    return start, end - start


def cumulative_length(points: np.ndarray, closed: bool) -> tuple[np.ndarray, float]:
    """Arc length at each point (starting at 0) and the total length."""
    _, d = segments(points, closed)
    seg = np.hypot(d[:, 0], d[:, 1])
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return (s[:-1], float(s[-1])) if closed else (s, float(s[-1]))


def polyline_length(points: np.ndarray, closed: bool) -> float:
    return cumulative_length(points, closed)[1]


def resample(points: np.ndarray, closed: bool, step: float = STEP_M, start_s: float = 0.0) -> np.ndarray:
    """Points every ~``step`` metres along the polyline (closed: exactly length/M, from ``start_s``)."""
    pts = np.concatenate([points, points[:1]]) if closed else points
    s, total = cumulative_length(pts, closed=False)
    keep = np.concatenate([[True], np.diff(s) > 1e-9])
    pts, s = pts[keep], s[keep]
    n = max(int(round(total / step)), 3)
    if closed:
        q = (start_s + np.arange(n) * (total / n)) % total
    else:
        q = np.linspace(0.0, total, n + 1)
    return np.column_stack([np.interp(q, s, pts[:, 0]), np.interp(q, s, pts[:, 1])])


def smooth(points: np.ndarray, closed: bool, sigma_m: float, step: float = STEP_M, debias: bool = False) -> np.ndarray:
    """Gaussian smoothing along the arc length, then uniform resampling.

    ``debias`` uses ``2 S(p) - S(S(p))`` ("twicing"), which cancels most of the inward shift
    plain smoothing gives a curve in its bends, so the line stays centred between its cones.
    """
    pts = resample(points, closed, step)
    mode = "wrap" if closed else "nearest"

    def gauss(p: np.ndarray) -> np.ndarray:
        return np.column_stack([gaussian_filter1d(p[:, i], sigma_m / step, mode=mode) for i in range(2)])

    out = gauss(pts)
    if debias:
        out = 2.0 * out - gauss(out)
    if not closed:  # keep the end points where they were (nearest-mode pulls them inwards)
        out[0], out[-1] = pts[0], pts[-1]
    return resample(out, closed, step)


def headings(points: np.ndarray, closed: bool) -> np.ndarray:
    """Tangent direction at each point (central differences; one-sided at open ends)."""
    if closed:
        d = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        d = np.gradient(points, axis=0)
    return cast(np.ndarray, np.arctan2(d[:, 1], d[:, 0]))


def curvatures(points: np.ndarray, closed: bool) -> np.ndarray:
    """Signed Menger curvature (1/m, positive = turning left) at each point."""
    p0 = np.roll(points, 1, axis=0)
    p2 = np.roll(points, -1, axis=0)
    a, b, c = points - p0, p2 - points, p2 - p0
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    denom = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1)
    k: np.ndarray = np.divide(2.0 * cross, denom, out=np.zeros(len(points)), where=denom > 1e-12)
    if not closed and len(k) > 2:
        k[0], k[-1] = k[1], k[-2]
    return k


def point_segment_distance(
    pts: np.ndarray, poly: np.ndarray, closed: bool, extend_ends: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point: distance to the nearest polyline segment, that segment's index and parameter t.

    ``extend_ends`` (open polylines) treats the first and last segments as rays, so points beyond
    the ends measure their distance to the extended boundary line.
    """
    a, d = segments(poly, closed)
    len2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    rel = pts[:, None, :] - a[None, :, :]
    t = np.einsum("nkj,kj->nk", rel, d) / len2
    lo = np.zeros(len(a))
    hi = np.ones(len(a))
    if extend_ends and not closed:
        lo[0], hi[-1] = -np.inf, np.inf
    t = np.clip(t, lo, hi)
    diff = rel - t[..., None] * d[None]
    dist2 = np.einsum("nkj,nkj->nk", diff, diff)
    k = np.argmin(dist2, axis=1)
    rows = np.arange(len(pts))
    return np.sqrt(dist2[rows, k]), k, t[rows, k]


def signed_lateral(pts: np.ndarray, poly: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of points to a polyline (positive = left) and their arc length along it."""
    dist, k, t = point_segment_distance(pts, poly, closed, extend_ends=True)
    a, d = segments(poly, closed)
    rel = pts - a[k]
    cross = d[k, 0] * rel[:, 1] - d[k, 1] * rel[:, 0]
    s, _ = cumulative_length(poly, closed)
    if not closed:
        s = s[:-1]
    return np.where(cross >= 0, dist, -dist), s[k] + t * np.hypot(d[k, 0], d[k, 1])


def self_intersects(poly: np.ndarray, closed: bool) -> bool:
    """True if the polyline crosses or touches itself (``shapely``: not a simple line or ring)."""
    return not bool(shapely.is_simple(shapely.linearrings(poly) if closed else shapely.linestrings(poly)))


def fit_circle(pts: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares (Kasa) circle fit: centre, radius and the RMS radial residual."""
    A = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    b = (pts**2).sum(axis=1)
    (cx2, cy2, c), *_ = np.linalg.lstsq(A, b, rcond=None)
    centre = np.array([cx2 / 2.0, cy2 / 2.0])
    radius = float(np.sqrt(c + centre @ centre))
    resid = float(np.sqrt(np.mean((np.linalg.norm(pts - centre, axis=1) - radius) ** 2)))
    return centre, radius, resid


# ---------------------------------------------------------------------------------------------
# cones -> ordered centerline


def mixed_edge_chain(points: np.ndarray, side: np.ndarray) -> tuple[np.ndarray, bool]:
    """Ordered midpoints of the Delaunay edges joining a left cone to a right cone.

    ``side`` is +1 (left) / -1 (right) per point. Every triangle with both sides has exactly two
    such edges, so the edges chain through the triangles into a path (open lane) or a cycle
    (closed track). Returns the midpoints of the longest chain and whether it is a cycle.
    """
    if len(points) < 3 or (side > 0).sum() == 0 or (side < 0).sum() == 0:
        return np.empty((0, 2)), False
    try:
        tri = Delaunay(points)
    except QhullError:  # all cones on one line (or another degenerate layout): no triangles, no track
        return np.empty((0, 2)), False
    links: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for simplex in tri.simplices:
        mixed = []
        for u, v in ((simplex[0], simplex[1]), (simplex[1], simplex[2]), (simplex[2], simplex[0])):
            if side[u] != side[v]:
                mixed.append((min(u, v), max(u, v)))
        if len(mixed) == 2:
            e0, e1 = mixed
            links.setdefault(e0, []).append(e1)
            links.setdefault(e1, []).append(e0)
    best: list[tuple[int, int]] = []
    best_closed = False
    seen: set[tuple[int, int]] = set()
    for key in sorted(links):
        if key in seen:
            continue
        comp = _component(key, links)
        seen.update(comp)
        ends = sorted(e for e in comp if len(links[e]) == 1)
        start = ends[0] if ends else min(comp)
        order = _walk(start, links)
        if len(order) > len(best):
            best, best_closed = order, not ends
    mids = np.array([(points[u] + points[v]) / 2.0 for u, v in best]).reshape(-1, 2)
    return mids, best_closed


def _component(key: tuple[int, int], links: dict[tuple[int, int], list[tuple[int, int]]]) -> set[tuple[int, int]]:
    stack, comp = [key], {key}
    while stack:
        for nxt in links[stack.pop()]:
            if nxt not in comp:
                comp.add(nxt)
                stack.append(nxt)
    return comp


def _walk(start: tuple[int, int], links: dict[tuple[int, int], list[tuple[int, int]]]) -> list[tuple[int, int]]:
    order, prev, cur = [start], None, start
    while True:
        nxt = [e for e in links[cur] if e != prev and e != start]
        nxt = [e for e in nxt if e not in order[-2:]]
        if not nxt:
            return order
        prev, cur = cur, nxt[0]
        order.append(cur)


def order_by_arc(pts: np.ndarray, line: np.ndarray, closed: bool) -> np.ndarray:
    """Indices sorting ``pts`` by the arc length of their projection on ``line``."""
    _, s = signed_lateral(pts, line, closed)
    return np.argsort(s, kind="stable")


def half_widths(
    centerline: np.ndarray, left: np.ndarray, right: np.ndarray, closed: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Distance of each centerline point to the left and right boundary polylines."""
    out = []
    for poly in (left, right):
        if len(poly) == 1:
            out.append(np.linalg.norm(centerline - poly[0], axis=1))
        else:
            out.append(point_segment_distance(centerline, poly, closed, extend_ends=True)[0])
    return out[0], out[1]


# ---------------------------------------------------------------------------------------------
# generated tracks


def offset(points: np.ndarray, closed: bool, distance: float) -> np.ndarray:
    """Parallel curve at ``distance`` (positive = left)."""
    h = headings(points, closed)
    return points + distance * np.column_stack([-np.sin(h), np.cos(h)])


def place_on(poly: np.ndarray, spacing: np.ndarray, start_s: float) -> np.ndarray:
    """Points along a closed polyline from arc ``start_s`` with a local target spacing per vertex.

    The count is the integral of 1/spacing rounded; points sit at equal steps of that integral,
    so the actual spacing follows the target within the rounding (a few per cent).
    """
    s, total = cumulative_length(poly, closed=True)
    s_closed = np.concatenate([s, [total]])
    density = 1.0 / np.concatenate([spacing, spacing[:1]])
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(s_closed))])
    n = max(int(round(cum[-1])), 3)
    c0 = np.interp(start_s % total, s_closed, cum)
    targets = (c0 + np.arange(n) * cum[-1] / n) % cum[-1]
    q = np.interp(targets, cum, s_closed)
    pts = np.concatenate([poly, poly[:1]])
    return np.column_stack([np.interp(q, s_closed, pts[:, 0]), np.interp(q, s_closed, pts[:, 1])])


def min_clearance(points: np.ndarray, closed: bool, skip_m: float) -> float:
    """Smallest distance between two centerline points more than ``skip_m`` apart along the track."""
    s, total = cumulative_length(points, closed)
    ds = np.abs(s[:, None] - s[None, :])
    if closed:
        ds = np.minimum(ds, total - ds)
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    far = ds > skip_m
    return float(d[far].min()) if far.any() else np.inf


def random_centerline(
    rng: np.random.Generator, length: float, min_radius: float, clearance: float, max_tries: int = 200
) -> np.ndarray:
    """A smooth closed centerline of the given length (counter-clockwise), from ``rng`` only.

    10-18 control points at jittered angles and random radii (0.3-1 of the largest, the shape
    stretched 1-1.8x along x) joined by a periodic cubic spline and scaled to ``length``; then
    smoothed with a growing Gaussian until the tightest radius is at least ``min_radius``.
    Candidates that cross themselves or bring non-neighbouring parts closer than ``clearance``
    are rejected.
    """
    for _ in range(max_tries):
        n = int(rng.integers(10, 19))
        ang = np.sort((np.arange(n) + rng.uniform(-0.3, 0.3, n)) * 2.0 * np.pi / n)
        rad = rng.uniform(0.3, 1.0, n)
        stretch = rng.uniform(1.0, 1.8)
        ctrl = np.column_stack([stretch * rad * np.cos(ang), rad * np.sin(ang)])
        ctrl = np.vstack([ctrl, ctrl[:1]])
        u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ctrl, axis=0), axis=1))])
        raw = CubicSpline(u, ctrl, bc_type="periodic")(np.linspace(0.0, u[-1], 1000, endpoint=False))
        raw = resample(raw * (length / polyline_length(raw, closed=True)), closed=True)
        sigma = 1.0
        for _ in range(30):
            pts = smooth(raw, closed=True, sigma_m=sigma)
            pts = resample(pts * (length / polyline_length(pts, closed=True)), closed=True)
            if 1.0 / max(np.abs(curvatures(pts, closed=True)).max(), 1e-9) >= min_radius:
                break
            sigma *= 1.3
        else:
            continue
        if self_intersects(pts, closed=True):
            continue
        if min_clearance(pts[::4], True, skip_m=np.pi * clearance) < clearance:
            continue
        return pts
    raise RuntimeError(f"no random track met the constraints in {max_tries} tries (length {length} m)")


def straightest_index(points: np.ndarray, closed: bool, window_m: float = 20.0) -> int:
    """Index of the point whose ±window has the smallest peak |curvature| (a good start line)."""
    k = np.abs(curvatures(points, closed))
    w = max(int(window_m / STEP_M), 1)
    peak = maximum_filter1d(k, size=2 * w + 1, mode="wrap" if closed else "nearest")
    return int(np.argmin(peak))
