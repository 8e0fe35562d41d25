"""``sb3``: a stable-baselines3 policy behind the ``Agent`` protocol.

Wraps a model instance (``model=``) or loads a saved zip (``path=``, with ``algo=`` naming the
algorithm class, PPO by default). ``act`` calls ``model.predict(obs, deterministic=True)``; the
observation is passed as the env gives it, so train and drive with the same wrappers.

Example:
    >>> from weather_gym.agents import AGENTS
    >>> agent = AGENTS.get("sb3")(None, None, path="runs/ppo_cones.zip", algo="PPO")  # doctest: +SKIP
    >>> agent.act(obs)                                                                # doctest: +SKIP

A stand-in model (anything with ``predict``) shows the contract without loading one:
    >>> import numpy as np
    >>> class Straight:
    ...     def predict(self, obs, state=None, deterministic=True):
    ...         return np.array([0.0, 0.5]), None
    >>> agent = AGENTS.get("sb3")(None, None, model=Straight())
    >>> agent.reset(seed=0)
    >>> agent.act({"state": np.zeros(5, np.float32)})
    array([0. , 0.5], dtype=float32)
"""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from weather_gym.agents._checks import check_action
from weather_gym.agents.cone_memory import ConeMemory, ConeMemoryConfig
from weather_gym.agents.cone_shield import ConeShield, ConeShieldConfig
from weather_gym.core.errors import FileFormatError, InputError, MissingInputError

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import Track

__all__ = ["SB3Agent", "SB3_ALGOS", "model_sidecar"]

SB3_ALGOS = ("A2C", "DDPG", "PPO", "SAC", "TD3")
"""stable-baselines3 algorithms with continuous (Box) actions."""


def model_sidecar(model: str | Path) -> Path | None:
    """The JSON ``weather-gym train`` wrote for a saved model: beside it (``model.json``,
    ``ppo_<N>_steps.json``, ``best_model.json``), else the run folder's ``model.json`` one or two folders
    up (``best/`` and ``checkpoints/`` sit in the run folder); None when there is none."""
    model = Path(model)
    for candidate in (model.with_suffix(".json"), model.parent / "model.json", model.parent.parent / "model.json"):
        if candidate.is_file():
            return candidate
    return None


_Config = TypeVar("_Config", ConeMemoryConfig, ConeShieldConfig)


def _read_sidecar(model: Path) -> tuple[Path | None, dict]:
    """A saved model's sidecar (:func:`model_sidecar`) and what it records ({} without one)."""
    sidecar = model_sidecar(model)
    if sidecar is None:
        return None, {}
    try:
        meta = json.loads(sidecar.read_text())
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{sidecar}: the model's JSON sidecar could not be read ({exc})") from None
    return sidecar, meta if isinstance(meta, dict) else {}


def _recorded(sidecar: Path | None, meta: dict, key: str, kind: type[_Config]) -> bool | _Config:
    """What the sidecar's ``meta`` records under ``key`` (``cone_memory``, ``cone_shield``): False
    without the key, else True/False or a ``kind`` (ConeMemoryConfig, ConeShieldConfig)."""
    recorded = meta.get(key, False)
    if isinstance(recorded, bool):
        return recorded
    try:
        return kind.from_dict(recorded)
    except InputError as exc:
        raise FileFormatError(f"{sidecar}: {exc}") from None  # the message names the key


def _config(value: object, kind: type[_Config], name: str) -> _Config | None:
    """``cone_memory=`` / ``cone_shield=`` as given (None/False, True, a config or its dict) -> a config or None."""
    if value is None or value is False:
        return None
    if value is True:
        return kind()
    if isinstance(value, dict):
        return kind.from_dict(value)
    if isinstance(value, kind):
        return value
    raise InputError(f"sb3 agent: {name} must be true, false, a {kind.__name__} or its fields, got {value!r}")


class SB3Agent:
    """Drive with a stable-baselines3 model.

    Args:
        track, camera: unused (factory signature).
        model: a model with ``predict(obs, deterministic=True)``; or
        path: a file saved by ``model.save(...)``, loaded with ``algo`` (one of ``SB3_ALGOS``).
        device: torch device for loading (default ``"cpu"``).
        cone_memory: pass the cone list through a :class:`~weather_gym.agents.cone_memory.ConeMemory`
            first (``True`` for the default tuning, or a ``ConeMemoryConfig`` or its dict), as for a
            policy trained with ``weather-gym train --cone-memory``; ``None`` (default): as the saved
            model's JSON sidecar (:func:`model_sidecar`) records under ``"cone_memory"``, none without one.
        cone_shield: pass each action through a :class:`~weather_gym.agents.cone_shield.ConeShield`,
            which steers it off the cones in the (remembered) cone list (``True``, a ``ConeShieldConfig``
            or its dict); ``None`` (default): as the sidecar records under ``"cone_shield"``, none without one.
    """

    def __init__(self, track: Track | None = None, camera: CameraConfig | None = None, *, model: Any = None,
                 path: str | Path | None = None, algo: str = "PPO", device: str = "cpu",
                 cone_memory: bool | dict | ConeMemoryConfig | None = None,
                 cone_shield: bool | dict | ConeShieldConfig | None = None) -> None:
        if (model is None) == (path is None):
            raise InputError("sb3 agent: give exactly one of model= (a stable-baselines3 model) or path= (a saved .zip)")
        if model is None:
            p = Path(path)  # type: ignore[arg-type]  # given: exactly one of model and path is
            if not p.exists() and p.with_suffix(".zip").exists():
                p = p.with_suffix(".zip")
            if not p.is_file():
                raise MissingInputError(f"sb3 agent: model file {str(path)!r} not found")
            if algo not in SB3_ALGOS:
                raise InputError(f"sb3 agent: unknown algo {algo!r}; expected one of {', '.join(SB3_ALGOS)}")
            cls = getattr(importlib.import_module("stable_baselines3"), algo)
            model = cls.load(str(p), device=device)
            if cone_memory is None or cone_shield is None:
                sidecar, meta = _read_sidecar(p)
                if cone_memory is None:
                    cone_memory = _recorded(sidecar, meta, "cone_memory", ConeMemoryConfig)
                if cone_shield is None:
                    cone_shield = _recorded(sidecar, meta, "cone_shield", ConeShieldConfig)
        if not callable(getattr(model, "predict", None)):
            raise InputError(f"sb3 agent: model {type(model).__name__} has no predict(obs, deterministic=...) method")
        self.model = model
        memory = _config(cone_memory, ConeMemoryConfig, "cone_memory")
        shield = _config(cone_shield, ConeShieldConfig, "cone_shield")
        self.memory = ConeMemory(memory, camera=camera) if memory is not None else None
        self.shield = ConeShield(shield) if shield is not None else None

    def reset(self, seed: int | None = None, info: dict | None = None) -> None:
        self._state = None  # recurrent policies keep a hidden state between steps
        if self.memory is not None:
            self.memory.reset()
        if self.shield is not None:
            self.shield.reset()

    def act(self, obs: Any, info: dict | None = None) -> np.ndarray:
        if self.memory is not None:
            obs = self.memory(obs)
        action, self._state = self.model.predict(obs, state=getattr(self, "_state", None), deterministic=True)
        action = check_action(np.asarray(action, dtype=np.float32).reshape(-1), "sb3 model")
        return action if self.shield is None else self.shield(obs, action)
