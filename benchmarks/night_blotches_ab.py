"""The night camera's colour blotches as before and as now, in one process (the baseline side by side).

    python benchmarks/night_blotches_ab.py [--repeats 100]

Before: numpy's axis mean of the three offsets, then + the positive part and - the negative part of the
enlarged blotches, each a saturating uint8 pass with a temporary frame. Now
(:func:`weather_gym.weather.dim.add_chroma_blotches`): the mean written out and one
``cv2.addWeighted(img, 1, big, 1, -128)``, the same bytes (checked here and in
``tests/weather/test_weather_dim.py``). The whole ``low_light@1`` and ``low_light@4`` frames (672x376,
moving, with depth) are timed, the two versions taking turns, each turn an untimed call and 4 timed
ones, by the CPU time of the thread (the machine may be loaded); medians.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import cv2
import numpy as np

from weather_gym.weather import dim, parse_weather
from weather_gym.weather._common import flat, gauss_lut, into
from weather_gym.weather.sample import sample_frame

NOW = dim.add_chroma_blotches


def before(img, sigma, cell_px, raw, weight=None):
    """``add_chroma_blotches`` as it was."""
    if isinstance(raw, np.random.Generator):
        raw = dim.chroma_draw(raw, img.shape, cell_px)
    h, w = img.shape[:2]
    gh, gw = dim.chroma_grid(img.shape, cell_px)
    z = gauss_lut()[raw].reshape(gh, gw, 3)
    z -= z.mean(axis=2, keepdims=True)
    z *= np.float32(sigma * math.sqrt(1.5))
    if weight is not None:
        z *= weight[:, :, None]
    grid = np.clip(np.rint(z + 128.0), 0, 255).astype(np.uint8)
    big = cv2.resize(grid, (w, h), interpolation=cv2.INTER_LINEAR)
    f, b = flat(img), flat(big)
    into(cv2.add(f, cv2.subtract(b, np.full_like(b, 128)), dst=f), f)
    into(cv2.subtract(f, cv2.subtract(np.full_like(b, 128), b), dst=f), f)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=100, help="turns (default %(default)s)")
    args = p.parse_args()
    cv2.setNumThreads(1)
    frame, depth = sample_frame(376, 672, seed=0)
    state = {"speed": 10.0, "yaw_rate": 0.3}
    times: dict[str, list[float]] = {}
    for spec in ("low_light@1", "low_light@4"):
        outs = {}
        for label, fn in (("before", before), ("now", NOW)):
            dim.add_chroma_blotches = fn
            e = parse_weather(spec)
            e.reset(0)
            outs[label] = e(frame, depth=depth, state=state)
        assert np.array_equal(outs["before"], outs["now"]), spec
    effects = {spec: parse_weather(spec) for spec in ("low_light@1", "low_light@4")}
    for _ in range(args.repeats):
        for spec, e in effects.items():
            for label, fn in (("before", before), ("now", NOW)):
                dim.add_chroma_blotches = fn
                e(frame, depth=depth, state=state)
                for _ in range(4):
                    t = time.thread_time()
                    e(frame, depth=depth, state=state)
                    times.setdefault(f"{spec} {label}", []).append(time.thread_time() - t)
    dim.add_chroma_blotches = NOW
    for key, v in times.items():
        print(f"{key:22s} {1000 * statistics.median(v):.3f} ms (CPU time, median of {len(v)})")


if __name__ == "__main__":
    main()
