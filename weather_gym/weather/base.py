"""The effect contract shared by every weather effect.

An effect is an immutable configuration (a frozen dataclass validated at construction). Producing
a frame has two parts, as in Albumentations' ``get_params`` / ``apply``:

    draw = effect.sample(rng, shape, episode)          # every random value of the frame
    out = effect.render(image, draw, depth=..., state=...)   # pure: no generator, nothing changes

Per-episode state (the episode generator, the lens drops of persistent droplets, a ramp's
position) lives in an :class:`EffectRun`, not in the effect: ``run = effect.start(seed)`` and then
``run(image)`` frame after frame (``WeatherWrapper`` holds one per episode). For convenience every
effect is also called directly, with a run of its own behind it::

    effect(image, *, depth=None, state=None, rng=None) -> new uint8 image
    effect.reset(seed)            # start a new episode of that run

* ``image``: uint8 ``H x W x 3`` RGB (or a batch ``N x H x W x 3``), C-contiguous or not, never
  modified. The result is a new array of the same shape and dtype.
* ``depth``: optional float ``H x W`` (``N x H x W`` for a batch) metric z-depth in metres.
* ``state``: optional mapping with any of ``speed`` (m/s), ``yaw_rate`` (rad/s), ``exposure_s``,
  ``fx`` (focal length, px) and ``binning`` (the frame was scaled down from the sensor's pixels by
  this factor: sensor noise then acts at the sensor's pixels, as if before the scaling); effects
  that need them use documented defaults otherwise. A batch
  takes one mapping for all frames or a sequence of ``N`` mappings.
* ``rng``: optional ``numpy.random.Generator``. Without it the effect draws from its episode
  generator, ``numpy.random.default_rng(seed)`` from the last ``reset(seed)`` (or
  ``start(seed)``); if ``reset`` was never called, from ``default_rng(DEFAULT_SEED)`` created at
  first use. There is no global RNG.

``k`` in ``[0, 1]`` is the one severity knob of an effect; ``k = 0`` returns an exact copy.

Example:
    >>> import numpy as np
    >>> from weather_gym.weather import make
    >>> img = np.full((4, 6, 3), 200, np.uint8)
    >>> out = make("dim", k=0.5)(img)
    >>> int(out[0, 0, 0]), int(img[0, 0, 0])   # the input is untouched
    (100, 200)
    >>> noise = make("noise", k=0.5)
    >>> draw = noise.sample(np.random.default_rng(0), img.shape)
    >>> bool((noise.render(img, draw) == noise(img, rng=np.random.default_rng(0))).all())
    True
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import typing
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
import pydantic
from pydantic_core import PydanticCustomError

from weather_gym.core.errors import InputError, LimitError
from weather_gym.core.limits import check_image_size

__all__ = ["DEFAULT_SEED", "STATE_BOUNDS", "STATE_KEYS", "Effect", "EffectRun", "KnobEffect", "check_depth",
           "check_image", "param_schema"]

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


class EffectRun:
    """One episode of an effect: its episode generator and per-episode state, called like the effect.

    ``effect.start(seed)`` returns one; ``run(image, depth=..., state=..., rng=...)`` makes the
    next frame (``rng`` overrides the episode generator for that frame, the state still moves on);
    ``run.restart(seed)`` begins a new episode. Each run is independent: two runs of one effect
    never share state.

    Example:
        >>> import numpy as np
        >>> from weather_gym.weather import make
        >>> lens = make("droplets", k=0.55, persistent=True)
        >>> a, b = lens.start(3), lens.start(3)
        >>> bool((a(np.zeros((120, 200, 3), np.uint8)) == b(np.zeros((120, 200, 3), np.uint8))).all())
        True
    """

    def __init__(self, effect: Effect, seed: SeedLike = None) -> None:
        self.effect = effect
        self.restart(seed)

    def restart(self, seed: SeedLike = None) -> None:
        """A new episode: the generator becomes ``default_rng(seed)``, the state starts afresh."""
        self.rng = np.random.default_rng(check_seed(seed, self.effect.name or type(self.effect).__name__))
        self.episode = self.effect.new_episode()

    def adopt(self, other: EffectRun) -> None:
        """Continue ``other``'s episode (its generator and state) with this run's effect."""
        self.rng, self.episode = other.rng, other.episode

    @property
    def current(self) -> Effect:
        """The effect (for a ramp: with the k) that the next frame gets."""
        return self.effect

    def sample(self, shape: tuple[int, ...], rng: np.random.Generator | None = None) -> Any:
        """The draw of the next frame (or batch) of ``shape``; moves the episode on by that many frames."""
        return self.effect.sample(rng if rng is not None else self.rng, tuple(shape), self.episode)

    def __call__(self, image: np.ndarray, *, depth: np.ndarray | None = None,
                 state: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None,
                 rng: np.random.Generator | None = None) -> np.ndarray:
        who = self.effect.name or type(self.effect).__name__
        img, batched = check_image(image, who)
        d = check_depth(depth, img.shape, who)
        st = check_state(state, img.shape[0] if batched else None, who)
        out = self._produce(img, d, st, check_rng(rng, who), batched)
        if np.may_share_memory(out, image):  # the contract: always a new array
            out = out.copy()
        return out

    def _produce(self, img: np.ndarray, depth: np.ndarray | None, state: Any,
                 rng: np.random.Generator | None, batched: bool) -> np.ndarray:
        """Validated input -> output: sample, then render."""
        return self.effect._render(img, self.sample(img.shape, rng), depth, state, batched)


class Effect:
    """Base of everything that degrades images (effects, :class:`Compose`, schedules).

    Subclasses implement :meth:`sample` (random values -> a draw), ``_render`` (validated input
    and a draw -> a new image, pure) and, when they keep state across frames, :meth:`new_episode`
    and a run class (``start``).
    """

    name: ClassVar[str] = ""
    #: True when the effect keeps state across frames of an episode (see :class:`EffectRun`).
    stateful: ClassVar[bool] = False

    # -- public API --------------------------------------------------------------------------
    def __call__(self, image: np.ndarray, *, depth: np.ndarray | None = None,
                 state: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None,
                 rng: np.random.Generator | None = None) -> np.ndarray:
        """The next frame of this effect's own run (see :class:`EffectRun`)."""
        return self._own_run(image, depth=depth, state=state, rng=rng)

    def start(self, seed: SeedLike = None) -> EffectRun:
        """A new, independent episode of this effect."""
        return EffectRun(self, seed)

    def reset(self, seed: SeedLike = None) -> None:
        """Start a new episode of the effect's own run: its generator becomes ``default_rng(seed)``."""
        self._own_run.restart(seed)

    @property
    def current(self) -> Effect:
        """The effect the next frame of the own run gets (a ramp: its effect at the current k)."""
        return self._own_run.current

    def new_episode(self) -> Any:
        """Fresh per-episode state that :meth:`sample` moves on (``None``: the effect keeps none)."""
        return None

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any = None) -> Any:
        """Every random value of one frame (``shape`` ``(H, W, 3)``) or batch (``(N, H, W, 3)``)."""
        raise NotImplementedError

    def render(self, image: np.ndarray, draw: Any = None, *, depth: np.ndarray | None = None,
               state: Mapping[str, float] | Sequence[Mapping[str, float]] | None = None) -> np.ndarray:
        """The degraded image for ``draw`` (from :meth:`sample`): pure, no generator, nothing changes."""
        who = self.name or type(self).__name__
        img, batched = check_image(image, who)
        out = self._render(img, draw, check_depth(depth, img.shape, who),
                           check_state(state, img.shape[0] if batched else None, who), batched)
        return out.copy() if np.may_share_memory(out, image) else out

    def params(self) -> dict[str, Any]:
        raise NotImplementedError

    # -- for subclasses ----------------------------------------------------------------------
    @functools.cached_property
    def _own_run(self) -> EffectRun:
        """The run behind ``effect(image)`` and ``effect.reset(seed)``, started at first use."""
        return self.start(None)

    def _render(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: Any,
                batched: bool) -> np.ndarray:
        """Validated input (C-contiguous, never modified) and a draw -> a new array."""
        raise NotImplementedError


