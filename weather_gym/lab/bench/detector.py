"""``weather-gym bench detector``: the ONNX cone detector's cost, and where a full env step's time goes.

Reports, each a median of many runs after a warm-up:

* model size, parameters and FLOPs (2 x multiply-adds, counted by torch at export, from the sidecar);
* one 672x376 frame through ``ConeDetector`` (letterbox + onnxruntime + decoding) on 1 and 2 threads,
  and the bare ``session.run`` alone;
* batch throughput (frames/s, batch of ``--batch``);
* baseline in the same run: the reference study's YOLOv3-tiny layout at 608x352 (2 classes, random
  weights: only its cost matters), exported to ONNX and run the same way - needs torch, skipped without;
* the whole step (``--step``): ``ConeTrackEnv.step`` (physics + render), weather (droplets k=0.55),
  detector + ranging, and the end-to-end rate of ``env -> WeatherWrapper -> DetectorWrapper``.

With ``--sizes 336x188,672x376,1280x720`` it times only ``detect()`` (one thread) on a frame of each
camera size (the 672x376 frame resized), with the input following the camera (the default) and, as
the baseline in the same run, pinned at the native 512x288 (``input_size="native"``), the two
alternating run by run.

Example:
    weather-gym bench detector --repeats 100 --out bench_detector.md
    weather-gym bench detector --sizes 336x188,672x376,1280x720 --repeats 50

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'detector', '--repeats', '100', '--out', 'bench_detector.md'])
    >>> args.target, args.repeats, args.batch
    ('detector', 100, 8)
    >>> parse_sizes("336x188,672x376")
    [(336, 188), (672, 376)]
"""

from __future__ import annotations

import os
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from weather_gym.agents import AGENTS
from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.core.limits import MAX_CAMERA_SIDE, check_image_size
from weather_gym.core.limits import parse_sizes as size_list
from weather_gym.lab.bench._timing import machine_line, markdown_table, median_ms
from weather_gym.perception.onnx_detector import ConeDetector
from weather_gym.perception.ranging import detections_to_cones
from weather_gym.pipeline import make_env
from weather_gym.weather import make


