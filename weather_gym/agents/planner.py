"""Centre-line planner: the path ahead of the car from mapped blue (left) and yellow (right) cones.

As Formula Student teams do it: a Delaunay triangulation (``scipy.spatial.Delaunay``) of the cones
near the car; edges that join a left and a right cone and are about one track width long cross the
track, and their midpoints lie on the centre line. Where one side is missing (cones not yet mapped,
missed by the detector, or a sparse inner boundary), each side's cones are chained into a boundary
and offset inwards by the track's half-width (estimated from the midpoints, else a nominal value).
The candidates are then chained from the car forwards (distance and turning limits) and smoothed.

Orange cones (start / finish, braking zones) are put on the side of the car they are on.

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.planner import CenterlinePlanner
    >>> x = np.arange(2.0, 30.0, 4.0)
    >>> cones = np.r_[np.c_[x, np.full_like(x, 1.75)], np.c_[x, np.full_like(x, -1.75)]]
    >>> classes = np.r_[np.zeros(len(x), int), np.ones(len(x), int)]     # blue left, yellow right
    >>> plan = CenterlinePlanner().plan(cones, classes, pose=(0.0, 0.0, 0.0))
    >>> bool(np.abs(plan.path[:, 1]).max() < 0.05), bool(plan.path[-1, 0] > 20)
    (True, True)
    >>> blue_only = CenterlinePlanner().plan(cones[classes == 0], classes[classes == 0], pose=(0.0, 0.0, 0.0))
    >>> bool(np.abs(blue_only.path[:, 1]).max() < 0.05)               # blue boundary offset by 1.75 m
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import Delaunay, QhullError

from weather_gym.core.cone_spec import CONE_CLASSES
from weather_gym.core.errors import InputError
from weather_gym.core.schema import Positive, check_fields

__all__ = ["PlannerConfig", "Plan", "CenterlinePlanner"]

BLUE, YELLOW = CONE_CLASSES.index("blue"), CONE_CLASSES.index("yellow")
_LINK_MAX_TURN = math.radians(100.0)


@dataclass(frozen=True)
class PlannerConfig:
    """Tuning of the centre-line planner (metres, radians in degrees where named so).

    Attributes:
        radius: cones closer than this to the car are used.
        behind: cones more than this far behind the rear axle are ignored.
        min_width, max_width: a left-right Delaunay edge of this length crosses the track.
        nominal_half_width: half-width used to offset a lone boundary before any width is measured
            (FS rules: the track is at least 3 m wide).
        boundary_step: largest gap between consecutive cones of one boundary.
        max_step: largest gap between consecutive centre-line points.
        max_turn_deg: largest change of direction between consecutive chain links.
        virtual_clearance: an offset (virtual) centre point closer than this to a measured midpoint
            is dropped, so measured midpoints win where both sides are mapped.
        horizon: the planned path stops after this length.
        smooth_sigma: Gaussian smoothing of the path (m).
    """

    radius: Positive = 25.0
    behind: Positive = 2.0
    min_width: Positive = 2.5
    max_width: Positive = 8.5
    nominal_half_width: Positive = 1.75
    boundary_step: Positive = 7.0
    max_step: Positive = 7.0
    max_turn_deg: Positive = 65.0
    virtual_clearance: Positive = 2.5
    horizon: Positive = 30.0
    smooth_sigma: Positive = 1.0

    def __post_init__(self) -> None:
        check_fields(self)
        if self.max_width <= self.min_width:
            raise InputError(f"PlannerConfig.max_width ({self.max_width}) must exceed min_width ({self.min_width})")


@dataclass
class Plan:
    """Output of one planning step, all in the map (odometry) frame.

    ``path`` (P, 2) is the smoothed centre line ahead (empty when nothing usable is mapped);
    ``left``/``right`` the ordered boundary chains; ``midpoints`` the measured centre points;
    ``virtual`` the centre points offset from a lone boundary; ``half_width`` the estimate used.
    """

    path: np.ndarray
    left: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    right: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    midpoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    virtual: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    half_width: float = float("nan")

    @property
    def length(self) -> float:
        return float(np.hypot(*np.diff(self.path, axis=0).T).sum()) if len(self.path) > 1 else 0.0


def _chain(points: np.ndarray, start: np.ndarray, direction: np.ndarray, max_step: float,
           max_turn: float, first_step: float, horizon: float = math.inf) -> np.ndarray:
    """Indices of ``points`` visited by a greedy forward walk from ``start`` heading ``direction``."""
    order: list[int] = []
    used = np.zeros(len(points), bool)
    cur, d = start.astype(np.float64), direction / max(float(np.hypot(*direction)), 1e-9)
    travelled = 0.0
    while travelled < horizon:
        v = points - cur
        dist = np.hypot(v[:, 0], v[:, 1])
        cosang = (v @ d) / np.maximum(dist, 1e-9)
        ang = np.arccos(np.clip(cosang, -1.0, 1.0))
        limit = first_step if not order else max_step
        ok = ~used & (dist > 0.3) & (dist <= limit) & (ang <= max_turn)
        used |= dist <= 0.3  # duplicates of the current point
        if not ok.any():
            break
        cost = np.where(ok, dist * (1.0 + 2.0 * ang / max_turn), np.inf)
        j = int(np.argmin(cost))
        order.append(j)
        used[j] = True
        step = points[j] - cur
        travelled += float(np.hypot(*step))
        d = 0.5 * d + 0.5 * step / max(float(np.hypot(*step)), 1e-9)
        d /= max(float(np.hypot(*d)), 1e-9)
        cur = points[j]
    return np.asarray(order, dtype=np.int64)


def _geometric_sides(points: np.ndarray, guide: np.ndarray | None) -> np.ndarray:
    """+1 / -1: whether each point lies left or right of ``guide`` (the previous plan's centre line, car
    frame: the side of its nearest segment), or of the car's heading without one."""
    if guide is None or len(guide) < 2 or not len(points):
        return np.where(points[:, 1] >= 0, 1, -1)
    a, b = guide[:-1], guide[1:]
    seg = b - a
    rel = points[:, None, :] - a[None, :, :]
    t = np.clip((rel * seg[None]).sum(axis=2) / np.maximum((seg * seg).sum(axis=1), 1e-9)[None], 0.0, 1.0)
    nearest = a[None] + t[..., None] * seg[None]
    j = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)).argmin(axis=1)
    cross = seg[j, 0] * (points[:, 1] - a[j, 1]) - seg[j, 1] * (points[:, 0] - a[j, 0])
    return np.where(cross >= 0, 1, -1)


