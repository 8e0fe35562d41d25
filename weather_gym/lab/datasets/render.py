"""Render COCO datasets by driving the ground-truth driver around tracks (``weather-gym dataset render``).

Frames are spread over short episodes: each episode picks a start point along the track (uniform
arc length), a lateral offset and heading error, an initial speed and - with ``randomize`` - a random
``Look`` (light direction and colour, ground and sky textures, cone shades, camera mount jitter),
then saves every ``every``-th env step while ``gt_pure_pursuit`` drives. Everything derives from
``seed`` (same seed, same bytes); an interrupted render resumes with ``resume=True``.

Example:
    >>> from weather_gym.lab.datasets.render import render_dataset
    >>> render_dataset("scratch/demo", tracks=["small_track"], frames=10, seed=0)   # doctest: +SKIP

How ``frames`` are spread over tracks and episodes (nothing is rendered):
    >>> episode_plan(["peanut", "hairpin"], frames=5, frames_per_episode=2)
    [('peanut', 2), ('peanut', 1), ('hairpin', 2)]
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from weather_gym.agents import AGENTS
from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core._io import atomic_write
from weather_gym.core.errors import InputError
from weather_gym.core.limits import check_seed
from weather_gym.envs.config import EnvConfig
from weather_gym.lab.datasets import coco_writer
from weather_gym.pipeline import make_env
from weather_gym.sim.config import SCENES, SimConfig
from weather_gym.sim.look import DEFAULT_LOOK, REALISTIC_LOOK, sample_look
from weather_gym.sim.randomize import RandomizeRanges, sample_realistic
from weather_gym.tracks import load_track, track_file_part

__all__ = ["render_dataset", "ViewRenderer", "episode_plan"]


def episode_plan(tracks: Sequence[str], frames: int, frames_per_episode: int) -> list[tuple[str, int]]:
    """Split ``frames`` over the tracks (as evenly as possible) and into episodes: ``[(track, n), ...]``."""
    if frames < 1:
        raise InputError(f"frames must be >= 1, got {frames}")
    if not tracks:
        raise InputError("at least one track is needed")
    if frames_per_episode < 1:
        raise InputError(f"frames_per_episode must be >= 1, got {frames_per_episode}")
    per_track = [frames // len(tracks) + (1 if i < frames % len(tracks) else 0) for i in range(len(tracks))]
    plan = []
    for t, n in zip(tracks, per_track, strict=True):
        while n > 0:
            k = min(n, frames_per_episode)
            plan.append((t, k))
            n -= k
    return plan


def _make_env(track: str, camera: CameraConfig, max_steps: int, scene: str = "plain", shadows: bool | None = None):
    return make_env(track=track, camera=camera, laps=0, terminate_off_track=True, max_episode_steps=max_steps,
                    episode_statistics=False, sim=SimConfig(scene=scene, shadows=shadows))


def _start_end(track) -> float:
    """The arc length up to which start points are drawn: the whole loop, or on an open track up to
    25 m before the finish (room to drive and save frames)."""
    return float(track.length) if track.closed else max(float(track.finish_s) - 25.0, 1.0)


def check_start_window(track, window: tuple[float, float] | None) -> None:
    """Refuse a start window that is empty or, on an open track, leaves the drivable arc length."""
    if window is None:
        return
    low, high = (float(v) for v in window)
    if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
        raise InputError(f"start window must be two finite metres LOW < HIGH around the start line, got {window}")
    if not track.closed:
        end = _start_end(track)
        a, b = float(track.start_line_s) + low, float(track.start_line_s) + high
        if a < 0.0 or b > end:
            raise InputError(f"start window {low:g},{high:g} m around the start line of open track {track.name!r} "
                             f"covers arc length {a:g}..{b:g} m; its start points must lie in 0..{end:g} m")


def _start_pose(track, rng: np.random.Generator, lateral_max: float,
                window: tuple[float, float] | None = None) -> tuple[float, float, float]:
    if window is None:
        s = float(rng.uniform(0.0, _start_end(track)))
    else:  # metres of arc length relative to the start line (negative: before it)
        s = float(track.start_line_s) + float(rng.uniform(float(window[0]), float(window[1])))
    x, y, h = track.point_at(s)
    left, right = track.half_widths_at(s)
    off = float(rng.uniform(-1.0, 1.0)) * min(lateral_max, 0.5 * min(left, right))
    dyaw = float(rng.uniform(-0.12, 0.12))
    return (x - off * math.sin(h), y + off * math.cos(h), h + dyaw)


def _checked_settings(seed: int, scene: str, ranges, every: int,
                      camera_model: CameraModel | None) -> tuple[RandomizeRanges, CameraModel]:
    """:func:`render_dataset`'s settings checked; ``(ranges, camera_model)`` with their defaults filled in."""
    check_seed(seed)
    if scene not in SCENES:
        raise InputError(f"scene must be one of {SCENES}, got {scene!r}")
    if ranges is not None and not isinstance(ranges, RandomizeRanges):
        raise InputError(f"ranges must be a RandomizeRanges, got {type(ranges).__name__}")
    if every < 1:
        raise InputError(f"every must be >= 1, got {every}")
    if camera_model is None:
        camera_model = EnvConfig().camera_model  # the env's default finishing stage
    if not isinstance(camera_model, CameraModel):
        raise InputError(f"camera_model must be a CameraModel, got {type(camera_model).__name__}")
    return ranges or RandomizeRanges(), camera_model


