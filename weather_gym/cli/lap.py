"""``weather-gym lap``: drive scripted laps (sim -> weather -> perception -> agent) and report them.

Examples:
    weather-gym lap                                             # ground-truth driver, default track
    weather-gym lap --track peanut --laps 2 --video peanut.mp4
    weather-gym lap --track small_track --agent mapper_pure_pursuit --perception oracle --laps 2
    weather-gym lap --track small_track --weather droplets:0.55 --agent mapper_pure_pursuit --video out.mp4
    weather-gym lap --agent sb3 --agent-arg path=runs/ppo.zip --perception detector
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from weather_gym.cli._detector_args import add_detector_args, detector_spec_from_args
from weather_gym.errors import InputError

PERCEPTION_MODES = ("auto", "detector", "oracle", "none")
PERCEPTION_AGENTS = frozenset({"mapper_pure_pursuit", "ppo_cones"})
"""Agents that read cone lists: ``--perception auto`` gives them the detector."""
MIN_SPEED_FOR_LIMIT = 2.0
"""Default step limit: every lap may take up to length / 2 m/s (at least a minute)."""

EPILOG = """\
perception (what the agent sees):
  auto      the detector for agents that read cone lists (mapper_pure_pursuit), else none
  detector  DetectorWrapper: the ONNX cone detector on the (weathered) camera image
  oracle    GroundTruthConeWrapper: the env's ground truth as a perfect cone list
  none      the raw observation (image, depth, state); gt_pure_pursuit drives from info

weather: a spec for weather_gym.weather.parse_weather, e.g. droplets:0.55, "droplets:0.55,dim:0.3",
  droplets@3 (a calibrated preset, severity 0-4), low_light@2, clear.

