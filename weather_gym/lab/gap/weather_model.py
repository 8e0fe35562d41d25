"""Weather model files (TOML) and applying a model to clean frames.

A model file lists the ordered weather effects and their parameters::

    [[effects]]
    name = "dim"
    k = 0.6

    [[effects]]
    name = "noise"
    k = 0.25
    read_noise_e = 4.0

An empty file (or ``effects = []``) is the clean simulator. Names are the weather registry's
(``weather_gym.weather.EFFECTS``); parameters are those of :func:`weather_gym.weather.make`; or a
measured member of a family (``tone_curve``, ``noise_level``, ``radial_gain``, ``blur_kernel``:
:mod:`weather_gym.lab.gap.measured`), whose curves are arrays of numbers.
The workflow writes the same format back (parameters that differ from the effect's defaults, plus
``k``), so ``parse_weather(tomllib.load(f)["effects"])`` rebuilds the model exactly.

Each effect in a chain draws from its own generator, seeded by ``(seed, frame id, effect name,
occurrence)``: the same frame gets the same random numbers from an effect whatever else is in the
model (common random numbers make candidate models comparable).

Example:
    >>> import tempfile, os
    >>> from weather_gym.lab.gap.weather_model import read_model, write_model
    >>> path = os.path.join(tempfile.mkdtemp(), "m.toml")
    >>> write_model(path, [__import__("weather_gym.weather", fromlist=["make"]).make("dim", k=0.6)])
    >>> [(e.name, e.k) for e in read_model(path)]
    [('dim', 0.6)]
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core._io import atomic_write
from weather_gym.core._toml import toml_document
from weather_gym.core.errors import FileFormatError, MissingInputError, check_known
from weather_gym.lab.gap.measured import MEASURED, PARTNERS, make_measured
from weather_gym.weather import EFFECTS, KnobEffect, make

__all__ = ["chain_order", "read_model", "write_model", "model_tables", "insert_position",
           "apply_chain", "describe"]


def chain_order() -> tuple[str, ...]:
    """Where an added effect goes in the chain: every registered effect by its declared ``CHAIN_RANK``
    (the scene and atmosphere first, then the lens, the car's motion, exposure, the sensor, and
    encoding last; an effect that declares none after them), ties by name.

    Example:
        >>> chain_order()[:3], chain_order()[-1]
        (('fog', 'rain', 'glare'), 'jpeg')
    """
    return tuple(sorted(EFFECTS, key=lambda n: (EFFECTS.get(n).CHAIN_RANK, n)))


def __getattr__(name: str) -> Any:
    """``CHAIN_ORDER``: :func:`chain_order`, read from the registry when asked."""
    if name == "CHAIN_ORDER":
        return chain_order()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def read_model(path: str | os.PathLike) -> list[KnobEffect]:
    """Read a model file: a list of effects (empty for the clean simulator). Errors name the file and key."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"model file {path} not found")
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:  # a TOML file is UTF-8 text
        raise FileFormatError(f"model file {path} is not valid TOML: {exc}") from None
    check_known(data, ("effects",), what=f"model file {path}", kind="top-level key", error=FileFormatError,
                hint=" (an array of [[effects]] tables)")
    tables = data.get("effects", [])
    if not isinstance(tables, list) or not all(isinstance(t, Mapping) for t in tables):
        raise FileFormatError(f"model file {path}: 'effects' must be an array of tables ([[effects]] with name and k)")
    effects: list[KnobEffect] = []
    seen: set[str] = set()
    for i, t in enumerate(tables):
        name = t.get("name")
        if not isinstance(name, str) or (name not in EFFECTS and name not in MEASURED):
            raise FileFormatError(f"model file {path}: effects[{i}] has name {name!r}; expected one of "
                             f"{', '.join(EFFECTS.names() + MEASURED.names())}")
        if "k" not in t:
            raise FileFormatError(f"model file {path}: effects[{i}] ({name}) needs 'k' (severity in [0, 1])")
        if name in seen:
            raise FileFormatError(f"model file {path}: effect {name!r} appears twice; list each effect once")
        seen.add(name)
        try:
            params = {k: v for k, v in t.items() if k != "name"}
            effects.append(make_measured(name, **params) if name in MEASURED else make(name, **params))
        except (ValueError, TypeError) as exc:
            raise FileFormatError(f"model file {path}: effects[{i}]: {exc}") from None
    return effects


def model_tables(effects: Sequence[KnobEffect]) -> list[dict[str, Any]]:
    """``[{"name", "k", <non-default parameters>}]`` of a model (what :func:`write_model` writes)."""
    out = []
    for e in effects:
        defaults = {f.name: f.default for f in dataclasses.fields(e)}
        table: dict[str, Any] = {"name": e.name, "k": e.k}
        for key, value in e.params().items():
            if key != "k" and value != defaults.get(key):
                table[key] = value
        out.append(table)
    return out


def write_model(path: str | os.PathLike, effects: Sequence[KnobEffect],
                comments: Mapping[int, str] | None = None, header: str | None = None, *,
                overwrite: bool = False) -> None:
    """Write ``effects`` as a model file; ``comments[i]`` is written above effect ``i`` (an existing
    file only with ``overwrite``)."""
    lines = [f"# {line}" for line in (header or "").splitlines()]
    if not effects:
        lines.append("effects = []  # the clean simulator")
    for i, table in enumerate(model_tables(effects)):
        if lines:
            lines.append("")
        if comments and i in comments:
            lines += [f"# {c}" for c in comments[i].splitlines()]
        lines.append("[[effects]]")  # one table per effect, so that its comment stands above it
        lines.append(toml_document(table, finite=True).rstrip("\n"))  # flat: every effect parameter is a scalar
    atomic_write(path, "\n".join(lines) + "\n", overwrite=overwrite)


def insert_position(effects: Sequence[KnobEffect], name: str) -> int:
    """Index at which effect ``name`` joins the chain (after every effect that comes before it in
    :func:`chain_order`)."""
    rank = _rank(name)
    pos = 0
    for i, e in enumerate(effects):
        if _rank(e.name) <= rank:
            pos = i + 1
    return pos


def _rank(name: str) -> float:
    """Place of an effect in :func:`chain_order`; a measured member goes right after its kind's effects."""
    if name in PARTNERS:
        return max(_rank(p) for p in PARTNERS[name]) + 0.5
    order = chain_order()
    return float(order.index(name)) if name in order else float(len(order))


def _effect_seed(seed: int, frame_id: int, name: str) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(seed), int(frame_id), zlib.crc32(name.encode())])


def apply_chain(effects: Sequence[KnobEffect], image: np.ndarray, *, depth: np.ndarray | None,
                state: Mapping[str, float] | None, seed: int, frame_id: int) -> np.ndarray:
    """Apply ``effects`` in order to one frame, each with its own seeded generator (see module doc)."""
    out = image
    for e in effects:
        ss = _effect_seed(seed, frame_id, e.name)
        e.reset(ss)
        out = e(out, depth=depth, state=state, rng=np.random.default_rng(ss))
    return out if out is not image else image.copy()


def describe(effect: KnobEffect) -> str:
    """``name(k=..., param=...)`` with the parameters that differ from the defaults (a measured member:
    the shape it measured)."""
    if hasattr(effect, "summary"):
        return effect.summary()
    t = model_tables([effect])[0]
    args = ", ".join(f"{k}={_fmt(v)}" for k, v in t.items() if k != "name")
    return f"{effect.name}({args})"


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