def _episode_look(rng: np.random.Generator, realistic: bool, randomize: bool, ranges: RandomizeRanges,
                  camera: CameraConfig, camera_model: CameraModel) -> tuple[Any, CameraModel, CameraConfig]:
    """``(look, camera model, camera)`` of one episode: drawn from ``rng`` when ``randomize``."""
    if realistic and randomize:
        draw = sample_realistic(rng, ranges)
        return draw.look, draw.camera_model, draw.camera(camera)
    if realistic:
        return REALISTIC_LOOK, camera_model, camera
    return (sample_look(rng) if randomize else DEFAULT_LOOK), camera_model, camera


def render_dataset(
    out: str | os.PathLike,
    *,
    tracks: Sequence[str],
    frames: int,
    seed: int = 0,
    randomize: bool = False,
    camera: CameraConfig | None = None,
    every: int = 3,
    frames_per_episode: int = 20,
    lateral_max: float = 0.8,
    progress: bool = True,
    overwrite: bool = False,
    resume: bool = False,
    scene: str = "plain",
    ranges=None,
    start_window: tuple[float, float] | None = None,
    camera_model: CameraModel | None = None,
    jpeg_quality: int | None = None,
    shadows: bool | None = None,
) -> Path:
    """Render ``frames`` frames over ``tracks`` into the COCO folder ``out``; returns annotations.json.

    Args:
        tracks: track specs (registered names, ``"random:SEED"``, ``"reverse:SPEC"``, ``"mirror:SPEC"`` or
            cone CSV paths; a CSV is copied into ``out/tracks/`` and the records name that copy).
        randomize: draw a random appearance per episode: in the plain scene a random ``Look``
            (``weather_gym.sim.look.sample_look``), in the realistic one a ``Look``, a camera model and a
            field of view from ``ranges`` (``weather_gym.sim.randomize.sample_realistic``); otherwise
            every frame uses the scene's default look (``REALISTIC_LOOK`` or ``DEFAULT_LOOK``).
        scene: ``"plain"`` (the default world) or ``"realistic"`` (``SimConfig.scene``).
        camera_model: the camera's finishing stage for every frame (None: the env's default,
            ``CameraModel.realistic()``; ``CameraModel.ideal()``: the study's ideal camera, as the plain world
            had before the camera model became the default); a randomised realistic render draws its own.
        ranges: ``RandomizeRanges`` of the realistic randomisation (None: the defaults).
        every: save one frame every ``every`` env steps (30 Hz control: every=3 -> 10 frames/s).
        frames_per_episode: frames saved per episode before a new start point / look is drawn.
        jpeg_quality: store the frames as JPEG of this quality (1-100) instead of PNG (None): smaller
            training sets to move to a GPU machine; the labels and depth maps are the same.
        start_window: ``(low, high)`` metres of arc length around the start line (negative: before it) to
            draw start points from instead of the whole track, e.g. ``(-35, -3)`` for frames approaching
            the start line and its big orange cones (None: uniform over the track).
        shadows: ``SimConfig.shadows`` (None: the renderer's own way, as the calibration's sets; False: EGL
            frames without PyBullet's shadow map). Recorded in the set (and so in its id) when given.
    """


    ranges, camera_model = _checked_settings(seed, scene, ranges, every, camera_model)
    if shadows is not None and not isinstance(shadows, bool):
        raise InputError(f"shadows must be True, False or None, got {shadows!r}")
    realistic = scene == "realistic"
    camera = camera or CameraConfig()
    plan = episode_plan(list(tracks), int(frames), int(frames_per_episode))
    # every episode's seed comes from the master seed, so resuming replays exactly the same episodes
    episode_seeds = np.random.SeedSequence(seed).generate_state(len(plan), dtype=np.uint32).tolist()
    info = {"tracks": list(tracks), "frames": int(frames), "seed": int(seed), "randomize": bool(randomize),
            "every": int(every), "frames_per_episode": int(frames_per_episode), "scene": scene,
            **({"randomize_ranges": ranges.to_dict()} if randomize and realistic else {}),
            **({"start_window": [float(v) for v in start_window]} if start_window is not None else {}),
            **({"shadows": shadows} if shadows is not None else {})}
    # a resumed render must be asked for exactly what the interrupted one was (seed included)
    identity = {**info, "camera": camera.to_dict(), "camera_model": camera_model.to_dict(),
                "jpeg_quality": jpeg_quality, "lateral_max": float(lateral_max)}
    writer = coco_writer.CocoWriter(out, overwrite=overwrite, resume=resume, jpeg_quality=jpeg_quality, info=info,
                              identity=identity)
    try:
        recorded = _record_tracks(Path(out), list(tracks))
    except BaseException:
        writer.abort()  # releases the folder's lock
        raise
    done_before = writer.done
    bar = tqdm(total=int(frames), initial=done_before, desc=f"render {Path(out).name}", unit="frame",
               disable=not progress)
    env = None
    env_track = None
    written = 0  # frames accounted for (including those of a resumed journal)
    try:
        for ep, ((track_spec, n_frames), ep_seed) in enumerate(zip(plan, episode_seeds, strict=True)):
            if written + n_frames <= done_before:  # this whole episode was written before the interruption
                written += n_frames
                continue
            rng = np.random.default_rng(ep_seed)
            look, model, ep_camera = _episode_look(rng, realistic, randomize, ranges, camera, camera_model)
            if env_track != (track_spec, ep_camera):
                if env is not None:
                    env.close()
                env = _make_env(track_spec, ep_camera, max_steps=every * frames_per_episode * 4 + 50, scene=scene,
                                shadows=shadows)
                env_track = (track_spec, ep_camera)
                check_start_window(env.unwrapped.track, start_window)
            assert env is not None  # made for the first episode
            pose = _start_pose(env.unwrapped.track, rng, lateral_max, start_window)
            speed = float(rng.uniform(0.0, 6.0))
            obs, info = env.reset(seed=int(ep_seed), options={"look": look, "start_pose": pose, "start_speed": speed,
                                                              "camera_model": model})
            agent = AGENTS.get("gt_pure_pursuit")(env.unwrapped.track, ep_camera)
            agent.reset(seed=int(ep_seed), info=info)
            saved = 0
            step = 0
            while saved < n_frames:
                if step % every == 0 and step > 0:
                    if written >= done_before:
                        record = {
                            "track": recorded[track_spec],
                            "pose": [float(v) for v in info["pose"]],
                            "speed": float(info["speed"]),
                            "yaw_rate": float(info["yaw_rate"]),
                            "camera": ep_camera.to_dict(),
                            "look": look.to_dict(),
                            "scene": scene,
                            **({"shadows": shadows} if shadows is not None else {}),
                            "camera_model": model.to_dict(),
                            "seed": int(ep_seed),
                            "episode": ep,
                            "step": step,
                        }
                        writer.add(obs["image"], record, info["gt"], depth=obs["depth"])
                        bar.update(1)
                    written += 1
                    saved += 1
                    if saved >= n_frames:
                        break
                obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
                step += 1
                if terminated or truncated:
                    # left the track or ran out of steps: fill the rest of this episode's quota from a new start
                    pose = _start_pose(env.unwrapped.track, rng, lateral_max, start_window)
                    obs, info = env.reset(options={"look": look, "start_pose": pose, "start_speed": 0.0,
                                                   "camera_model": model})
                    agent.reset(seed=int(ep_seed), info=info)
                    step = 0
    except BaseException:
        writer.abort()
        raise
    finally:
        bar.close()
        if env is not None:
            env.close()
    return writer.close()


