"""Hyper-parameters of a PPO run: one declared schema (:class:`Hyperparams`) for the file in rl-zoo3's
YAML format (:func:`load_hyperparams`) and the options given on the command line
(:func:`resolve_hyperparams`).

Every key a file may hold is a field of :class:`Hyperparams`; its :class:`Bound` (the field's
metadata) declares its type, its range and the option that sets it, and is both the check and the
error message. A key that is no field is refused (``seed``, ``verbose`` and ``device`` too: they are
``--seed``, the progress bar and the CPU, :data:`NOT_IN_FILE`); ``policy`` is one of :data:`POLICIES`
(nothing named in a file is imported).

Example:
    >>> from weather_gym.lab.training.policy import HYPERPARAMS
    >>> hp = load_hyperparams(HYPERPARAMS, "WeatherGym/ConeTrackCones-v0")
    >>> hp["n_envs"], hp["ppo"]["n_steps"]
    (16, 256)
    >>> Hyperparams(gamma=5)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.LimitError: gamma must be a number in (0, 1], got 5
    >>> Bound(int, 1, 64).expected()
    'an integer in [1, 64]'
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from weather_gym.core.errors import (
    FileFormatError,
    InputError,
    LimitError,
    MissingDependencyError,
    MissingInputError,
    check_known,
)
from weather_gym.pipeline import MAX_SYNC_ENVS

__all__ = ["Bound", "Hyperparams", "LinearSchedule", "MAX_FILE_BYTES", "MAX_N_ENVS", "MAX_ROLLOUT", "MAX_TIMESTEPS",
           "NOT_IN_FILE", "POLICIES", "load_hyperparams", "ppo_arguments", "resolve_hyperparams"]

MAX_N_ENVS = MAX_SYNC_ENVS
"""Most training envs of one run, as :func:`weather_gym.pipeline.make_vec_env` builds in one process (each is
a PyBullet world in memory); ``--vec subproc`` (a process each) allows at most 4 per CPU core, as its
``"async"`` mode."""
MAX_TIMESTEPS = 10**9
"""Most environment steps of one run (``n_timesteps``, ``--timesteps``)."""
MAX_ROLLOUT = 2**20
"""Most steps of one rollout, ``n_steps * n_envs`` (PPO keeps them all in memory)."""
MAX_FILE_BYTES = 1_000_000
"""Largest hyper-parameter file read (rl-zoo3's ppo.yml, every env id it tunes, is 16 kB)."""
POLICIES = ("weather_gym.agents.sb3_features.ConeListPolicy", "MultiInputPolicy")
"""The policies a file may name: the cone list's (an rl-zoo3 import path, resolved from this list, never
imported by name) and SB3's own for Dict observations."""
NOT_IN_FILE = {"seed": "give --seed (run.json and model.json record it)",
               "verbose": "training shows a progress bar and logs to logs/ (no SB3 verbosity)",
               "device": "training runs on the CPU (the envs, not the network, take the time)",
               "tensorboard_log": "TensorBoard files are written to logs/ of --out"}
"""PPO keywords a file may not set, and what to do instead."""


# ------------------------------------------------------------------ the declared bounds
@dataclass(frozen=True)
class Bound:
    """The declared type and range of one setting: its check and its error message.

    ``kind`` int, float, bool or str; ``lo``/``hi`` the range (``None``: unbounded), open at an end with
    ``lo_open``/``hi_open``; ``choices`` for a str; ``null`` allows None; ``schedule`` allows rl-zoo3's
    ``"lin_<v>"`` (a linear schedule from ``v`` to 0, ``v`` in the range); ``option`` the command-line option
    that sets it; ``why`` a reason the message gives.

    Example:
        >>> Bound(float, 0, 1, lo_open=True, schedule=True).check("lin_3e-4", "learning_rate")
        'lin_3e-4'
        >>> Bound(int, 1).check("many", "n_steps")
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.InputError: n_steps must be an integer >= 1, got 'many'
    """

    kind: type
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    null: bool = False
    schedule: bool = False
    option: str | None = None
    why: str = ""

    def expected(self) -> str:
        """What a value must be, in words (the end of every error message)."""
        if self.kind is bool:
            text = "true or false"
        elif self.kind is dict:
            text = "a dict of keywords"
        elif self.choices:
            text = f"one of {list(self.choices)}"
        else:
            noun = "an integer" if self.kind is int else "a number"
            if self.lo is not None and self.hi is not None:
                text = f"{noun} in {'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}{')' if self.hi_open else ']'}"
            elif self.lo is not None:
                text = f"{noun} {'>' if self.lo_open else '>='} {_num(self.lo)}"
            elif self.hi is not None:
                text = f"{noun} {'<' if self.hi_open else '<='} {_num(self.hi)}"
            else:
                text = f"a finite {noun[2:].lstrip()}" if self.kind is float else noun
        if self.schedule:
            text += " or 'lin_<that>' (a linear schedule to 0)"
        return text + (" or null" if self.null else "") + (f" ({self.why})" if self.why else "")

    def check(self, value: Any, name: str) -> Any:
        """``value`` checked (a whole float as an int for int settings), else :class:`InputError` (wrong
        type) or :class:`LimitError` (out of range) saying ``NAME must be EXPECTED, got VALUE``."""
        if value is None and self.null:
            return None
        if self.schedule and isinstance(value, str) and value.startswith("lin_"):
            try:
                start = float(value[4:])
            except ValueError:
                raise InputError(f"{name} must be {self.expected()}, got {value!r}") from None
            self._range(start, name, value)
            return value
        if self.kind is bool:
            if not isinstance(value, bool):
                raise InputError(f"{name} must be {self.expected()}, got {value!r}")
            return value
        if self.kind is str:
            if not isinstance(value, str) or (self.choices and value not in self.choices):
                raise InputError(f"{name} must be {self.expected()}, got {value!r}")
            return value
        if isinstance(value, float) and self.kind is int and value.is_integer():
            value = int(value)  # YAML's !!float 3e5
        if isinstance(value, bool) or not isinstance(value, int if self.kind is int else (int, float)):
            raise InputError(f"{name} must be {self.expected()}, got {value!r}")
        self._range(value, name, value)
        return float(value) if self.kind is float else value

    def _range(self, v: float, name: str, shown: Any) -> None:
        ok = math.isfinite(v)
        if self.lo is not None:
            ok = ok and (v > self.lo if self.lo_open else v >= self.lo)
        if self.hi is not None:
            ok = ok and (v < self.hi if self.hi_open else v <= self.hi)
        if not ok:
            raise LimitError(f"{name} must be {self.expected()}, got {shown!r}")


def _num(x: float) -> str:
    """A bound as written: whole numbers in full (1048576, not 1.04858e+06)."""
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def _key(bound: Bound, default: Any = None, *, ppo: bool = True) -> Any:
    """A declared key: its bound, its default, and whether it is a PPO keyword (else the run's: n_envs, ...)."""
    return field(default=default, metadata={"bound": bound, "ppo": ppo})


UNIT: dict[str, Any] = {"lo": 0, "hi": 1}
POLICY_KWARGS = {"log_std_init": Bound(float, -10, 2, option="--log-std-init"), "ortho_init": Bound(bool),
                 "share_features_extractor": Bound(bool), "full_std": Bound(bool), "use_expln": Bound(bool),
                 "squash_output": Bound(bool)}
"""``policy_kwargs`` a file may give (with ``net_arch``: a list of layer widths or ``dict(pi=[...], vf=[...])``)."""
MAX_LAYER = 4096
NORMALIZE = {"norm_obs": Bound(bool), "norm_reward": Bound(bool), "clip_obs": Bound(float, 0, lo_open=True),
             "clip_reward": Bound(float, 0, lo_open=True), "epsilon": Bound(float, 0, 1, lo_open=True),
             "gamma": Bound(float, 0, 1, lo_open=True)}
"""``normalize`` keywords (``VecNormalize``'s) a file may give."""


@dataclass(frozen=True)
class Hyperparams:
    """Every key of a hyper-parameter section, declared: ``None`` for a PPO keyword means "not given"
    (PPO's default, :data:`PPO_DEFAULTS`, applies). Built checked; ``source`` names where each value came
    from (a file's section or an option) for the error messages.

    Example:
        >>> Hyperparams(n_steps=64, batch_size=64, n_envs=2).as_dict()["ppo"]
        {'n_steps': 64, 'batch_size': 64}
        >>> Hyperparams(n_steps=64, batch_size=48, n_envs=1)
        Traceback (most recent call last):
        ...
        weather_gym.core.errors.LimitError: batch_size (48) must divide the rollout n_steps * n_envs = 64 * 1 = 64 \
(PPO's mini-batches; SB3 warns of a truncated one otherwise), e.g. 2, 4, 8, 16, 32, 64
    """

    n_envs: int = _key(Bound(int, 1, MAX_N_ENVS, option="--n-envs"), 1, ppo=False)
    n_timesteps: int | None = _key(Bound(int, 1, MAX_TIMESTEPS, null=True, option="--timesteps"), ppo=False)
    policy: str = _key(Bound(str, choices=POLICIES), "MultiInputPolicy", ppo=False)
    normalize: Any = _key(Bound(dict), False, ppo=False)  # true/false or VecNormalize keywords (NORMALIZE)
    policy_kwargs: Any = _key(Bound(dict), None, ppo=False)  # POLICY_KWARGS and net_arch
    # PPO's keywords
    learning_rate: float | str | None = _key(Bound(float, 0, 1, lo_open=True, schedule=True, option="--learning-rate"))
    n_steps: int | None = _key(Bound(int, 1, MAX_ROLLOUT, option="--n-steps"))
    batch_size: int | None = _key(Bound(int, 2, MAX_ROLLOUT, option="--batch-size",
                                        why="PPO normalises the advantage over each mini-batch"))
    n_epochs: int | None = _key(Bound(int, 1, 1000, option="--n-epochs"))
    gamma: float | None = _key(Bound(float, 0, 1, lo_open=True, option="--gamma"))
    gae_lambda: float | None = _key(Bound(float, **UNIT))
    clip_range: float | str | None = _key(Bound(float, 0, 1, lo_open=True, schedule=True))
    clip_range_vf: float | str | None = _key(Bound(float, 0, lo_open=True, schedule=True, null=True))
    normalize_advantage: bool | None = _key(Bound(bool))
    ent_coef: float | None = _key(Bound(float, **UNIT, option="--ent-coef"))
    vf_coef: float | None = _key(Bound(float, **UNIT))
    max_grad_norm: float | None = _key(Bound(float, 0, 100, lo_open=True))
    use_sde: bool | None = _key(Bound(bool))
    sde_sample_freq: int | None = _key(Bound(int, -1, MAX_ROLLOUT))
    target_kl: float | None = _key(Bound(float, 0, 1, lo_open=True, null=True))
    stats_window_size: int | None = _key(Bound(int, 1, 100_000))
    source: dict[str, str] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if "bound" not in f.metadata or f.name in ("normalize", "policy_kwargs"):
                continue
            v = getattr(self, f.name)
            if v is None and f.default is None:
                continue  # not given: PPO's default
            object.__setattr__(self, f.name, f.metadata["bound"].check(v, self._name(f.name)))
        object.__setattr__(self, "normalize", self._normalize(self.normalize))
        object.__setattr__(self, "policy_kwargs", self._policy_kwargs(self.policy_kwargs))
        self._check_rollout()

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The keys a file's section may hold."""
        return tuple(f.name for f in dataclasses.fields(cls) if "bound" in f.metadata)

    @classmethod
    def ppo_keys(cls) -> tuple[str, ...]:
        """The keys that are PPO's keywords."""
        return tuple(f.name for f in dataclasses.fields(cls) if f.metadata.get("ppo"))

    def _name(self, key: str) -> str:
        return self.source.get(key, key)

    def get(self, key: str) -> Any:
        """The value PPO gets for ``key``: given, or PPO's default."""
        v = getattr(self, key)
        return PPO_DEFAULTS[key] if v is None and key in PPO_DEFAULTS else v

    def _check_rollout(self) -> None:
        n_steps, batch, n_envs = self.get("n_steps"), self.get("batch_size"), self.n_envs
        rollout = n_steps * n_envs
        where = self._name("n_steps") if self.n_steps is not None else "n_steps (PPO's default)"
        if rollout < 2:
            raise LimitError(f"{where}: the rollout n_steps * n_envs = {n_steps} * {n_envs} must be at least 2 "
                             "(PPO normalises the advantage over it)")
        if rollout > MAX_ROLLOUT:
            raise LimitError(f"{where}: the rollout n_steps * n_envs = {n_steps} * {n_envs} = {rollout} must be at "
                             f"most {MAX_ROLLOUT} steps (PPO keeps it in memory)")
        if rollout % batch:
            fits = [d for d in range(2, rollout + 1) if rollout % d == 0]
            near = sorted(fits, key=lambda d: abs(d - batch))[:6]
            raise LimitError(f"{self._name('batch_size')} ({batch}) must divide the rollout n_steps * n_envs = "
                             f"{n_steps} * {n_envs} = {rollout} (PPO's mini-batches; SB3 warns of a truncated one "
                             f"otherwise), e.g. {', '.join(map(str, sorted(near)))}")

    def _normalize(self, value: Any) -> bool | dict[str, Any]:
        name = self._name("normalize")
        value = _literal(value, name)
        if value is True:
            return {}
        if value is False or value is None:
            return False
        if not isinstance(value, dict):
            raise InputError(f"{name} must be true, false or a dict of VecNormalize keywords "
                             f"{sorted(NORMALIZE)}, got {value!r}")
        check_known(value, NORMALIZE, what=name, kind="keyword")
        return {k: NORMALIZE[k].check(v, f"{name} {k}") for k, v in value.items()}

    def _policy_kwargs(self, value: Any) -> dict[str, Any]:
        name = self._name("policy_kwargs")
        value = _literal(value, name)
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise InputError(f"{name} must be a dict, got {value!r}")
        check_known(value, [*POLICY_KWARGS, "net_arch"], what=name, kind="keyword")
        out = {k: POLICY_KWARGS[k].check(v, self.source.get(f"policy_kwargs.{k}", f"{name} {k}"))
               for k, v in value.items() if k != "net_arch"}
        if "net_arch" in value:
            out = {"net_arch": _net_arch(value["net_arch"], f"{name} net_arch"), **out}
        return {k: out[k] for k in value}  # in the file's order

    def as_dict(self) -> dict[str, Any]:
        """``{"n_envs", "n_timesteps", "policy", "normalize", "policy_kwargs", "ppo": {the PPO keywords given}}``."""
        return {"n_envs": self.n_envs, "n_timesteps": self.n_timesteps, "policy": self.policy,
                "normalize": self.normalize, "policy_kwargs": dict(self.policy_kwargs),
                "ppo": {k: getattr(self, k) for k in self.ppo_keys() if getattr(self, k) is not None}}


PPO_DEFAULTS = {"learning_rate": 3e-4, "n_steps": 2048, "batch_size": 64, "n_epochs": 10, "gamma": 0.99,
                "gae_lambda": 0.95, "clip_range": 0.2, "clip_range_vf": None, "normalize_advantage": True,
                "ent_coef": 0.0, "vf_coef": 0.5, "max_grad_norm": 0.5, "use_sde": False, "sde_sample_freq": -1,
                "target_kl": None, "stats_window_size": 100}
"""PPO's own defaults (stable-baselines3 2.x; a test compares them with ``PPO.__init__``)."""


def _net_arch(value: Any, name: str) -> Any:
    def widths(v: Any) -> list[int]:
        if not isinstance(v, list | tuple) or not v or not all(
                isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_LAYER for w in v):
            raise LimitError(f"{name} must be a list of layer widths in [1, {MAX_LAYER}] or dict(pi=[...], "
                             f"vf=[...]), got {value!r}")
        return list(v)

    if isinstance(value, dict):
        check_known(value, ("pi", "vf"), what=name, kind="keyword")
        return {k: widths(v) for k, v in value.items()}
    return widths(value)


# ------------------------------------------------------------------ rl-zoo3's schedules
@dataclass(frozen=True)
class LinearSchedule:
    """rl-zoo3's ``lin_<v>``: ``v`` at the start, falling linearly to 0 at the end (SB3 calls it with the
    progress remaining, 1 -> 0).

    Example:
        >>> LinearSchedule(3e-4)(0.5)
        0.00015
    """

    start: float

    def __call__(self, progress_remaining: float) -> float:
        return progress_remaining * self.start


def ppo_arguments(hp: dict[str, Any]) -> dict[str, Any]:
    """The PPO keywords of ``hp`` (:meth:`Hyperparams.as_dict`) as PPO takes them (``lin_<v>``: a
    :class:`LinearSchedule`)."""
    return {k: LinearSchedule(float(v[4:])) if isinstance(v, str) and v.startswith("lin_") else v
            for k, v in hp["ppo"].items()}


# ------------------------------------------------------------------ reading
def _literal(text: Any, where: str) -> Any:
    """A value of rl-zoo3's string-encoded keys: Python literals and ``dict(...)`` calls of them."""
    if not isinstance(text, str):
        return text

    def ev(node: ast.AST) -> Any:
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args:
            return {kw.arg: ev(kw.value) for kw in node.keywords}
        if isinstance(node, ast.Dict):
            return {ev(k): ev(v) for k, v in zip(node.keys, node.values)}  # type: ignore[arg-type]  # a None key (**spread) fails in ev
        if isinstance(node, ast.List | ast.Tuple):
            vals = [ev(e) for e in node.elts]
            return vals if isinstance(node, ast.List) else tuple(vals)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -ev(node.operand)
        if isinstance(node, ast.Constant):
            return node.value
        raise InputError(f"{where}: only literals and dict(...) are read here, got {ast.unparse(node)!r}")

    try:
        return ev(ast.parse(text, mode="eval").body)
    except InputError:
        raise
    except (SyntaxError, ValueError, TypeError, RecursionError, MemoryError):
        raise InputError(f"{where}: not a Python literal: {text!r}") from None


def load_hyperparams(path: str | Path, key: str) -> dict[str, Any]:
    """Section ``key`` of an rl-zoo3 hyper-parameter YAML file, checked (:class:`Hyperparams`), as
    :meth:`Hyperparams.as_dict`."""
    return _read(Path(path), key).as_dict()


def _read(path: Path, key: str, overrides: dict[str, Any] | None = None,
          options: dict[str, str] | None = None) -> Hyperparams:
    try:
        import yaml
    except ImportError:
        raise MissingDependencyError("reading a hyper-parameter file needs PyYAML (pip install pyyaml)") from None
    if not path.is_file():
        raise MissingInputError(f"hyper-parameter file {path} not found")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise FileFormatError(f"{path}: {path.stat().st_size} bytes; a hyper-parameter file has at most "
                              f"{MAX_FILE_BYTES} (a few keys per env id)")
    try:
        data = yaml.safe_load(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not UTF-8 text (byte {exc.start}); a hyper-parameter file is YAML "
                              "in UTF-8") from None
    except yaml.YAMLError as exc:
        raise FileFormatError(f"{path}: not YAML ({exc})") from None
    except RecursionError:
        raise FileFormatError(f"{path}: nested too deeply to be a hyper-parameter file") from None
    if not isinstance(data, dict) or key not in data or not isinstance(data[key], dict):
        keys = sorted(map(str, data)) if isinstance(data, dict) else []
        raise FileFormatError(f"{path}: no section {key!r} (sections: {keys})")
    sec = dict(data[key])
    where = f"{path} [{key}]"
    bad = sorted(str(k) for k in sec if k in NOT_IN_FILE)
    if bad:
        raise FileFormatError(f"{where}: {bad[0]!r} is not read from a hyper-parameter file: {NOT_IN_FILE[bad[0]]}")
    check_known(map(str, sec), Hyperparams.keys(), what=where, error=FileFormatError)
    source = {k: f"{where} {k}" for k in sec}
    for k, opt in (options or {}).items():
        source[k] = opt
    values = {**sec, **(overrides or {})}
    log_std = values.pop("_log_std_init", None)
    if log_std is not None:  # --log-std-init: one key of policy_kwargs
        kwargs = _literal(values.get("policy_kwargs"), source.get("policy_kwargs", "policy_kwargs")) or {}
        if not isinstance(kwargs, dict):
            raise FileFormatError(f"{where} policy_kwargs must be a dict, got {kwargs!r}")
        values["policy_kwargs"] = {**kwargs, "log_std_init": log_std}
        source["policy_kwargs.log_std_init"] = "--log-std-init"
    return Hyperparams(**values, source=source)


OPTIONS = {"n_envs": "--n-envs", "timesteps": "--timesteps", "n_steps": "--n-steps", "batch_size": "--batch-size",
           "n_epochs": "--n-epochs", "learning_rate": "--learning-rate", "gamma": "--gamma", "ent_coef": "--ent-coef"}
"""``weather-gym train``'s options that set a hyper-parameter (argparse name -> option)."""


def resolve_hyperparams(args: argparse.Namespace) -> dict[str, Any]:
    """The run's hyper-parameters: the file's section, with the options given on the command line,
    checked together (an option's error names the option)."""
    overrides: dict[str, Any] = {}
    options: dict[str, str] = {}
    for attr, opt in OPTIONS.items():
        v = getattr(args, attr, None)
        if v is not None:
            key = "n_timesteps" if attr == "timesteps" else attr
            overrides[key], options[key] = v, opt
    if getattr(args, "log_std_init", None) is not None:
        overrides["_log_std_init"] = args.log_std_init
    if overrides.get("n_timesteps") == 0 and getattr(args, "pretrain", None) is not None:
        overrides.pop("n_timesteps")  # --timesteps 0 --pretrain: only the cloned policy (checked by the caller)
        hp = _read(Path(args.hyperparams), args.hyperparams_key, overrides, options).as_dict()
        hp["n_timesteps"] = 0
        return hp
    hp = _read(Path(args.hyperparams), args.hyperparams_key, overrides, options).as_dict()
    if hp["n_timesteps"] is None:
        raise InputError(f"{args.hyperparams} [{args.hyperparams_key}] has no n_timesteps; give --timesteps")
    return hp
