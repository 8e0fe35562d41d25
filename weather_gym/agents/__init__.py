"""Agents: anything with ``reset(seed, info)`` and ``act(obs, info) -> action`` drives the car.

``AGENTS`` maps a name to a factory ``(track, camera, **kwargs) -> Agent``:

* ``gt_pure_pursuit`` - ground-truth driver: pure pursuit on the track's centre line using the true
  pose from ``info["pose"]`` and ``info["speed"]`` (laps, datasets, env tests).
* ``mapper_pure_pursuit`` - the perception stack: ``ConeMapper`` + centre-line planner + pure
  pursuit, reading only ``obs["cones"]``, ``obs["mask"]`` and ``obs["state"]``.
* ``sb3`` - a stable-baselines3 model (``model=`` an instance or ``path=`` a saved zip).
* ``ppo_cones`` - the shipped PPO driver (``examples/train_ppo.py``, ``docs/rl.md``): reads the
  cone list like ``mapper_pure_pursuit``; needs stable-baselines3 (``pip install -e ".[rl]"``).

An agent of your own needs no registration: ``"my_pkg.drivers:MyAgent"`` (a module path, a colon
and the name of a factory ``(track, camera, **kwargs) -> Agent`` in it, for example the agent's
class) works wherever a registered name does (``--agent`` of ``weather-gym lap`` and ``evaluate``,
:func:`make_agent`); its module is imported then, and only then.

Callers always pass the step's ``info``; perception-driven agents never read ground truth from it.
Each factory declares the observation keys its agent reads (:func:`agent_observes`: ``cones``,
``mask``, ``state`` for the cone-list drivers, none for ``gt_pure_pursuit``, unknown for ``sb3``),
so a perception mode that does not give them is refused before the episode starts.
:func:`run_episode` is the one loop that drives an agent through an episode (``EpisodeResult``).

Example:
    >>> import numpy as np
    >>> from weather_gym.agents import AGENTS, Agent
    >>> AGENTS.names()
    ['gt_pure_pursuit', 'mapper_pure_pursuit', 'ppo_cones', 'sb3']
    >>> sorted(agent_observes("mapper_pure_pursuit")), agent_observes("gt_pure_pursuit")
    (['cones', 'mask', 'state'], frozenset())
    >>> class Straight:                       # a user's own stack: two methods are enough
    ...     def reset(self, seed=None, info=None): pass
    ...     def act(self, obs, info=None): return np.array([0.0, 0.3], np.float32)
    >>> isinstance(Straight(), Agent)
    True
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, runtime_checkable

import numpy as np

from weather_gym.agents._checks import check_action
from weather_gym.agents.gt_pure_pursuit import GroundTruthPurePursuit
from weather_gym.agents.sb3 import SB3Agent
from weather_gym.agents.stack import MapperPurePursuit
from weather_gym.core.errors import InputError
from weather_gym.core.moved import deprecated_exports, moved_path
from weather_gym.core.paths import PPO_CONES_MODEL
from weather_gym.core.registry import Registry

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import Track

__all__ = ["Agent", "AGENTS", "agent_factory", "agent_observes", "check_action", "make_agent", "observes"]

# the episode driver moved up to the pipeline layer (weather_gym.pipeline.episode); old names for one release
__path__.append(moved_path(__name__))  # the old module paths, deprecated (weather_gym.core.moved)
__getattr__ = deprecated_exports(__name__, {"run_episode": "weather_gym.pipeline.episode",
                                            "EpisodeResult": "weather_gym.pipeline.episode"})

F = TypeVar("F", bound=Callable[..., Any])
CONE_LIST_KEYS = frozenset({"cones", "mask", "state"})


@runtime_checkable
class Agent(Protocol):
    """The one interface between an env loop and a driver (ours, a user's, or a trained policy)."""

    def reset(self, seed: int | None = None, info: dict | None = None) -> None:
        """Start a new episode (``info`` is the env's reset info)."""

    def act(self, obs: Any, info: dict | None = None) -> np.ndarray:
        """Float32 ``(steering, throttle/brake)`` in [-1, 1] for this step's observation."""


AGENTS: Registry = Registry("agent")


def agent_factory(name: str) -> Callable[..., Agent]:
    """The factory ``(track, camera, **kwargs) -> Agent`` of a registered agent ``name``, or of
    ``"module.path:attribute"`` (an agent of your own, imported now); InputError naming what is wrong."""
    if not isinstance(name, str) or ":" not in name:
        return AGENTS.get(name)  # ValueError lists the valid names
    module, _, attribute = name.partition(":")
    if not module or not attribute or not all(p.isidentifier() for p in (*module.split("."), *attribute.split("."))):
        raise InputError(f"agent {name!r}: expected a registered name ({', '.join(AGENTS.names())}) or "
                         "'module.path:Factory' (a module you can import, a colon, a factory in it)")
    try:
        obj: Any = importlib.import_module(module)
    except ImportError as exc:
        raise InputError(f"agent {name!r}: cannot import module {module!r} ({exc}); is it on PYTHONPATH "
                         "(the current folder is, for `python -m`)?") from None
    for part in attribute.split("."):
        if not hasattr(obj, part):
            raise InputError(f"agent {name!r}: module {module!r} has no {attribute!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise InputError(f"agent {name!r}: {attribute!r} is a {type(obj).__name__}, not a factory "
                         "(track, camera, **kwargs) -> agent")
    return obj


def make_agent(name: str, track: Track, camera: CameraConfig, **kwargs: Any) -> Agent:
    """Build the agent ``name``: a registered one (``ValueError`` lists the valid names) or
    ``"module.path:Factory"`` (:func:`agent_factory`)."""
    return agent_factory(name)(track, camera, **kwargs)


def observes(keys: Iterable[str] | None) -> Callable[[F], F]:
    """Declare on an agent factory the observation keys its agent reads (None: not known in advance)."""

    def mark(factory: F) -> F:
        factory.observes = None if keys is None else frozenset(keys)  # type: ignore[attr-defined]  # a mark on the function, read by agent_observes
        return factory

    return mark


def agent_observes(name: str) -> frozenset[str] | None:
    """The observation keys agent ``name`` reads (None: not declared, e.g. a loaded policy or an agent of
    your own without :func:`observes`)."""
    observed = getattr(agent_factory(name), "observes", None)
    return None if observed is None else frozenset(observed)


@AGENTS.register("gt_pure_pursuit")
@observes(())
def _gt_pure_pursuit(track: Track, camera: CameraConfig, **kwargs: Any) -> Agent:
    return GroundTruthPurePursuit(track, camera, **kwargs)


@AGENTS.register("mapper_pure_pursuit")
@observes(CONE_LIST_KEYS)
def _mapper_pure_pursuit(track: Track, camera: CameraConfig, **kwargs: Any) -> Agent:
    return MapperPurePursuit(track, camera, **kwargs)


@AGENTS.register("sb3")
@observes(None)
def _sb3(track: Track, camera: CameraConfig, **kwargs: Any) -> Agent:
    return SB3Agent(track, camera, **kwargs)


@AGENTS.register("ppo_cones")
@observes(CONE_LIST_KEYS)
def _ppo_cones(track: Track, camera: CameraConfig, **kwargs: Any) -> Agent:
    return SB3Agent(track, camera, path=PPO_CONES_MODEL, algo="PPO", **kwargs)

