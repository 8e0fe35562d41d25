"""Weather effects vs the study's recipe; same as ``weather-gym bench weather [options]``.

Run: python benchmarks/bench_weather.py [--sizes 672x376] [--repeats 200] [--out table.md]
"""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "weather", *sys.argv[1:]]))
