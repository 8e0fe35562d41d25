"""``weather-gym lap``: drive scripted laps (sim -> weather -> perception -> agent) and report them.

Examples:
    weather-gym lap                                             # ground-truth driver, default track
    weather-gym lap --track peanut --laps 2 --video peanut.mp4
    weather-gym lap --track small_track --agent mapper_pure_pursuit --perception oracle --laps 2
    weather-gym lap --track small_track --weather droplets:0.55 --agent mapper_pure_pursuit --video out.mp4
    weather-gym lap --agent sb3 --agent-arg path=runs/ppo.zip --perception detector
    weather-gym lap --agent mapper_pure_pursuit --perception gt_cones     # nothing rendered: fast
    weather-gym lap --agent mapper_pure_pursuit --perception surrogate --weather droplets@3
    weather-gym lap --track hairpin --agent mapper_pure_pursuit --perception detector --weather droplets@3 --bag lap_bag

A command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['lap', '--track', 'small_track', '--agent', 'mapper_pure_pursuit', '--perception', 'oracle', '--laps', '2'])
    >>> args.track, args.agent, args.perception, args.laps
    ('small_track', 'mapper_pure_pursuit', 'oracle', 2)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, cast

import numpy as np
from tqdm import tqdm

from weather_gym.agents import AGENTS, agent_factory, agent_observes
from weather_gym.agents.mapper import MapperConfig
from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.cli._help import literal
from weather_gym.cli._presets_arg import add_presets_arg, default_choice, env_scenario, presets_from_arg
from weather_gym.cli._seed_arg import seed_arg
from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._option_alias import alias
from weather_gym.core.errors import InputError
from weather_gym.envs.cone_track import ConeTrackEnv
from weather_gym.envs.registration import scenario_of
from weather_gym.envs.scenario import build_config
from weather_gym.lab.evaluation.metrics import DetectorScoring, Episode, episode_metrics, lap_lines
from weather_gym.lidar_weather import parse_lidar_weather
from weather_gym.perception.ranging import check_depth_quantile
from weather_gym.pipeline import make_env
from weather_gym.pipeline.episode import run_episode
from weather_gym.pipeline.modes import (
    PERCEPTION_MODES,
    PerceptionMode,
    auto_mode,
    check_agent_observes,
    modes_where,
    perception_mode,
)
from weather_gym.ros.bag_output import check_bag_output
from weather_gym.ros.episode_bag import BAG_IMAGES, ConeNoise, EpisodeBag
from weather_gym.tracks import load_track, track_label
from weather_gym.viz.overlay import TopDownView, compose_frame, cone_list_boxes, draw_boxes
from weather_gym.viz.video import FrameSampler, VideoWriter, check_output_path, save_strip
from weather_gym.weather import parse_weather

AUTO = "auto"
"""``--perception auto``: the first registered mode that gives what the agent observes."""
MIN_SPEED_FOR_LIMIT = 2.0
"""Default time limit: every lap may take up to length / 2 m/s (at least a minute)."""

def perception_choices() -> tuple[str, ...]:
    """``--perception``'s choices: ``auto`` and every registered mode."""
    return (AUTO, *PERCEPTION_MODES)


def _epilog() -> str:
    modes = [f"  {AUTO:<9} the first mode below that gives what the agent reads (agents that read cone lists:"
             f" {auto_mode(frozenset({'cones'})).name}), else {auto_mode(()).name}"]
    modes += [f"  {m.name:<9} {m.describe()}" for m in PERCEPTION_MODES.values()]
    return ("perception (what the agent sees; the modes of weather_gym.pipeline.modes.PERCEPTION_MODES):\n"
            + "\n".join(modes) + "\n\n" + EPILOG)


