"""Simulator speed benchmark; same as ``weather-gym bench sim``."""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "sim", *sys.argv[1:]]))
