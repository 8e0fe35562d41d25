"""The car's LiDAR: one scan of beams against the PyBullet world (ground, cones, the car's own body).

Each beam's first hit gives a return: its point in the sensor frame, range, ring, intensity and the
ground truth of which cone it hit (:class:`~weather_gym.core.point_cloud.PointCloud`). Intensity is the
hit surface's reflectivity at 905 nm times the cosine of the incidence angle (a Lambertian surface;
the unit reports range-compensated reflectivity, as Velodyne's calibrated intensity does). The
reflectivities (:data:`REFLECTIVITY`) are assumed values, not measured ones: asphalt about 0.15, the
cones' bodies by colour and their stripes white (high) or black (low), so a cone's rings show its
stripe pattern.

**How a scan stays cheap.** The car moves on the flat ground plane without pitch or roll, so every
beam's hit on the ground and on the car's own body (a box) is the same in the sensor frame at every
pose: computed once, analytically. Only beams within a cone's angular window that pass near its
collision hull can end elsewhere. A standing cone's hull (the convex hull PyBullet makes of the cone
mesh, pushed out by Bullet's 1 mm collision margin) is met analytically (Cyrus-Beck clipping against
its 26 faces, all beams at once); a knocked cone's beams are cast with PyBullet's ``rayTestBatch``.
:meth:`LidarSensor.scan_naive` casts every beam through ``rayTestBatch`` instead (the benchmark's
baseline, ``weather-gym bench lidar``): the same returns but for grazing beams (under 1 % of the cone
returns), cone ranges within 3 mm at the 99th percentile (Bullet's ray test is iterative; its hits
lie 0.9-2 mm outside the hull). With ``analytic = False`` the standing cones' beams within 1 cm of
their hull are cast instead: bit for bit the naive scan (tests/sim/test_lidar.py). Track-side scenery
of the realistic world has no collision shapes (it is drawn only) and so returns nothing.

Example:
    >>> import numpy as np
    >>> from weather_gym.sim.config import SimConfig
    >>> from weather_gym.sim.lidar_config import LidarConfig
    >>> from weather_gym.sim.world import World
    >>> from weather_gym.tracks import load_track
    >>> world = World(load_track("small_track"), sim=SimConfig(renderer="none"))
    >>> world.reset(world.track.point_at(0.0))
    >>> scan = world.lidar_scan(LidarConfig())
    >>> bool(len(scan) > 10_000), bool((scan.cone >= 0).any()), scan.xyz.dtype.name
    (True, True, 'float32')
    >>> world.close()
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
from scipy.spatial import ConvexHull

from weather_gym.core.cone_spec import CONE_BASE_M, CONE_CLASSES, CONE_HEIGHT_M
from weather_gym.core.point_cloud import PointCloud, label_id
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.sim.meshes import cone_dimensions, cone_obj
from weather_gym.sim.textures import STRIPES

__all__ = ["REFLECTIVITY", "LidarSensor", "beam_directions"]

REFLECTIVITY: dict[str, float] = {
    "ground": 0.15,  # asphalt at 905 nm: 0.1-0.2
    "car": 0.4,
    "blue": 0.25, "yellow": 0.6, "orange": 0.5, "big_orange": 0.5,  # cone bodies by colour
    "white": 0.85, "black": 0.05,  # the stripes
}
"""Assumed normalised reflectivity (0-1) of each surface at 905 nm (not measured: see the module doc)."""

_STRIPE_REFL = {"blue": "white", "yellow": "black", "orange": "white", "big_orange": "white"}
_GROUND, _CONE, _CAR = label_id("ground"), label_id("cone"), label_id("car")
_MAX_BATCH = 8192  # rays per rayTestBatch call (PyBullet drops some beyond about 16 000)
HULL_MARGIN_M = 0.01
BULLET_MARGIN_M = 0.001
"""Bullet's collision margin on a convex mesh (PyBullet's default): its ray tests hit a cone's hull pushed
out by about this much (0.9-2.0 mm measured), and so does the analytic cone hit."""
"""How far outside a standing cone's collision hull a beam may pass and still be cast through PyBullet
(Bullet's convex ray test is iterative and its shapes carry a margin: a beam that misses the hull by
less than this is cast, one that misses it by more cannot hit)."""


def beam_directions(cfg: LidarConfig) -> tuple[np.ndarray, np.ndarray]:
    """Unit beam directions ``(channels * columns, 3)`` in the sensor frame and in the car frame
    (turned by the mount's yaw and pitch), ring-major (ring 0, the lowest, first)."""
    el = np.radians(cfg.elevations_deg)[:, None]
    az = np.radians(cfg.azimuths_deg)[None, :]
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)
    d = d.reshape(-1, 3)
    return d, d @ _mount_rotation(cfg).T