output: per-lap times, cones hit, off-track events, mean/max cross-track error; --video writes an MP4
  of the camera view (weathered) with the cone boxes the agent received and a top-down map inset;
  --strip a PNG grid of frames. Existing files are never replaced without --overwrite.
  Exit status 0 when every requested lap was completed, 1 when not (crash, time or step limit).

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
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--track", help="track name, 'random:SEED' or a cone CSV (default: the scenario's track); "
                                   "see `weather-gym tracks list`")
    p.add_argument("--env", default="WeatherGym/ConeTrack-v0", help="Gymnasium env id (default %(default)s)")
    p.add_argument("--agent", default="gt_pure_pursuit",
                   help="registered agent: gt_pure_pursuit (default), mapper_pure_pursuit, sb3")
    p.add_argument("--agent-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="keyword for the agent factory, repeatable (e.g. v_max=12, path=model.zip)")
    p.add_argument("--weather", help="weather spec (e.g. droplets:0.55 or droplets@3); default: the scenario's")
    p.add_argument("--perception", choices=PERCEPTION_MODES, default="auto", help="what the agent sees (see below)")
    add_detector_args(p, what="for --perception detector")
    p.add_argument("--laps", type=int, default=1, help="laps to drive (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (default %(default)s)")
    p.add_argument("--max-steps", type=int, help="step limit (default: laps x max(60 s, length / 2 m/s))")
    p.add_argument("--video", type=Path, metavar="PATH.mp4", help="write an MP4 of the run")
    p.add_argument("--strip", type=Path, metavar="PATH.png", help="write a PNG strip of frames")
    p.add_argument("--strip-frames", type=int, default=8, help="frames in the strip (default %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace existing --video / --strip files")
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
    from weather_gym.viz.video import check_output_path

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
    detector = detector_spec_from_args(args)
    agent_kwargs = parse_agent_args(args.agent_arg)
    result = run_laps(
        env_id=args.env, track=args.track, agent=args.agent, agent_kwargs=agent_kwargs, weather=args.weather,
        perception=args.perception, detector=detector, laps=args.laps, seed=args.seed,
        max_steps=args.max_steps, video=args.video, strip=args.strip, strip_frames=args.strip_frames,
        overwrite=args.overwrite, progress=True,
    )
    print(format_result(result))
    return 0 if result["completed"] else 1


def _make_env(env_id: str, track: str | None, weather: str | None, perception: str, detector: Any,
              laps: int, keep_image: bool):
    import gymnasium as gym

    import weather_gym  # noqa: F401  (registers the env ids)

    if env_id not in gym.registry:
        ids = sorted(k for k in gym.registry if k.startswith("WeatherGym/"))
        raise InputError(f"unknown env id {env_id!r}; registered: {', '.join(ids)}")
    kwargs: dict[str, Any] = {"laps": laps, "max_episode_steps": 10**9}  # the step limit is ours
    if track is not None:
        kwargs["track"] = track
    if weather is not None:
        from weather_gym.weather import parse_weather

        parse_weather(weather)  # a bad spec fails here, with the parser's message
        kwargs["weather"] = weather
    if perception == "detector":
        det: dict[str, Any] = {"keep_image": keep_image}
        if detector is not None:
            det["detector"] = detector  # a spec: the shipped model, conenet:PATH, yolov8:PATH, ...
        kwargs["detector"] = det
    else:
        kwargs["detector"] = {"enabled": False}
    env = gym.make(env_id, **kwargs)
    if perception == "oracle":
        from weather_gym.wrappers import GroundTruthConeWrapper

        env = GroundTruthConeWrapper(env, keep_image=keep_image)
    return env


def run_laps(*, env_id: str = "WeatherGym/ConeTrack-v0", track: str | None = None, agent: str = "gt_pure_pursuit",
             agent_kwargs: dict[str, Any] | None = None, weather: str | None = None, perception: str = "auto",
             detector: Any = None, laps: int = 1, seed: int = 0, max_steps: int | None = None,
             video: Path | None = None, strip: Path | None = None, strip_frames: int = 8,
             overwrite: bool = False, progress: bool = False) -> dict[str, Any]:
    """Drive ``laps`` laps and return the measurements (see ``format_result``)."""
    import numpy as np

    from weather_gym.agents import AGENTS, check_action

    if perception not in PERCEPTION_MODES:
        raise InputError(f"perception must be one of {', '.join(PERCEPTION_MODES)}, got {perception!r}")
    factory = AGENTS.get(agent)
    mode = perception if perception != "auto" else ("detector" if agent in PERCEPTION_AGENTS else "none")
    recording = video is not None or strip is not None
    env = _make_env(env_id, track, weather, mode, detector, laps, keep_image=recording)
    try:
        base = env.unwrapped
        trk, camera = base.track, base.config.camera
        hz = float(base.config.sim.control_hz)
        limit = max_steps or int(math.ceil(laps * max(60.0, trk.length / MIN_SPEED_FOR_LIMIT) * hz))
        driver = factory(trk, camera, **(agent_kwargs or {}))
        obs, info = env.reset(seed=seed)
        driver.reset(seed=seed, info=info)
        weather_desc = weather or _describe_weather(info.get("weather"))
        recorder = (_Recorder(video, strip, strip_frames, overwrite, hz, trk, driver, agent, weather_desc)
                    if recording else None)
        cte, steps, wall0 = [], 0, time.perf_counter()
        terminated = truncated = False
        bar = _LapProgress(laps * trk.length, f"{agent} on {trk.name}", enabled=progress)
        seen = _SeenByPerception(score_detector=mode == "detector")
        try:
            seen.add(info)
            if recorder is not None:
                recorder.add(obs, info, laps)
            while steps < limit:
                action = check_action(driver.act(obs, info), agent)
                obs, _, terminated, truncated, info = env.step(action)
                steps += 1
                cte.append(float(info["cross_track_error"]))
                seen.add(info)
                if recorder is not None:
                    recorder.add(obs, info, laps)
                if steps % 30 == 0:
                    bar.update(info, laps)
                if terminated or truncated:
                    break
        except BaseException:
            if recorder is not None:
                recorder.abort()  # an interrupted run leaves no half-written video or strip
            raise
        finally:
            bar.close()
        if recorder is not None:
            recorder.close()
        wall = time.perf_counter() - wall0
    finally:
        env.close()
    lap_times = [float(t) for t in info["lap_times"]]
    if terminated and len(lap_times) < laps:
        reason = "off track" if info.get("off_track") else "terminated"
    elif len(lap_times) >= laps:
        reason = "laps completed"
    elif truncated:
        reason = "env time limit"
    else:
        reason = f"step limit ({limit} steps)"
    result = {
        "env": env_id, "track": track or trk.name, "event": trk.event, "track_length_m": float(trk.length), "agent": agent,
        "perception": mode, "weather": weather_desc, "seed": seed, "laps_requested": laps,
        "lap_times_s": lap_times, "completed": len(lap_times) >= laps, "end": reason, "steps": steps,
        "sim_time_s": steps / hz, "wall_time_s": wall, "cones_hit": int(info["cones_hit"]),
        "off_track_events": int(info.get("off_track_events", 0)),
        "cte_mean_m": float(np.mean(cte)) if cte else float("nan"),
        "cte_max_m": float(np.max(cte)) if cte else float("nan"),
    }
    result.update(seen.summary())
    cone_map = getattr(driver, "last_map", None)
    if cone_map is not None:
        result["map"] = cone_map.summary()
    if recording:
        result["video"] = str(video) if video is not None else None
        result["video_frames"] = recorder.video.frames if recorder.video is not None else 0
        result["video_codec"] = recorder.video.codec if recorder.video is not None else None
        result["strip"] = str(strip) if strip is not None else None
    return result


class _SeenByPerception:
    """What the weather and the detector did on the frames of the lap: the detector's mAP@0.5 on the
    frames it saw (pycocotools, against the env's ground truth) and the mean time each added per step."""

    def __init__(self, *, score_detector: bool) -> None:
        self.score_detector = score_detector
        self.gts: list[Any] = []
        self.dets: list[Any] = []
        self.weather_ms: list[float] = []
        self.detector_ms: list[float] = []

    def add(self, info: dict) -> None:
        if "weather_latency_ms" in info:
            self.weather_ms.append(float(info["weather_latency_ms"]))
        if "detector_latency_ms" in info:
            self.detector_ms.append(float(info["detector_latency_ms"]))
        if self.score_detector and info.get("gt") is not None and info.get("detections") is not None:
            self.gts.append(info["gt"])
            self.dets.append(info["detections"])

    def summary(self) -> dict[str, Any]:
        import numpy as np

        out: dict[str, Any] = {
            "weather_latency_ms": float(np.mean(self.weather_ms)) if self.weather_ms else None,
            "detector_latency_ms": float(np.mean(self.detector_ms)) if self.detector_ms else None,
        }
        if self.gts:
            from weather_gym.perception import evaluate as score

            res = score(self.gts, self.dets)
            out.update(det_map50=float(res.map50), det_recall=float(res.recall), det_frames=int(res.n_images))
        return out


class _LapProgress:
    """Distance driven along the track: a tqdm bar on a terminal, a plain line every 10 s otherwise."""

    EVERY_S = 10.0

    def __init__(self, total_m: float, desc: str, *, enabled: bool) -> None:
        import sys

        from tqdm import tqdm

        self.enabled, self.desc = enabled, desc
        self.tty = enabled and sys.stderr.isatty()
        self.bar = tqdm(total=round(total_m), unit="m", desc=desc, leave=False, disable=not self.tty)
        self.t0 = self.last = time.perf_counter()

    def update(self, info: dict, laps: int) -> None:
        import sys

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
    for i, t in enumerate(r["lap_times_s"], 1):
        lines.append(f"lap {i}: {t:.2f} s")
    lines.append(f"laps completed: {len(r['lap_times_s'])}/{r['laps_requested']} ({r['end']}) in {r['steps']} steps, "
                 f"{r['sim_time_s']:.1f} s simulated, {r['wall_time_s']:.1f} s wall")
    lines.append(f"cones hit: {r['cones_hit']}   off-track events: {r['off_track_events']}")
    lines.append(f"cross-track error: mean {r['cte_mean_m']:.3f} m, max {r['cte_max_m']:.3f} m")
    if r.get("det_frames"):
        lines.append(f"detector: mAP@0.5 {r['det_map50']:.3f}, recall {r['det_recall']:.3f} on the {r['det_frames']} "
                     f"frames it saw")
    added = [f"{name} {r[key]:.1f} ms" for name, key in (("weather", "weather_latency_ms"),
                                                         ("detector", "detector_latency_ms")) if r.get(key) is not None]
    if added:
        lines.append("added per step: " + ", ".join(added))
    if "map" in r:
        m = r["map"]
        lines.append(f"map: {m['confirmed']} confirmed cones, mean position std {m['mean_position_std_m']:.3f} m, "
                     f"colour confidence {m['mean_class_confidence']:.2f}")
    if r.get("video"):
        codec = {"h264": "H.264", "mp4v": "MPEG-4 Part 2"}.get(r.get("video_codec"), r.get("video_codec"))
        lines.append(f"video: {r['video']} ({r['video_frames']} frames, {codec})")
    if r.get("strip"):
        lines.append(f"strip: {r['strip']}")
    return "\n".join(lines)


class _Recorder:
    """Composes the frames of ``--video`` / ``--strip``: camera image, cone boxes, map inset, HUD."""

    def __init__(self, video, strip, strip_frames, overwrite, fps, track, driver, agent_name, weather) -> None:
        import numpy as np

        from weather_gym.viz.overlay import TopDownView
        from weather_gym.viz.video import FrameSampler, VideoWriter

        self.video = VideoWriter(video, fps=fps, overwrite=overwrite) if video is not None else None
        self.sampler = FrameSampler(strip_frames) if strip is not None else None
        self.strip, self.overwrite = strip, overwrite
        self.track, self.driver, self.agent_name = track, driver, agent_name
        self.weather = weather
        self.view = TopDownView.around(np.vstack([track.cones_xy, track.centerline]), size=160)
        self.trajectory: list[tuple[float, float]] = []

    def add(self, obs, info, laps: int) -> None:
        import numpy as np

        from weather_gym.viz.overlay import compose_frame, cone_list_boxes, draw_boxes

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
        from weather_gym.viz.video import save_strip

        if self.video is not None:
            self.video.close()
        if self.sampler is not None and self.sampler.frames():
            save_strip(self.sampler.frames(), self.strip, overwrite=self.overwrite)
