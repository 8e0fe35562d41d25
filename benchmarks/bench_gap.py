"""The gap workflow on 200 frames at 1024x768; same as ``weather-gym bench gap [options]``.

Run: python benchmarks/bench_gap.py [--baseline] [--frames 200] [--size 1024x768] [--out table.md]
"""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "gap", *sys.argv[1:]]))
