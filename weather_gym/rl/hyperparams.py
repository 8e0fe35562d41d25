"""Hyper-parameters of a PPO run from a file in rl-zoo3's YAML format (:func:`load_hyperparams`), with
the options given on the command line (:func:`resolve_hyperparams`).

Example:
    >>> from weather_gym.rl import HYPERPARAMS
    >>> hp = load_hyperparams(HYPERPARAMS, "WeatherGym/ConeTrackCones-v0")
    >>> hp["n_envs"], hp["ppo"]["n_steps"]
    (8, 256)
"""

from __future__ import annotations

import argparse
import ast
import inspect
from pathlib import Path
from typing import Any

from weather_gym.errors import FileFormatError, InputError, MissingDependencyError, check_known

_RUN_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "policy_kwargs")
"""Keys of a hyper-parameter section that are not PPO keywords."""
_CLI_PPO = {"n_steps": "n_steps", "batch_size": "batch_size", "n_epochs": "n_epochs",
            "learning_rate": "learning_rate", "gamma": "gamma", "ent_coef": "ent_coef"}




# ------------------------------------------------------------------ hyper-parameters
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
    except SyntaxError:
        raise InputError(f"{where}: not a Python expression: {text!r}") from None


def load_hyperparams(path: str | Path, key: str) -> dict[str, Any]:
    """Section ``key`` of an rl-zoo3 hyper-parameter YAML file, checked: ``{"n_envs", "n_timesteps",
    "policy", "normalize" (VecNormalize keywords), "policy_kwargs", "ppo" (PPO keywords)}``."""
    try:
        import yaml
    except ImportError:
        raise MissingDependencyError("reading a hyper-parameter file needs PyYAML (pip install pyyaml)") from None
    path = Path(path)
    if not path.is_file():
        raise InputError(f"hyper-parameter file {path} not found")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise FileFormatError(f"{path}: not YAML ({exc})") from None
    if not isinstance(data, dict) or key not in data or not isinstance(data[key], dict):
        keys = sorted(data) if isinstance(data, dict) else []
        raise FileFormatError(f"{path}: no section {key!r} (sections: {keys})")
    from stable_baselines3 import PPO

    sec = dict(data[key])
    where = f"{path} [{key}]"
    valid_ppo = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env", "_init_setup_model"}
    check_known(sec, set(_RUN_KEYS) | valid_ppo, what=where, error=FileFormatError)
    normalize = _literal(sec.pop("normalize", False), f"{where} normalize")
    if normalize is True:
        normalize = {}
    if normalize is not False and not isinstance(normalize, dict):
        raise FileFormatError(f"{where}: normalize must be true/false or a dict of VecNormalize keywords")
    policy_kwargs = _literal(sec.pop("policy_kwargs", {}), f"{where} policy_kwargs")
    if not isinstance(policy_kwargs, dict):
        raise FileFormatError(f"{where}: policy_kwargs must be a dict")
    out = {"n_envs": sec.pop("n_envs", 1), "n_timesteps": sec.pop("n_timesteps", None),
           "policy": sec.pop("policy", "MultiInputPolicy"), "normalize": normalize, "policy_kwargs": policy_kwargs}
    for name in ("n_envs", "n_timesteps"):
        v = out[name]
        if isinstance(v, float) and v.is_integer():
            v = out[name] = int(v)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise FileFormatError(f"{where}: {name} must be an integer >= 1, got {v!r}")
    out["ppo"] = sec
    return out


def resolve_hyperparams(args: argparse.Namespace) -> dict[str, Any]:
    """The run's hyper-parameters: the file's section, with the options given on the command line."""
    hp = load_hyperparams(args.hyperparams, args.hyperparams_key)
    if args.n_envs is not None:
        hp["n_envs"] = args.n_envs
    if args.timesteps is not None:
        hp["n_timesteps"] = args.timesteps
    if hp["n_timesteps"] is None:
        raise InputError(f"{args.hyperparams} [{args.hyperparams_key}] has no n_timesteps; give --timesteps")
    for opt, key in _CLI_PPO.items():
        if getattr(args, opt) is not None:
            hp["ppo"][key] = getattr(args, opt)
    if args.log_std_init is not None:
        hp["policy_kwargs"]["log_std_init"] = args.log_std_init
    return hp
