"""Reading a TOML file with typed errors (``tomllib``), and writing one (``tomli-w``).

Example:
    >>> from weather_gym.core._toml import toml_document
    >>> print(toml_document({"k": 0.123456789, "bad": float("nan"), "effects": [{"name": "dim", "k": 0.6}]},
    ...                     digits=4), end="")
    k = 0.1235
    bad = nan
    effects = [
        { name = "dim", k = 0.6 },
    ]
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w

from weather_gym.core.errors import FileFormatError, InputError, MissingInputError

__all__ = ["read_toml", "toml_document"]


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """The TOML file ``path`` as a dict; :class:`MissingInputError` ("``what`` PATH does not exist")
    or :class:`FileFormatError` ("PATH: malformed TOML: ...")."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MissingInputError(f"{what} {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: malformed TOML: {exc}") from None


def _prepared(v: Any, digits: int | None, finite: bool, none: Any) -> Any:
    """``v`` with floats rounded, ``None`` replaced and non-finite numbers checked (tomli-w writes the rest)."""
    if v is None:
        if none is None:
            raise InputError("cannot write None as a TOML value (TOML has no null)")
        return none
    if isinstance(v, float):
        if not math.isfinite(v):
            if finite:
                raise InputError(f"cannot write the non-finite number {v!r} here")
            return v
        return round(v, digits) if digits is not None and (abs(v) >= 1e-4 or v == 0) else v
    if isinstance(v, Mapping):
        return {str(k): _prepared(x, digits, finite, none) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_prepared(x, digits, finite, none) for x in v]
    return v


def toml_document(data: Mapping[str, Any], *, digits: int | None = None, finite: bool = False,
                  none: Any = None) -> str:
    """``data`` as a TOML document (written by tomli-w; lists of tables become ``[[name]]`` blocks).

    ``digits``: round floats to that many decimals (values below ``1e-4`` keep their precision);
    ``finite``: refuse NaN and infinities (:class:`InputError`) instead of writing TOML's ``nan``/``inf``;
    ``none``: the value written for ``None`` (TOML has no null; by default ``None`` is an error).
    """
    try:
        return tomli_w.dumps(_prepared(dict(data), digits, finite, none))
    except TypeError as exc:
        raise InputError(f"cannot write this value as TOML: {exc}") from None
