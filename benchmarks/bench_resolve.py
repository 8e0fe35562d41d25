"""Presets resolved per scenario: first use and cached cost; same as ``weather-gym bench resolve [options]``.

Run: python benchmarks/bench_resolve.py [--track small_track] [--frames 160] [--cache DIR] [--repeats 200]
"""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "resolve", *sys.argv[1:]]))
