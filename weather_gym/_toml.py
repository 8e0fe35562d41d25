"""Reading a TOML file with typed errors, and writing TOML values (``tomllib`` only reads).

Example:
    >>> from weather_gym._toml import toml_value
    >>> toml_value({"name": "dim", "k": 0.6, "mode": "physical"})
    '{ name = "dim", k = 0.6, mode = "physical" }'
    >>> toml_value(float("nan")), toml_value(1.0), toml_value(0.123456789, digits=4)
    ('nan', '1.0', '0.1235')
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from weather_gym.errors import FileFormatError, InputError, MissingInputError

__all__ = ["read_toml", "toml_value"]


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """The TOML file ``path`` as a dict; :class:`MissingInputError` ("``what`` PATH does not exist")
    or :class:`FileFormatError` ("PATH: malformed TOML: ...")."""
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MissingInputError(f"{what} {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: malformed TOML: {exc}") from None


def toml_value(v: Any, *, digits: int | None = None, finite: bool = False, none: str | None = None) -> str:
    """``v`` (bool, int, float, str, mapping, list/tuple, nested) as a TOML value.

    ``digits``: round floats to that many decimals (values below ``1e-4`` keep their precision);
    ``finite``: refuse NaN and infinities (ValueError) instead of writing TOML's ``nan``/``inf``;
    ``none``: the text written for ``None`` (TOML has no null; by default ``None`` is an error).
    """
    kw = {"digits": digits, "finite": finite, "none": none}
    if v is None and none is not None:
        return none
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            if finite:
                raise InputError(f"cannot write the non-finite number {v!r} here")
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        if digits is not None and (abs(v) >= 1e-4 or v == 0):
            v = round(v, digits)
        text = repr(v)
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{k} = {toml_value(x, **kw)}" for k, x in v.items()) + " }"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(toml_value(x, **kw) for x in v) + "]"
    raise InputError(f"cannot write {type(v).__name__} {v!r} as a TOML value")
