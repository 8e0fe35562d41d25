"""The figures and numbers of docs/lidar.md: cone recall against range per LiDAR weather and severity, and
bird's-eye views of one scan in clear air, fog, rain and snow beside the camera's frame.

    PYTHONPATH=. python docs/lidar/figures.py [--tracks small_track,peanut] [--every 15] [--overwrite]

Scans: the ground-truth driver laps each track; every ``--every``-th step (at 30 Hz) both sensors (the
default HDL-32E and the solid-state preset) scan. Each scan goes through every weather at severities 1-5
(its own seed per scan and weather) and the cone extraction; the cones are scored against the cones the
clear scan hit with at least 2 returns (:mod:`weather_gym.perception.lidar_scoring`). Writes
``curves.json`` (every number), ``recall_by_range.png`` and ``birdseye.png`` here.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from weather_gym.agents import AGENTS  # noqa: E402
from weather_gym.camera.config import CameraConfig  # noqa: E402
from weather_gym.core._figures import save_figure  # noqa: E402
from weather_gym.core._io import atomic_file  # noqa: E402
from weather_gym.core.point_cloud import LABELS  # noqa: E402
from weather_gym.lidar_weather import LIDAR_EFFECTS, parse_lidar_weather  # noqa: E402
from weather_gym.perception.lidar_cones import cones_from_points  # noqa: E402
from weather_gym.perception.lidar_scoring import LidarScoring  # noqa: E402
from weather_gym.sim.config import SimConfig  # noqa: E402
from weather_gym.sim.lidar_config import LidarConfig  # noqa: E402
from weather_gym.sim.world import World  # noqa: E402
from weather_gym.tracks import load_track  # noqa: E402
from weather_gym.weather import make  # noqa: E402

HERE = Path(__file__).resolve().parent
SENSORS = {"HDL-32E": LidarConfig.hdl32e(), "solid-state": LidarConfig.solid_state()}
WEATHERS = ("fog", "rain", "snow", "wet")


def scans(track: str, every: int) -> list[tuple[tuple[float, float, float], dict, list[int]]]:
    """(pose, {sensor: clear scan}, cone ids seen) every ``every``-th step of a ground-truth lap."""
    trk = load_track(track)
    world = World(trk, sim=SimConfig(renderer="none"))
    out = []
    try:
        world.reset(tuple(trk.start_pose))
        agent = AGENTS.get("gt_pure_pursuit")(trk, CameraConfig())
        agent.reset(info={"pose": world.car.pose, "speed": 0.0})
        progress, last = 0.0, trk.project(*world.car.pose[:2]).s
        step = 0
        while progress < trk.length and step < 6000:
            a = agent.act(None, {"pose": world.car.pose, "speed": world.car.speed})
            world.step(float(a[0]), float(a[1]))
            s = trk.project(*world.car.pose[:2], s_hint=last).s
            progress += (s - last + trk.length / 2) % trk.length - trk.length / 2
            last = s
            step += 1
            if step % every == 0:
                clouds = {k: world.lidar_scan(cfg, np.random.default_rng(step)) for k, cfg in SENSORS.items()}
                truth = {k: _truth(c, world) for k, c in clouds.items()}
                out.append((world.car.pose, clouds, truth))
    finally:
        world.close()
    return out


def _truth(cloud, world) -> np.ndarray:
    ids, counts = np.unique(cloud.cone[cloud.cone >= 0], return_counts=True)
    ids = ids[counts >= 2]
    return np.asarray(world.cone_xy, float)[ids]


def _body(xy: np.ndarray, pose) -> np.ndarray:
    x, y, yaw = pose
    c, s = np.cos(yaw), np.sin(yaw)
    d = xy - (x, y)
    return np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]


def curves(frames, seed: int = 0) -> dict:
    out: dict = {}
    for sensor, cfg in SENSORS.items():
        out[sensor] = {}
        specs = ["clear"] + [f"{w}@{s}" for w in WEATHERS for s in range(1, 6)]
        for spec in specs:
            weather = parse_lidar_weather(spec)
            scoring = LidarScoring()
            for i, (pose, clouds, truth) in enumerate(frames):
                cloud = weather(clouds[sensor], np.random.default_rng([seed, i, len(spec)]))
                cones = cones_from_points(cloud, cfg)
                gt = _body(truth[sensor], pose)
                scoring.add(det_xy=np.c_[cones["x_body"], cones["y_body"]], gt_xy=gt,
                            gt_ranges=np.hypot(gt[:, 0] - cfg.mount_x, gt[:, 1] - cfg.mount_y),
                            det_ranges=np.asarray(cones["ranges"], float))
            out[sensor][spec] = {"weather": weather.describe(), **scoring.result().as_dict()}
    return out


def plot_curves(data: dict, path: Path, overwrite: bool) -> None:
    fig, axes = plt.subplots(len(SENSORS), len(WEATHERS), figsize=(4 * len(WEATHERS), 3.4 * len(SENSORS)),
                             sharey=True)
    for r, sensor in enumerate(SENSORS):
        for c, w in enumerate(WEATHERS):
            ax = axes[r, c]
            for sev in range(0, 6):
                spec = "clear" if sev == 0 else f"{w}@{sev}"
                rbr = data[sensor][spec]["recall_by_range"]
                labels = list(rbr)
                ax.plot(range(len(labels)), [rbr[k]["recall"] for k in labels], marker="o",
                        color=plt.cm.viridis(sev / 5), label="clear" if sev == 0 else
                        f"S{sev}: {LIDAR_EFFECTS.get(w).SEVERITIES[sev - 1]:g} {LIDAR_EFFECTS.get(w).PHYSICAL[1]}")
                ax.set_xticks(range(len(labels)), labels, fontsize=7)
            ax.set_title(f"{sensor}: {w}", fontsize=9)
            ax.set_ylim(0, 1.02)
            ax.legend(fontsize=6)
            if c == 0:
                ax.set_ylabel("cone recall")
    fig.tight_layout()
    save_figure(fig, path, overwrite=overwrite, dpi=90)


def birdseye(track: str, path: Path, overwrite: bool) -> None:
    trk = load_track(track)
    pose = tuple(float(v) for v in trk.point_at(12.0))
    world = World(trk, sim=SimConfig(renderer="tiny"))
    try:
        world.reset(pose)
        frame = world.render(segmentation=False).rgb
        cfg = LidarConfig.hdl32e()
        clear = world.lidar_scan(cfg, np.random.default_rng(0))
    finally:
        world.close()
    panels = [("clear", "clear")] + [(s, s) for s in ("fog:mor=50", "rain:rate=7.29", "snow:rate=2")]
    fig, axes = plt.subplots(1, 1 + len(panels), figsize=(4.2 * (1 + len(panels)), 4.2))
    fog_cam = make("fog", k=0.06 * 15.0 / 3.912)(frame)  # extinction 0.06 /m, as the LiDAR's fog@5
    axes[0].imshow(np.concatenate([frame, fog_cam], axis=0))
    axes[0].set_title("camera: clear / fog beta 0.06 /m", fontsize=9)
    axes[0].axis("off")
    colours = {"ground": "#999999", "cone": "#ff7f0e", "car": "#444444", "other": "#444444", "fog": "#1f77b4",
               "rain": "#1f77b4", "snow": "#17becf"}
    for ax, (title, spec) in zip(axes[1:], panels):
        cloud = parse_lidar_weather(spec)(clear, np.random.default_rng(1))
        cones = cones_from_points(cloud, cfg)
        for k, name in enumerate(LABELS):
            sel = cloud.label == k
            if sel.any():
                ax.scatter(cloud.xyz[sel, 0] + cfg.mount_x, cloud.xyz[sel, 1], s=1.0 if name == "ground" else 3.0,
                           c=colours[name], label=f"{name} ({int(sel.sum())})")
        ax.scatter(cones["x_body"], cones["y_body"], s=60, facecolors="none", edgecolors="red",
                   label=f"cones found ({cones.count})")
        ax.set_xlim(-8, 25)
        ax.set_ylim(-16.5, 16.5)
        ax.set_aspect("equal")
        ax.set_title(f"HDL-32E, {title}", fontsize=9)
        ax.legend(fontsize=6, loc="lower right", markerscale=3)
    fig.tight_layout()
    save_figure(fig, path, overwrite=overwrite, dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tracks", default="small_track,peanut")
    ap.add_argument("--every", type=int, default=15)
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args()
    frames = [f for t in args.tracks.split(",") for f in scans(t.strip(), args.every)]
    data = {"tracks": args.tracks, "every": args.every, "scans": len(frames), "curves": curves(frames)}
    with atomic_file(HERE / "curves.json", "w", overwrite=args.overwrite) as f:
        json.dump(data, f, indent=1)
    plot_curves(data["curves"], HERE / "recall_by_range.png", args.overwrite)
    birdseye(args.tracks.split(",")[0].strip(), HERE / "birdseye.png", args.overwrite)
    print(f"{len(frames)} scans; wrote {HERE / 'curves.json'}, recall_by_range.png, birdseye.png")


if __name__ == "__main__":
    main()
