"""Declared validation of the frozen configuration dataclasses (pydantic v2).

A configuration declares what each field accepts in its annotation, with pydantic's markers::

    @dataclass(frozen=True)
    class RewardConfig:
        progress: float = 1.0                                    # a finite number
        laps: Annotated[int, Field(ge=0)] = 1                    # an integer >= 0
        view: Literal["chase", "camera"] = "chase"               # one of these
        sim: InstanceOf[SimConfig] = field(default_factory=SimConfig)

        def __post_init__(self) -> None:
            check_fields(self)

and :func:`check_fields` checks every field against the schema those annotations make (:func:`schema_of`,
strict: ``True`` is not an integer, ``"1"`` not a number; numbers are finite unless a field says
``AllowInfNan(True)``), normalises the values (``1`` -> ``1.0`` for a float field) and raises
:class:`~weather_gym.core.errors.InputError` naming the class, the key, the value and what was expected,
the expected range read from the declaration itself. A validator named in a class's annotation is a
module-level function (a ``lambda`` written there is evaluated among the class's names and cannot see the
module's). The class stays a plain frozen dataclass (equality,
hashing, pickling and ``dataclasses.replace`` as before), and ``pydantic.TypeAdapter(cls).json_schema()``
gives the JSON Schema of a file that holds one. A loader that reads a config from a file prefixes the file
(``"scenario.toml: EnvConfig.laps must be ..."``); :func:`validate_table` checks a table read from a file
against a schema in one call and names the file itself.

Example:
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Demo:
    ...     laps: NonNegativeInt = 1
    ...     share: Share = 0.5
    ...     def __post_init__(self) -> None:
    ...         check_fields(self)
    >>> Demo(share=1).share
    1.0
    >>> Demo(laps=-1)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: Demo.laps must be an integer >= 0, got -1
    >>> Demo(share=True)
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: Demo.share must be a finite number in [0, 1], got True
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
import pydantic
from pydantic_core import core_schema

from weather_gym.core.errors import InputError

__all__ = ["option", "Interval", "ListAsTuple", "NonNegative", "NonNegativeInt", "OneOf", "Positive", "PositiveInt", "Share", "check_fields", "describe",
           "error_message", "schema_of", "validate_table"]

#: the field kinds most configs need (any other constraint: ``Annotated[float, pydantic.Field(...)]``)
NonNegative = Annotated[float, pydantic.Field(ge=0)]
Positive = Annotated[float, pydantic.Field(gt=0)]
Share = Annotated[float, pydantic.Field(ge=0, le=1)]
NonNegativeInt = Annotated[int, pydantic.Field(ge=0)]
PositiveInt = Annotated[int, pydantic.Field(ge=1)]


def option(flag: str) -> Any:
    """``Annotated[..., option("--lr")]``: the command-line option that sets the field, named beside the
    key in its error message (``TrainConfig.lr (--lr) must be ...``) and in its JSON Schema."""
    return pydantic.Field(json_schema_extra={"option": flag})


#: ``Annotated[tuple[...], ListAsTuple]``: a list (a TOML array) is taken as the tuple it lists
ListAsTuple = pydantic.BeforeValidator(lambda v: tuple(v) if isinstance(v, list) else v)

#: the settings of every declared config schema: strict types, finite numbers, no unknown keys
CONFIG = pydantic.ConfigDict(strict=True, allow_inf_nan=False, arbitrary_types_allowed=True, extra="forbid")



@dataclasses.dataclass(frozen=True)
class OneOf:
    """``Annotated[str, OneOf(CHOICES)]``: one of a tuple of choices kept in a variable (``Literal`` for
    choices written out); the JSON Schema says ``enum``.

    Example:
        >>> import pydantic
        >>> pydantic.TypeAdapter(Annotated[str, OneOf(("a", "b"))]).json_schema()
        {'enum': ['a', 'b'], 'type': 'string'}
    """

    choices: tuple[Any, ...]

    def __get_pydantic_core_schema__(self, source: Any, handler: pydantic.GetCoreSchemaHandler) -> Any:
        return core_schema.literal_schema(list(self.choices))


@dataclasses.dataclass(frozen=True)
class Interval:
    """``Annotated[tuple[float, float], Interval(LO, HI)]``: a ``(low, high)`` range (a list too) with
    ``LO <= low <= high <= HI``, as a tuple of floats.

    Example:
        >>> import pydantic
        >>> pydantic.TypeAdapter(Annotated[tuple[float, float], Interval(0, 1)]).validate_python([0, 0.5])
        (0.0, 0.5)
    """

    lo: float
    hi: float

    def __get_pydantic_core_schema__(self, source: Any, handler: pydantic.GetCoreSchemaHandler) -> Any:
        side = core_schema.float_schema(ge=self.lo, le=self.hi, allow_inf_nan=False, strict=True)
        pair = core_schema.tuple_schema([side, side], strict=True)
        ordered = core_schema.no_info_after_validator_function(self._ordered, pair)
        return core_schema.no_info_before_validator_function(
            lambda v: tuple(v) if isinstance(v, list) else v, ordered)

    def _ordered(self, pair: tuple[float, float]) -> tuple[float, float]:
        if pair[0] > pair[1]:
            raise InputError(f"{pair} must satisfy {self.lo:g} <= low <= high <= {self.hi:g}")
        return pair


_SCHEMAS: dict[type, type[pydantic.BaseModel]] = {}


def schema_of(cls: type) -> type[pydantic.BaseModel]:
    """The pydantic model of a dataclass's init fields, from their annotations (cached per class)."""
    if cls not in _SCHEMAS:
        hints = typing.get_type_hints(cls, include_extras=True)
        declared: dict[str, Any] = {f.name: (hints[f.name], ...) for f in dataclasses.fields(cls) if f.init}
        _SCHEMAS[cls] = pydantic.create_model(f"{cls.__name__}Schema", __config__=CONFIG, **declared)
    return _SCHEMAS[cls]