def _corridor(body: np.ndarray, cls: np.ndarray, guide: np.ndarray | None,
              reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Drop the cones of unknown colour farther than ``reach`` from ``guide`` (the previous centre line,
    car frame; without one, from the car's heading line): they belong to another part of the track."""
    unknown = cls < 0
    if guide is None or len(guide) < 2:
        dist = np.abs(body[:, 1])
    else:
        a, seg = guide[:-1], np.diff(guide, axis=0)
        rel = body[:, None, :] - a[None]
        t = np.clip((rel * seg[None]).sum(axis=2) / np.maximum((seg * seg).sum(axis=1), 1e-9)[None], 0.0, 1.0)
        dist = np.hypot(*(rel - t[..., None] * seg[None]).transpose(2, 0, 1)).min(axis=1)
    keep = ~unknown | (dist <= reach)
    return body[keep], cls[keep]


def _sides(body: np.ndarray, cls: np.ndarray, guide: np.ndarray | None = None) -> np.ndarray:
    """+1 (left) for blue, -1 (right) for yellow. An orange cone joins the side it stands on across
    the track: its position along the segment from the nearest blue to the nearest yellow cone
    (start / finish line, braking zones); without both colours near, the side of the car it is on.
    A cone of unknown colour (:data:`~weather_gym.core.cone_spec.UNKNOWN_CLASS`, a LiDAR's) takes the side
    of ``guide`` it stands on (the previous plan's centre line in the car frame; without one, the
    side of the car)."""
    side = np.where(cls == BLUE, 1, np.where(cls == YELLOW, -1, 0))
    unknown = np.flatnonzero(cls < 0)
    if len(unknown):
        side[unknown] = _geometric_sides(body[unknown], guide)
    other = np.flatnonzero(side == 0)
    if not len(other):
        return side
    side[other] = np.where(body[other, 1] >= 0, 1, -1)
    blue, yellow = body[cls == BLUE], body[cls == YELLOW]
    if not (len(blue) and len(yellow)):
        return side
    o = body[other]
    nb = blue[np.hypot(*(o[:, None, :] - blue[None, :, :]).transpose(2, 0, 1)).argmin(axis=1)]
    ny = yellow[np.hypot(*(o[:, None, :] - yellow[None, :, :]).transpose(2, 0, 1)).argmin(axis=1)]
    across = ny - nb
    t = ((o - nb) * across).sum(axis=1) / np.maximum((across * across).sum(axis=1), 1e-9)
    close = np.minimum(np.hypot(*(o - nb).T), np.hypot(*(o - ny).T)) < 8.0
    side[other[close]] = np.where(t[close] < 0.5, 1, -1)
    return side


class CenterlinePlanner:
    """``plan(cones_xy, classes, pose)`` -> :class:`Plan` (map frame). Keeps a running half-width."""

    def __init__(self, config: PlannerConfig | None = None) -> None:
        self.config = config or PlannerConfig()
        self.half_width = self.config.nominal_half_width
        self._last_path: np.ndarray | None = None  # map frame: sides the next plan's unknown-colour cones

    def reset(self) -> None:
        self.half_width = self.config.nominal_half_width
        self._last_path = None

    def plan(self, cones_xy: np.ndarray, classes: np.ndarray, pose) -> Plan:
        cfg = self.config
        xy = np.asarray(cones_xy, dtype=np.float64).reshape(-1, 2)
        classes = np.asarray(classes, dtype=np.int64).reshape(-1)
        if classes.shape[0] != xy.shape[0]:
            raise InputError(f"plan: {xy.shape[0]} cone positions but {classes.shape[0]} classes")
        px, py, yaw = (float(v) for v in np.asarray(pose, dtype=np.float64).reshape(3))
        c, s = math.cos(yaw), math.sin(yaw)
        # everything below works in the car frame (x forward, y left)
        dx, dy = xy[:, 0] - px, xy[:, 1] - py
        body = np.c_[c * dx + s * dy, -s * dx + c * dy]
        near = (np.hypot(body[:, 0], body[:, 1]) < cfg.radius) & (body[:, 0] > -cfg.behind)
        body, cls = body[near], classes[near]
        guide = None
        if (cls < 0).any():
            if self._last_path is not None:
                g = self._last_path - (px, py)
                guide = np.c_[c * g[:, 0] + s * g[:, 1], -s * g[:, 0] + c * g[:, 1]]
            # a cone of unknown colour far from the corridor (another part of the track) is left out
            body, cls = _corridor(body, cls, guide, cfg.max_width / 2 + 1.0)
        side = _sides(body, cls, guide)

        mids, half, links = self._gates(body, side)
        if len(half):
            self.half_width = float(np.clip(0.8 * self.half_width + 0.2 * np.median(half),
                                            cfg.min_width / 2, cfg.max_width / 2))
        max_turn = math.radians(cfg.max_turn_deg)
        chains = {sgn: self._boundary(body[side == sgn], sgn, max_turn) for sgn in (1, -1)}
        virtual = self._virtual(chains)
        if len(virtual) and len(mids):
            d = np.hypot(*(virtual[:, None, :] - mids[None, :, :]).transpose(2, 0, 1))
            virtual = virtual[d.min(axis=1) > cfg.virtual_clearance]

        path = self._walk(mids, links, max_turn)
        # beyond the last gate (or without any), follow the lone boundary's offset
        length = float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0
        if length < cfg.horizon and len(virtual):
            if len(path):
                start = path[-1]
                direction = path[-1] - path[-2] if len(path) > 1 else path[-1]
                ahead = virtual[(virtual - start) @ direction > 0]
            else:
                start, direction, ahead = np.zeros(2), np.array([1.0, 0.0]), virtual
            order = _chain(ahead, start, direction, cfg.max_step, max_turn,
                           first_step=cfg.max_step + (0.0 if len(path) else 3.0), horizon=cfg.horizon - length)
            path = np.vstack([path.reshape(-1, 2), ahead[order]])
        if len(path):
            path = self._smooth(path)
            # extend the centre line straight backwards to behind the car, so the controller always
            # projects onto it and the look-ahead point lies on the centre line, not on a car-to-path join
            t0 = path[1] - path[0] if len(path) > 1 else path[0]
            t0 = t0 / max(float(np.hypot(*t0)), 1e-9)
            back = max(float(path[0] @ t0), 0.0) + 1.0
            path = np.vstack([path[0] - t0 * back, path])

        def to_map(p: np.ndarray) -> np.ndarray:
            p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
            return np.c_[px + c * p[:, 0] - s * p[:, 1], py + s * p[:, 0] + c * p[:, 1]]

        self._last_path = to_map(path) if len(path) > 1 else None
        return Plan(path=to_map(path), left=to_map(chains[1]), right=to_map(chains[-1]), midpoints=to_map(mids),
                    virtual=to_map(virtual), half_width=self.half_width)

    # ---- helpers ---------------------------------------------------------------------------------
    def _gates(self, body: np.ndarray, side: np.ndarray):
        """Midpoints of the left-right Delaunay edges of track width, their half lengths, and the links
        between two such edges of one triangle (consecutive gates along the corridor)."""
        cfg = self.config
        none: tuple[np.ndarray, np.ndarray, list[list[int]]] = np.zeros((0, 2)), np.zeros(0), [[] for _ in range(0)]
        if not ((side == 1).any() and (side == -1).any()):
            return none
        tri = None
        if len(body) >= 3:
            try:
                tri = Delaunay(body)
            except (QhullError, ValueError):
                tri = None
        simplices = tri.simplices if tri is not None else np.zeros((0, 3), np.int64)
        if tri is None:  # too few or collinear cones: every pair, no links
            ii, jj = np.triu_indices(len(body), 1)
            edges = np.c_[ii, jj]
        else:
            edges = np.unique(np.sort(np.vstack([simplices[:, [0, 1]], simplices[:, [1, 2]], simplices[:, [2, 0]]]),
                                      axis=1), axis=0)
        length = np.hypot(*(body[edges[:, 0]] - body[edges[:, 1]]).T)
        good = (side[edges[:, 0]] != side[edges[:, 1]]) & (length >= cfg.min_width) & (length <= cfg.max_width)
        edges, length = edges[good], length[good]
        index: dict[tuple[int, ...], int] = {(int(a), int(b)): k for k, (a, b) in enumerate(edges)}
        links: list[list[int]] = [[] for _ in range(len(edges))]
        for tri_v in simplices:
            found = [index.get(tuple(sorted((int(tri_v[i]), int(tri_v[(i + 1) % 3]))))) for i in range(3)]
            ids = [k for k in found if k is not None]
            if len(ids) == 2:
                links[ids[0]].append(ids[1])
                links[ids[1]].append(ids[0])
        return 0.5 * (body[edges[:, 0]] + body[edges[:, 1]]), 0.5 * length, links

    def _walk(self, mids: np.ndarray, links: list[list[int]], max_turn: float) -> np.ndarray:
        """Gates in driving order from the car: along triangle links, jumping a gap where links break."""
        cfg = self.config
        if not len(mids):
            return np.zeros((0, 2))
        dist = np.hypot(mids[:, 0], mids[:, 1])
        ok = (mids[:, 0] > -1.5) & (dist < cfg.max_step + 3.0)
        if not ok.any():
            return np.zeros((0, 2))
        cur = int(np.flatnonzero(ok)[np.argmin(dist[ok])])
        order, used = [cur], np.zeros(len(mids), bool)
        used[cur] = True
        d = np.array([1.0, 0.0])
        if mids[cur, 0] > 0.5:
            d = mids[cur] / max(float(dist[cur]), 1e-9)
            d = 0.5 * d + 0.5 * np.array([1.0, 0.0])
        travelled = float(dist[cur])
        while travelled < cfg.horizon:
            nxt = [k for k in links[cur] if not used[k]]
            best, best_cost = None, math.inf
            for k in nxt:
                v = mids[k] - mids[cur]
                n = float(np.hypot(*v))
                if n < 1e-6:
                    used[k] = True
                    continue
                ang = math.acos(max(-1.0, min(1.0, float(v @ d) / n)))
                # a triangle link is the corridor's own topology: only forbid turning back
                if ang <= _LINK_MAX_TURN and n <= cfg.max_step and ang < best_cost:
                    best, best_cost = k, ang
            if best is None:  # the links end: jump to the best gate ahead, if any
                j = _chain(mids[~used], mids[cur], d, cfg.max_step, max_turn, first_step=cfg.max_step)
                if not len(j):
                    break
                best = int(np.flatnonzero(~used)[j[0]])
            if travelled > 10.0 and float(np.hypot(*mids[best])) < 4.0:
                break  # back where the car is: the whole (small) loop is planned
            v = mids[best] - mids[cur]
            n = max(float(np.hypot(*v)), 1e-9)
            travelled += n
            d = v / n
            used[best] = True
            order.append(best)
            cur = best
        return mids[order]

    def _boundary(self, pts: np.ndarray, sgn: int, max_turn: float) -> np.ndarray:
        """One side's cones in driving order, from beside the car forwards."""
        cfg = self.config
        start = np.array([0.0, sgn * self.half_width])
        idx = _chain(pts, start, np.array([1.0, 0.0]), cfg.boundary_step, max_turn,
                     first_step=cfg.boundary_step + 3.0)
        return pts[idx]

    def _virtual(self, chains: dict[int, np.ndarray]) -> np.ndarray:
        """Centre points offset inwards by the half-width from boundaries of two or more cones."""
        out = []
        for sgn, chain in chains.items():
            if len(chain) < 2:
                continue
            t = np.gradient(chain, axis=0)
            t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-9)[:, None]
            inward = -sgn * np.c_[-t[:, 1], t[:, 0]]  # right normal for the left boundary, and back
            out.append(chain + inward * self.half_width)
        return np.vstack(out) if out else np.zeros((0, 2))

    def _smooth(self, path: np.ndarray) -> np.ndarray:
        seg = np.hypot(*np.diff(path, axis=0).T)
        s = np.r_[0.0, np.cumsum(seg)]
        keep = np.r_[True, seg > 1e-6]
        path, s = path[keep], s[keep]
        if len(path) < 3:
            return path
        step = 0.5
        si = np.arange(0.0, s[-1] + 1e-9, step)
        if si[-1] < s[-1]:
            si = np.r_[si, s[-1]]
        p = np.c_[np.interp(si, s, path[:, 0]), np.interp(si, s, path[:, 1])]
        sigma = self.config.smooth_sigma / step
        return np.c_[gaussian_filter1d(p[:, 0], sigma, mode="nearest"), gaussian_filter1d(p[:, 1], sigma, mode="nearest")]
