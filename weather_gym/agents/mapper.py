"""``ConeMapper``: a global cone map built from noisy cone lists and the car's odometry.

Each step the detections (car frame) are moved into the odometry frame, associated with the mapped
cones by a gated global nearest neighbour (Hungarian assignment, ``scipy.optimize.linear_sum_assignment``,
on Mahalanobis distances), and fused with a per-cone Kalman update of its position. Every cone keeps a
colour vote (detector scores summed per class) and counts of hits and misses; it is *confirmed*
after ``min_hits`` associations within ``confirm_window`` updates (M-of-N), so an isolated false
detection never becomes a cone, and a tentative cone that stays undetected while in view is dropped.
Cones not associated for ``assoc_max_age`` updates are archived: odometry drifts and there is no
loop closure, so a lap later they are mapped afresh.

Example:
    >>> import numpy as np
    >>> from weather_gym.agents.mapper import ConeMapper
    >>> mapper = ConeMapper()
    >>> for step in range(4):   # one blue cone 10 m ahead, seen four times (min_hits) from a car at rest
    ...     _ = mapper.update(np.array([[10.0, 1.5]]), np.array([0]), np.array([0.9]), pose=(0.0, 0.0, 0.0))
    >>> m = mapper.map(confirmed_only=True)
    >>> m.xy.round(2).tolist(), m.classes.tolist(), len(m)
    ([[10.0, 1.5]], [0], 1)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from weather_gym.core.cone_spec import CONE_CLASSES, UNKNOWN_CLASS
from weather_gym.core.errors import InputError
from weather_gym.core.schema import NonNegative, Positive, PositiveInt, check_fields
from weather_gym.perception.cones import unpack_cones

__all__ = ["MapperConfig", "ConeMap", "ConeMapper"]

_N_CLASSES = len(CONE_CLASSES)
_UNASSIGNED = 1e9


@dataclass(frozen=True)
class MapperConfig:
    """Tuning of the cone mapper.

    Attributes:
        range_std, range_std_rel: measurement noise along the line of sight, ``std + rel * range`` (m).
        bearing_std: measurement noise across the line of sight (rad).
        process_std: random-walk std (m per update) added to every cone, which lets the map follow
            the slow odometry drift.
        gate_chi2: Mahalanobis gate (chi-square, 2 dof; 9.21 = 99 %).
        gate_max: hard cap of the association distance (m), below the spacing of neighbouring cones.
        min_hits, confirm_window: a cone is confirmed after ``min_hits`` associations within
            ``confirm_window`` updates of its first sighting, else dropped (M-of-N confirmation).
        max_misses: a tentative cone not detected this many times while in view is dropped.
        ghost_ratio: a confirmed cone is dropped when misses > ghost_ratio * hits + 10.
        min_score: detections below this confidence are ignored.
        max_range: detections farther than this (m from the camera) are ignored. 20 m: beyond it a
            cone is a few pixels tall and its range is unreliable; in the realistic world 75 % of the
            shipped detector's cones at 20-30 m were more than 1 m off (a median 2.3 m too long) and
            left ghost cones 1-2.5 m from the real ones (docs/world.md).
        view_range: a mapped cone counts as "in view" (so a non-detection is a miss) closer than this.
        hfov_deg, mount_x: camera field of view and forward offset, for the in-view test.
        spawn_dist, spawn_chi2: an unassociated detection closer than ``spawn_dist`` (m) to a mapped
            cone, or within ``spawn_chi2`` of it (Mahalanobis), starts no new cone: it is a noisy view
            of that cone, and a duplicate would split its hits.
        merge_dist: two cones closer than this (m) after an update are merged into one.
        assoc_max_age: cones not associated for this many updates (10 s at 30 Hz) stay in the map but
            take no further part in association: odometry drifts, so when the car comes back to them
            a lap later they no longer line up (there is no loop closure); the new sightings start
            fresh cones instead of corrupting the old ones.
    """

    range_std: Positive = 0.05
    range_std_rel: NonNegative = 0.04
    bearing_std: Positive = 0.01
    process_std: NonNegative = 0.005
    gate_chi2: Positive = 9.21
    gate_max: Positive = 1.5
    min_hits: PositiveInt = 4
    confirm_window: PositiveInt = 15
    max_misses: PositiveInt = 4
    ghost_ratio: NonNegative = 3.0
    min_score: NonNegative = 0.0
    max_range: Positive = 20.0
    view_range: Positive = 12.0
    hfov_deg: Positive = 90.0
    mount_x: float = 0.6
    spawn_dist: NonNegative = 1.0
    spawn_chi2: NonNegative = 16.0
    merge_dist: NonNegative = 0.3
    assoc_max_age: PositiveInt = 300

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class ConeMap:
    """A snapshot of the map (odometry frame) with its uncertainty.

    Attributes:
        xy: (K, 2) cone positions.
        cov: (K, 2, 2) position covariances (m^2).
        class_prob: (K, 4) colour vote, normalised (rows sum to 1; all zero for a cone whose colour was
            never seen, e.g. mapped from LiDAR cones: its class is ``UNKNOWN_CLASS``).
        hits, misses: (K,) association / in-view-but-undetected counts.
        confirmed: (K,) bool.
        age: (K,) updates since the cone was last associated (0 = seen in the latest frame).
    """

    xy: np.ndarray
    cov: np.ndarray
    class_prob: np.ndarray
    hits: np.ndarray
    misses: np.ndarray
    confirmed: np.ndarray
    age: np.ndarray

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @property
    def classes(self) -> np.ndarray:
        """Most voted class id per cone."""
        if not len(self):
            return np.zeros(0, np.int64)
        return np.where(self.class_prob.max(axis=1) > 0, self.class_prob.argmax(axis=1), UNKNOWN_CLASS)

    @property
    def class_confidence(self) -> np.ndarray:
        """Share of the colour vote that went to the winning class (1 = unanimous)."""
        return self.class_prob.max(axis=1) if len(self) else np.zeros(0)

    @property
    def position_std(self) -> np.ndarray:
        """Per-cone position std along its worst axis (m): sqrt of the covariance's largest eigenvalue."""
        if not len(self):
            return np.zeros(0)
        return np.sqrt(np.linalg.eigvalsh(self.cov)[:, -1])

    def summary(self) -> dict[str, float]:
        """The map's own uncertainty in a few numbers (over confirmed cones)."""
        c = self.confirmed
        return {
            "confirmed": int(c.sum()),
            "tentative": int((~c).sum()),
            "mean_position_std_m": float(self.position_std[c].mean()) if c.any() else float("nan"),
            "max_position_std_m": float(self.position_std[c].max()) if c.any() else float("nan"),
            "mean_class_confidence": float(self.class_confidence[c].mean()) if c.any() else float("nan"),
        }


