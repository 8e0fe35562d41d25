"""The ONNX cone detector and the whole env step; same as ``weather-gym bench detector [options]``.

Run: python benchmarks/bench_detector.py [--step] [--repeats 100] [--out table.md]
"""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "detector", *sys.argv[1:]]))