def _is_real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _finite_float(v: Any) -> float:
    """A real, finite number as a float (``1`` -> ``1.0``, ``numpy.float32`` -> ``float``); not a bool."""
    if _is_real(v) and math.isfinite(float(v)):
        return float(v)
    raise PydanticCustomError("finite_number", "must be a finite number")


def _whole(v: Any) -> int:
    """A real, finite, whole number as an int (``2.0`` -> ``2``); not a bool."""
    f = _finite_float(v)
    if f != int(f):
        raise PydanticCustomError("integer", "must be an integer")
    return int(f)


def _boolean(v: Any) -> bool:
    """``True``/``False`` (or numpy's) as a bool; nothing else (``1``, ``"yes"``) is one."""
    if isinstance(v, bool | np.bool_):
        return bool(v)
    raise PydanticCustomError("boolean", "must be true or false")


#: What each kind of failure of a parameter says, after ``<effect>: parameter <name>=<value>``.
_PARAM_PHRASES = {
    "finite_number": "must be a finite number in [{lo}, {hi}]",
    "integer": "must be an integer in [{lo}, {hi}]",
    "greater_than_equal": "is outside [{lo}, {hi}]",
    "less_than_equal": "is outside [{lo}, {hi}]",
    "boolean": "must be true or false",
    "literal_error": "must be one of {choices}",
}


