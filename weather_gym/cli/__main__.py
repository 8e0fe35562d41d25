"""``python -m weather_gym.cli``: the ``weather-gym`` command. Its call sits under the main guard, so
that worker processes started with forkserver or spawn (vector envs, the training's split env) can
import this module without running a command."""

import sys

from weather_gym.cli import main

if __name__ == "__main__":
    sys.exit(main())
