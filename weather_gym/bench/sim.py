"""``weather-gym bench sim``: physics steps/s, camera frames/s per renderer and resolution, real-time factor.

Example:
    $ weather-gym bench sim --repeats 30
"""

from __future__ import annotations

import argparse

import numpy as np

from weather_gym.bench._timing import machine_line, markdown_table, median_ms
from weather_gym.camera import CameraConfig
from weather_gym.pipeline import make_env
from weather_gym.sim.config import SimConfig
from weather_gym.sim.world import World
from weather_gym.tracks import load_track


def register(targets) -> None:
    p = targets.add_parser("sim", help="simulator speed: physics, camera per renderer, real-time factor",
                           description="Times the PyBullet world: one control step of physics (8 substeps at "
                                       "240 Hz), one camera frame at 672x376 and 336x188 with each available "
                                       "renderer, and whole env steps (physics + camera + ground truth).")
    p.add_argument("--track", default="small_track", help="track to time on (default: small_track)")
    p.add_argument("--repeats", type=int, default=40, help="timed calls per measurement (median is reported)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    track = load_track(args.track)
    rows = []
    physics_ms = None
    for renderer in ("tiny", "egl"):
        for w, h in ((672, 376), (336, 188)):
            try:
                world = World(track, sim=SimConfig(renderer=renderer), camera=CameraConfig(width=w, height=h))
            except RuntimeError as exc:
                print(f"renderer {renderer}: unavailable ({exc})")
                break
            try:
                world.reset(track.start_pose)
                if physics_ms is None:
                    physics_ms = median_ms(lambda w=world: w.step(0.0, 0.2), repeats=args.repeats)
                    world.reset(track.start_pose)
                frame_ms = median_ms(world.render, repeats=args.repeats)
            finally:
                world.close()
            env = make_env(track=args.track, sim=SimConfig(renderer=renderer), camera=CameraConfig(width=w, height=h),
                           max_episode_steps=10**6, terminate_off_track=False, episode_statistics=False)
            try:
                env.reset(seed=0)
                action = np.array([0.0, 0.1], np.float32)
                step_ms = median_ms(lambda e=env, a=action: e.step(a), repeats=args.repeats)
            finally:
                env.close()
            rows.append([renderer, f"{w}x{h}", frame_ms, 1000.0 / frame_ms, step_ms, 1000.0 / step_ms,
                         (1000.0 / step_ms) / 30.0])
    print(f"Machine: {machine_line()}")
    print(f"Track: {args.track} ({len(track.cones_xy)} cones); median of {args.repeats} calls after warm-up")
    assert physics_ms is not None
    print(f"Physics: one 30 Hz control step = 8 PyBullet steps at 240 Hz + bicycle model: {physics_ms:.2f} ms "
          f"({8000.0 / physics_ms:.0f} physics steps/s)")
    print(markdown_table(["renderer", "resolution", "camera frame ms", "frames/s", "env step ms", "env steps/s",
                          "real-time factor (30 Hz)"], rows))
    return 0
