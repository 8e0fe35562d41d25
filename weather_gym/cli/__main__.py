import sys

from weather_gym.cli import main

sys.exit(main())
