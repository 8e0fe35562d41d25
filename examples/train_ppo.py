"""Train a stable-baselines3 PPO driver on the cone-list observation: ``weather-gym train`` as a script.

The training lives in :mod:`weather_gym.lab.training.policy.train` (logs, checkpoints with their ``.json`` metadata,
held-out evaluation, resume, a usable ``model.zip`` after Ctrl-C); this script takes the same options.
Hyper-parameters come from ``weather_gym/lab/training/policy/ppo.yml`` (rl-zoo3's format; ``--hyperparams`` for another
file); see ``docs/rl.md``.

Usage:
    python examples/train_ppo.py --out runs/driver                 # warm start, PPO, the best held-out policy kept
    python examples/train_ppo.py --out runs/driver --resume        # after a stop
    python examples/train_ppo.py --out runs/ppo_smoke --timesteps 4096 --n-envs 2 --pretrain none --eval-freq 0
"""

from __future__ import annotations

import sys

from weather_gym.cli import run_command
from weather_gym.lab.training.policy.train import (  # noqa: F401 - the script's public names, as before
    DEFAULT_NOISE,
    DEFAULT_TRACKS,
    LapSuccess,
    RandomStart,
    build_parser,
    latest_checkpoint,
    make_training_env,
    plot_learning_curve,
    train,
)


def main(argv: list[str] | None = None) -> int:
    """The same options and outcome (exit status) as ``weather-gym train``."""
    return run_command(train, build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