_SCHEMAS: dict[type, type[pydantic.BaseModel]] = {}


def param_schema(cls: type[KnobEffect]) -> type[pydantic.BaseModel]:
    """The declared schema of an effect's parameters: one pydantic field per dataclass field, its type
    from the annotation and its constraints from ``PARAM_BOUNDS`` / ``PARAM_LIMITS`` / ``CHOICES``
    (:meth:`KnobEffect.param_type`); its JSON Schema is ``param_schema(cls).model_json_schema()``.

    Example:
        >>> from weather_gym.weather import EFFECTS
        >>> param_schema(EFFECTS.get("vignette")).model_json_schema()["properties"]["exponent"]
        {'default': 2.0, 'maximum': 8.0, 'minimum': 0.5, 'title': 'Exponent', 'type': 'number'}
    """
    if cls in _SCHEMAS:
        return _SCHEMAS[cls]
    hints = typing.get_type_hints(cls)
    declared: dict[str, Any] = {
        f.name: (cls.param_type(f.name, hints[f.name]),
                 pydantic.Field(default=f.default) if f.default is not dataclasses.MISSING else ...)
        for f in dataclasses.fields(cls) if f.init}
    model: type[pydantic.BaseModel] = pydantic.create_model(
        f"{cls.__name__}Params", __config__=pydantic.ConfigDict(arbitrary_types_allowed=True, extra="forbid"),
        **declared)
    _SCHEMAS[cls] = model
    return model


