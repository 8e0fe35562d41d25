"""PPO training throughput per vector env kind; same as ``weather-gym bench train [options]``.

Run: python benchmarks/bench_train.py [--pairs 5] [--vecs dummy,auto] [--timesteps 40960] [--out table.md]
"""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "train", *sys.argv[1:]]))