def check_fields(obj: Any, *, who: str = "", error: type[InputError] = InputError, by_option: bool = False) -> None:
    """Check every init field of the dataclass ``obj`` against its declared schema (:func:`schema_of`) and
    write back the normalised values; a failure raises ``error`` (:func:`error_message`; ``who`` names the
    config there, default its class; ``by_option``: a field's option alone, :func:`error_message`). A numpy number counts as the Python number it holds and is kept as
    it is (a frame's arithmetic stays the same)."""
    cls = type(obj)
    given = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init}
    model = schema_of(cls)
    try:
        checked = model.model_validate({key: _plain(value) for key, value in given.items()})
    except pydantic.ValidationError as exc:
        raise error(error_message(exc, model, who or cls.__name__, given, by_option=by_option)) from None
    for key, value in given.items():
        new = getattr(checked, key)
        if new is not value and not isinstance(value, np.generic):
            object.__setattr__(obj, key, new)  # the dataclass idiom for a frozen field's own value


def _plain(value: Any) -> Any:
    """A numpy number (not a numpy bool) as the Python number it holds, also inside a tuple or list."""
    if isinstance(value, np.integer | np.floating):
        return value.item()
    if isinstance(value, tuple | list) and any(isinstance(v, np.generic) for v in value):
        return type(value)(_plain(v) for v in value)
    return value


def validate_table(model: type[pydantic.BaseModel], table: Mapping[str, Any], *, who: str,
                   error: type[InputError] = InputError) -> pydantic.BaseModel:
    """``model`` validated from a table read from a file; ``who`` (the file, and the table in it) starts
    the message of the ``error`` raised for an unknown key or a bad value."""
    try:
        return model.model_validate(dict(table))
    except pydantic.ValidationError as exc:
        raise error(error_message(exc, model, who, dict(table), sep=": ")) from None