EPILOG = """\
weather: a spec for weather_gym.weather.parse_weather, e.g. droplets:0.55, "droplets:0.55,dim:0.3",
  droplets@3 (a calibrated preset, severity 0-4), low_light@2, clear.

output: per-lap times, cones hit, off-track events, mean/max cross-track error, why the run ended
  (laps | off_track | time_limit) and the renderer; --video writes an MP4 of the camera view
  (weathered) with the cone boxes the agent received and a top-down map inset; --strip a PNG grid
  of frames. Existing files are never replaced without --overwrite.
  Exit status 0 when every requested lap was completed, 1 when not (off track or time limit).

examples:
  weather-gym lap --track peanut --laps 2 --video peanut.mp4
  weather-gym lap --track small_track --agent mapper_pure_pursuit --perception oracle --laps 2
  weather-gym lap --weather droplets:0.55 --agent mapper_pure_pursuit --laps 2 --video out.mp4
"""


def register(sub) -> None:
    p = sub.add_parser(
        "lap", help="drive laps with an agent; print lap times, cones hit, off-track events, cross-track error",
        description="Drive scripted laps through the whole pipeline (simulator -> weather -> perception -> "
                    "agent) and report lap times, cones hit, off-track events and cross-track error; "
                    "optionally record a video or a PNG strip.",
        epilog=_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--track", help="track name, 'random:SEED', 'reverse:SPEC', 'mirror:SPEC' or a cone CSV "
                                   "(default: the scenario's track); see `weather-gym tracks list`")
    p.add_argument("--env-id", dest="env", default="WeatherGym/ConeTrack-v0", help="Gymnasium env id (default %(default)s)")
    alias(p, "--env-id", "--env")
    p.add_argument("--agent", default="gt_pure_pursuit",
                   help=f"registered agent ({literal(', '.join(AGENTS))}) or an agent of your own as "
                        "'module.path:Factory' (default gt_pure_pursuit)")
    p.add_argument("--agent-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="keyword for the agent factory, repeatable (e.g. v_max=12, path=model.zip)")
    p.add_argument("--weather", help="weather spec (e.g. droplets:0.55 or droplets@3); default: the scenario's")
    p.add_argument("--perception", choices=perception_choices(), default=AUTO, help="what the agent sees (see below)")
    p.add_argument("--lidar-weather", metavar="SPEC",
                   help="weather on the LiDAR (--perception lidar): fog:mor=60, rain:rate=5, snow@3, wet@2, joined by "
                        "'+' (weather_gym.lidar_weather; default clear)")
    p.add_argument("--conditions", metavar="STATE",
                   help="one physical weather for the camera, the LiDAR and the tyres: rain:8mm/h, fog:60m, "
                        "dusk:20lux, film:0.5mm, joined by '+' (docs/conditions.md); not with --weather / --lidar-weather")
    add_detector_args(p, what=f"for --perception {' / '.join(modes_where(runs_detector=True))}")
    add_presets_arg(p)
    p.add_argument("--depth-quantile", type=float, default=None, metavar="Q",
                   help="quantile of the depths inside a detection's box that gives its range (a perception "
                        "that runs the detector; default the median, 0.5; 0.25 ranges far cones better: docs/perception.md)")
    p.add_argument("--laps", type=int, default=1, help="laps to drive (default %(default)s)")
    p.add_argument("--seed", type=seed_arg, default=0, help="episode seed (default %(default)s)")
    p.add_argument("--max-steps", type=int,
                   help="time limit in steps (TimeLimit; default: laps x max(60 s, length / 2 m/s))")
    p.add_argument("--video", type=Path, metavar="PATH.mp4", help="write an MP4 of the run")
    p.add_argument("--strip", type=Path, metavar="PATH.png", help="write a PNG strip of frames")
    p.add_argument("--strip-frames", type=int, default=8, help="frames in the strip (default %(default)s)")
    p.add_argument("--bag", type=Path, metavar="FOLDER",
                   help="write an MCAP rosbag2 of the run: camera (clear and weathered), CameraInfo, detected and "
                        "true cones (eufs_msgs/ConeArrayWithCovariance), odometry, TF (docs/ros.md)")
    p.add_argument("--bag-images", choices=BAG_IMAGES, default="jpeg",
                   help="camera frames in --bag: jpeg (CompressedImage, quality 90) or raw (Image rgb8, the exact "
                        "pixels, about ten times larger); default %(default)s")
    p.add_argument("--overwrite", action="store_true", help="replace existing --video / --strip files / --bag")
    p.add_argument("--json", type=Path, metavar="PATH.json",
                   help="write the result as one JSON object (the summary's numbers, machine-readable); '-' prints "
                        "it instead of the text summary")
    p.set_defaults(func=_run)


def parse_agent_args(items: list[str]) -> dict[str, Any]:
    """``["v_max=12", "path=a.zip"]`` -> ``{"v_max": 12, "path": "a.zip"}`` (ints, floats, booleans parsed)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--agent-arg {item!r}: expected KEY=VALUE")
        value: Any = raw
        if raw.lower() in ("true", "false"):
            value = raw.lower() == "true"
        else:
            for cast in (int, float):
                try:
                    value = cast(raw)
                    break
                except ValueError:
                    continue
        out[key.strip()] = value
    return out


def _run(args) -> int:
    if args.laps < 1:
        raise InputError(f"--laps must be >= 1, got {args.laps}")
    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps must be >= 1, got {args.max_steps}")
    if args.strip_frames < 1:
        raise InputError(f"--strip-frames must be >= 1, got {args.strip_frames}")
    if args.video is not None:
        check_output_path(args.video, overwrite=args.overwrite, suffixes=(".mp4",))
    if args.strip is not None:
        check_output_path(args.strip, overwrite=args.overwrite, suffixes=(".png",))
    if args.video is not None and args.strip is not None and args.video.resolve() == args.strip.resolve():
        raise InputError("--video and --strip must be different files")
    to_stdout = args.json is not None and str(args.json) == "-"
    if args.json is not None and not to_stdout:
        check_output(args.json, overwrite=args.overwrite, suffixes=(".json",), what="--json")
    detector = detector_spec_from_args(args)
    agent_kwargs = parse_agent_args(args.agent_arg)
    mode = auto_mode(agent_observes(args.agent)) if args.perception == AUTO else perception_mode(args.perception)
    presets = presets_from_arg(default_choice(args.presets, args.weather, mode),
                               lambda: env_scenario(args.env, args.track, detector))
    result = run_laps(
        env_id=args.env, track=args.track, agent=args.agent, agent_kwargs=agent_kwargs, weather=args.weather,
        perception=args.perception, detector=detector, laps=args.laps, seed=args.seed,
        max_steps=args.max_steps, video=args.video, strip=args.strip, strip_frames=args.strip_frames,
        overwrite=args.overwrite, progress=True, depth_quantile=args.depth_quantile, bag=args.bag,
        bag_images=args.bag_images, lidar_weather=args.lidar_weather, presets=presets, conditions=args.conditions,
    )
    if to_stdout:
        print(result_json(result))
    else:
        print(format_result(result))
        if args.json is not None:
            atomic_write(args.json, result_json(result) + "\n", overwrite=args.overwrite)
            print(f"json: {args.json}")
    return 0 if result["completed"] else 1


def result_json(result: dict[str, Any]) -> str:
    """The lap's result as one JSON object: numbers as JSON numbers, a metric that could not be
    measured (None, NaN) as null.

    Example:
        >>> result_json({"lap_times_s": [np.float64(20.77)], "metrics": {"map50": float("nan")}})
        '{"lap_times_s": [20.77], "metrics": {"map50": null}}'
    """

    def plain(value: Any) -> Any:
        if isinstance(value, dict):
            return {str(k): plain(v) for k, v in value.items()}
        if isinstance(value, (list, tuple, np.ndarray)):
            return [plain(v) for v in value]
        if isinstance(value, (np.integer, np.bool_)):
            return value.item()
        if isinstance(value, (float, np.floating)):
            return float(value) if math.isfinite(value) else None
        return value

    return json.dumps(plain(result))


def default_max_steps(env_id: str, track: str | None, laps: int) -> int:
    """The lap command's time limit: every lap may take up to max(60 s, length / 2 m/s)."""

    cfg = build_config(scenario_of(env_id), {"track": track} if track is not None else None)
    length = load_track(cfg.track, seed=cfg.track_seed).length
    return int(math.ceil(laps * max(60.0, length / MIN_SPEED_FOR_LIMIT) * cfg.sim.control_hz))


def _perception_kwargs(mode: PerceptionMode, recording: bool, depth_quantile: float | None,
                       lidar_weather: str | None = None) -> dict[str, Any]:
    """The perception wrapper's keyword arguments for ``mode``: its recording ones when ``recording``,
    ``depth_quantile`` (checked; only for a mode that runs the detector) and ``lidar_weather`` (checked;
    only for a mode with a LiDAR)."""
    kwargs = dict(mode.record_kwargs) if recording else {}
    if lidar_weather is not None:
        if not mode.takes_lidar_weather:
            raise InputError(f"--lidar-weather acts on the LiDAR, and perception {mode.name!r} has none; take "
                             f"--perception {' or '.join(modes_where(takes_lidar_weather=True))}")
        parse_lidar_weather(lidar_weather)  # a bad spec fails here, with the parser's message
        kwargs["lidar_weather"] = lidar_weather
    if depth_quantile is not None:
        if not mode.runs_detector:
            raise InputError(f"--depth-quantile ranges the detector's boxes, and perception is {mode.name!r}; "
                             f"it needs --perception {' or '.join(modes_where(runs_detector=True))}")
        kwargs["depth_quantile"] = check_depth_quantile(depth_quantile)
    return kwargs


def run_laps(*, env_id: str = "WeatherGym/ConeTrack-v0", track: str | None = None, agent: str = "gt_pure_pursuit",  # noqa: C901
             agent_kwargs: dict[str, Any] | None = None, weather: str | None = None, perception: str = AUTO,
             detector: Any = None, laps: int = 1, seed: int = 0, max_steps: int | None = None,
             video: Path | None = None, strip: Path | None = None, strip_frames: int = 8,
             overwrite: bool = False, progress: bool = False, depth_quantile: float | None = None,
             bag: Path | None = None, bag_images: str = "jpeg", lidar_weather: str | None = None,
             presets: Any = None, conditions: str | None = None) -> dict[str, Any]:
    """Drive ``laps`` laps and return the measurements (see ``format_result``).

    ``conditions``: one physical weather state for the camera, the LiDAR and the tyres
    (:mod:`weather_gym.conditions`; not with ``weather`` or ``lidar_weather``).

    ``bag``: also write the run as an MCAP rosbag2 folder (:class:`~weather_gym.ros.episode_bag.EpisodeBag`).

    The env comes from :func:`weather_gym.pipeline.make_env` (its ``TimeLimit`` is ``max_steps``)
    and the episode from :func:`weather_gym.pipeline.run_episode`. ``presets``: the presets file a
    ``CONDITION@SEVERITY`` reads (None: resolved for the run's scenario, unless ``$WEATHER_GYM_PRESETS`` is
    ``pool`` or a file: :mod:`weather_gym.pipeline.presets_default`); the
    result's ``weather_k`` and ``weather_source`` say which k was used and where it came from.
    """

    factory = agent_factory(agent)
    observes = agent_observes(agent)
    mode = auto_mode(observes) if perception == AUTO else perception_mode(perception)
    check_agent_observes(agent, observes, mode)
    recording = video is not None or strip is not None
    if bag is not None:
        check_bag_output(bag, "rosbag2", overwrite, what="--bag")
        if bag_images not in BAG_IMAGES:
            raise InputError(f"--bag-images must be one of {', '.join(BAG_IMAGES)}, got {bag_images!r}")
    if recording and not mode.can_record_video:
        alike = (modes_where(can_record_video=True, observation=mode.observation)
                 or modes_where(can_record_video=True))
        raise InputError(f"--video/--strip record the camera, and perception {mode.name} renders none; take "
                         f"--perception {' or '.join(alike)} for a video")
    if max_steps is None:
        max_steps = default_max_steps(env_id, track, laps)
    env_kwargs: dict[str, Any] = {"laps": laps}
    if track is not None:
        env_kwargs["track"] = track
    if weather is not None:
        parse_weather(weather, presets)  # a bad spec fails here, with the parser's message
    perception_kwargs = _perception_kwargs(mode, recording or (bag is not None and mode.can_record_video),
                                           depth_quantile, lidar_weather)
    env = make_env(env_id, perception=mode.name, weather=weather, detector=detector if mode.runs_detector else None,
                   perception_kwargs=perception_kwargs or None, max_episode_steps=max_steps, presets=presets,
                   conditions=conditions, **env_kwargs)
    recorder = None
    episode_bag: EpisodeBag | None = None
    try:
        base = cast(ConeTrackEnv, env.unwrapped)
        trk, camera = base.track, base.config.camera
        hz = float(base.config.sim.control_hz)
        driver = factory(trk, camera, **(agent_kwargs or {}))
        bar = _LapProgress(laps * trk.length, f"{agent} on {trk.name}", enabled=progress)
        scoring = DetectorScoring(mode, final_frame=True)  # every frame the detector saw, the last one too
        state: dict[str, Any] = {}

        def on_step(step: int, obs: Any, info: dict, done: bool) -> None:
            nonlocal recorder, episode_bag
            if step == 0:
                state["weather"] = weather or info.get("conditions") or info.get("lidar_weather") or _describe_weather(info.get("weather"))
                state["weather_k"] = info.get("weather", [])
                state["weather_source"] = info.get("weather_source", "given")
                state["weathered"] = "weather" in info
                if recording:
                    recorder = _Recorder(video, strip, strip_frames, overwrite, hz, trk, driver, agent,
                                         state["weather"])
                if bag is not None:
                    m = MapperConfig()  # the cones' covariance: the mapper's range/bearing noise model
                    episode_bag = EpisodeBag.for_env(bag, base, weathered=state["weathered"], images=bag_images,
                                                     noise=ConeNoise(m.range_std, m.range_std_rel, m.bearing_std),
                                                     overwrite=overwrite)
            scoring(step, obs, info, done)
            if recorder is not None:
                recorder.add(obs, info, laps)
            if episode_bag is not None:
                episode_bag.add_step(base, obs, info)
            if step and step % 30 == 0:
                bar.update(info, laps)

        try:
            res = run_episode(env, driver, seed=seed, on_step=on_step, agent_name=agent)
        except BaseException as exc:
            if recorder is not None:
                recorder.abort()  # an interrupted run leaves no half-written video or strip
            if episode_bag is not None:
                episode_bag.__exit__(type(exc), exc, None)  # nor a bag
            raise
        finally:
            bar.close()
        if recorder is not None:
            recorder.close()
        if episode_bag is not None:
            episode_bag.__exit__(None, None, None)
        renderer = base.renderer
    finally:
        env.close()
    result = {
        "env": env_id, "track": trk.name if track is None else track_label(track), "track_spec": track or trk.name,
        "event": trk.event, "track_length_m": float(trk.length), "agent": agent,
        "perception": mode.name, "weather": state["weather"], "weather_k": state.get("weather_k", []),
        "weather_source": state.get("weather_source", "given"), "presets": None if presets is None else str(presets),
        "seed": seed, "laps_requested": laps,
        "lap_times_s": list(res.lap_times_s), "completed": res.completed, "end": res.end_reason,
        "steps": res.steps, "sim_time_s": res.steps / hz, "wall_time_s": res.wall_time_s,
        "max_steps": max_steps, "renderer": renderer,
        "metrics": episode_metrics(Episode(res, driver, trk, mode, scoring.scores(), state["weathered"]), lap=True),
    }
    cone_map = getattr(driver, "last_map", None)
    if cone_map is not None:
        result["map"] = cone_map.summary()
    if recording:
        result["video"] = str(video) if video is not None else None
        result["video_frames"] = recorder.video.frames if recorder is not None and recorder.video is not None else 0
        result["video_codec"] = recorder.video.codec if recorder is not None and recorder.video is not None else None
        result["strip"] = str(strip) if strip is not None else None
    if episode_bag is not None:
        result["bag"] = str(bag)
        result["bag_topics"] = dict(sorted(episode_bag.counts.items()))
    return result


class _LapProgress:
    """Distance driven along the track: a tqdm bar on a terminal, a plain line every 10 s otherwise."""

    EVERY_S = 10.0

    def __init__(self, total_m: float, desc: str, *, enabled: bool) -> None:
        self.enabled, self.desc = enabled, desc
        self.tty = enabled and sys.stderr.isatty()
        self.bar = tqdm(total=round(total_m), unit="m", desc=desc, leave=False, disable=not self.tty)
        self.t0 = self.last = time.perf_counter()

    def update(self, info: dict, laps: int) -> None:
        done = max(0.0, float(info.get("progress", 0.0)))
        lap = min(int(info["lap"]) + 1, laps)
        if self.tty:
            self.bar.n = min(round(done), self.bar.total)
            self.bar.set_postfix(lap=f"{lap}/{laps}", v=f"{info['speed']:.1f}")
        elif self.enabled and time.perf_counter() - self.last >= self.EVERY_S:
            self.last = time.perf_counter()
            print(f"{self.desc}: lap {lap}/{laps}, {done:.0f}/{self.bar.total} m, "
                  f"{float(info.get('time', 0.0)):.1f} s simulated, {self.last - self.t0:.0f} s wall",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        self.bar.close()


def _describe_weather(spec: Any) -> str:
    """``info["weather"]`` (a list of effect tables, or None) as ``name:k,...``; ``clear`` without."""
    if not spec:
        return "clear"
    try:
        return ",".join(f"{e['name']}:{float(e['k']):g}" for e in spec)
    except (TypeError, KeyError, ValueError):
        return str(spec)


def format_result(r: dict[str, Any]) -> str:
    lines = [f"track {r['track']} ({r['event']}, {r['track_length_m']:.1f} m) | agent {r['agent']} | "
             f"perception {r['perception']} | weather {r['weather']} | seed {r['seed']}"]
    if r.get("weather_k"):
        ks = ", ".join(f"{t['name']} k={t['k']:.3f}" for t in r["weather_k"] if "k" in t)
        src = r.get("weather_source", "given")
        lines.append(f"weather k used: {ks} ({src}" + (f": {r['presets']})" if r.get("presets") and src != "pool" else ")"))
    for i, t in enumerate(r["lap_times_s"], 1):
        lines.append(f"lap {i}: {t:.2f} s")
    end = r["end"] if r["end"] != "time_limit" else f"time_limit, {r['max_steps']} steps"
    lines.append(f"laps completed: {len(r['lap_times_s'])}/{r['laps_requested']} ({end}) in {r['steps']} steps, "
                 f"{r['sim_time_s']:.1f} s simulated, {r['wall_time_s']:.1f} s wall, renderer {r['renderer']}")
    lines += lap_lines(r["metrics"])  # the metrics of weather_gym.lab.evaluation.metrics.METRICS, in their lap form
    if "map" in r:
        m = r["map"]
        lines.append(f"map: {m['confirmed']} confirmed cones, mean position std {m['mean_position_std_m']:.3f} m, "
                     f"colour confidence {m['mean_class_confidence']:.2f}")
    if r.get("video"):
        codec = {"h264": "H.264", "mp4v": "MPEG-4 Part 2"}.get(r.get("video_codec"), r.get("video_codec"))  # type: ignore[arg-type]  # None: stays None
        lines.append(f"video: {r['video']} ({r['video_frames']} frames, {codec})")
    if r.get("strip"):
        lines.append(f"strip: {r['strip']}")
    if r.get("bag"):
        lines.append(f"bag: {r['bag']} (MCAP rosbag2): " + ", ".join(f"{t} {n}" for t, n in r["bag_topics"].items()))
    return "\n".join(lines)


class _Recorder:
    """Composes the frames of ``--video`` / ``--strip``: camera image, cone boxes, map inset, HUD."""

    def __init__(self, video, strip, strip_frames, overwrite, fps, track, driver, agent_name, weather) -> None:
        self.video = VideoWriter(video, fps=fps, overwrite=overwrite) if video is not None else None
        self.sampler = FrameSampler(strip_frames) if strip is not None else None
        self.strip, self.overwrite = strip, overwrite
        self.track, self.driver, self.agent_name = track, driver, agent_name
        self.weather = weather
        self.view = TopDownView.around(np.vstack([track.cones_xy, track.centerline]), size=160)
        self.trajectory: list[tuple[float, float]] = []

    def add(self, obs, info, laps: int) -> None:
        if not isinstance(obs, dict) or "image" not in obs:
            raise InputError("recording needs the camera image in the observation (a Dict with 'image')")
        image = np.asarray(obs["image"])
        h, w = image.shape[:2]
        if "cones" in obs and "mask" in obs:
            boxes = cone_list_boxes(obs["cones"], obs["mask"], w, h)
        else:
            gt = info.get("gt") or {}
            n = len(gt.get("classes", ()))
            boxes = {"boxes": np.asarray(gt.get("boxes", np.zeros((0, 4)))).reshape(n, 4),
                     "scores": np.ones(n), "classes": np.asarray(gt.get("classes", np.zeros(0)), np.int64)}
        frame = draw_boxes(image, boxes, labels=False)
        if hasattr(self.driver, "last_map") and "state" in obs:  # a mapping agent: its own map, odometry frame
            cone_map, plan = self.driver.last_map, getattr(self.driver, "last_plan", None)
            pose = np.asarray(obs["state"], dtype=np.float64)[2:5]
            self.trajectory.append((float(pose[0]), float(pose[1])))
            c = cone_map.confirmed if cone_map is not None else None
            inset = self.view.draw(cones_xy=None if c is None else cone_map.xy[c],
                                   classes=None if c is None else cone_map.classes[c],
                                   path=None if plan is None else plan.path, trajectory=np.array(self.trajectory),
                                   pose=pose)
        else:  # the true track and pose
            pose = np.asarray(info["pose"], dtype=np.float64)
            self.trajectory.append((float(pose[0]), float(pose[1])))
            inset = self.view.draw(cones_xy=self.track.cones_xy, classes=self.track.cone_classes,
                                   trajectory=np.array(self.trajectory), pose=pose)
        hud = [f"{self.agent_name} | {self.weather} | lap {min(info['lap'] + 1, laps)}/{laps} "
               f"t {info['lap_time']:.1f} s",
               f"v {info['speed']:.1f} m/s  cte {info['cross_track_error']:.2f} m  hit {info['cones_hit']}  "
               f"off {info.get('off_track_events', 0)}"]
        frame = compose_frame(frame, inset, hud)
        if self.video is not None:
            self.video.write(frame)
        if self.sampler is not None:
            self.sampler.offer(frame)

    def abort(self) -> None:
        if self.video is not None:
            self.video.abort()

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
        if self.sampler is not None and self.sampler.frames():
            save_strip(self.sampler.frames(), self.strip, overwrite=self.overwrite)