def register(targets) -> None:
    p = targets.add_parser("detector", help="time the ONNX cone detector and a full env step",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: the shipped one)")
    p.add_argument("--repeats", type=int, default=100, help="timed runs per row (default %(default)s)")
    p.add_argument("--batch", type=int, default=8, help="batch size of the throughput row (default %(default)s)")
    p.add_argument("--no-baseline", action="store_true", help="skip the YOLOv3-tiny baseline")
    p.add_argument("--step", action="store_true", help="also time the whole env step (needs the simulator)")
    p.add_argument("--steps", type=int, default=150, help="env steps timed with --step (default %(default)s)")
    p.add_argument("--sizes", default=None, metavar="WxH,...",
                   help="time only detect() at these camera sizes, input following the camera vs pinned at "
                        "512x288 (e.g. 336x188,672x376,1280x720)")
    p.add_argument("--out", type=Path, help="also write the markdown tables to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``"336x188,672x376"`` -> ``[(336, 188), (672, 376)]``; InputError naming ``--sizes`` otherwise."""
    sizes = size_list(text, what="--sizes")
    for w, h in sizes:
        check_image_size((h, w), what=f"--sizes {w}x{h}")
        if max(w, h) > MAX_CAMERA_SIDE:
            raise InputError(f"--sizes {w}x{h}: a camera side is at most {MAX_CAMERA_SIDE} pixels")
    return sizes


def size_benchmark(model=None, sizes=((336, 188), (672, 376), (1280, 720)), repeats: int = 50,
                   frame: np.ndarray | None = None) -> list[list[Any]]:
    """``detect()`` ms on one thread at each camera size: input pinned at native (baseline) vs following."""
    frame = _frame() if frame is None else frame
    pinned = ConeDetector(model, threads=1, input_size="native")
    follow = ConeDetector(model, threads=1)
    rows = []
    for w, h in sizes:
        im = frame if (w, h) == (frame.shape[1], frame.shape[0]) else cv2.resize(
            frame, (w, h), interpolation=cv2.INTER_AREA if w < frame.shape[1] else cv2.INTER_LINEAR)
        times: dict[str, list[float]] = {"pinned": [], "follow": []}
        for i in range(repeats + 5):  # alternate, so load changes hit both alike; 5 warm-up runs
            for name, det in (("pinned", pinned), ("follow", follow)):
                t0 = time.perf_counter()
                det(im)
                if i >= 5:
                    times[name].append(time.perf_counter() - t0)
        pm, fm = (1000 * float(np.median(times[k])) for k in ("pinned", "follow"))
        pin_in, fol_in = pinned.input_size_for(w, h), follow.input_size_for(w, h)
        rows.append([f"{w}x{h}", "x".join(map(str, pin_in)), pm, "x".join(map(str, fol_in)), fm, pm / fm])
    return rows


def format_sizes(rows: list[list[Any]], repeats: int) -> str:
    return "\n".join([f"Machine: {machine_line()}", "",
                      f"detect() per frame, 1 thread, median of {repeats} (pinned and follow alternating):", "",
                      markdown_table(["camera", "pinned input", "pinned ms", "follow input", "follow ms",
                                      "speed-up"], rows)])


def _frame() -> np.ndarray:
    """A 672x376 frame with cones: a rendered one when the simulator works, else a synthetic one."""
    try:
        from weather_gym.pipeline import make_env

        env = make_env(track="small_track", episode_statistics=False)
        try:
            return env.reset(seed=0)[0]["image"]
        finally:
            env.close()
    except Exception:  # pragma: no cover - no simulator: time on a synthetic frame
        rng = np.random.default_rng(0)
        return rng.integers(0, 256, (376, 672, 3), dtype=np.uint8)


def yolov3_tiny_onnx(path: str | os.PathLike, width: int = 608, height: int = 352, classes: int = 2) -> Path:
    """Export the YOLOv3-tiny layout (Redmon & Farhadi 2018) with random weights, for timing only."""

    import torch
    from torch import nn

    def cbl(i, o, k):
        return nn.Sequential(nn.Conv2d(i, o, k, 1, k // 2, bias=False), nn.BatchNorm2d(o), nn.LeakyReLU(0.1))

    class Tiny(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            chans = [3, 16, 32, 64, 128, 256]
            layers: list[nn.Module] = []
            for i in range(5):
                layers += [cbl(chans[i], chans[i + 1], 3), nn.MaxPool2d(2, 2)]
            self.backbone = nn.Sequential(*layers[:-1])  # ends with the 256-channel conv (route)
            self.tail = nn.Sequential(nn.MaxPool2d(2, 2), cbl(256, 512, 3), nn.ZeroPad2d((0, 1, 0, 1)),
                                      nn.MaxPool2d(2, 1), cbl(512, 1024, 3), cbl(1024, 256, 1))
            out = 3 * (5 + classes)
            self.head1 = nn.Sequential(cbl(256, 512, 3), nn.Conv2d(512, out, 1))
            self.lat = nn.Sequential(cbl(256, 128, 1), nn.Upsample(scale_factor=2))
            self.head2 = nn.Sequential(cbl(384, 256, 3), nn.Conv2d(256, out, 1))

        def forward(self, x):
            r = self.backbone(x)
            y = self.tail(r)
            return self.head1(y), self.head2(torch.cat([self.lat(y), r], 1))

    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(Tiny().eval(), torch.zeros(1, 3, height, width), str(path), opset_version=17, dynamo=False,  # type: ignore[arg-type]  # one input tensor: torch takes it
                          input_names=["images"])
    return path


def _session(path, threads: int):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


def run_benchmark(model=None, repeats: int = 100, batch: int = 8, baseline: bool = True, step: bool = False,
                  steps: int = 150) -> dict[str, Any]:
    frame = _frame()
    det1 = ConeDetector(model, threads=1)
    det2 = ConeDetector(model, threads=2)
    meta = det1.meta
    w, h = det1.input_size
    x = np.zeros((1, 3, h, w), np.float32)
    rows = []
    for threads, det in ((1, det1), (2, det2)):
        rows.append([f"ConeNet {w}x{h}: detect() on a 672x376 frame", threads, median_ms(lambda d=det: d(frame), repeats)])  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
        rows.append([f"ConeNet {w}x{h}: session.run only", threads,
                     median_ms(lambda d=det: d.session.run(None, {d.input_name: x}), repeats)])  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
    frames = [frame] * batch
    batch_ms = median_ms(lambda: det2.detect_batch(frames), max(10, repeats // batch))
    rows.append([f"ConeNet {w}x{h}: detect_batch({batch}), per frame", 2, batch_ms / batch])
    base = None
    if baseline:
        try:
            with tempfile.TemporaryDirectory() as tmp:
                p = yolov3_tiny_onnx(Path(tmp) / "yolov3_tiny.onnx")
                xb = np.zeros((1, 3, 352, 608), np.float32)
                for threads in (1, 2):
                    s = _session(p, threads)
                    rows.append(["baseline: YOLOv3-tiny layout 608x352 (study), session.run", threads,
                                 median_ms(lambda s=s: s.run(None, {"images": xb}), max(10, repeats // 4))])  # type: ignore[misc]  # a lambda with a default argument: mypy cannot infer it
                base = True
        except ImportError:
            base = False
    res: dict[str, Any] = {
        "machine": machine_line(),
        "model": str(det1.path),
        "size_mb": det1.path.stat().st_size / 1e6,
        "params": meta.get("params"),
        "gflops": (meta.get("flops") or 0) / 1e9,
        "rows": rows,
        "baseline": base,
    }
    if step:
        res["step"] = _time_step(det1, det2, steps)
    return res


def _time_step(det1, det2, steps: int) -> dict[str, Any]:
    settings: dict[str, Any] = {"track": "small_track", "laps": 0, "max_episode_steps": 10**6, "episode_statistics": False}
    env = make_env(**settings)
    cfg = env.unwrapped.config  # type: ignore[attr-defined]  # a ConeTrackEnv
    eff = make("droplets", k=0.55)
    agent = AGENTS.get("gt_pure_pursuit")(env.unwrapped.track, cfg.camera)  # type: ignore[attr-defined]  # a ConeTrackEnv
    t_env, t_w, t_d = [], [], []
    try:
        obs, info = env.reset(seed=0)
        eff.reset(0)
        agent.reset(seed=0, info=info)
        for _ in range(steps):
            a = agent.act(obs, info)
            t0 = time.perf_counter()
            obs, _, term, trunc, info = env.step(a)
            t1 = time.perf_counter()
            img = eff(obs["image"], depth=obs["depth"], state={"speed": float(obs["state"][0])})
            t2 = time.perf_counter()
            detections_to_cones(det1(img), cfg.camera, obs["depth"])
            t3 = time.perf_counter()
            t_env.append(t1 - t0)
            t_w.append(t2 - t1)
            t_d.append(t3 - t2)
            if term or trunc:
                obs, info = env.reset()
                agent.reset(info=info)
    finally:
        env.close()
    stack = make_env(**settings, weather={"droplets": 0.55}, perception="detector", detector=det1)
    try:
        obs, info = stack.reset(seed=0)
        agent.reset(seed=0, info=info)
        t0 = time.perf_counter()
        for _ in range(steps):
            obs, _, term, trunc, info = stack.step(agent.act(obs, info))
            if term or trunc:
                obs, info = stack.reset()
                agent.reset(info=info)
        e2e = steps / (time.perf_counter() - t0)
    finally:
        stack.close()
    med = {k: 1000 * float(np.median(v)) for k, v in (("env.step (physics + render)", t_env),
                                                       ("weather: droplets k=0.55", t_w),
                                                       ("detector (1 thread) + ranging", t_d))}
    return {"median_ms": med, "sum_ms": sum(med.values()), "end_to_end_steps_per_s": e2e, "steps": steps}


def format_table(res: dict[str, Any]) -> str:
    lines = [f"Machine: {res['machine']}",
             f"Model: {Path(res['model']).name}, {res['size_mb']:.2f} MB, {res['params']} parameters, "
             f"{res['gflops']:.3f} GFLOPs per frame", "",
             markdown_table(["what", "threads", "median ms"], res["rows"])]
    if res.get("baseline") is False:
        lines.append("(baseline skipped: torch is not installed)")
    if "step" in res:
        s = res["step"]
        rows = [[k, v, 100 * v / s["sum_ms"]] for k, v in s["median_ms"].items()]
        rows.append(["sum", s["sum_ms"], 100.0])
        lines += ["", f"Whole step at 672x376 ({s['steps']} steps of small_track, gt_pure_pursuit driving):", "",
                  markdown_table(["part", "median ms", "%"], rows), "",
                  f"end to end, env -> WeatherWrapper(droplets 0.55) -> DetectorWrapper: "
                  f"{s['end_to_end_steps_per_s']:.1f} steps/s"]
    return "\n".join(lines)


def _run(args) -> int:
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, what="--out")
    if args.sizes is not None:
        text = format_sizes(size_benchmark(args.model, parse_sizes(args.sizes), args.repeats), args.repeats)
    else:
        res = run_benchmark(args.model, args.repeats, args.batch, not args.no_baseline, args.step, args.steps)
        text = format_table(res)
    print(text)
    if args.out is not None:
        atomic_write(args.out, text + "\n", overwrite=args.overwrite)
    return 0
