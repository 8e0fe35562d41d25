"""Weather specs, their inverse, and the presets table."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from weather_gym.core.errors import InputError
from weather_gym.weather import (
    CONDITIONS,
    EFFECTS,
    SEVERITIES,
    Compose,
    Ramp,
    current_spec,
    load_presets,
    make,
    parse_weather,
    preset_entry,
    preset_spec,
    to_spec,
)
from weather_gym.weather.presets import DEFAULT_PRESETS, STUDY_CONDITIONS, nominal_rows


def test_every_form_of_spec():
    two = Compose([make("droplets", k=0.55), make("dim", k=0.3)])
    assert parse_weather({"droplets": 0.55, "dim": 0.3}) == two
    assert parse_weather("droplets:0.55, dim:0.3") == two
    assert parse_weather([{"name": "droplets", "k": 0.55}, {"name": "dim", "k": 0.3}]) == two
    assert parse_weather([make("droplets", k=0.55), "dim:0.3"]) == two
    assert parse_weather(two) is two
    one = parse_weather({"droplets": {"k": 0.55, "persistent": True}})
    assert one == make("droplets", k=0.55, persistent=True)
    assert parse_weather({"name": "dim", "k": 0.6, "mode": "physical"}) == make("dim", k=0.6, mode="physical")


@pytest.mark.parametrize("clear", [None, "clear", " Clear ", "none", {}, [], Compose([])])
def test_clear_weather_is_the_identity(clear, noisy_image):
    w = parse_weather(clear)
    np.testing.assert_array_equal(w(noisy_image), noisy_image)
    assert to_spec(w) == []


def _preset_effect(condition, severity):
    (table,) = preset_spec(condition, severity)
    return make(**table)


def test_presets_in_every_spelling():
    expected = _preset_effect("low_light", 2)
    assert expected.name == "dim" and 0 < expected.k < 1
    for spec in ("low_light@2", ("low_light", 2), "dim@2", ("dim", 2), " low_light @ 2"):
        assert parse_weather(spec) == expected, spec
    assert parse_weather("droplets@3") == _preset_effect("droplets", 3)
    assert parse_weather("droplets@0") == Compose([])
    assert parse_weather("droplets@4,low_light@1") == Compose([_preset_effect("droplets", 4),
                                                               _preset_effect("low_light", 1)])


@pytest.mark.parametrize(("spec", "message"), [
    ("snow:0.5", "unknown weather effect 'snow'; valid names: blur"),
    ("droplets:high", "k 'high' must be a number"),
    ("droplets", "must be NAME:K"),
    ("droplets:1.5", "parameter k=1.5 is outside"),
    ("snow@2", "unknown weather condition 'snow'; valid conditions: droplets, low_light, blur"),
    ("droplets@7", "invalid severity 7; valid severities: 0, 1, 2, 3, 4"),
    ("droplets@x", "severity 'x' must be an integer"),
    ({"droplets": "wet"}, "expected k"),
    ({"droplets": {"persistent": True}}, "need 'k'"),
    ({"droplets": {"k": 0.5, "radius": 3}}, "droplets: unknown parameter(s) ['radius']; valid parameters: ['k', 'fog_coef'"),
    ([{"k": 0.5}], "needs a 'name'"),
    ([{"name": "dim"}], "needs 'k'"),
    ([{"name": "dim", "k": float("nan")}], "parameter k=nan"),
    (3.5, "cannot read weather spec"),
    ({"name": "ramp", "k_end": 0.5}, "a ramp needs 'effect'"),
    ("droplets:0.5:k=0.7", "'k' is reserved, not a parameter"),
    ("droplets:0.5:name=dim", "'name' is reserved, not a parameter"),
    ({"droplets": {"k": 0.5, "name": "dim"}}, "weather spec 'droplets': 'name' is reserved"),
    ([{"name": "compose", "k": -1, "bogus": 1}], "unknown key(s) ['bogus', 'k']; valid keys: ['effects']"),
    ([{"name": "compose", "effects": "dim:0.5"}], "'effects' must be a list of effect tables"),
])
def test_errors_name_the_bad_part(spec, message):
    with pytest.raises(InputError, match=re.escape(message)):
        parse_weather(spec)


def test_reserved_names_are_typed_errors_in_every_entry_point():
    from weather_gym.weather.spec import parse_open_k

    with pytest.raises(InputError, match="'k' is reserved"):
        parse_open_k("droplets:k:k=0.3")
    assert parse_weather([{"name": "compose", "effects": [{"name": "dim", "k": 0.5}]}]) == Compose([make("dim", k=0.5)])


_effect = st.builds(
    lambda name, k: make(name, k=k),
    st.sampled_from(EFFECTS.names()),
    st.floats(0.0, 1.0),
)


@settings(max_examples=30, deadline=None)
@given(effects=st.lists(_effect, min_size=0, max_size=4).filter(lambda e: len(e) != 1))
def test_to_spec_round_trips_through_json(effects):
    w = Compose(effects)
    spec = to_spec(w)
    assert parse_weather(json.loads(json.dumps(spec))) == w


def test_round_trip_with_parameters_and_ramps():
    w = Compose([make("droplets", k=0.2, persistent=True, fog_coef=0.3),
                 Ramp("dim", k_start=0.1, k_end=0.9, steps=100, mode="physical", stops=8.0)])
    spec = to_spec(w)
    assert spec[1] == {"name": "ramp", "effect": "dim", "k_start": 0.1, "k_end": 0.9, "steps": 100,
                       "mode": "physical", "stops": 8.0}
    assert parse_weather(spec) == w
    single = make("fog", k=0.3, airlight=0.9)
    assert parse_weather(to_spec(single)) == single


def test_current_spec_shows_the_ramps_k():
    ramp = Ramp("dim", 0.0, 1.0, steps=4)
    img = np.zeros((2, 2, 3), np.uint8)
    ramp(img)
    ramp(img)
    assert current_spec(ramp)[0]["k"] == 0.25 and current_spec(ramp)[0]["name"] == "dim"


#: The first, uncalibrated table (k guesses), kept as a fixed input for the file-format tests.
UNCALIBRATED = Path(__file__).with_name("data") / "presets_uncalibrated.toml"


@pytest.mark.parametrize("path", [DEFAULT_PRESETS, UNCALIBRATED], ids=["shipped", "uncalibrated"])
def test_presets_are_complete_and_grow_with_severity(path):
    data = load_presets(path)
    want = set(CONDITIONS)  # the file's conditions and every other effect's nominal rows
    assert set(data["presets"]) == want
    for cond in want:
        assert sorted(data["presets"][cond]) == list(SEVERITIES)
        assert preset_spec(cond, 0, path) == []
        ks = [preset_spec(cond, s, path)[0]["k"] for s in SEVERITIES[1:]]
        assert ks == sorted(ks)
    entry = preset_entry("low_light", 2, path)
    assert entry["measured_map"] == 0.273 and entry["description"] == "Sunset"


def test_every_effect_has_a_severity_table_marked_calibrated_or_nominal():
    from weather_gym.weather import EFFECTS, parse_weather, to_spec
    from weather_gym.weather.presets import canonical_condition

    data = load_presets()
    for name in EFFECTS.names():
        rows = data["presets"][canonical_condition(name)]
        assert {type(r["calibrated"]) for r in rows.values()} == {bool}
        assert to_spec(parse_weather(f"{name}@4"))[0]["name"] == name
    assert data["calibrated_conditions"] == ("droplets", "low_light")
    rain = preset_entry("rain", 2)
    assert rain["calibrated"] is False and "nominal" in rain["note"]
    assert to_spec(parse_weather("rain@2")) == [{"name": "rain", **parse_weather("rain:0.5").params()}]
    assert preset_entry("droplets", 3)["calibrated"] is True


def test_a_file_may_hold_some_conditions_and_says_which_are_missing(tmp_path):
    # a condition whose effect declares no nominal rows (low_light: calibrated only) must be in the file
    text = UNCALIBRATED.read_text()
    only_drops = tmp_path / "drops.toml"
    only_drops.write_text(text[:text.index('condition = "low_light"')].rsplit("[[presets]]", 1)[0])
    with pytest.raises(ValueError, match="has no rows for condition 'low_light' \\(it has: droplets, blur, "):
        preset_spec("low_light", 2, only_drops)
    # the other effects' nominal rows come with every file: a file need not repeat them
    assert preset_entry("rain", 2, UNCALIBRATED) == preset_entry("rain", 2) == nominal_rows("rain")[2]


def test_nominal_rows_are_declared_by_the_effect_and_a_file_row_replaces_them(tmp_path):
    from weather_gym.weather import EFFECTS

    for name in EFFECTS:
        cls = EFFECTS.get(name)
        rows = nominal_rows(cls.condition())
        if cls.NOMINAL_K is None:
            assert rows == {} and cls.condition() in STUDY_CONDITIONS
            continue
        assert [r["effects"] for r in rows.values()] == [[]] + [[{"name": name, "k": k}] for k in cls.NOMINAL_K]
        assert {r["calibrated"] for r in rows.values()} == {False}
    text = UNCALIBRATED.read_text() + "".join(
        f'\n[[presets]]\ncondition = "rain"\nseverity = {s}\neffects = [{{ name = "rain", k = {s / 8} }}]\n'
        for s in SEVERITIES)
    path = tmp_path / "rain.toml"
    path.write_text(text)
    assert preset_spec("rain", 2, path) == [{"name": "rain", "k": 0.25}]
    assert preset_spec("fog", 2, path) == [{"name": "fog", "k": 0.5}]


def test_an_uncalibrated_table_says_so():
    data = load_presets(UNCALIBRATED)
    assert data["calibrated"] is False and data["calibrated_conditions"] == ()
    assert preset_entry("droplets", 3, UNCALIBRATED)["calibrated"] is False
    assert preset_spec("droplets", 3, UNCALIBRATED) == [{"name": "droplets", "k": 0.55}]
    assert preset_spec("low_light", 3, UNCALIBRATED) == [{"name": "dim", "k": 0.78}]
    assert np.isnan(preset_entry("low_light", 2, UNCALIBRATED)["achieved_relative"])


def test_preset_lookup_errors():
    with pytest.raises(ValueError, match="valid conditions: droplets, low_light, blur"):
        preset_spec("snow", 1)
    with pytest.raises(ValueError, match="valid severities: 0, 1, 2, 3, 4"):
        preset_spec("droplets", 5)
    with pytest.raises(ValueError, match="valid severities"):
        preset_spec("droplets", True)


def test_a_rewritten_presets_file_is_read_without_code_changes(tmp_path):
    text = UNCALIBRATED.read_text().replace("calibrated = false", "calibrated = true")
    text = text.replace('effects = [{ name = "droplets", k = 0.55 }]',
                        'effects = [{ name = "droplets", k = 0.61, persistent = true }]\nnote = "fitted"')
    path = tmp_path / "presets.toml"
    path.write_text(text)
    data = load_presets(path)
    assert data["calibrated"] is True
    assert preset_spec("droplets", 3, path) == [{"name": "droplets", "k": 0.61, "persistent": True}]
    assert preset_entry("droplets", 3, path)["note"] == "fitted"


@pytest.mark.parametrize(("edit", "message"), [
    (lambda t: t.replace('condition = "low_light"\nseverity = 4', 'condition = "low_light"\nseverity = 3'),
     "appears twice"),
    (lambda t: t.replace('name = "dim", k = 0.92', 'name = "dimm", k = 0.92'), "unknown weather effect 'dimm'"),
    (lambda t: t.replace('condition = "droplets"\nseverity = 2', 'condition = "snow"\nseverity = 2'),
     "unknown weather condition 'snow'"),
    (lambda t: t.replace('condition = "droplets"\nseverity = 2', 'condition = "fog"\nseverity = 2'),
     "condition 'droplets' has no preset for severity \\[2\\]"),
    (lambda t: t.replace('severity = 2\n', 'severity = 2\ncalibrated = 1\n', 1), "'calibrated' must be true or false"),
    (lambda t: t + "\n[[presets]]\ncondition = 'droplets'\n", "missing key 'severity'"),
    (lambda t: t.replace("calibrated = false", "calibrated = 'no'"), "'calibrated' must be true or false"),
    (lambda t: t.replace("calibrated = false", "calibrated = = false"), "not valid TOML"),
])
def test_a_broken_presets_file_is_a_clear_error(tmp_path, edit, message):
    path = tmp_path / "presets.toml"
    path.write_text(edit(UNCALIBRATED.read_text()))
    with pytest.raises(ValueError, match=message):
        load_presets(path)
    with pytest.raises(FileNotFoundError):
        load_presets(tmp_path / "missing.toml")
