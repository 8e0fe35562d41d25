"""The effect contract shared by every weather effect.

An effect is an immutable configuration (a frozen dataclass validated at construction) plus, for
the few stateful effects, per-episode state. Every effect is called the same way::

    effect(image, *, depth=None, state=None, rng=None) -> new uint8 image
    effect.reset(seed)            # start a new episode

* ``image``: uint8 ``H x W x 3`` RGB (or a batch ``N x H x W x 3``), C-contiguous or not, never
  modified. The result is a new array of the same shape and dtype.
* ``depth``: optional float ``H x W`` (``N x H x W`` for a batch) metric z-depth in metres.
* ``state``: optional mapping with any of ``speed`` (m/s), ``yaw_rate`` (rad/s), ``exposure_s``,
  ``fx`` (focal length, px) and ``binning`` (the frame was scaled down from the sensor's pixels by
  this factor: sensor noise then acts at the sensor's pixels, as if before the scaling); effects
  that need them use documented defaults otherwise. A batch
  takes one mapping for all frames or a sequence of ``N`` mappings.
* ``rng``: optional ``numpy.random.Generator``. Without it the effect draws from its episode
  generator, ``numpy.random.default_rng(seed)`` from the last ``reset(seed)``; if ``reset`` was
  never called, from ``default_rng(DEFAULT_SEED)`` created at first use. There is no global RNG.

``k`` in ``[0, 1]`` is the one severity knob of an effect; ``k = 0`` returns an exact copy.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((4, 6, 3), 200, np.uint8)
    >>> out = make("dim", k=0.5)(img)
    >>> int(out[0, 0, 0]), int(img[0, 0, 0])   # the input is untouched
    (100, 200)
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from weather_gym.errors import InputError, LimitError
from weather_gym.limits import check_image_size

__all__ = ["DEFAULT_SEED", "STATE_BOUNDS", "STATE_KEYS", "Effect", "KnobEffect", "check_image", "check_depth"]

#: Seed of the episode generator of an effect whose ``reset`` was never called.
DEFAULT_SEED = 20220607

#: Keys of the vehicle ``state`` mapping that effects read (others are ignored).
STATE_KEYS = ("speed", "yaw_rate", "exposure_s", "fx", "binning")

#: Physical range of each state value (checked up front: a yaw rate of 1e8 rad/s would otherwise
#: ask for a blur kernel millions of pixels wide).
STATE_BOUNDS: dict[str, tuple[float, float, str]] = {
    "speed": (-150.0, 150.0, "m/s"),
    "yaw_rate": (-20.0, 20.0, "rad/s"),
    "exposure_s": (0.0, 1.0, "s"),
    "fx": (1.0, 1e7, "px"),
}

SeedLike = int | np.random.SeedSequence | None


def check_image(image: Any, who: str) -> tuple[np.ndarray, bool]:
    """Validate an image or batch; returns ``(C-contiguous uint8 array, is_batch)``."""
    if not isinstance(image, np.ndarray):
        raise InputError(f"{who}: expected a numpy uint8 array of shape (H, W, 3) or (N, H, W, 3), "
                         f"got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise InputError(f"{who}: expected dtype uint8 (0-255 RGB), got {image.dtype}")
    if image.ndim not in (3, 4) or image.shape[-1] != 3:
        raise InputError(f"{who}: expected shape (H, W, 3) or (N, H, W, 3) with 3 RGB channels, "
                         f"got shape {image.shape}")
    if min(image.shape[:-1]) < 1:
        raise InputError(f"{who}: expected H, W (and N) >= 1, got shape {image.shape}")
    check_image_size(image.shape[-3:], what=who, min_side=1)
    return np.ascontiguousarray(image), image.ndim == 4


def check_depth(depth: Any, image_shape: tuple[int, ...], who: str) -> np.ndarray | None:
    """Validate a depth map against the image shape; returns a C-contiguous float32 array."""
    if depth is None:
        return None
    expected = tuple(image_shape[:-1])
    if not isinstance(depth, np.ndarray) or not np.issubdtype(depth.dtype, np.floating):
        got = depth.dtype if isinstance(depth, np.ndarray) else type(depth).__name__
        raise InputError(f"{who}: depth must be a float array of metres with shape {expected}, got {got}")
    if depth.shape != expected:
        raise InputError(f"{who}: depth must have shape {expected} matching the image, got {depth.shape}")
    return np.ascontiguousarray(depth, dtype=np.float32)


def _check_state_one(state: Any, who: str) -> dict[str, float]:
    if state is None:
        return {}
    if not isinstance(state, Mapping):
        raise InputError(f"{who}: state must be a mapping with optional keys {', '.join(STATE_KEYS)}, "
                         f"got {type(state).__name__}")
    out: dict[str, float] = {}
    for key in STATE_KEYS:
        if key in state and state[key] is not None:
            v = state[key]
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise InputError(f"{who}: state[{key!r}] must be a number, got {v!r}") from None
            if not math.isfinite(f):
                raise InputError(f"{who}: state[{key!r}] must be finite, got {v!r}")
            out[key] = f
    if "fx" in out and out["fx"] <= 0:
        raise InputError(f"{who}: state['fx'] must be a positive focal length in pixels, got {out['fx']}")
    if "exposure_s" in out and out["exposure_s"] < 0:
        raise InputError(f"{who}: state['exposure_s'] must be >= 0, got {out['exposure_s']}")
    for key, (lo, hi, unit) in STATE_BOUNDS.items():
        if key in out and not lo <= out[key] <= hi:
            raise LimitError(f"{who}: state[{key!r}] = {out[key]:g} is outside its physical range "
                             f"[{lo:g}, {hi:g}] {unit}")
    return out


def check_state(state: Any, n: int | None, who: str) -> list[dict[str, float]] | dict[str, float]:
    """A validated state dict (single frame) or list of ``n`` dicts (batch)."""
    if n is None:
        return _check_state_one(state, who)
    if state is None or isinstance(state, Mapping):
        one = _check_state_one(state, who)
        return [one] * n
    if isinstance(state, Sequence) and not isinstance(state, str | bytes):
        if len(state) != n:
            raise InputError(f"{who}: a batch of {n} frames needs one state mapping or {n}, got {len(state)}")
        return [_check_state_one(s, who) for s in state]
    raise InputError(f"{who}: state must be a mapping (or a sequence of mappings for a batch), "
                     f"got {type(state).__name__}")


def check_rng(rng: Any, who: str) -> np.random.Generator | None:
    if rng is None or isinstance(rng, np.random.Generator):
        return rng
    raise InputError(f"{who}: rng must be a numpy.random.Generator or None, got {type(rng).__name__}")


def check_seed(seed: Any, who: str) -> np.random.SeedSequence:
    """``seed`` as a SeedSequence (``None`` means ``DEFAULT_SEED``)."""
    if seed is None:
        return np.random.SeedSequence(DEFAULT_SEED)
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, numbers.Integral) and not isinstance(seed, bool) and int(seed) >= 0:
        return np.random.SeedSequence(int(seed))
    raise InputError(f"{who}: seed must be a non-negative int, a numpy SeedSequence or None, got {seed!r}")


class Effect:
    """Base of everything that degrades images (effects, :class:`Compose`, schedules).

    Subclasses implement ``_run(img, depth, state, rng)`` for one frame (``img`` is a
    C-contiguous uint8 ``H x W x 3`` array that must not be modified) and may override
    ``_run_into`` (one frame written into a given array: batches then need no extra copy) and
    ``_run_batch`` when frames can be processed together.
    """

    name: ClassVar[str] = ""
    #: True when the effect keeps state across frames of an episode (see :meth:`reset`).
    stateful: ClassVar[bool] = False

    # -- public API --------------------------------------------------------------------------
    def __call__(self, image: np.ndarray, *, depth: np.ndarray | None = None,
                 state: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None,
                 rng: np.random.Generator | None = None) -> np.ndarray:
        who = self.name or type(self).__name__
        img, batched = check_image(image, who)
        d = check_depth(depth, img.shape, who)
        st = check_state(state, img.shape[0] if batched else None, who)
        out = self._process(img, d, st, check_rng(rng, who), batched)
        if np.may_share_memory(out, image):  # the contract: always a new array
            out = out.copy()
        return out

    def reset(self, seed: SeedLike = None) -> None:
        """Start a new episode: the episode generator becomes ``default_rng(seed)``."""
        object.__setattr__(self, "_rng", np.random.default_rng(check_seed(seed, self.name)))
        self._reset_state()

    def params(self) -> dict[str, Any]:
        raise NotImplementedError

    # -- for subclasses ----------------------------------------------------------------------
    def _episode_rng(self) -> np.random.Generator:
        rng = getattr(self, "_rng", None)
        if rng is None:
            self.reset(DEFAULT_SEED)
            rng = self._rng
        return rng

    def _reset_state(self) -> None:
        """Clear per-episode state (stateful effects override)."""

    def _process(self, img: np.ndarray, depth: np.ndarray | None, state: Any,
                 rng: np.random.Generator | None, batched: bool) -> np.ndarray:
        """Validated input -> output; ``rng`` None means this effect's episode generator."""
        g = rng if rng is not None else self._episode_rng()
        if batched:
            return self._run_batch(img, depth, state, g)
        return self._run(img, depth, state, g)

    def _run(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
             rng: np.random.Generator) -> np.ndarray:
        raise NotImplementedError

    def _run_batch(self, imgs: np.ndarray, depth: np.ndarray | None, states: list[dict[str, float]],
                   rng: np.random.Generator) -> np.ndarray:
        out = np.empty_like(imgs)
        for i in range(imgs.shape[0]):
            self._run_into(imgs[i], None if depth is None else depth[i], states[i], rng, out[i])
        return out

    def _run_into(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
                  rng: np.random.Generator, out: np.ndarray) -> None:
        """One frame written into ``out`` (a C-contiguous uint8 array of the image's shape)."""
        np.copyto(out, self._run(img, depth, state, rng))


