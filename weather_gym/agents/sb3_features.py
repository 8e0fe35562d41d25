"""``ConeListExtractor``: what a stable-baselines3 policy reads from the cone-list observation.

The cone list (``Dict(cones, mask, state)``, :mod:`weather_gym.perception.cones`) is the same
whether the cones come from geometry (``gt_cones``), the rendered ground truth (``oracle``) or the
detector on a weathered frame (``detector``), so one policy trains on the cheap one and drives on
any. The extractor keeps what a controller needs and nothing that ties it to one track: for the
``max_cones`` nearest valid cones, the colour (blue, yellow, orange of either size), the position in
the car frame (``x_body / 20 m``, ``y_body / 10 m``) and the valid flag; plus speed (/ 10 m/s) and
yaw rate from the state. Odometry position and heading are left out (they say where on *this*
track the car is). The class is saved with the model by reference, so a saved policy loads wherever
weather-gym is installed.

Example:
    >>> import numpy as np, torch
    >>> from gymnasium import spaces
    >>> from weather_gym.agents.sb3_features import ConeListExtractor
    >>> space = spaces.Dict({"cones": spaces.Box(-np.inf, np.inf, (64, 14), np.float32),
    ...                      "mask": spaces.Box(0, 1, (64,), np.int8),
    ...                      "state": spaces.Box(-np.inf, np.inf, (5,), np.float32)})
    >>> ex = ConeListExtractor(space, max_cones=16)
    >>> obs = {k: torch.as_tensor(v[None]) for k, v in space.sample().items()}
    >>> ex(obs).shape, ex.features_dim
    (torch.Size([1, 98]), 98)
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from stable_baselines3.common.policies import MultiInputActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from weather_gym.core.errors import InputError
from weather_gym.perception.cones import FIELD

__all__ = ["ConeListExtractor", "ConeListPolicy"]

X_SCALE_M = 20.0
Y_SCALE_M = 10.0
SPEED_SCALE = 10.0
_PER_CONE = 6  # blue, yellow, orange (either size), x, y, valid


class ConeListExtractor(BaseFeaturesExtractor):
    """Features of the ``max_cones`` nearest cones and the car's speed and yaw rate (see the module doc)."""

    def __init__(self, observation_space: spaces.Dict, max_cones: int = 24) -> None:
        for key in ("cones", "mask", "state"):
            if key not in observation_space.spaces:
                raise InputError(f"ConeListExtractor needs a Dict observation with {key!r} (a cone list), "
                                 f"got keys {list(observation_space.spaces)}")
        n = observation_space["cones"].shape[0]  # type: ignore[index]  # a Box: it has a shape
        if not (isinstance(max_cones, int) and 1 <= max_cones <= n):
            raise InputError(f"ConeListExtractor: max_cones must be an integer in [1, {n}], got {max_cones!r}")
        super().__init__(observation_space, features_dim=max_cones * _PER_CONE + 2)
        self.max_cones = max_cones

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        k = self.max_cones
        cones = obs["cones"][:, :k].float()
        valid = obs["mask"][:, :k].float().unsqueeze(-1)
        blue = cones[..., FIELD["is_blue"]:FIELD["is_blue"] + 1]
        yellow = cones[..., FIELD["is_yellow"]:FIELD["is_yellow"] + 1]
        orange = cones[..., FIELD["is_orange"]:FIELD["is_orange"] + 1] + cones[..., FIELD["is_big_orange"]:
                                                                                  FIELD["is_big_orange"] + 1]
        x = cones[..., FIELD["x_body"]:FIELD["x_body"] + 1] / X_SCALE_M
        y = cones[..., FIELD["y_body"]:FIELD["y_body"] + 1] / Y_SCALE_M
        per_cone = torch.cat([blue, yellow, orange, x, y, torch.ones_like(x)], dim=-1) * valid
        state = obs["state"].float()
        car = torch.stack([state[:, 0] / SPEED_SCALE, state[:, 1]], dim=-1)
        return torch.cat([per_cone.flatten(1), car], dim=-1)


class ConeListPolicy(MultiInputActorCriticPolicy):
    """PPO's ``MultiInputPolicy`` reading the cone list through :class:`ConeListExtractor` (its default
    ``features_extractor_class``): a policy a hyper-parameter file names by import path
    (``policy: weather_gym.agents.sb3_features.ConeListPolicy``, rl-zoo3's format; ``weather-gym train``)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("features_extractor_class", ConeListExtractor)
        super().__init__(*args, **kwargs)