def _mount_rotation(cfg: LidarConfig) -> np.ndarray:
    """Sensor-to-car rotation: the mount's yaw, then its downward pitch."""
    pitch, yaw = math.radians(cfg.pitch_deg), math.radians(cfg.yaw_deg)
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    return np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0],
                                                                                 [-sp, 0.0, cp]])


def _cone_hulls() -> np.ndarray:
    """The half-spaces ``(n_x, n_y, n_z, offset)`` of each cone class's collision hull (the convex hull
    PyBullet builds from the cone mesh's vertices, :func:`weather_gym.sim.meshes.cone_obj`, as written to
    its file), a point ``x`` inside where ``n . x + offset <= 0``; ``(classes, faces, 4)``, padded with
    half-spaces everything satisfies."""
    planes = []
    for name in CONE_CLASSES:
        text = cone_obj(CONE_HEIGHT_M[name], CONE_BASE_M[name])
        verts = np.array([[float(v) for v in line.split()[1:4]] for line in text.splitlines() if line.startswith("v ")])
        planes.append(np.unique(np.round(ConvexHull(verts).equations, 9), axis=0))
    out = np.zeros((len(planes), max(len(q) for q in planes), 4))
    out[:, :, 3] = -1.0
    for i, q in enumerate(planes):
        out[i, :len(q)] = q
    return out


def _hull_hits(p0: np.ndarray, d: np.ndarray, planes: np.ndarray, t_max: np.ndarray) -> np.ndarray:
    """Whether each ray ``p0 + t d`` (``0 <= t <= t_max``) meets the convex polytope ``planes`` ((N, F, 4),
    its half-spaces; Cyrus-Beck clipping, all rays at once)."""
    n, off = planes[:, :, :3], planes[:, :, 3]
    den = np.einsum("nfk,nk->nf", n, d)
    num = -(np.einsum("nfk,nk->nf", n, p0) + off)  # den * t <= num inside
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = num / den
    enter = np.max(np.where(den < 0, ratio, -np.inf), axis=1, initial=0.0)
    leave = np.min(np.where(den > 0, ratio, np.inf), axis=1, initial=np.inf)
    parallel_out = ((den == 0) & (num < 0)).any(axis=1)
    return (enter <= np.minimum(leave, t_max)) & ~parallel_out


