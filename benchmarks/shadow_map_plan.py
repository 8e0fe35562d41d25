"""What planning a frame's shadow map costs: reading every body's pose and projecting what moved
(``weather_gym.sim.egl.shadow_reuse.ShadowMapReuse``), per frame of a straight drive.

    python benchmarks/shadow_map_plan.py [--frames 40] [--cases small_track:plain,fsds_training:realistic]

Prints the median of the plans after the first five frames, with the number of bodies in the scene.
Needs PyBullet's EGL plugin (the plan is made for EGL frames only).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.sim.bullet import pybullet as p
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl.shadow_reuse import ShadowMapReuse
from weather_gym.sim.world import World
from weather_gym.tracks import load_track


def plan_ms(track_name: str, scene: str, frames: int) -> tuple[int, float]:
    """Bodies in the scene, and the median ms of a frame's plan (after the first five frames)."""
    track = load_track(track_name)
    world = World(track, sim=SimConfig(scene=scene))
    real = ShadowMapReuse._plan
    times: list[float] = []

    def timed(self, light):
        t0 = time.perf_counter()
        real(self, light)
        times.append(time.perf_counter() - t0)

    try:
        if world.camera.shadow_reuse is None:
            raise SystemExit("the default world does not reuse its shadow map here (no EGL?)")
        world.reset(track.start_pose)
        ShadowMapReuse._plan = timed
        for _ in range(frames):
            world.step(0.0, 0.5)
            world.render()
        return p.getNumBodies(physicsClientId=world.client), 1000 * float(np.median(times[5:]))
    finally:
        ShadowMapReuse._plan = real
        world.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=40, help="frames per case (default 40)")
    parser.add_argument("--cases", default="small_track:plain,fsds_training:plain,fsds_training:realistic",
                        help="comma-separated TRACK:SCENE pairs")
    args = parser.parse_args(argv)
    if args.frames < 6:
        parser.error(f"--frames must be >= 6, got {args.frames}")
    rows = []
    for case in args.cases.split(","):
        track, _, scene = case.partition(":")
        if scene not in ("plain", "realistic"):
            parser.error(f"--cases: {case!r} must be TRACK:plain or TRACK:realistic")
        bodies, ms = plan_ms(track, scene, args.frames)
        rows.append([track, scene, bodies, ms])
    print(f"Machine: {machine_line()}; median of {args.frames - 5} frames per case")
    print(markdown_table(["track", "scene", "bodies", "plan ms"], rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
