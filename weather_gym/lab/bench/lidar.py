"""``weather-gym bench lidar``: one LiDAR scan, fast against every beam through ``rayTestBatch``; its weather and cones.

For each sensor (the default HDL-32E and the solid-state preset) the car stands at ``--poses`` places
along each track's centre line; at each, the fast scan (:mod:`weather_gym.sim.lidar`: ground, car and
standing cones analytic, ``rayTestBatch`` only for knocked cones) and the naive one (every beam through
``rayTestBatch``, the baseline) are compared return by return (the returns on a beam of one scan only or
on another cone or surface; the range differences of the other cone returns, 99th percentile and
largest) and timed: wall-clock and process CPU time, the median over all poses of ``--repeats`` scans
(``--naive-repeats`` for the baseline), one thread. Then the LiDAR weather effects (severity 3) and
the cone extraction, per scan. The machine's load average is printed with the table: other processes
on the same cores lower every number.

Example:
    $ weather-gym bench lidar --track small_track --poses 10

The command line above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['bench', 'lidar', '--track', 'small_track', '--poses', '10'])
    >>> args.target, args.poses, args.repeats
    ('lidar', 10, 30)
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from weather_gym.core._option_alias import alias
from weather_gym.core.errors import InputError
from weather_gym.lab.bench._timing import machine_line, markdown_table
from weather_gym.lidar_weather import parse_lidar_weather
from weather_gym.perception.lidar_cones import cones_from_points
from weather_gym.sim.config import SimConfig
from weather_gym.sim.lidar_config import LidarConfig
from weather_gym.sim.world import World
from weather_gym.tracks import load_track

SENSORS = {"HDL-32E (default)": LidarConfig.hdl32e(), "solid-state 120x25": LidarConfig.solid_state()}
WEATHER = ("fog@3", "rain@3", "snow@3", "wet@3")


def register(targets) -> None:
    p = targets.add_parser("lidar", help="one LiDAR scan: fast vs every beam through rayTestBatch; weather, cones",
                           description=__doc__.split("\n\n")[1])
    p.add_argument("--track", dest="tracks", default="small_track,hairpin", help="tracks, comma-separated (default %(default)s)")
    alias(p, "--track", "--tracks")
    p.add_argument("--poses", type=int, default=10, help="places along each track (default %(default)s)")
    p.add_argument("--repeats", type=int, default=30, help="fast scans timed per place (default %(default)s)")
    p.add_argument("--naive-repeats", type=int, default=3, help="naive scans timed per place (default %(default)s)")
    p.set_defaults(func=run)


def _timed(fn, repeats: int, wall: list, cpu: list):
    out = None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return out


def bench_sensor(cfg: LidarConfig, tracks: list[str], poses: int, repeats: int, naive_repeats: int) -> dict:
    t: dict[str, list[float]] = {k: [] for k in ("fast_wall", "fast_cpu", "naive_wall", "naive_cpu")}
    diff: dict[str, float] = {"scans": 0, "returns": 0, "different": 0, "cone_returns": 0}
    clouds, ranges = [], []
    for name in tracks:
        world = World(load_track(name), sim=SimConfig(renderer="none"))
        try:
            for s in np.linspace(0.0, world.track.length, poses, endpoint=False):
                world.reset(world.track.point_at(float(s)))
                world.lidar_scan(cfg)  # warm-up
                fast = _timed(lambda w=world: w.lidar_scan(cfg), repeats, t["fast_wall"], t["fast_cpu"])
                naive = _timed(lambda w=world: w.lidar_scan(cfg, naive=True), naive_repeats, t["naive_wall"],
                               t["naive_cpu"])
                diff["scans"] += 1
                diff["returns"] += len(naive)
                diff["cone_returns"] += int((naive.cone >= 0).sum())
                d = compare_scans(fast, naive, cfg)
                diff["different"] += d["different"]
                ranges.append(d["range_diff"])
                clouds.append(world.lidar_scan(cfg, np.random.default_rng(0)))
        finally:
            world.close()
    med = {k: 1000.0 * statistics.median(v) for k, v in t.items()}
    dr = np.concatenate(ranges) if ranges else np.zeros(1)
    diff["range_p99_mm"], diff["range_max_mm"] = 1000 * float(np.percentile(dr, 99)), 1000 * float(dr.max())
    return {"times": med, "diff": diff, "clouds": clouds}


def compare_scans(fast, naive, cfg: LidarConfig) -> dict:
    """Return by return, keyed by beam (ring and azimuth step): how many returns are on one side only or hit
    another cone or surface (``different``), and the range differences of the other cone returns (m)."""
    def beams(c) -> np.ndarray:
        az = np.degrees(np.arctan2(c.xyz[:, 1], c.xyz[:, 0]))
        col = np.round((az - cfg.azimuths_deg[0]) / cfg.h_res_deg).astype(np.int64) % cfg.columns
        return c.ring.astype(np.int64) * cfg.columns + col
    kf, kn = beams(fast), beams(naive)
    _, i_f, i_n = np.intersect1d(kf, kn, return_indices=True)
    same = (fast.cone[i_f] == naive.cone[i_n]) & (fast.label[i_f] == naive.label[i_n])
    different = len(kf) + len(kn) - 2 * len(i_f) + int((~same).sum())
    on_cone = same & (naive.cone[i_n] >= 0)
    return {"different": different, "range_diff": np.abs(fast.ranges[i_f][on_cone] - naive.ranges[i_n][on_cone])}


def run(args: argparse.Namespace) -> int:
    for name in ("poses", "repeats", "naive_repeats"):
        if getattr(args, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    tracks = [t.strip() for t in args.tracks.split(",") if t.strip()]
    print(f"Machine: {machine_line()}; load average {os.getloadavg()[0]:.1f}")
    rows, weather_rows = [], []
    for label, cfg in SENSORS.items():
        r = bench_sensor(cfg, tracks, args.poses, args.repeats, args.naive_repeats)
        tm, d = r["times"], r["diff"]
        rows.append([label, cfg.rays, f"{d['returns'] / d['scans']:.0f}", f"{tm['fast_wall']:.2f} / {tm['fast_cpu']:.2f}",
                     f"{tm['naive_wall']:.1f} / {tm['naive_cpu']:.1f}", f"{tm['naive_cpu'] / tm['fast_cpu']:.0f}x",
                     f"{d['different']} of {d['returns']} ({d['cone_returns']} on cones)",
                     f"{d['range_p99_mm']:.2f} / {d['range_max_mm']:.1f}"])
        rng = np.random.default_rng(0)
        for spec in WEATHER:
            w = parse_lidar_weather(spec)
            wall: list = []
            for c in r["clouds"]:
                _timed(lambda c=c, w=w, g=rng: w(c, g), 5, wall, [])
            weather_rows.append([label, spec, f"{1000 * statistics.median(wall):.2f}"])
        wall = []
        for c in r["clouds"]:
            _timed(lambda c=c, f=cfg: cones_from_points(c, f), 5, wall, [])
        weather_rows.append([label, "cones from points", f"{1000 * statistics.median(wall):.2f}"])
    print(f"\nOne scan, median over {args.poses} places on each of {', '.join(tracks)} (fast: {args.repeats} scans "
          f"each, naive: {args.naive_repeats}); ms wall / ms CPU; load average {os.getloadavg()[0]:.1f}:")
    print(markdown_table(["sensor", "beams", "returns per scan", "fast scan ms", "naive rayTestBatch ms",
                          "speed-up (CPU)", "returns differing", "range diff. mm (99th pct. / max)"], rows))
    print("\nPer scan (ms, median):")
    print(markdown_table(["sensor", "step", "ms"], weather_rows))
    return 0
