"""``weather-gym train``: train a PPO driver on the cone list (:mod:`weather_gym.lab.training.policy.train`).

Examples:
    weather-gym train --out runs/driver            # clone gt_pure_pursuit (DAgger), PPO 100k steps, best held-out kept
    weather-gym train --out runs/driver --resume   # after a stop (Ctrl-C included)
    weather-gym train --out runs/bc --timesteps 0  # the clone alone
    weather-gym train --out runs/smoke --timesteps 4096 --n-envs 2 --pretrain none --eval-freq 0   # a smoke run

The smoke run above, parsed (nothing runs):
    >>> from weather_gym.cli import build_parser
    >>> args = build_parser().parse_args(['train', '--out', 'runs/smoke', '--timesteps', '4096', '--n-envs', '2'])
    >>> str(args.out), args.timesteps, args.n_envs, args.perception, args.pretrain
    ('runs/smoke', 4096, 2, 'surrogate', 'gt_pure_pursuit')
"""

from __future__ import annotations

import argparse


def register(sub) -> None:
    from weather_gym.lab.training.policy.train import __doc__ as doc
    from weather_gym.lab.training.policy.train import build_parser

    p = sub.add_parser("train", help="train a PPO driver on the cone list (logs, checkpoints, held-out eval, resume)",
                       description=doc.split("Example:")[0].strip(),
                       formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    build_parser(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    from weather_gym.lab.training.policy.train import train

    return train(args)
