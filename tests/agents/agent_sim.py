"""Closed-loop helpers for agent tests: the car's numpy dynamics and synthetic tracks, no PyBullet.

Imported by the tests in this folder as ``agent_sim`` (pytest puts the folder on ``sys.path``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core.cone_spec import cone_height
from weather_gym.perception.cones import pack_cones
from weather_gym.sim.car import Car
from weather_gym.sim.config import CarConfig

CONTROL_DT = 1.0 / 30.0
SUBSTEPS = 8


@dataclass
class SynthTrack:
    """Just enough of ``weather_gym.tracks.Track`` for the agents: centre line, width, cones."""

    centerline: np.ndarray
    closed: bool
    half_width: float
    cones_xy: np.ndarray
    cone_classes: np.ndarray

    @property
    def start_pose(self) -> tuple[float, float, float]:
        d = self.centerline[1] - self.centerline[0]
        return float(self.centerline[0, 0]), float(self.centerline[0, 1]), float(np.arctan2(d[1], d[0]))


def _cones_along(centerline: np.ndarray, closed: bool, half_width: float, spacing: float):
    p = np.vstack([centerline, centerline[:1]]) if closed else centerline
    seg = np.hypot(*np.diff(p, axis=0).T)
    s = np.r_[0.0, np.cumsum(seg)]
    si = np.arange(0.0, s[-1] - (0.5 * spacing if closed else 0.0), spacing)
    x, y = np.interp(si, s, p[:, 0]), np.interp(si, s, p[:, 1])
    tx, ty = np.interp(si + 0.1, s, p[:, 0]) - x, np.interp(si + 0.1, s, p[:, 1]) - y
    n = np.hypot(tx, ty)
    nx, ny = -ty / n, tx / n
    left = np.c_[x + half_width * nx, y + half_width * ny]
    right = np.c_[x - half_width * nx, y - half_width * ny]
    xy = np.vstack([left, right])
    classes = np.r_[np.zeros(len(left), np.int64), np.ones(len(right), np.int64)]
    return xy, classes


def make_track(centerline: np.ndarray, closed: bool = True, half_width: float = 1.75, spacing: float = 4.0):
    xy, classes = _cones_along(np.asarray(centerline, float), closed, half_width, spacing)
    return SynthTrack(np.asarray(centerline, float), closed, half_width, xy, classes)


def stadium(r: float = 5.0, length: float = 30.0) -> np.ndarray:
    t = np.linspace(-np.pi / 2, np.pi / 2, 60)
    right = np.c_[length + r * np.cos(t), r * np.sin(t)]
    left = np.c_[-r * np.cos(t), -r * np.sin(t)]
    top = np.c_[np.linspace(length, 0, 40), np.full(40, r)]
    bottom = np.c_[np.linspace(0, length, 40), np.full(40, -r)]
    return np.vstack([bottom[:-1], right[:-1], top[:-1], left[:-1]])


def random_loop(seed: int, n: int = 400, radius: float = 30.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = radius + sum(rng.normal(0, 6 / k) * np.cos(k * t + rng.uniform(0, 2 * np.pi)) for k in range(2, 6))
    return np.c_[r * np.cos(t), r * np.sin(t)]


def distance_to_polyline(points: np.ndarray, line: np.ndarray, closed: bool) -> np.ndarray:
    """Distance of each point to the polyline (segments, not just vertices)."""
    a = line
    b = np.roll(line, -1, axis=0) if closed else line[1:]
    a = a if closed else line[:-1]
    ab = b - a
    out = np.empty(len(points))
    for i, q in enumerate(points):
        t = np.clip(((q - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0, 1)
        out[i] = np.min(np.hypot(*(a + t[:, None] * ab - q).T))
    return out


class CarSim:
    """The env's car dynamics at the env's control rate, without rendering."""

    def __init__(self, pose, friction: float = 1.0) -> None:
        self.car = Car(CarConfig(friction=friction))
        self.car.reset(*pose)
        self.t = 0.0

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.car.pose

    @property
    def speed(self) -> float:
        return self.car.speed

    def step(self, action: np.ndarray) -> None:
        assert action.dtype == np.float32 and action.shape == (2,)
        assert np.all(np.abs(action) <= 1.0)
        for _ in range(SUBSTEPS):
            self.car.step(CONTROL_DT / SUBSTEPS, float(action[0]), float(action[1]))
        self.t += CONTROL_DT


class SyntheticCones:
    """Cone lists as a perfect (or noisy) detector would report them, from the true pose; no rendering.

    Cones in the camera's field of view closer than ``max_range`` are reported (no occlusion);
    ``range_noise`` (relative std), ``bearing_noise`` (rad std), ``miss_prob`` and ``false_per_frame``
    (Poisson mean of phantom cones) degrade it, ``swap_prob`` flips blue/yellow.
    """

    def __init__(self, track, camera: CameraConfig | None = None, max_range: float = 20.0, seed: int = 0,
                 range_noise: float = 0.0, bearing_noise: float = 0.0, miss_prob: float = 0.0,
                 false_per_frame: float = 0.0, swap_prob: float = 0.0) -> None:
        self.track, self.camera = track, camera or CameraConfig()
        self.max_range = max_range
        self.rng = np.random.default_rng(seed)
        self.range_noise, self.bearing_noise, self.miss_prob = range_noise, bearing_noise, miss_prob
        self.false_per_frame, self.swap_prob = false_per_frame, swap_prob

    def _polar(self, pose):
        cam = self.camera
        x, y, yaw = pose
        c, s = np.cos(yaw), np.sin(yaw)
        cx, cy = x + cam.mount_x * c, y + cam.mount_x * s
        d = np.asarray(self.track.cones_xy) - [cx, cy]
        xc, yc = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        half = np.radians(cam.hfov_deg) / 2 - 0.02
        rng_, brg = np.hypot(xc, yc), np.arctan2(yc, xc)
        return rng_, brg, (xc > 0.5) & (rng_ < self.max_range) & (np.abs(brg) < half), half

    def visible(self, pose) -> np.ndarray:
        """Indices of the track's cones in view from ``pose`` (before misses)."""
        return np.flatnonzero(self._polar(pose)[2])

    def __call__(self, pose) -> tuple[np.ndarray, np.ndarray]:
        cam = self.camera
        rng_, brg, vis, half = self._polar(pose)
        vis &= self.rng.random(len(vis)) >= self.miss_prob
        classes = np.asarray(self.track.cone_classes)[vis].copy()
        r, b = rng_[vis], brg[vis]
        n_false = self.rng.poisson(self.false_per_frame) if self.false_per_frame else 0
        if n_false:
            r = np.r_[r, self.rng.uniform(3, self.max_range, n_false)]
            b = np.r_[b, self.rng.uniform(-half, half, n_false)]
            classes = np.r_[classes, self.rng.integers(0, 2, n_false)]
        if len(r):
            r = r * (1 + self.range_noise * self.rng.standard_normal(len(r)))
            b = b + self.bearing_noise * self.rng.standard_normal(len(b))
            swap = (self.rng.random(len(classes)) < self.swap_prob) & (classes < 2)
            classes[swap] = 1 - classes[swap]
        u = cam.cx - cam.fx * np.tan(b)
        h = cam.fy * np.array([cone_height(int(k)) for k in classes]) / np.maximum(r, 0.1)
        boxes = np.c_[u - 0.35 * h, cam.cy - 0.2 * h, u + 0.35 * h, cam.cy + 0.8 * h]
        return pack_cones(classes=classes, ranges=r, bearings=b, scores=np.ones(len(r)), boxes=boxes, camera=cam)


