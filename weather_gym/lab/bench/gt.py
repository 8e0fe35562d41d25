"""``weather-gym bench gt``: ground truth without rendering - how close to the rendered one, how fast.

Agreement: the ground-truth driver drives ``--steps`` steps of each track; every ``--every``-th
frame the cones that geometry says are visible (``World.ground_truth``, nothing rendered) are
compared with the rendered frame's segmentation (``info["gt"]``), in the plain and the realistic
world (whose clutter and ego car hide cones that geometry does not know of): recall and precision of the
visible set (by cone id), IoU of the visible boxes, relative error of the visible pixel count
(cones of 20+ rendered pixels).

Speed: env-steps/s of one env of the ``gt_cones`` perception (nothing rendered) and, as the
baseline in the same run, the ``oracle`` perception (the same cone list from the rendered frame),
each the median of ``--repeats`` blocks of ``--block`` steps after a warm-up, the car driving the
ground-truth lap (the agent's time is not counted). The machine's load average is printed with the
table: other processes on the same cores lower every number.

Example:
    $ weather-gym bench gt --track small_track,hairpin --camera 672x376

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'gt', '--track', 'small_track,hairpin', '--camera', '672x376'])
    >>> args.target, args.tracks, args.steps
    ('gt', 'small_track,hairpin', 900)
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from typing import Any

import numpy as np

from weather_gym.agents import AGENTS
from weather_gym.camera.config import CameraConfig
from weather_gym.core._option_alias import alias
from weather_gym.core.errors import InputError
from weather_gym.core.limits import parse_size
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.pipeline import make_env
from weather_gym.sim.config import SCENES, SimConfig
from weather_gym.sim.world import World
from weather_gym.tracks import load_track

BIG_PX = 20
"""Cones with at least this many rendered pixels are the ones whose pixel counts are compared."""


def register(targets) -> None:
    p = targets.add_parser("gt", help="ground truth from geometry: agreement with the rendered one, env-steps/s",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--track", dest="tracks", default="small_track,hairpin,peanut",
                   help="tracks to compare on, comma-separated (default %(default)s)")
    alias(p, "--track", "--tracks")
    p.add_argument("--camera", default="672x376", help="camera WxH (default %(default)s)")
    p.add_argument("--steps", type=int, default=900, help="steps driven per track (default %(default)s)")
    p.add_argument("--every", type=int, default=3, help="compare every N-th frame (default %(default)s)")
    p.add_argument("--block", type=int, default=200, help="steps per timed block (default %(default)s)")
    p.add_argument("--repeats", type=int, default=7, help="timed blocks per row (default %(default)s)")
    p.add_argument("--skip-speed", action="store_true", help="only the agreement table")
    p.set_defaults(func=run)


def _iou(a, b) -> float:
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - w * h
    return w * h / union if union > 0 else 0.0


def compare_ground_truth(track_name: str, camera: CameraConfig, steps: int = 900, every: int = 3,
                         scene: str = "plain") -> dict[str, Any]:
    """Geometric against rendered ground truth on ``steps`` steps of a ground-truth lap (see the module doc)
    in the world ``scene`` (the realistic world's clutter hides cones that geometry still counts).

    Returns the counts (``rendered``, ``geometric``, ``both``, ``big``, ``big_missed``) and the
    per-cone lists ``iou`` and ``pixel_err`` (geometric / rendered - 1).
    """

    track = load_track(track_name)
    world = World(track, camera=camera, sim=SimConfig(scene=scene))
    try:
        world.reset(tuple(track.start_pose))  # type: ignore[arg-type]  # (x, y, yaw)
        agent = AGENTS.get("gt_pure_pursuit")(track, camera)
        agent.reset(info={"pose": world.car.pose, "speed": 0.0})
        s: dict[str, Any] = {"rendered": 0, "geometric": 0, "both": 0, "big": 0, "big_missed": 0,
                             "iou": [], "pixel_err": []}
        for step in range(steps):
            a = agent.act(None, {"pose": world.car.pose, "speed": world.car.speed})
            world.step(float(a[0]), float(a[1]))
            if step % every:
                continue
            r, g = world.render().gt, world.ground_truth()
            assert r is not None  # render() segments by default
            ri = {int(c): i for i, c in enumerate(r["cone_ids"])}
            gi = {int(c): i for i, c in enumerate(g["cone_ids"])}
            s["rendered"] += len(ri)
            s["geometric"] += len(gi)
            s["both"] += len(ri.keys() & gi.keys())
            for c, i in ri.items():
                if r["pixels"][i] >= BIG_PX:
                    s["big"] += 1
                    s["big_missed"] += c not in gi
            for c in ri.keys() & gi.keys():
                s["iou"].append(_iou(r["boxes"][ri[c]], g["boxes"][gi[c]]))
                if r["pixels"][ri[c]] >= BIG_PX:
                    s["pixel_err"].append(float(g["pixels"][gi[c]]) / float(r["pixels"][ri[c]]) - 1.0)
        return s
    finally:
        world.close()


def agreement_row(track: str, s: dict[str, Any]) -> list[Any]:
    iou, err = np.asarray(s["iou"]), np.abs(np.asarray(s["pixel_err"]))
    return [track, s["rendered"], f"{s['both'] / max(s['rendered'], 1):.3f}", f"{s['both'] / max(s['geometric'], 1):.3f}",
            f"{s['big_missed']}/{s['big']}", f"{np.median(iou):.3f} / {np.percentile(iou, 10):.3f}",
            f"{100 * np.median(err):.1f} % / {100 * np.percentile(err, 90):.1f} %"]


def steps_per_s(perception: str, camera: CameraConfig, block: int, repeats: int) -> float:
    """Median env-steps/s of one env of ``perception`` driving the ground-truth lap of small_track."""

    env = make_env(perception=perception, camera=camera, laps=0, max_episode_steps=10**9, episode_statistics=False)
    try:
        u = env.unwrapped
        agent = AGENTS.get("gt_pure_pursuit")(u.track, camera)  # type: ignore[attr-defined]  # a ConeTrackEnv
        obs, info = env.reset(seed=0)
        agent.reset(info=info)
        actions = []
        for _ in range(block * (repeats + 1)):  # record the lap's actions: the agent is not timed
            a = agent.act(obs, info)
            actions.append(a)
            obs, _, term, trunc, info = env.step(a)
            if term or trunc:
                obs, info = env.reset(seed=0)
                agent.reset(info=info)
        env.reset(seed=0)
        rates = []
        for r in range(repeats + 1):
            chunk = actions[r * block:(r + 1) * block]
            t0 = time.perf_counter()
            for a in chunk:
                env.step(a)
            if r:  # the first block is the warm-up
                rates.append(len(chunk) / (time.perf_counter() - t0))
        return statistics.median(rates)
    finally:
        env.close()


def run(args: argparse.Namespace) -> int:
    w, h = parse_size(args.camera, what="--camera")
    for name in ("steps", "every", "block", "repeats"):
        if getattr(args, name) < 1:
            raise InputError(f"--{name} must be >= 1, got {getattr(args, name)}")
    camera = CameraConfig(width=w, height=h)
    tracks = [t for t in args.tracks.split(",") if t.strip()]
    rows = [[scene, *agreement_row(t, compare_ground_truth(t, camera, args.steps, args.every, scene))]
            for t in tracks for scene in SCENES]
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f}")
    print(f"Ground truth from geometry vs rendered, camera {w}x{h}, {args.steps} steps of a ground-truth lap, "
          f"every {args.every}th frame:")
    print(markdown_table(["world", "track", "cones visible (rendered)", "recall", "precision",
                          f"missed of {BIG_PX}+ px", "box IoU median / 10th pct.",
                          "pixel count error median / 90th pct."], rows))
    if not args.skip_speed:
        speed = [[p, f"{steps_per_s(p, camera, args.block, args.repeats):.0f}"] for p in ("gt_cones", "oracle")]
        print(f"\nOne env, small_track, camera {w}x{h}, median of {args.repeats} blocks of {args.block} steps "
              f"(load average {os.getloadavg()[0]:.1f}):")
        print(markdown_table(["perception", "env-steps/s"], speed))
    return 0