def error_message(exc: pydantic.ValidationError, model: type[pydantic.BaseModel], who: str,
                  given: Mapping[str, Any], *, sep: str = ".", by_option: bool = False) -> str:
    """The message of the first failure: ``WHO.KEY must be EXPECTED, got VALUE`` (``WHO.KEY (--OPTION)`` for a
    field declared with :func:`option`; only ``--OPTION`` with ``by_option``: a config a command builds from
    its options); an ``InputError`` raised inside a field's own validator: ``WHO.KEY: ITS MESSAGE``; an
    unknown key lists the known ones."""
    err = exc.errors()[0]
    key = str(err["loc"][0]) if err.get("loc") else "?"
    if err["type"] == "extra_forbidden":
        return f"{who}: unknown key {key!r}; valid keys: {sorted(model.model_fields)}"
    if err["type"] == "missing" and len(err["loc"]) == 1:
        return f"{who}{sep}{key} is missing"
    try:
        schema = model.model_json_schema(mode="validation")
    except pydantic.PydanticUserError:  # a field of a kind JSON Schema cannot say
        schema = {}
    prop = schema.get("properties", {}).get(key, {})
    subject = f"{who}{sep}{key}" + (f" ({prop['option']})" if "option" in prop else "")
    if by_option and "option" in prop:
        subject = prop["option"]
    raised = err.get("ctx", {}).get("error")
    if isinstance(raised, InputError):  # a field's own validator: its message, with the key in front
        text = str(raised)
        return text if text.startswith(f"{who}{sep}{key}") else f"{subject}: {text}"
    if not prop:
        return f"{subject}: {err['msg']}, got {given.get(key)!r}"
    return f"{subject} must be {describe(prop, schema.get('$defs', {}))}, got {given.get(key)!r}"


def describe(prop: Mapping[str, Any], defs: Mapping[str, Any] | None = None) -> str:
    """What a JSON Schema of one value accepts, in words: ``an integer >= 0``, ``one of a, b``,
    ``a finite number in [0, 1]``, ``a SimConfig``, ``a string or None``.

    Example:
        >>> describe({"type": "number", "exclusiveMinimum": 0, "maximum": 1})
        'a finite number in (0, 1]'
    """
    defs = defs or {}
    if "$ref" in prop:
        name = prop["$ref"].rsplit("/", 1)[-1]
        return f"a {defs.get(name, {}).get('title', name)}"
    if "anyOf" in prop:
        return " or ".join(describe(p, defs) for p in prop["anyOf"])
    if "enum" in prop or "const" in prop:
        choices = prop.get("enum", [prop.get("const")])
        return "one of " + ", ".join(str(c) for c in choices)
    kind = prop.get("type")
    words = {"boolean": "true or false", "integer": "an integer", "number": "a finite number",
             "null": "None", "object": "a table"}
    if kind == "string":
        if "pattern" in prop:
            return f"a string matching {prop['pattern']}"
        return "a non-empty string" if prop.get("minLength") == 1 else "a string"
    if kind == "array":
        fixed = [describe(p, defs) for p in prop.get("prefixItems", [])]
        if fixed and len(set(fixed)) == 1:
            return f"{len(fixed)} values, each {fixed[0]}"
        if fixed:
            return f"{len(fixed)} values: " + "; ".join(fixed)
        items, least = prop.get("items"), prop.get("minItems", prop.get("minLength", 0))
        return ("a list" + (f" of at least {least}" if least else "")
                + (f" {'of ' if not least else ''}{_plural(describe(items, defs))}" if items else ""))
    text = words.get(kind, "a value") if isinstance(kind, str) else "a value"
    return text + _range(prop)


def _plural(text: str) -> str:
    return text.removeprefix("an ").removeprefix("a ").replace("integer", "integers").replace(
        "number", "numbers").replace("string", "strings")


def _range(prop: Mapping[str, Any]) -> str:
    lo, hi = prop.get("minimum", prop.get("exclusiveMinimum")), prop.get("maximum", prop.get("exclusiveMaximum"))
    open_lo, open_hi = "exclusiveMinimum" in prop, "exclusiveMaximum" in prop
    if lo is not None and hi is not None:
        return f" in {'(' if open_lo else '['}{_num(lo)}, {_num(hi)}{')' if open_hi else ']'}"
    if lo is not None:
        return f" {'>' if open_lo else '>='} {_num(lo)}"
    if hi is not None:
        return f" {'<' if open_hi else '<='} {_num(hi)}"
    return ""


def _num(x: float) -> str:
    """A bound as written: whole numbers in full (9223372036854775807, not 9.22337e+18)."""
    if isinstance(x, int):
        return str(x)
    return str(int(x)) if float(x).is_integer() else f"{x:g}"
