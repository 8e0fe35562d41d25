"""Every effect's parameters have a declared schema (``param_schema``) whose ranges and choices are the
effect's own declarations, and a bad parameter is an InputError naming the effect, parameter, value and
range."""

from __future__ import annotations

import dataclasses
import typing

import numpy as np
import pytest

from weather_gym.core.errors import InputError
from weather_gym.weather import EFFECTS, make
from weather_gym.weather.base import KnobEffect, param_schema


@pytest.mark.parametrize("name", EFFECTS.names())
def test_the_schema_is_the_effects_declarations(name):
    cls = EFFECTS.get(name)
    props = param_schema(cls).model_json_schema()["properties"]
    hints = typing.get_type_hints(cls)
    assert set(props) == {f.name for f in dataclasses.fields(cls)}
    for f in dataclasses.fields(cls):
        p = props[f.name]
        if f.name in cls.CHOICES:
            assert p["enum"] == list(cls.CHOICES[f.name]), f.name
        elif hints[f.name] in (float, int):
            assert (p["minimum"], p["maximum"]) == cls.bounds_of(f.name), f.name
            assert p["type"] == ("number" if hints[f.name] is float else "integer")
        elif hints[f.name] is bool:
            assert p["type"] == "boolean"
        assert p["default"] == f.default


@pytest.mark.parametrize("params, message", [
    ({"k": 1.5}, "vignette: parameter k=1.5 is outside [0.0, 1.0]"),
    ({"k": "0.5"}, "vignette: parameter k='0.5' must be a finite number in [0.0, 1.0]"),
    ({"k": float("nan")}, "vignette: parameter k=nan must be a finite number in [0.0, 1.0]"),
    ({"k": True}, "vignette: parameter k=True must be a finite number in [0.0, 1.0]"),
    ({"exponent": 9}, "vignette: parameter exponent=9.0 is outside [0.5, 8.0]"),
])
def test_a_bad_parameter_names_effect_parameter_value_and_range(params, message):
    with pytest.raises(InputError) as exc:
        make("vignette", **params)
    assert str(exc.value) == message


def test_values_are_normalised_not_coerced():
    e = make("droplets", k=1, persistent=np.bool_(True))
    assert type(e.k) is float and type(e.persistent) is bool and e == make("droplets", k=1.0, persistent=True)
    with pytest.raises(InputError, match="persistent=1 must be true or false"):
        make("droplets", k=0.5, persistent=1)
    with pytest.raises(InputError, match="mode='dusk' must be one of"):
        make("droplets", k=0.5, mode="dusk")
    assert isinstance(make("vignette", k=0.5).with_params(k=0.25), KnobEffect)
    with pytest.raises(InputError, match="k=2.0 is outside"):
        make("vignette", k=0.5).with_params(k=2.0)