def _is_real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


@dataclasses.dataclass(frozen=True)
class KnobEffect(Effect):
    """An effect with one severity knob ``k`` in ``[0, 1]`` and named physical parameters.

    Class attributes a subclass declares:

    * ``name``: its registry key.
    * ``PARAM_BOUNDS``: ``{param: (lo, hi)}`` for the parameters worth fitting (k is always
      fitted in ``[0, 1]`` and is not listed).
    * ``PARAM_LIMITS``: ``{param: (lo, hi)}`` valid ranges of the other numeric parameters.
    * ``CHOICES``: ``{param: (allowed strings...)}``.

    Every constructor argument is a float, int, bool or str, so :meth:`params` is JSON/TOML
    serialisable and ``make(name, **effect.params())`` rebuilds an equal effect.
    """

    k: float = 0.0

    PARAM_BOUNDS: ClassVar[Mapping[str, tuple[float, float]]] = {}
    PARAM_LIMITS: ClassVar[Mapping[str, tuple[float, float]]] = {}
    CHOICES: ClassVar[Mapping[str, tuple[str, ...]]] = {}

    def __post_init__(self) -> None:
        who = self.name or type(self).__name__
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            ftype = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
            if f.name in self.CHOICES:
                allowed = self.CHOICES[f.name]
                if v not in allowed:
                    raise InputError(f"{who}: parameter {f.name}={v!r} must be one of {', '.join(allowed)}")
            elif ftype == "bool":
                if not isinstance(v, bool | np.bool_):
                    raise InputError(f"{who}: parameter {f.name}={v!r} must be true or false")
                object.__setattr__(self, f.name, bool(v))
            elif ftype in ("float", "int"):
                lo, hi = self.bounds_of(f.name)
                if not _is_real(v) or not math.isfinite(float(v)):
                    raise InputError(f"{who}: parameter {f.name}={v!r} must be a finite number in [{lo}, {hi}]")
                if ftype == "int":
                    if float(v) != int(v):
                        raise InputError(f"{who}: parameter {f.name}={v!r} must be an integer in [{lo}, {hi}]")
                    v = int(v)
                else:
                    v = float(v)
                if not lo <= v <= hi:
                    raise InputError(f"{who}: parameter {f.name}={v!r} is outside [{lo}, {hi}]")
                object.__setattr__(self, f.name, v)
            else:  # pragma: no cover - a programming error in an effect definition
                raise TypeError(f"{who}: parameter {f.name} has unsupported type {ftype}")
        object.__setattr__(self, "_rng", None)
        self._reset_state()

    @classmethod
    def bounds_of(cls, param: str) -> tuple[float, float]:
        """Valid range of a numeric parameter (``k``: ``(0, 1)``)."""
        if param == "k":
            return (0.0, 1.0)
        if param in cls.PARAM_BOUNDS:
            return cls.PARAM_BOUNDS[param]
        if param in cls.PARAM_LIMITS:
            return cls.PARAM_LIMITS[param]
        raise KeyError(f"{cls.name}: numeric parameter {param!r} has no declared range")

    @classmethod
    def param_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    def params(self) -> dict[str, Any]:
        """All constructor arguments (``k`` included), JSON/TOML serialisable."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def with_params(self, **changes: Any) -> KnobEffect:
        """A copy with some parameters changed that keeps this effect's episode (RNG and state)."""
        new = dataclasses.replace(self, **changes)
        object.__setattr__(new, "_rng", self._rng)
        new._adopt_state(self)
        return new

    def _adopt_state(self, other: KnobEffect) -> None:
        """Take over ``other``'s per-episode state (stateful effects override)."""

    def _run(self, img, depth, state, rng):
        if self.k == 0.0:
            self._idle(img.shape, rng)
            return img.copy()
        return self._apply(img, depth, state, rng)

    def _run_into(self, img, depth, state, rng, out):
        if self.k == 0.0:
            self._idle(img.shape, rng)
            np.copyto(out, img)
        else:
            self._apply_into(img, depth, state, rng, out)

    def _idle(self, shape: tuple[int, ...], rng: np.random.Generator) -> None:
        """Called instead of ``_apply`` when ``k == 0`` (stateful effects keep time going)."""

    def _apply(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
               rng: np.random.Generator) -> np.ndarray:
        """The degraded frame (``k > 0``), a new array. Subclasses override this or :meth:`_apply_into`."""
        if type(self)._apply_into is KnobEffect._apply_into:
            raise NotImplementedError(f"{type(self).__name__} implements neither _apply nor _apply_into")
        out = np.empty_like(img)
        self._apply_into(img, depth, state, rng, out)
        return out

    def _apply_into(self, img: np.ndarray, depth: np.ndarray | None, state: dict[str, float],
                    rng: np.random.Generator, out: np.ndarray) -> None:
        """:meth:`_apply` written into ``out``; batches call this frame by frame, with no extra copy."""
        np.copyto(out, self._apply(img, depth, state, rng))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"