def _record_tracks(out: Path, tracks: list[str]) -> dict[str, str]:
    """How each track spec is recorded in the image records: names as they are; a cone CSV is copied
    into ``out/tracks/`` and recorded by that relative path, so the dataset is self-contained (and a
    dataset's track path never leads outside it, see ``weather_gym.lab.datasets.coco.record_path``)."""

    recorded: dict[str, str] = {}
    used: set[str] = set()
    for spec in dict.fromkeys(tracks):
        part = track_file_part(spec)
        if part is None:
            recorded[spec] = spec
            continue
        prefix, file = part
        load_track(spec)  # a bad file fails here, before anything is rendered
        stem, n = Path(file).stem, 1
        name = f"tracks/{stem}.csv"
        while name in used:
            n += 1
            name = f"tracks/{stem}_{n}.csv"
        used.add(name)
        atomic_write(out / name, Path(file).read_bytes(), overwrite=True)  # the dataset's own copy
        recorded[spec] = prefix + name
    return recorded


class ViewRenderer:
    """Re-render dataset views: same track, camera, look and pose. Envs are cached per (track, camera)."""

    def __init__(self) -> None:
        self._envs: dict[tuple, Any] = {}

    def render(self, record: dict) -> dict[str, Any]:
        for key in ("track", "pose", "look", "camera"):
            if key not in record:
                raise InputError(f"image record {record.get('id')!r} has no {key!r}: it cannot be re-rendered")
        camera = CameraConfig(**record["camera"])
        scene = str(record.get("scene", "plain"))  # records before the "scene" key are of the plain world
        shadows = record.get("shadows")  # only sets rendered with SimConfig.shadows given have the key
        env_key = (record["track"], tuple(sorted(record["camera"].items())), scene, shadows)
        env = self._envs.get(env_key)
        if env is None:
            env = self._envs[env_key] = _make_env(record["track"], camera, max_steps=10, scene=scene, shadows=shadows)
        options = {"look": record["look"], "start_pose": record["pose"], "start_speed": float(record.get("speed", 0.0))}
        # records before the "camera_model" key were rendered without one (the ideal camera)
        options["camera_model"] = record.get("camera_model", CameraModel.ideal())
        # the sensor noise of the recorded frame: ``step`` frames after the episode's seeded reset
        options["camera_frame"] = int(record.get("step", 0))
        obs, info = env.reset(seed=int(record.get("seed", 0)), options=options)
        return {"image": obs["image"], "depth": obs["depth"], "gt": info["gt"]}

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