@dataclasses.dataclass(frozen=True)
class KnobEffect(Effect):
    """An effect with one severity knob ``k`` in ``[0, 1]`` and named physical parameters.

    Class attributes a subclass declares:

    * ``name``: its registry key.
    * ``PARAM_BOUNDS``: ``{param: (lo, hi)}`` for the parameters worth fitting (k is always
      fitted in ``[0, 1]`` and is not listed).
    * ``PARAM_LIMITS``: ``{param: (lo, hi)}`` valid ranges of the other numeric parameters.
    * ``CHOICES``: ``{param: (allowed strings...)}``.
    * ``CONDITION``: the presets' condition it is (``rain@2``; default: its ``name``).
    * ``CHAIN_RANK``: its place when a chain is built effect by effect (the gap workflow): the scene and
      atmosphere first (fog 10, rain 20, glare 30), then the lens (droplets 40, blur 50), the car's motion
      (60), lens shading (70), exposure (dim 80, exposure 90), the sensor (noise 100) and encoding (jpeg
      110); default: last.
    * ``NOMINAL_K``: the k of severities 1-4 of its **nominal** presets rows, used where a presets file has
      no row for its condition (default ``(0.25, 0.5, 0.75, 1.0)``: severity / 4; ``None``: its rows are
      calibrated, no nominal ones), and ``NOMINAL_NOUN``, what their descriptions call it (default: the
      name, ``_`` as a space).

    and implements ``_render_into(img, draw, depth, state, out)`` (one frame written into ``out``)
    or ``_render_frame(img, draw, depth, state)`` (a new array), plus ``_sample_frame(rng, shape,
    episode)`` when it draws random values. ``k = 0`` is an exact copy without drawing anything
    (unless ``keeps_time``). The parameters are checked when the effect is built, against the schema
    these declarations and the field annotations make (:func:`param_schema`, pydantic; a bad one is an
    ``InputError`` naming the effect, the parameter, its value and its range or choices). Every
    constructor argument is a float, int, bool or str, so
    :meth:`params` is JSON/TOML serialisable and ``make(name, **effect.params())`` rebuilds an
    equal effect.
    """

    k: float = 0.0

    PARAM_BOUNDS: ClassVar[Mapping[str, tuple[float, float]]] = {}
    PARAM_LIMITS: ClassVar[Mapping[str, tuple[float, float]]] = {}
    CHOICES: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    CONDITION: ClassVar[str] = ""
    CHAIN_RANK: ClassVar[float] = math.inf
    NOMINAL_K: ClassVar[tuple[float, ...] | None] = (0.25, 0.5, 0.75, 1.0)
    NOMINAL_NOUN: ClassVar[str] = ""

    @classmethod
    def condition(cls) -> str:
        """The presets' condition of the effect (``CONDITION``, else its ``name``)."""
        return cls.CONDITION or cls.name

    def __post_init__(self) -> None:
        """Every parameter checked against the declared schema (:func:`param_schema`) and normalised
        (``1`` -> ``1.0`` for a float parameter, ``numpy.bool_`` -> ``bool``); an error names the effect,
        the parameter, its value and what was expected."""
        cls = type(self)
        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}
        try:
            checked = param_schema(cls).model_validate(given)
        except pydantic.ValidationError as exc:
            raise InputError(self._param_error(exc.errors()[0])) from None
        for key, value in given.items():
            new = getattr(checked, key)
            if new is not value:
                object.__setattr__(self, key, new)  # the dataclass idiom for a frozen field's own value

    @classmethod
    def param_type(cls, param: str, annotation: Any) -> Any:
        """The declared type of a parameter: a string of ``CHOICES``, a bool, a float or int in its
        declared range (:meth:`bounds_of`), else the annotation as it is (a subclass's own kind of
        parameter: it overrides this, or checks it itself)."""
        if param in cls.CHOICES:
            return Literal[tuple(cls.CHOICES[param])]
        if annotation is bool:
            return Annotated[bool, pydantic.BeforeValidator(_boolean)]
        if annotation in (float, int):
            lo, hi = cls.bounds_of(param)
            kind = _finite_float if annotation is float else _whole
            return Annotated[annotation, pydantic.Field(ge=lo, le=hi), pydantic.BeforeValidator(kind)]
        return Annotated[Any, annotation]

    @classmethod
    def _param_error(cls, error: Mapping[str, Any]) -> str:
        """The message of a failed parameter: ``<effect>: parameter <name>=<value> <what was expected>``."""
        who = cls.name or cls.__name__
        param = str(error["loc"][0]) if error.get("loc") else "?"
        raised = error.get("ctx", {}).get("error")
        if isinstance(raised, InputError):  # a parameter's own check (``param_type``) says it all
            return str(raised)
        phrase = _PARAM_PHRASES.get(error["type"])
        if phrase is None:
            return f"{who}: parameter {param}={error.get('input')!r}: {error['msg']}"
        lo, hi = cls.bounds_of(param) if "{lo}" in phrase else (None, None)
        return f"{who}: parameter {param}={error.get('input')!r} " + phrase.format(
            lo=lo, hi=hi, choices=", ".join(cls.CHOICES.get(param, ())))

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
        """A copy with some parameters changed whose own run continues this effect's episode."""
        new = dataclasses.replace(self, **changes)
        new._own_run.adopt(self._own_run)
        return new

    # -- sampling ----------------------------------------------------------------------------
    @property
    def keeps_time(self) -> bool:
        """True when :meth:`sample` must run at ``k = 0`` too (state that moves on every frame)."""
        return False

    def sample(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any = None) -> Any:
        """The draw of one frame, or a list of one draw per frame for a batch; ``None`` when idle."""
        if self.k == 0.0 and not self.keeps_time:
            return None
        if len(shape) == 4:
            return [self._sample_frame(rng, shape[1:], episode) for _ in range(shape[0])]
        return self._sample_frame(rng, shape, episode)

    def _sample_frame(self, rng: np.random.Generator, shape: tuple[int, ...], episode: Any) -> Any:
        """Random values of one ``H x W x 3`` frame (default: none)."""
        if hasattr(self, "_apply_into"):  # an effect written against the fused hook (gap/measured.py)
            return _Fused(rng)
        return None

    # -- rendering ---------------------------------------------------------------------------
    def _render(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: Any,
                batched: bool) -> np.ndarray:
        if self.k == 0.0:
            return img.copy()
        if batched:
            return self._render_batch(img, draw, depth, state)
        return self._render_frame(img, draw, depth, state)

    def _render_batch(self, imgs: np.ndarray, draws: list[Any] | None, depth: np.ndarray | None,
                      states: list[dict[str, float]]) -> np.ndarray:
        out = np.empty_like(imgs)
        for i in range(imgs.shape[0]):
            self._render_into(imgs[i], None if draws is None else draws[i], None if depth is None else depth[i],
                              states[i], out[i])
        return out

    def _render_frame(self, img: np.ndarray, draw: Any, depth: np.ndarray | None,
                      state: dict[str, float]) -> np.ndarray:
        """The degraded frame (``k > 0``), a new array. Subclasses override this or :meth:`_render_into`."""
        if type(self)._render_into is KnobEffect._render_into and not isinstance(draw, _Fused):
            raise NotImplementedError(f"{type(self).__name__} implements neither _render_frame nor _render_into")
        out = np.empty_like(img)
        self._render_into(img, draw, depth, state, out)
        return out

    def _render_into(self, img: np.ndarray, draw: Any, depth: np.ndarray | None, state: dict[str, float],
                     out: np.ndarray) -> None:
        """:meth:`_render_frame` written into ``out``; batches call this frame by frame, with no extra copy."""
        if isinstance(draw, _Fused):
            self._apply_into(img, depth, state, draw.rng, out)  # type: ignore[attr-defined]  # the fused hook, when defined
        else:
            np.copyto(out, self._render_frame(img, draw, depth, state))

    def _reset_state(self) -> None:
        """No per-effect state: kept for subclasses written against the fused hook (gap/measured.py)."""

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"


@dataclasses.dataclass(frozen=True)
class _Fused:
    """The draw of an effect that draws while it renders (``_apply_into(img, depth, state, rng, out)``)."""

    rng: np.random.Generator