def _hull_entry(p0: np.ndarray, d: np.ndarray, planes: np.ndarray,
                t_max: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each ray ``p0 + t d`` enters the convex polytope ``planes`` ((N, F, 4)) within ``0 < t <= t_max``:
    ``(hit, t, face)`` (Cyrus-Beck; ``face`` indexes the entered half-space, whose normal is the surface's)."""
    n, off = planes[:, :, :3], planes[:, :, 3]
    den = np.einsum("nfk,nk->nf", n, d)
    num = -(np.einsum("nfk,nk->nf", n, p0) + off)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = num / den
    ent = np.where(den < 0, ratio, -np.inf)
    face = ent.argmax(axis=1)
    enter = ent[np.arange(len(ent)), face]
    leave = np.min(np.where(den > 0, ratio, np.inf), axis=1, initial=np.inf)
    hit = (enter > 0) & (enter <= np.minimum(leave, t_max)) & ~((den == 0) & (num < 0)).any(axis=1)
    return hit, enter, face


def _box_hits(origin: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance along each unit ray ``d`` from ``origin`` to an axis-aligned box (inf: none) and the
    cosine of the incidence angle there (slab method; a ray starting inside the box hits nothing)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0, t1 = (lo - origin) * inv, (hi - origin) * inv
    tmin, tmax = np.minimum(t0, t1), np.maximum(t0, t1)
    tmin = np.where(np.isnan(tmin), -np.inf, tmin)
    tmax = np.where(np.isnan(tmax), np.inf, tmax)
    enter, leave = tmin.max(axis=1), tmax.min(axis=1)
    hit = (enter <= leave) & (enter > 0)
    t = np.where(hit, enter, np.inf)
    axis = tmin.argmax(axis=1)
    cos = np.abs(d[np.arange(len(d)), axis])
    return t, np.where(hit, cos, 0.0)


class LidarSensor:
    """Casts the scans of one :class:`LidarConfig` in one world (see the module doc).

    Args:
        config: the sensor.
        client: the world's PyBullet client.
        ground_body, car_body: PyBullet ids of the ground plane and the car's collision box.
        car_box: the car's box in the car frame, ``(x0, x1, y0, y1, z0, z1)`` metres.
        cone_classes, cone_heights: (N,) of the world's cones.
    """

    def __init__(self, config: LidarConfig, client: int, ground_body: int, car_body: int,
                 car_box: tuple[float, float, float, float, float, float], cone_classes: np.ndarray,
                 cone_heights: np.ndarray) -> None:
        self.config = cfg = config
        self.client, self.ground_body, self.car_body = client, ground_body, car_body
        # Bullet keeps a static body's broadphase bounds from its creation, where a cone's (made with its
        # centre of mass above its base) sit com_z too low: rays missed every cone's top third until the
        # first physics step or reset moved it. Refresh them all once (no body moves).
        p.performCollisionDetection(physicsClientId=client)
        self.dirs_sensor, self.dirs_car = beam_directions(cfg)
        self.origin = np.array([cfg.mount_x, cfg.mount_y, cfg.mount_z])
        self.ring = np.repeat(np.arange(cfg.channels, dtype=np.int16), cfg.columns)
        # the static part of every scan: the ground plane and the car's body, in the car frame
        dz = self.dirs_car[:, 2]
        with np.errstate(divide="ignore"):
            t_ground = np.where(dz < 0, cfg.mount_z / -np.minimum(dz, -1e-12), np.inf)
        lo, hi = np.array(car_box[0::2]), np.array(car_box[1::2])
        t_car, cos_car = _box_hits(self.origin, self.dirs_car, lo, hi)
        car_first = t_car < t_ground
        self._t_static = np.where(car_first, t_car, t_ground)
        self._label_static = np.where(car_first, _CAR, _GROUND).astype(np.uint8)
        self._refl_static = np.where(car_first, REFLECTIVITY["car"], REFLECTIVITY["ground"]).astype(np.float32)
        self._cos_static = np.where(car_first, cos_car, np.maximum(-dz, 0.0)).astype(np.float32)
        static = np.flatnonzero(self._detected(self._t_static, self._refl_static * self._cos_static))
        # the static returns (ground, car) in beam order: a scan merges its cone returns into them
        self._s_rows, self._s_t = static, self._t_static[static]
        self._s_xyz = (self.dirs_sensor[static] * self._s_t[:, None]).astype(np.float32)
        self._s_int = (self._refl_static * self._cos_static)[static].astype(np.float32)
        self._s_refl, self._s_label = self._refl_static[static], self._label_static[static]
        self._s_cone, self._s_ring = np.full(len(static), -1, dtype=np.int32), self.ring[static]
        self._cone_classes = np.asarray(cone_classes, dtype=np.int64)
        self._cone_heights = np.asarray(cone_heights, dtype=np.float64)
        base = np.array([CONE_BASE_M[CONE_CLASSES[c]] for c in self._cone_classes])
        self._cone_radius = base / math.sqrt(2) + 0.01  # the base plate's half-diagonal, and 1 cm
        # the top ring's radius (weather_gym.sim.meshes)
        self._cone_top = np.array([cone_dimensions(h, b)["r1"] for h, b in zip(self._cone_heights, base)])
        self._elev = np.radians(cfg.elevations_deg)
        self._az0 = math.radians(cfg.azimuths_deg[0])
        self._res = math.radians(cfg.h_res_deg)
        hull = _cone_hulls()
        self._hull = hull.copy()
        self._hull[:, :, 3] -= HULL_MARGIN_M  # unit normals: every face pushed out by the margin
        self._hull_exact = hull
        self._hull_exact[:, :, 3] -= BULLET_MARGIN_M
        self.analytic = True

    # ------------------------------------------------------------------ the scan
    def _pose(self, car_pose: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
        """The sensor's origin in the world (3,) and the car-to-world rotation (3, 3)."""
        x, y, yaw = car_pose
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return np.array([x, y, 0.0]) + rot @ self.origin, rot

    def candidates(self, car_pose, cone_xy: np.ndarray, tilted: dict | None = None, *,
                   analytic: bool = False) -> tuple:
        """Indices of the beams to cast (sorted) and how far each must be cast (m); with ``analytic``, also
        the standing cones' hits ``(beams, ranges, surface normals (world), cone indices)`` (None: none).

        A standing cone fits in an upright cylinder of radius ``r`` (its base plate's half-diagonal) and
        its height, so its beams lie within the azimuths ``centre +- asin(r / distance)`` and between the
        elevations of the cylinder's bottom and top at its near and far side (a knocked cone: a cylinder
        of its length around its centre of mass; a mount pitched by ``a`` widens both windows by ``2 a``).
        Beams that meet the ground or the car before the cone's near side drop out. Of the rest, a
        standing cone keeps those through a solid of revolution enclosing its hull (a quadratic per beam),
        then those that meet the hull itself: within ``HULL_MARGIN_M`` (cast) or exactly, on the hull
        pushed out by ``BULLET_MARGIN_M`` (``analytic``). A knocked cone's window beams are all cast."""
        cfg = self.config
        eye, rot = self._pose(car_pose)
        xy = np.asarray(cone_xy, dtype=np.float64)
        empty: tuple = (np.zeros(0, np.int64), np.zeros(0)) + ((None,) if analytic else ())
        if len(xy) == 0:
            return empty
        r, z0, z1 = self._cone_radius.copy(), np.zeros(len(xy)), self._cone_heights + 0.01
        standing = np.ones(len(xy), bool)
        if tilted:
            for i in tilted:
                r[i] = z1[i] = float(np.hypot(2 * self._cone_radius[i], self._cone_heights[i]))
                standing[i] = False
        rel = (xy - eye[:2]) @ rot[:2, :2]  # car frame, relative to the sensor
        dist = np.hypot(rel[:, 0], rel[:, 1])
        near = np.flatnonzero(dist - r < cfg.max_range)
        if not len(near):
            return empty
        rel, dist, r, z0, z1 = rel[near], dist[near], r[near], z0[near], z1[near]
        widen = 2.0 * abs(math.radians(cfg.pitch_deg)) + 1e-9
        inside = dist <= r + 0.05  # the sensor within a cone's reach: every azimuth
        half = np.arcsin(np.minimum(r / np.maximum(dist, 1e-9), 1.0)) + widen
        centre = np.arctan2(rel[:, 1], rel[:, 0]) - math.radians(cfg.yaw_deg)
        d_near, d_far = np.maximum(dist - r, 1e-3), dist + r
        lo_z, hi_z = z0 - cfg.mount_z, z1 - cfg.mount_z
        e_lo = np.minimum(np.arctan2(lo_z, d_near), np.arctan2(lo_z, d_far)) - widen
        e_hi = np.maximum(np.arctan2(hi_z, d_near), np.arctan2(hi_z, d_far)) + widen
        r_lo = np.searchsorted(self._elev, e_lo, side="left")
        r_hi = np.searchsorted(self._elev, e_hi, side="right")
        cols = cfg.columns
        c_lo = np.ceil((centre - half - self._az0) / self._res).astype(np.int64)
        c_hi = np.floor((centre + half - self._az0) / self._res).astype(np.int64) + 1
        full = inside | (c_hi - c_lo >= cols)
        c_lo, c_hi = np.where(full, 0, c_lo), np.where(full, cols, c_hi)
        if not cfg.spinning:
            c_lo, c_hi = np.clip(c_lo, 0, cols), np.clip(c_hi, 0, cols)
        ok = np.flatnonzero((r_hi > r_lo) & (c_hi > c_lo))
        if not len(ok):
            return empty
        nr, nc = (r_hi - r_lo)[ok], (c_hi - c_lo)[ok]
        per = nr * nc
        j = np.repeat(ok, per)  # every (beam, cone) pair of the windows, vectorised
        k = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
        width = np.repeat(nc, per)
        ray = (r_lo[j] + k // width) * cols + (c_lo[j] + k % width) % cols
        # a beam that meets the ground or the car's own body short of the cone's near side cannot reach it
        t_stop = np.minimum(self._t_static[ray], cfg.max_range)
        keep = t_stop >= d_near[j]
        ray, j, t_stop = ray[keep], j[keep], t_stop[keep]
        idx = near[j]
        h, top = self._cone_heights[idx] + 0.01, self._cone_top[idx] + 0.01
        keep = ~standing[idx] | self._through(ray, rel[j], self._cone_radius[idx] + 0.005, top, h)
        ray, j, idx, t_stop = ray[keep], j[keep], idx[keep], t_stop[keep]
        # then the standing cones' beams that pass within HULL_MARGIN_M of the collision hull itself
        test = np.flatnonzero(standing[idx])
        found = None
        if len(test):
            base = np.zeros((len(test), 3))
            base[:, :2] = xy[idx[test]]
            p0, d_world = eye - base, self.dirs_car[ray[test]] @ rot.T
            keep = np.ones(len(ray), bool)
            if analytic:  # the hit itself, on the hull Bullet's ray test sees (its margin included)
                planes = self._hull_exact[self._cone_classes[idx[test]]]
                hit, t_in, face = _hull_entry(p0, d_world, planes, t_stop[test])
                keep[test] = False
                first = np.lexsort((t_in[hit], ray[test][hit]))  # by beam, nearest cone first
                b, t_b = ray[test][hit][first], t_in[hit][first]
                one = np.r_[True, b[1:] != b[:-1]]
                normal = planes[hit][first][one, face[hit][first][one], :3]
                found = (b[one], t_b[one], normal, idx[test][hit][first][one])
            else:
                hit = _hull_hits(p0, d_world, self._hull[self._cone_classes[idx[test]]], t_stop[test])
                keep[test[~hit]] = False
            ray, j = ray[keep], j[keep]
        far = np.hypot(d_far, np.maximum(np.abs(lo_z), np.abs(hi_z))) + 0.05  # past the cylinder's far side
        reach = np.zeros(cfg.rays)
        np.maximum.at(reach, ray, far[j])
        rays = np.flatnonzero(reach)
        if analytic:
            return rays, reach[rays], found
        return rays, reach[rays]

    def _through(self, ray: np.ndarray, rel: np.ndarray, a0: np.ndarray, a1: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Whether each beam ``ray`` passes through an upright solid of revolution standing on the ground
        at ``rel`` (relative to the sensor, car frame) whose radius falls linearly from ``a0`` at the
        ground to ``a1`` at height ``h`` (a cylinder when they are equal)."""
        cfg = self.config
        d = self.dirs_car[ray]
        slope = (a0 - a1) / h
        px, py, pz = -rel[:, 0], -rel[:, 1], np.full(len(ray), cfg.mount_z)  # the sensor, seen from the base
        g0, g1 = a0 - slope * pz, slope * d[:, 2]  # the radius along the beam: g0 - g1 t
        qa = d[:, 0] ** 2 + d[:, 1] ** 2 - g1 ** 2
        qb = 2.0 * (px * d[:, 0] + py * d[:, 1] + g0 * g1)
        qc = px ** 2 + py ** 2 - g0 ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (0.0 - pz) / d[:, 2], (h - pz) / d[:, 2]
        flat = np.abs(d[:, 2]) < 1e-12
        t0 = np.where(flat, 0.0, np.minimum(ta, tb))
        t1 = np.where(flat, np.where((pz >= 0) & (pz <= h), cfg.max_range, -1.0), np.maximum(ta, tb))
        t0 = np.maximum(t0, 0.0)
        t1 = np.minimum(t1, cfg.max_range)
        valid = t1 >= t0
        f0 = (qa * t0 + qb) * t0 + qc
        f1 = (qa * t1 + qb) * t1 + qc
        with np.errstate(divide="ignore", invalid="ignore"):
            tv = np.clip(-qb / (2.0 * qa), t0, t1)
        fv = np.where(qa > 0, (qa * tv + qb) * tv + qc, np.inf)
        return valid & (np.minimum(np.minimum(f0, f1), fv) <= 0.0)

    def scan(self, car_pose: tuple[float, float, float], cone_xy: np.ndarray, cone_lut: np.ndarray, *,
             cone_frames: dict | None = None, rng: np.random.Generator | None = None) -> PointCloud:
        """The returns of one scan at ``car_pose`` (rear axle x, y, yaw). ``cone_lut`` maps PyBullet body
        id + 1 to cone index; ``cone_frames`` (knocked cones: index -> (base origin (3,), rotation (3, 3)));
        ``rng`` draws the range noise (None: none)."""
        cfg = self.config
        found = None
        if self.analytic:
            cand, far, found = self.candidates(car_pose, cone_xy, cone_frames, analytic=True)
        else:
            cand, far = self.candidates(car_pose, cone_xy, cone_frames)
        static = (self._s_rows, self._s_t, self._s_xyz, self._s_int, self._s_refl, self._s_cone, self._s_ring,
                  self._s_label)
        rows, t, xyz, intensity, refl, cone, ring, label = static
        eye, rot = self._pose(car_pose)
        parts = [] if found is None else [found]
        if len(cand):  # knocked cones (or every cone without the analytic hits): through rayTestBatch
            reach = np.minimum(np.minimum(self._t_static[cand], cfg.max_range), far)
            d_world = self.dirs_car[cand] @ rot.T
            hits = self._cast(eye, d_world, reach)
            body = np.fromiter((h[0] for h in hits), np.int64, len(hits))
            idx = cone_lut[np.clip(body + 1, 0, len(cone_lut) - 1)]
            got = np.flatnonzero((body >= 0) & (idx >= 0))
            if len(got):
                t_cast = np.fromiter((hits[k][2] for k in got), float, len(got)) * reach[got]
                normals = np.array([hits[k][4] for k in got], dtype=np.float64).reshape(-1, 3)
                parts.append((cand[got], t_cast, normals, idx[got].astype(np.int64)))
        if parts:
            beams, t_hit, normals, ci = (np.concatenate(a) for a in zip(*parts))
            if len(parts) > 1:  # a beam that meets two cones returns from the nearer
                first = np.lexsort((t_hit, beams))
                one = first[np.r_[True, beams[first][1:] != beams[first][:-1]]]
                beams, t_hit, normals, ci = beams[one], t_hit[one], normals[one], ci[one]
            if len(beams):
                rows, t, xyz, intensity, refl, cone, ring, label = self._merge(
                    static, beams, t_hit, normals, self.dirs_car[beams] @ rot.T, eye, ci, cone_xy, cone_frames)
        if rng is not None and cfg.range_noise_m > 0:
            r = t + cfg.range_noise_m * rng.standard_normal(len(t))
            xyz = (self.dirs_sensor[rows] * r[:, None]).astype(np.float32)
        return PointCloud.trusted(xyz=xyz.copy() if xyz is self._s_xyz else xyz,
                                  intensity=intensity.copy() if intensity is self._s_int else intensity,
                                  reflectivity=refl.copy() if refl is self._s_refl else refl,
                                  ring=ring.copy() if ring is self._s_ring else ring,
                                  cone=cone.copy() if cone is self._s_cone else cone,
                                  label=label.copy() if label is self._s_label else label)

    def _merge(self, static: tuple, beams: np.ndarray, t_hit: np.ndarray, normals: np.ndarray, d_world: np.ndarray,
               eye: np.ndarray, ci: np.ndarray, cone_xy: np.ndarray, frames: dict | None) -> tuple:
        """The static returns' arrays with the cone hits of the sorted ``beams`` (range ``t_hit``, surface
        ``normals``, cone ``ci``) in place of what lay behind them; those detected join in beam order."""
        points = eye + d_world * t_hit[:, None]
        cos = np.abs(np.einsum("ij,ij->i", normals, d_world))
        refl = self._cone_reflectivity(ci, points, cone_xy, frames)
        seen = np.flatnonzero(self._detected(t_hit, refl * cos))
        rows = static[0]
        pos = np.searchsorted(rows, beams)
        hidden = pos[(pos < len(rows)) & (rows[np.minimum(pos, len(rows) - 1)] == beams)]
        kept = np.delete(np.arange(len(rows)), hidden)
        new_rows, new_t = beams[seen], t_hit[seen]
        new = (new_rows, new_t, (self.dirs_sensor[new_rows] * new_t[:, None]).astype(np.float32),
               (refl * cos)[seen].astype(np.float32), refl[seen], ci[seen].astype(np.int32), self.ring[new_rows],
               np.full(len(seen), _CONE, np.uint8))
        # where each output return comes from: a kept static one, or (index past the static ones) a new one
        src = np.insert(kept, np.searchsorted(rows[kept], new_rows), len(rows) + np.arange(len(seen)))
        return tuple(np.concatenate([a, b])[src] for a, b in zip(static, new))

    def _detected(self, t: np.ndarray, intensity: np.ndarray) -> np.ndarray:
        """Beams whose hit gives a return: within the range limits and with a received power
        (``intensity / t**2``) at least that of a ``ref_reflectivity`` target at ``max_range``."""
        cfg = self.config
        with np.errstate(invalid="ignore"):
            return ((t <= cfg.max_range) & (t >= cfg.min_range)
                    & (intensity * (cfg.max_range * cfg.max_range) >= cfg.ref_reflectivity * t * t))

    def _cast(self, eye: np.ndarray, d_world: np.ndarray, reach: np.ndarray) -> list:
        """``rayTestBatch`` from ``eye`` along ``d_world`` to ``reach`` metres. Each ray starts at the sensor:
        Bullet's convex ray cast is iterative, and a ray started just short of a cone hits it up to 7 mm
        elsewhere (and grazing beams another cone) than one from the sensor."""
        start = [eye.tolist()] * len(d_world)
        end = (eye + d_world * reach[:, None]).tolist()
        out: list = []
        for k in range(0, len(end), _MAX_BATCH):
            out += p.rayTestBatch(start[k:k + _MAX_BATCH], end[k:k + _MAX_BATCH], numThreads=1,
                                  physicsClientId=self.client)
        return out

    def _cone_reflectivity(self, ci: np.ndarray, points: np.ndarray, cone_xy: np.ndarray,
                           frames: dict | None) -> np.ndarray:
        """Reflectivity where each beam hit its cone: the stripe's or the body's, by the height along the
        cone's axis (the bands of :data:`weather_gym.sim.textures.STRIPES`)."""
        h = self._cone_heights[ci]
        v = points[:, 2] / h
        if frames:
            for k in np.flatnonzero(np.isin(ci, list(frames))):
                origin, rot = frames[int(ci[k])]
                v[k] = float((points[k] - origin) @ rot[:, 2]) / h[k]
        out = np.empty(len(ci), np.float32)
        for cls_id, name in enumerate(CONE_CLASSES):
            sel = self._cone_classes[ci] == cls_id
            if not sel.any():
                continue
            stripe = np.zeros(int(sel.sum()), bool)
            for lo, hi in STRIPES[name]:
                stripe |= (v[sel] >= lo) & (v[sel] < hi)
            out[sel] = np.where(stripe, REFLECTIVITY[_STRIPE_REFL[name]], REFLECTIVITY[name])
        return out

    # ------------------------------------------------------------------ the baseline
    def scan_naive(self, car_pose: tuple[float, float, float], cone_xy: np.ndarray, cone_lut: np.ndarray, *,
                   cone_frames: dict | None = None) -> PointCloud:
        """The same scan with every beam cast through ``rayTestBatch`` (no range noise): the benchmark's
        baseline and the fast path's check."""
        cfg = self.config
        eye, rot = self._pose(car_pose)
        d_world = self.dirs_car @ rot.T
        reach = np.full(cfg.rays, cfg.max_range)
        hits = self._cast(eye, d_world, reach)
        fraction = np.fromiter((h[2] for h in hits), float, len(hits))
        body = np.fromiter((h[0] for h in hits), np.int64, len(hits))
        t = np.where(body >= 0, fraction * cfg.max_range, np.inf)
        idx = cone_lut[np.clip(body + 1, 0, len(cone_lut) - 1)]
        normals = np.array([h[4] for h in hits], dtype=np.float64).reshape(-1, 3)
        cos = np.abs(np.einsum("ij,ij->i", normals, d_world)).astype(np.float32)
        label = np.where(idx >= 0, _CONE, np.where(body == self.car_body, _CAR, _GROUND)).astype(np.uint8)
        refl = np.where(body == self.car_body, REFLECTIVITY["car"], REFLECTIVITY["ground"]).astype(np.float32)
        is_cone = np.flatnonzero(idx >= 0)
        if len(is_cone):
            points = eye + d_world[is_cone] * t[is_cone, None]
            refl[is_cone] = self._cone_reflectivity(idx[is_cone].astype(np.int64), points, cone_xy, cone_frames)
        keep = np.flatnonzero(self._detected(t, refl * cos))
        xyz = (self.dirs_sensor[keep] * t[keep, None]).astype(np.float32)
        return PointCloud.trusted(xyz=xyz, intensity=(refl[keep] * cos[keep]).astype(np.float32),
                                  reflectivity=refl[keep], ring=self.ring[keep],
                                  cone=np.where(idx[keep] >= 0, idx[keep], -1).astype(np.int32), label=label[keep])
