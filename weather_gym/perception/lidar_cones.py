"""Cones from a LiDAR scan: ground removal, clustering, a size check, position, size and the stripe's colour.

1. **Into the car frame** (the mount's pitch, yaw and position undone).
2. **Ground removal**: the car drives on flat ground without pitch or roll, so the ground is the plane
   ``z = 0``; a return is ground below ``ground_z`` (1 cm) plus ``ground_sigmas`` (3) standard deviations
   of the sensor's range noise along its beam (``range_noise_m * |sin(elevation)|``: a beam 30 degrees
   down with 2 cm noise puts ground returns up to 3 cm high, which a fixed 1 cm cut took for cones
   beside the car; a beam near the horizon keeps the 1 cm cut, and sees a cone's 2 cm base plate at
   10-13 m). A stack on a real car would fit the plane, e.g. by RANSAC, each scan.
3. **Outlier removal** (DROR, Charron et al. 2018, "De-noising of Lidar Point Clouds Corrupted by
   Snowfall"): a return keeps only with at least ``min_neighbours`` other returns within
   ``max(0.05, dror_factor * r * h_res)`` (``r`` its range, ``h_res`` the sensor's azimuth step): the
   spacing of a surface's returns grows with range, isolated raindrops and snowflakes have none near.
4. **Clustering** of what stays within ``max_range`` by single linkage in the ground plane: returns
   closer than ``link_m`` (0.3 m) join (``scipy.spatial.cKDTree.query_pairs`` and
   ``scipy.sparse.csgraph.connected_components``).
5. **Cone check**: a cluster is a cone when it has ``min_points`` returns, is at most ``max_width_m``
   across the line of sight and ``max_depth_m`` along it (range noise in rain spreads a cone's returns
   along the beams) and its top lies between ``min_height_m`` and ``max_height_m`` above the ground (a
   small cone is 0.325 m tall, a big one 0.505 m, both under 0.3 m wide). Fog backscatter fails it: it
   spreads along arcs.
6. **Position**: the mean of the cluster's points in the ground plane, pushed ``0.05`` m further along
   the line of sight (the beams see the cone's near side; 0.05 m is its mean radius); **size**: width and
   height of the cluster.

7. **Colour from the stripes** (``stripe_colour``): a cluster taller than ``big_cone_m`` (0.42 m) is a
   big orange cone. On a small cone the returns inside the stripe band (:data:`STRIPE_BAND`, 0.42-0.62
   of its 0.325 m, 1 cm in from each edge) against those on the body above and below: a stripe
   ``bright_stripe`` (2.5) times brighter is blue (white on blue), 1.2-2.5 times orange (white on
   orange), ``dark_stripe`` (0.5) times or less yellow (black on yellow); otherwise, or without returns
   on both, the colour stays unknown (:data:`~weather_gym.core.cone_spec.UNKNOWN_CLASS`). The
   intensities are the sensor's assumed reflectivities (:data:`weather_gym.sim.lidar.REFLECTIVITY`)
   times the incidence cosine, so the thresholds sit between the assumed contrasts (3.4, 1.7, 0.08);
   fog and rain scale a cone's returns alike and leave the ratio. A sensor 0.3 m up sees the stripe
   (0.14-0.20 m) with its -1.33 degree ring at 4.3-7 m, its -2.67 degree ring at 2.1-3.5 m and lower
   rings nearer: beyond about 7 m the HDL-32E reads no colour.

Example:
    >>> import numpy as np
    >>> from weather_gym.perception.lidar_cones import cones_from_points
    >>> from weather_gym.core.point_cloud import PointCloud
    >>> from weather_gym.sim.lidar_config import LidarConfig
    >>> cfg = LidarConfig()
    >>> pts = np.array([[7.75, 1.0, -0.1], [7.76, 1.02, -0.12], [7.75, 0.98, -0.14], [5.0, -3.0, -0.3]])
    >>> cones = cones_from_points(PointCloud.from_arrays(xyz=pts, intensity=np.full(4, 0.5), ring=np.zeros(4)), cfg)
    >>> cones["x_body"].round(2).tolist(), cones["y_body"].round(2).tolist(), cones["classes"].tolist()
    ([10.05], [1.01], [-1])

(Equal intensities: no stripe contrast, the colour stays unknown.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from weather_gym.core.cone_arrays import ConeArrays
from weather_gym.core.cone_spec import CONE_CLASSES, CONE_HEIGHT_M, UNKNOWN_CLASS
from weather_gym.core.errors import InputError
from weather_gym.core.point_cloud import PointCloud

__all__ = ["LidarConeConfig", "STRIPE_BAND", "cones_from_points", "to_car_frame"]

STRIPE_BAND = (0.42, 0.62)
"""The stripe of a small cone, as fractions of its height (the sim's cones: weather_gym.sim.textures.STRIPES;
FS rules: one stripe in the middle)."""


@dataclass(frozen=True)
class LidarConeConfig:
    """Tuning of :func:`cones_from_points` (metres; see the module doc)."""

    ground_z: float = 0.01
    ground_sigmas: float = 3.0
    max_range: float = 30.0
    link_m: float = 0.3
    min_points: int = 2
    max_width_m: float = 0.45
    max_depth_m: float = 1.0
    min_neighbours: int = 1
    dror_factor: float = 3.0
    min_height_m: float = 0.015
    max_height_m: float = 0.6
    radius_m: float = 0.05
    stripe_colour: bool = True
    bright_stripe: float = 2.5
    dark_stripe: float = 0.5
    big_cone_m: float = 0.42

    def __post_init__(self) -> None:
        for name in ("ground_z", "ground_sigmas", "max_range", "link_m", "max_width_m", "max_depth_m", "dror_factor",
                     "min_height_m", "max_height_m", "radius_m", "bright_stripe", "dark_stripe", "big_cone_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise InputError(f"LidarConeConfig.{name} must be a finite number >= 0, got {v!r}")
        for name in ("min_points", "min_neighbours"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < (1 if name == "min_points" else 0):
                raise InputError(f"LidarConeConfig.{name} must be an integer >= {int(name == 'min_points')}, got {v!r}")
        if self.max_height_m <= self.min_height_m:
            raise InputError("LidarConeConfig.max_height_m must exceed min_height_m")


def to_car_frame(xyz: np.ndarray, lidar) -> np.ndarray:
    """(N, 3) sensor-frame points of ``lidar`` (a ``LidarConfig``) in the car frame."""
    pitch, yaw = math.radians(lidar.pitch_deg), math.radians(lidar.yaw_deg)
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    rot = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0],
                                                                                [-sp, 0.0, cp]])
    return np.asarray(xyz, np.float64) @ rot.T + np.array([lidar.mount_x, lidar.mount_y, lidar.mount_z])


def cones_from_points(cloud: PointCloud, lidar, config: LidarConeConfig | None = None) -> ConeArrays:
    """The cones in one scan (see the module doc): ``ConeArrays`` with ``x_body``, ``y_body`` (car frame),
    ``ranges``, ``bearings`` (from the sensor, horizontal), ``classes`` (from the stripes, else unknown), ``scores`` (1),
    ``widths``, ``heights``, ``points`` (returns per cone), in order of range."""
    cfg = config or LidarConeConfig()
    car = to_car_frame(cloud.xyz, lidar)
    dx, dy = car[:, 0] - lidar.mount_x, car[:, 1] - lidar.mount_y
    dz = car[:, 2] - lidar.mount_z
    # range noise moves a ground return along its beam: up to ground_sigmas standard deviations of it
    sin_el = np.abs(dz) / np.maximum(np.sqrt(dx * dx + dy * dy + dz * dz), 1e-9)
    ground = car[:, 2] <= cfg.ground_z + cfg.ground_sigmas * lidar.range_noise_m * sin_el
    keep = np.flatnonzero(~ground & (dx * dx + dy * dy <= cfg.max_range ** 2))
    pts, inten = car[keep], np.asarray(cloud.intensity, np.float64)[keep]
    if len(pts) < cfg.min_points:
        return _empty()
    if cfg.min_neighbours:
        r = np.sqrt(dx[keep] ** 2 + dy[keep] ** 2 + (car[keep, 2] - lidar.mount_z) ** 2)
        radius = np.maximum(0.05, cfg.dror_factor * r * math.radians(lidar.h_res_deg))
        near = cKDTree(pts).query_ball_point(pts, radius, return_length=True) - 1
        pts, inten = pts[near >= cfg.min_neighbours], inten[near >= cfg.min_neighbours]
        if len(pts) < cfg.min_points:
            return _empty()
    pairs = cKDTree(pts[:, :2]).query_pairs(cfg.link_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(pts), len(pts)))
    n, label = connected_components(graph, directed=False)
    count = np.bincount(label, minlength=n)
    order = np.argsort(label, kind="stable")
    starts = np.r_[0, np.cumsum(count)[:-1]]
    # extent across and along the line of sight to each cluster's mean
    mx = np.bincount(label, weights=pts[:, 0], minlength=n) / count - lidar.mount_x
    my = np.bincount(label, weights=pts[:, 1], minlength=n) / count - lidar.mount_y
    norm = np.maximum(np.hypot(mx, my), 1e-9)
    ux, uy = (mx / norm)[label], (my / norm)[label]
    px, py = pts[:, 0] - lidar.mount_x, pts[:, 1] - lidar.mount_y
    along, across = px * ux + py * uy, -px * uy + py * ux
    depth = np.maximum.reduceat(along[order], starts) - np.minimum.reduceat(along[order], starts)
    width = np.maximum.reduceat(across[order], starts) - np.minimum.reduceat(across[order], starts)
    top = np.maximum.reduceat(pts[order, 2], starts)
    cone = ((count >= cfg.min_points) & (width <= cfg.max_width_m) & (depth <= cfg.max_depth_m)
            & (top >= cfg.min_height_m) & (top <= cfg.max_height_m))
    ids = np.flatnonzero(cone)
    if not len(ids):
        return _empty()
    cx = np.bincount(label, weights=pts[:, 0], minlength=n)[ids] / count[ids]
    cy = np.bincount(label, weights=pts[:, 1], minlength=n)[ids] / count[ids]
    rx, ry = cx - lidar.mount_x, cy - lidar.mount_y
    rng = np.hypot(rx, ry)
    push = cfg.radius_m / np.maximum(rng, 1e-9)
    cx, cy = cx + rx * push, cy + ry * push
    rx, ry = cx - lidar.mount_x, cy - lidar.mount_y
    ranges, bearings = np.hypot(rx, ry), np.arctan2(ry, rx)
    o = np.argsort(ranges, kind="stable")
    classes = np.full(len(ids), UNKNOWN_CLASS, np.int64)
    if cfg.stripe_colour:
        classes = _stripe_classes(pts[:, 2], inten, label, ids, top[ids], cfg)
    return ConeArrays(x_body=cx[o], y_body=cy[o], ranges=ranges[o].astype(np.float32),
                      bearings=bearings[o].astype(np.float32), classes=classes[o],
                      scores=np.ones(len(o), np.float32), widths=width[ids][o].astype(np.float32),
                      heights=top[ids][o].astype(np.float32), points=count[ids][o].astype(np.int64))


def _stripe_classes(z: np.ndarray, intensity: np.ndarray, label: np.ndarray, ids: np.ndarray, top: np.ndarray,
                    cfg: LidarConeConfig) -> np.ndarray:
    """The colour of each cone cluster ``ids`` read from its returns (see the module doc): a cluster
    taller than ``big_cone_m`` is a big orange cone; on a small one, the returns inside the stripe band
    (0.42-0.62 of its height, 1 cm in from each edge) against those on the body above and below it: a
    stripe ``bright_stripe`` times brighter is blue (a white stripe on blue), 1.2-``bright_stripe``
    times orange (white on orange), ``dark_stripe`` times or darker yellow (black on yellow); without
    returns on both, or a contrast in between, unknown."""
    out = np.full(len(ids), UNKNOWN_CLASS, np.int64)
    v = z / CONE_HEIGHT_M["blue"]
    lo, hi = STRIPE_BAND
    edge = 0.01 / CONE_HEIGHT_M["blue"]
    stripe = (v >= lo + edge) & (v < hi - edge)
    body = ((v > 0.1) & (v < lo - edge)) | ((v >= hi + edge) & (v < 1.0))
    where = np.full(int(label.max()) + 1, -1, np.int64)
    where[ids] = np.arange(len(ids))
    k = where[label]
    for j in np.unique(k[(k >= 0) & stripe]):
        if top[j] > cfg.big_cone_m:
            continue
        on_body = (k == j) & body
        if not on_body.any():
            continue
        ratio = float(np.median(intensity[(k == j) & stripe])) / max(float(np.median(intensity[on_body])), 1e-9)
        if ratio >= cfg.bright_stripe:
            out[j] = CONE_CLASSES.index("blue")
        elif ratio >= 1.2:
            out[j] = CONE_CLASSES.index("orange")
        elif ratio <= cfg.dark_stripe:
            out[j] = CONE_CLASSES.index("yellow")
    out[top > cfg.big_cone_m] = CONE_CLASSES.index("big_orange")
    return out


def _empty() -> ConeArrays:
    f = np.zeros(0, np.float32)
    return ConeArrays(x_body=np.zeros(0), y_body=np.zeros(0), ranges=f, bearings=f, classes=np.zeros(0, np.int64),
                      scores=f, widths=f, heights=f, points=np.zeros(0, np.int64))
