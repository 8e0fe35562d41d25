"""``weather-gym bench weather``: every weather effect against the study's own recipe.

Times, on one core (``cv2.setNumThreads(1)`` for the run only), at 608x352 (the study's detector
input), 672x376 (its camera) and 1280x720:

* every registered effect (droplets at the study's k = 0.55, dim at 0.78, the others at 0.5) and
  the persistent-droplet, refractive-droplet (also at k = 1, its heaviest), physical-dim
  and night-dim variants, and every shipped preset that uses them (``droplets@2`` to ``@4``,
  ``low_light@1`` to ``@4``: what the presets resolve to), one frame per call, through the public call;
* at 672x376, ``--batch`` different frames as a loop of single calls that keeps its outputs (as a
  caller that needs every frame does) and as one batched call, per frame;
* in the same run the study's recipe (:mod:`weather_gym.weather.reference`: the Albumentations-era
  fog loop without blur, each disc on a full-image copy; Pillow brightness with its array
  conversions) and a plain frame copy (``np.copyto``), the memory floor.

The rows take turns, after a warm-up: each turn one untimed call (the row's data back in the
caches) and 4 timed calls back to back; each row reports the median of its timed calls. On a
shared machine a change of load so hits every row alike, and the ratios within a run hold even
when the absolute times do not. ``--cold`` times one call per row per turn instead, right after
the other rows' (the frame and buffers as a pipeline leaves them, mostly out of the core's
caches). ``--cpu-time`` reads each call's time from the CPU time of its thread instead of the
wall clock: on a loaded machine that leaves out the time other processes hold the core (what they do to
the caches stays in). The frame is :func:`weather_gym.weather.sample.sample_frame` (JPEG and bloom cost
depend on content).

Example:
    weather-gym bench weather --repeats 200 --out bench_weather.md

The first command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'weather', '--repeats', '200', '--out', 'bench_weather.md'])
    >>> args.target, args.repeats, args.sizes
    ('weather', 200, '608x352,672x376,1280x720')
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from weather_gym.core._io import atomic_write, check_output
from weather_gym.core._output_args import add_overwrite_arg
from weather_gym.core.errors import InputError
from weather_gym.core.limits import parse_sizes
from weather_gym.lab.bench._timing import interleaved_ms, machine_line, markdown_table
from weather_gym.weather import EFFECTS, make, parse_weather
from weather_gym.weather.reference import study_dim, study_droplets
from weather_gym.weather.sample import sample_frame

DEFAULT_SIZES = ((608, 352), (672, 376), (1280, 720))
STUDY_K = {"droplets": 0.55, "dim": 0.78}
REFERENCE_SIZE = (672, 376)
STUDY_DROPLETS = "study droplets: Albumentations-era fog loop (k=0.55)"
STUDY_DIM = "study dim: Pillow brightness (k=0.78)"


def register(targets) -> None:
    p = targets.add_parser("weather", help="time every weather effect against the study's recipe",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in DEFAULT_SIZES),
                   help="comma-separated WxH (default %(default)s)")
    p.add_argument("--repeats", type=int, default=200, help="rounds, i.e. timed calls per row, at most (default %(default)s)")
    p.add_argument("--warmup", type=int, default=10, help="untimed calls first (default %(default)s)")
    p.add_argument("--batch", type=int, default=8, help="batch size for the per-frame batch column (0: skip)")
    p.add_argument("--effects", default="all", help="comma-separated effect names (default all)")
    p.add_argument("--cold", action="store_true",
                   help="one timed call per row per turn, right after the other rows' (caches as a pipeline "
                        "leaves them) instead of short back-to-back runs")
    p.add_argument("--cpu-time", action="store_true",
                   help="time each call by the CPU time of its thread (time.thread_time) instead of the wall "
                        "clock: leaves out the time other processes hold the core, on a loaded machine")
    p.add_argument("--out", type=Path, help="also write the markdown table to this file")
    add_overwrite_arg(p, help="replace an existing --out")
    p.set_defaults(func=_run)


def _cases(names: list[str]) -> list[tuple[str, Any]]:
    cases = []
    for name in names:
        k = STUDY_K.get(name, 0.5)
        cases.append((f"{name} (k={k})", make(name, k=k)))
        if name == "droplets":
            cases.append((f"droplets persistent (k={k})", make(name, k=k, persistent=True)))
            for rk in (k, 1.0):
                cases.append((f"droplets refractive (k={rk})", make(name, k=rk, mode="refractive")))
            cases += _preset_cases("droplets")
            cases.append((f"droplets refractive persistent (k={k})",
                          make(name, k=k, mode="refractive", persistent=True)))
        if name == "dim":
            cases.append((f"dim physical (k={k})", make(name, k=k, mode="physical")))
            cases.append((f"dim night (k={k})", make(name, k=k, mode="night")))
            cases += _preset_cases("low_light")
        if name == "fog":
            cases.append((f"fog linear (k={k})", make(name, k=k, space="linear")))
    return cases


def _preset_cases(condition: str) -> list[tuple[str, Any]]:
    """Every shipped preset of ``condition`` that does something (k > 0), lightest first: what the
    presets resolve to (a scenario's resolved k lies near these)."""
    cases = []
    for severity in range(1, 5):
        effect = parse_weather(f"{condition}@{severity}")
        if getattr(effect, "k", 0.0) > 0:
            cases.append((f"{condition}@{severity} ({effect.mode} k={effect.k})", effect))  # type: ignore[attr-defined]  # a KnobEffect
    return cases


def _time_size(w: int, h: int, names: list[str], repeats: int, warmup: int, batch: int,
               rows: dict, batch_rows: dict, run: int = 4, clock: Any = time.perf_counter) -> None:
    """Time every row at one size (``batch`` > 0: also the loop-vs-batch columns)."""

    frame, depth = sample_frame(h, w, seed=0)
    state = {"speed": 10.0, "yaw_rate": 0.3}
    rng = np.random.default_rng(0)
    out = np.empty_like(frame)

    singles: dict[str, Any] = {"frame copy (np.copyto), the floor": lambda: np.copyto(out, frame)}
    if "droplets" in names:
        singles[STUDY_DROPLETS] = lambda: study_droplets(frame, STUDY_K["droplets"], rng)
    if "dim" in names:
        try:
            study_dim(frame, 0.5)
            singles[STUDY_DIM] = lambda: study_dim(frame, STUDY_K["dim"])
        except ImportError:  # pragma: no cover - Pillow is a dev dependency
            pass
    frames = np.stack([sample_frame(h, w, seed=i)[0] for i in range(max(batch, 1))])
    depths = np.repeat(depth[None], max(batch, 1), axis=0)
    pairs: dict[str, Any] = {}
    for label, effect in _cases(names):
        effect.reset(0)
        singles[label] = lambda e=effect: e(frame, depth=depth, state=state, rng=rng)
        if batch > 0:
            def loop(e=effect):  # keeps its outputs, as the batch does
                return [e(f, depth=d, state=state, rng=rng) for f, d in zip(frames, depths, strict=True)]

            pairs[label + " [loop]"] = loop
            pairs[label + " [batch]"] = lambda e=effect: e(frames, depth=depths, state=state, rng=rng)
    for label, ms in interleaved_ms(singles, repeats, warmup, 20.0, run, clock).items():
        rows.setdefault(label, {})[(w, h)] = ms
    if pairs:
        for label, ms in interleaved_ms(pairs, repeats, warmup, 60.0, run, clock).items():
            batch_rows.setdefault(label, {})[(w, h)] = ms / batch


def run_benchmark(sizes=DEFAULT_SIZES, repeats: int = 200, warmup: int = 10, batch: int = 8,
                  effects: list[str] | None = None, cold: bool = False, cpu_time: bool = False) -> dict[str, Any]:
    """Time everything; returns ``{"sizes", "rows": {label: {size: ms}}, "batch": {...}, "machine"}``
    (``cpu_time``: each call's CPU time of this thread, not its wall time)."""


    names = EFFECTS.names() if effects is None else effects
    for n in names:
        EFFECTS.get(n)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    rows: dict[str, dict[tuple[int, int], float]] = {}
    batch_rows: dict[str, dict[tuple[int, int], float]] = {}
    try:
        ref = REFERENCE_SIZE if REFERENCE_SIZE in sizes else sizes[0]
        for w, h in sizes:
            _time_size(w, h, names, repeats, warmup, batch if (w, h) == ref else 0, rows, batch_rows,
                       run=0 if cold else 4, clock=time.thread_time if cpu_time else time.perf_counter)
    finally:
        cv2.setNumThreads(threads)
    return {"sizes": list(sizes), "rows": rows, "batch": batch_rows, "batch_size": batch,
            "machine": machine_line(), "repeats": repeats, "cold": cold, "cpu_time": cpu_time}


def format_table(res: dict[str, Any]) -> str:
    """Markdown table: ms per size, batch ms/frame, ratio to the copy floor, speed-up vs the study."""
    sizes = res["sizes"]
    ref = REFERENCE_SIZE if REFERENCE_SIZE in sizes else sizes[0]
    rows, brows = res["rows"], res["batch"]
    copy_ms = rows["frame copy (np.copyto), the floor"][ref]
    study = {"droplets": rows.get(STUDY_DROPLETS, {}).get(ref), "dim": rows.get(STUDY_DIM, {}).get(ref)}
    rname = f"{ref[0]}x{ref[1]}"
    header = ["", *[f"{w}x{h} ms" for w, h in sizes]]
    if brows:
        n = res["batch_size"]
        header += [f"{rname} loop of {n} calls, ms/frame", f"{rname} one call on {n} frames, ms/frame"]
    header += [f"x copy ({rname})", f"speed-up vs study ({rname})"]
    table = []
    for label, by_size in rows.items():
        line: list[object] = [label, *[by_size.get(s, float("nan")) for s in sizes]]
        if brows:
            line += [brows.get(label + " [loop]", {}).get(ref, ""), brows.get(label + " [batch]", {}).get(ref, "")]
        line.append(f"{by_size[ref] / copy_ms:.1f}")
        name = label.split(" ")[0]
        base = study.get(name) if label.startswith(f"{name} (k=") else None
        line.append(f"{base / by_size[ref]:.1f}x" if base else "")
        table.append(line)
    return markdown_table(header, table)


def _run(args) -> int:
    if args.out is not None:
        check_output(args.out, overwrite=args.overwrite, what="--out")

    names = None if args.effects == "all" else [n.strip() for n in args.effects.split(",") if n.strip()]
    if names is not None:
        for n in names:
            EFFECTS.get(n)
    if args.repeats < 1 or args.warmup < 0 or args.batch < 0:
        raise InputError("--repeats must be >= 1, --warmup and --batch >= 0")
    load0 = os.getloadavg()[0]
    res = run_benchmark(parse_sizes(args.sizes, what="--sizes"), args.repeats, args.warmup, args.batch, names, args.cold,
                        args.cpu_time)
    how = ("one call per row per turn, caches as the other rows left them (`--cold`)" if args.cold else
           "rows taking turns, each turn an untimed call and 4 timed ones back to back")
    clock = "CPU time of the thread per call (`--cpu-time`)" if args.cpu_time else "wall time per call"
    text = (f"Machine: {res['machine']}; one OpenCV thread; median of up to {res['repeats']} calls per row "
            f"after warm-up, {how}, {clock} (`weather-gym bench weather`); 1-minute load average {load0:.1f} at the "
            f"start, {os.getloadavg()[0]:.1f} at the end.\n\n{format_table(res)}\n")
    print(text)
    if args.out is not None:
        atomic_write(args.out, text, overwrite=args.overwrite)
    return 0
