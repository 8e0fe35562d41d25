"""``weather-gym bench sim``: physics steps/s, camera frames/s per renderer and resolution, real-time factor.

Example:
    $ weather-gym bench sim --repeats 30
    $ weather-gym bench sim --naive --repeats 40   # the default camera env step vs a naive TinyRenderer frame
    $ WEATHER_GYM_SHADOW_MAP_REUSE=1 weather-gym bench sim --naive   # adds the opt-in shadow-map reuse row

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'sim', '--repeats', '30'])
    >>> args.target, args.repeats, args.track
    ('sim', 30, 'small_track')
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from weather_gym.agents import make_agent
from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel, CameraPipeline
from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import interleaved_ms, machine_line, markdown_table, median_ms
from weather_gym.pipeline import make_env
from weather_gym.sim import renderer as _renderer
from weather_gym.sim.baseline import NAIVE_CYLINDERS, naive_scene
from weather_gym.sim.config import SimConfig
from weather_gym.sim.egl import shadow_map as egl_shadow_map
from weather_gym.sim.egl import shadow_reuse as egl_shadow_reuse
from weather_gym.sim.look import DEFAULT_LOOK
from weather_gym.sim.world import World
from weather_gym.tracks import load_track

NAIVE_SIZES = ((672, 376), (336, 188))


def register(targets) -> None:
    p = targets.add_parser("sim", help="simulator speed: physics, camera per renderer, real-time factor",
                           description="Times the PyBullet world: one control step of physics (8 substeps at "
                                       "240 Hz), one camera frame at 672x376 and 336x188 with each available "
                                       "renderer, and whole env steps (physics + camera + ground truth).")
    p.add_argument("--track", default="small_track", help="track to time on (default: small_track)")
    p.add_argument("--repeats", type=int, default=40, help="timed calls per measurement (median is reported)")
    p.add_argument("--naive", action="store_true",
                   help="only the default camera env step (make_env() defaults: physics, render, camera model, "
                        "segmentation ground truth) against a naive TinyRenderer frame of a bare PyBullet scene "
                        "(ground + 80 cone-sized cylinders) at 672x376 and 336x188, the rows taking turns call by "
                        "call; also the env with shadows=False (EGL without its shadow map) and with "
                        "renderer='tiny' (what runs where EGL does not load)")
    p.add_argument("--worlds", action="store_true",
                   help="only the world comparison: plain (baseline) vs realistic scene with EGL at 672x376, "
                        "with and without the segmentation pass, the cast shadows' cost (off; a low sun), "
                        "and the camera model's cost")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.repeats < 1:
        raise InputError(f"--repeats must be >= 1, got {args.repeats}")
    track = load_track(args.track)
    if args.naive:
        return _naive(args, track)
    if args.worlds:
        return _worlds(args, track)
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
                    physics_ms = median_ms(lambda w=world: w.step(0.0, 0.2), repeats=args.repeats)  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
                    world.reset(track.start_pose)
                frame_ms = median_ms(world.render, repeats=args.repeats)
            finally:
                world.close()
            env = make_env(track=args.track, sim=SimConfig(renderer=renderer), camera=CameraConfig(width=w, height=h),
                           max_episode_steps=10**6, terminate_off_track=False, episode_statistics=False)
            try:
                env.reset(seed=0)
                action = np.array([0.0, 0.1], np.float32)
                step_ms = median_ms(lambda e=env, a=action: e.step(a), repeats=args.repeats)  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
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


def _worlds(args: argparse.Namespace, track) -> int:
    """Plain vs realistic world (EGL, 672x376): camera frame with / without segmentation, the cast
    shadows' cost, and the camera model's finishing stage; the plain world is the baseline of the same run."""


    cam = CameraConfig()
    real = replace(DEFAULT_LOOK, ego_seed=3, clutter_seed=5)
    low, az = math.radians(15.0), math.radians(200.0)
    low_sun = (math.cos(low) * math.cos(az), math.cos(low) * math.sin(az), math.sin(low))
    worlds = {"plain": ("plain", DEFAULT_LOOK, True), "realistic": ("realistic", real, True),
              "realistic, no ego car": ("realistic", replace(DEFAULT_LOOK, clutter_seed=5), True),
              "realistic, no cast shadows": ("realistic", real, False),
              "realistic, sun at 15 deg (long shadows)": ("realistic", replace(real, light_direction=low_sun), True),
              "realistic, sun at 15 deg, no cast shadows": ("realistic", replace(real, light_direction=low_sun), False)}
    rows = []
    renderer = None
    rgb = None
    for name, (scene, look, cast) in worlds.items():
        world = World(track, sim=SimConfig(renderer="egl" if renderer is None else renderer, scene=scene,
                                           cast_shadows=cast), camera=cam, look=look)
        renderer = world.renderer_name
        try:
            x, y, h = track.point_at(10.0)
            world.reset((float(x), float(y), float(h)))
            seg = median_ms(world.render, repeats=args.repeats)
            noseg = median_ms(lambda w=world: w.render(segmentation=False), repeats=args.repeats)  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
            geo = median_ms(lambda w=world: (w.render(segmentation=False), w.ground_truth()), repeats=args.repeats)  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
            if name == "realistic, no ego car":  # the camera model's input
                rgb = world.render(segmentation=False).rgb
        finally:
            world.close()
        rows.append([name, seg, noseg, geo])
    assert rgb is not None
    rng = np.random.default_rng(0)
    cm = []
    for label, model in (("camera model: realistic preset (JPEG 90)", CameraModel.realistic()),
                         ("camera model: realistic preset, no JPEG", replace(CameraModel.realistic(), jpeg_quality=0))):
        pipe = CameraPipeline(model, cam.width, cam.height, fx=cam.fx)
        cm.append([label, median_ms(lambda p=pipe: p.apply(rgb, rng), repeats=max(args.repeats, 50))])  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.2f} at the end")
    print(f"Track: {args.track}; renderer {renderer}; 672x376; median of {args.repeats} calls after warm-up")
    print(markdown_table(["world", "frame + segmentation GT ms", "frame only ms", "frame + geometric GT ms"], rows))
    print(markdown_table(["finishing stage", "ms per 672x376 frame"], cm))
    return 0


def _driving_actions(track_name: str, n: int) -> list[np.ndarray]:
    """``n`` actions of ``gt_pure_pursuit`` from the start of a seed-0 episode (taken render-free: the
    car's motion does not depend on the camera), so the timed env drives the track and sees cones."""
    env = make_env(track=track_name, camera_images=False, ground_truth="geometry", episode_statistics=False)
    try:
        agent = make_agent("gt_pure_pursuit", env.unwrapped.track, env.unwrapped.config.camera)  # type: ignore[attr-defined]  # a ConeTrackEnv
        _, info = env.reset(seed=0)
        agent.reset(seed=0, info=info)
        actions = []
        for _ in range(n):
            action = agent.act(None, info)
            actions.append(action)
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        return actions
    finally:
        env.close()


class _Driver:
    """Steps ``env`` through ``actions`` (a new seed-0 episode when they run out or the episode ends)."""

    def __init__(self, env, actions: list[np.ndarray]) -> None:
        self.env, self.actions, self.i = env, actions, 0
        self.info = env.reset(seed=0)[1]

    def __call__(self) -> None:
        if self.i == len(self.actions):
            self.env.reset(seed=0)
            self.i = 0
        _, _, terminated, truncated, self.info = self.env.step(self.actions[self.i])
        self.i += 1
        if terminated or truncated:
            self.i = len(self.actions)


def _naive(args: argparse.Namespace, track) -> int:
    """The default camera env step against a naive TinyRenderer frame of the same size (the rows take turns)."""
    actions = _driving_actions(args.track, 400)
    rows = []
    for w, h in NAIVE_SIZES:
        cam = CameraConfig(width=w, height=h)
        frame, close = naive_scene(cam)
        envs = {"default": make_env(track=args.track, camera=cam)}
        try:
            drivers: dict[str, Callable[[], object]] = {"naive": frame}
            drivers["default"] = _Driver(envs["default"], actions)
            default_renderer = drivers["default"].info["renderer"]  # type: ignore[attr-defined]  # a _Driver
            if default_renderer == "egl":
                envs["default"].unwrapped.world.camera.shadow_reuse = None  # type: ignore[attr-defined]  # the default: the whole map
                if (reason := egl_shadow_reuse.unavailable_reason()) is None:  # WEATHER_GYM_SHADOW_MAP_REUSE=1
                    envs["reuse"] = make_env(track=args.track, camera=cam)
                    drivers["reuse"] = _Driver(envs["reuse"], actions)
                elif (w, h) == NAIVE_SIZES[0]:
                    print(f"(no shadow-map reuse row: {reason})")
            if default_renderer == "egl":  # the same env without the EGL plugin's shadow-map pass
                no_switch = egl_shadow_map.unavailable_reason()
                if no_switch is None:
                    envs["no_shadow_map"] = make_env(track=args.track, camera=cam, sim=SimConfig(shadows=False))
                    drivers["no_shadow_map"] = _Driver(envs["no_shadow_map"], actions)
                elif (w, h) == NAIVE_SIZES[0]:
                    print(f"(no shadows=False row: {no_switch})")
            if default_renderer != "tiny":
                envs["tiny"] = make_env(track=args.track, camera=cam, sim=SimConfig(renderer="tiny"))
                drivers["tiny"] = _Driver(envs["tiny"], actions)
            ms = interleaved_ms(drivers, repeats=args.repeats, warmup=3, budget_s=1e9, run=0)
        finally:
            close()
            for env in envs.values():
                env.close()
        detail = f" ({_renderer.renderer_detail()})" if default_renderer == "egl" and _renderer.renderer_detail() else ""
        rows.append([f"{w}x{h}", "naive TinyRenderer frame (baseline)", ms["naive"], 1.0])
        rows.append([f"{w}x{h}", f"default camera env step, renderer {default_renderer}{detail}", ms["default"],
                     ms["naive"] / ms["default"]])
        if "reuse" in ms:
            rows.append([f"{w}x{h}", "camera env step, WEATHER_GYM_SHADOW_MAP_REUSE=1 (same bytes)",
                         ms["reuse"], ms["naive"] / ms["reuse"]])
        if "no_shadow_map" in ms:
            rows.append([f"{w}x{h}", "camera env step, shadows=False (EGL without its shadow map)",
                         ms["no_shadow_map"], ms["naive"] / ms["no_shadow_map"]])
        if "tiny" in ms:
            rows.append([f"{w}x{h}", "default camera env step, renderer tiny (no EGL)", ms["tiny"],
                         ms["naive"] / ms["tiny"]])
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.2f} at the end")
    print(f"Track: {args.track} ({len(track.cones_xy)} cones), driven by gt_pure_pursuit from a seed-0 start; "
          f"naive scene: ground + {NAIVE_CYLINDERS} cylinders; median of {args.repeats} calls per row, "
          "the rows taking turns call by call")
    print(markdown_table(["resolution", "row", "ms per call", "speed-up vs naive frame"], rows))
    return 0