def _rot(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


class ConeMapper:
    """Incremental cone map in the odometry frame. ``update`` once per step, ``map`` to read it."""

    def __init__(self, config: MapperConfig | None = None) -> None:
        self.config = config or MapperConfig()
        self.reset()

    def reset(self) -> None:
        self.xy = np.zeros((0, 2))
        self.cov = np.zeros((0, 2, 2))
        self.votes = np.zeros((0, _N_CLASSES))
        self.hits = np.zeros(0, np.int64)
        self.misses = np.zeros(0, np.int64)
        self.last_seen = np.zeros(0, np.int64)
        self.first_seen = np.zeros(0, np.int64)
        self.steps = 0
        self.last_assignment: np.ndarray = np.zeros(0, np.int64)  # landmark index per detection (-1 = new)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @property
    def confirmed(self) -> np.ndarray:
        return self.hits >= self.config.min_hits

    # ---- input -----------------------------------------------------------------------------------
    def update_from_obs(self, obs: dict) -> ConeMap:
        """Update from a cone-list observation (``cones``, ``mask``, ``state`` with odometry x, y, yaw)."""
        for key in ("cones", "mask", "state"):
            if key not in obs:
                raise InputError(f"ConeMapper needs obs[{key!r}] (a cone-list observation); got keys {sorted(obs)}")
        d = unpack_cones(obs["cones"], obs["mask"])
        state = np.asarray(obs["state"], dtype=np.float64).reshape(-1)
        if state.shape[0] < 5:
            raise InputError(f'obs["state"] must hold [speed, yaw_rate, odom_x, odom_y, odom_yaw], got {state.tolist()}')
        xy = np.c_[d["x_body"], d["y_body"]].astype(np.float64)
        return self.update(xy, d["classes"], d["score"], pose=state[2:5], ranges=d["range"], bearings=d["bearing"])

    def update(self, xy_body: np.ndarray, classes: np.ndarray, scores: np.ndarray, pose,
               ranges: np.ndarray | None = None, bearings: np.ndarray | None = None) -> ConeMap:
        """Fuse one frame of detections.

        Args:
            xy_body: (N, 2) cone positions in the car frame (x forward, y left, from the rear axle).
            classes, scores: (N,) class ids and confidences.
            pose: (x, y, yaw) of the car in the map (odometry) frame.
            ranges, bearings: camera range / bearing per detection (for the noise model); computed
                from ``xy_body`` when omitted.
        """
        cfg = self.config
        xy_body = np.asarray(xy_body, dtype=np.float64).reshape(-1, 2)
        n = xy_body.shape[0]
        classes = np.asarray(classes, dtype=np.int64).reshape(n)
        scores = np.asarray(scores, dtype=np.float64).reshape(n)
        px, py, yaw = (float(v) for v in np.asarray(pose, dtype=np.float64).reshape(3))
        if ranges is None or bearings is None:
            cam = xy_body - np.array([cfg.mount_x, 0.0])
            ranges, bearings = np.hypot(cam[:, 0], cam[:, 1]), np.arctan2(cam[:, 1], cam[:, 0])
        ranges = np.asarray(ranges, dtype=np.float64).reshape(n)
        bearings = np.asarray(bearings, dtype=np.float64).reshape(n)
        keep = (scores >= cfg.min_score) & (ranges <= cfg.max_range) & np.isfinite(xy_body).all(1)
        xy_body, classes, scores, ranges, bearings = (a[keep] for a in (xy_body, classes, scores, ranges, bearings))
        self.steps += 1
        # measurements in the map frame, with covariance from the range/bearing noise model
        c, s = math.cos(yaw), math.sin(yaw)
        z = np.c_[px + c * xy_body[:, 0] - s * xy_body[:, 1], py + s * xy_body[:, 0] + c * xy_body[:, 1]]
        sr = cfg.range_std + cfg.range_std_rel * ranges
        sb = np.maximum(ranges, 0.1) * cfg.bearing_std
        diag = np.zeros((len(z), 2, 2))
        diag[:, 0, 0], diag[:, 1, 1] = sr * sr, sb * sb
        rot = _rot(yaw + bearings)
        r_meas = rot @ diag @ np.swapaxes(rot, -1, -2)
        # prediction: static cones, plus a slow random walk for the odometry drift
        if len(self):
            self.cov = self.cov + (cfg.process_std**2) * np.eye(2)

        assign = self._associate(z, r_meas)
        self.last_assignment = assign
        matched = assign >= 0
        for i in np.flatnonzero(matched):  # Kalman update of each matched cone
            k = assign[i]
            p = self.cov[k]
            innov_cov = p + r_meas[i]
            gain = p @ np.linalg.inv(innov_cov)
            self.xy[k] = self.xy[k] + gain @ (z[i] - self.xy[k])
            self.cov[k] = (np.eye(2) - gain) @ p
            if classes[i] >= 0:  # a cone of unknown colour (a LiDAR's) casts no colour vote
                self.votes[k, classes[i]] += max(scores[i], 1e-3)
            self.hits[k] += 1
            self.last_seen[k] = self.steps
        # misses: mapped cones in view that nothing was associated with
        seen = np.zeros(len(self), bool)
        seen[assign[matched]] = True
        in_view = self._in_view(px, py, yaw)
        self.misses[in_view & ~seen] += 1
        # new (tentative) cones, but not from a detection that failed the gate right next to a mapped
        # cone: that is a noisy view of it (a duplicate would split its hits), not another cone
        new = ~matched
        if new.any() and len(self):
            new[np.flatnonzero(new)[self._explained(z[new], r_meas[new])]] = False
        if new.any():
            k0 = len(self)
            votes = np.zeros((int(new.sum()), _N_CLASSES))
            coloured = classes[new] >= 0
            votes[np.flatnonzero(coloured), classes[new][coloured]] = np.maximum(scores[new][coloured], 1e-3)
            self.xy = np.vstack([self.xy, z[new]])
            self.cov = np.concatenate([self.cov, r_meas[new]])
            self.votes = np.vstack([self.votes, votes])
            self.hits = np.r_[self.hits, np.ones(votes.shape[0], np.int64)]
            self.misses = np.r_[self.misses, np.zeros(votes.shape[0], np.int64)]
            self.last_seen = np.r_[self.last_seen, np.full(votes.shape[0], self.steps)]
            self.first_seen = np.r_[self.first_seen, np.full(votes.shape[0], self.steps)]
            assign[new] = np.arange(k0, k0 + votes.shape[0])
        self._prune()
        return self.map()

    # ---- internals -------------------------------------------------------------------------------
    def _associate(self, z: np.ndarray, r_meas: np.ndarray) -> np.ndarray:
        """Landmark index per measurement, -1 where none passes the gate (Hungarian on Mahalanobis d^2)."""
        cfg = self.config
        out = np.full(len(z), -1, np.int64)
        if not len(z) or not len(self):
            return out
        active = np.flatnonzero(self._active())
        if not len(active):
            return out
        tree = cKDTree(self.xy[active])
        near = tree.query_ball_point(z, r=cfg.gate_max)
        cand = np.unique(np.concatenate([np.asarray(v, np.int64) for v in near])) if any(near) else np.zeros(0, np.int64)
        if not len(cand):
            return out
        cand = active[cand]
        diff = z[:, None, :] - self.xy[cand][None, :, :]  # (N, C, 2)
        s = self.cov[cand][None, :, :, :] + r_meas[:, None, :, :]
        d2 = np.einsum("nci,ncij,ncj->nc", diff, np.linalg.inv(s), diff)
        eucl = np.hypot(diff[..., 0], diff[..., 1])
        ok = (d2 <= cfg.gate_chi2) & (eucl <= cfg.gate_max)
        cost = np.where(ok, d2, _UNASSIGNED)
        rows, cols = linear_sum_assignment(cost)
        good = ok[rows, cols]
        out[rows[good]] = cand[cols[good]]
        return out

    def _explained(self, z: np.ndarray, r_meas: np.ndarray) -> np.ndarray:
        """Which unassociated detections lie close to a mapped cone (Euclidean or Mahalanobis)."""
        cfg = self.config
        out = np.zeros(len(z), bool)
        active = np.flatnonzero(self._active())
        if not len(active):
            return out
        tree = cKDTree(self.xy[active])
        for i, near in enumerate(tree.query_ball_point(z, r=max(cfg.spawn_dist, 3.0 * cfg.gate_max))):
            if not near:
                continue
            near = active[near]
            diff = z[i] - self.xy[near]
            d2 = np.einsum("ki,kij,kj->k", diff, np.linalg.inv(self.cov[near] + r_meas[i]), diff)
            out[i] = bool((np.hypot(diff[:, 0], diff[:, 1]) < cfg.spawn_dist).any() or (d2 < cfg.spawn_chi2).any())
        return out

    def _active(self) -> np.ndarray:
        """Cones associated recently enough to take part in association (see ``assoc_max_age``)."""
        return self.steps - self.last_seen <= self.config.assoc_max_age

    def _in_view(self, px: float, py: float, yaw: float) -> np.ndarray:
        cfg = self.config
        if not len(self):
            return np.zeros(0, bool)
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = self.xy[:, 0] - px, self.xy[:, 1] - py
        xb, yb = c * dx + s * dy - cfg.mount_x, -s * dx + c * dy
        half = math.radians(cfg.hfov_deg) / 2 - 0.05  # a little inside the image edges
        view = (xb > 1.0) & (np.hypot(xb, yb) < cfg.view_range) & (np.abs(np.arctan2(yb, xb)) < half)
        return view & self._active()

    def _keep(self, keep: np.ndarray) -> None:
        self.xy, self.cov, self.votes = self.xy[keep], self.cov[keep], self.votes[keep]
        self.hits, self.misses, self.last_seen = self.hits[keep], self.misses[keep], self.last_seen[keep]
        self.first_seen = self.first_seen[keep]

    def _prune(self) -> None:
        cfg = self.config
        confirmed = self.confirmed
        drop = ~confirmed & (self.misses >= cfg.max_misses)
        drop |= ~confirmed & (self.steps - self.first_seen >= cfg.confirm_window)
        drop |= confirmed & (self.misses > cfg.ghost_ratio * self.hits + 10)
        if drop.any():
            self._keep(~drop)
        active = np.flatnonzero(self._active())
        if cfg.merge_dist > 0 and len(active) > 1:
            # duplicates of one cone: active (an archived cone a lap behind is displaced by the odometry
            # drift and only coincidentally close) and of the same colour
            pairs = active[cKDTree(self.xy[active]).query_pairs(cfg.merge_dist, output_type="ndarray")]
            if len(pairs):
                gone = np.zeros(len(self), bool)
                colour = self.votes.argmax(axis=1)
                for a, b in pairs:
                    if gone[a] or gone[b] or colour[a] != colour[b]:
                        continue
                    wa, wb = self.hits[a], self.hits[b]
                    self.xy[a] = (wa * self.xy[a] + wb * self.xy[b]) / (wa + wb)
                    if wb > wa:
                        self.cov[a] = self.cov[b]
                    self.votes[a] += self.votes[b]
                    self.hits[a] += self.hits[b]
                    self.misses[a] = min(self.misses[a], self.misses[b])
                    self.last_seen[a] = max(self.last_seen[a], self.last_seen[b])
                    self.first_seen[a] = min(self.first_seen[a], self.first_seen[b])
                    gone[b] = True
                self._keep(~gone)

    # ---- output ----------------------------------------------------------------------------------
    def map(self, confirmed_only: bool = False, max_age: int | None = None) -> ConeMap:
        """A copy of the map: all cones, or only confirmed ones; with ``max_age``, only cones
        associated within the last ``max_age`` updates (the part of the map the odometry drift has
        not yet displaced)."""
        sel = self.confirmed if confirmed_only else np.ones(len(self), bool)
        if max_age is not None:
            sel = sel & (self.steps - self.last_seen <= max_age)
        votes = self.votes[sel]
        total = votes.sum(axis=1, keepdims=True)
        prob = np.divide(votes, total, out=np.zeros_like(votes), where=total > 0)
        return ConeMap(
            xy=self.xy[sel].copy(), cov=self.cov[sel].copy(), class_prob=prob, hits=self.hits[sel].copy(),
            misses=self.misses[sel].copy(), confirmed=self.confirmed[sel].copy(),
            age=(self.steps - self.last_seen[sel]).astype(np.int64),
        )