class Odometry:
    """Wheel-speed and gyro dead reckoning from the true motion with a scale error and a gyro bias."""

    def __init__(self, pose, scale_error: float = 0.0, gyro_bias: float = 0.0) -> None:
        self.x, self.y, self.yaw = (float(v) for v in pose)
        self.scale_error, self.gyro_bias = scale_error, gyro_bias

    def step(self, car: Car, dt: float) -> None:
        st, lr = car.state, car.config.cg_to_rear
        vx_rear, vy_rear = st.vx, st.vy - lr * st.yaw_rate  # body-frame velocity of the rear axle
        v = np.hypot(vx_rear, vy_rear) * (1 + self.scale_error)
        slip = np.arctan2(vy_rear, max(vx_rear, 1e-6))
        self.yaw += (st.yaw_rate + self.gyro_bias) * dt
        self.x += v * np.cos(self.yaw + slip) * dt
        self.y += v * np.sin(self.yaw + slip) * dt

    @property
    def pose(self) -> tuple[float, float, float]:
        return self.x, self.y, self.yaw


def drive(track, agent, *, laps: float = 1.0, friction: float = 1.0, max_t: float = 300.0,
          perception: SyntheticCones | None = None, odometry: dict | None = None) -> dict:
    """Run ``agent`` on ``track`` (a real ``Track``) until ``laps`` are done (open tracks: the finish).

    Returns ``time``, ``completed``, ``min_margin`` (smallest gap between the car's side and the
    cone line, m; negative = a wheel crossed the boundary), ``max_error``, ``mean_error``.
    """
    sim = CarSim(track.start_pose, friction)
    odo = Odometry(track.start_pose, **(odometry or {}))

    def observe():
        state = np.array([sim.speed, sim.car.state.yaw_rate, *odo.pose], np.float32)
        obs = {"state": state}
        if perception is not None:
            obs["cones"], obs["mask"] = perception(sim.pose)
        return obs, {"pose": sim.pose, "speed": sim.speed}

    obs, info = observe()
    agent.reset(seed=0, info=info)
    s_prev = float(track.project(*sim.pose[:2]).s)
    progress = 0.0 if track.closed else s_prev
    goal = laps * track.length if track.closed else track.finish_s
    worst, errors = -np.inf, []
    while progress < goal and sim.t < max_t:
        sim.step(agent.act(obs, info))
        odo.step(sim.car, CONTROL_DT)
        obs, info = observe()
        p = track.project(sim.pose[0], sim.pose[1], s_hint=s_prev)
        ds = float(p.s) - s_prev
        if track.closed:
            ds = (ds + track.length / 2) % track.length - track.length / 2
        progress += ds
        s_prev = float(p.s)
        hl, hr = track.half_widths_at(p.s)
        lat = float(p.lateral)
        worst = max(worst, -(min(hl - lat, hr + lat) - 0.6))
        errors.append(abs(lat))
    return {"time": sim.t, "completed": progress >= goal, "min_margin": -worst,
            "max_error": float(np.max(errors)), "mean_error": float(np.mean(errors))}
