import math

import pytest

from weather_gym.conditions import CLEAR, WeatherState, parse_state
from weather_gym.core.errors import InputError, LimitError


def test_spec_items_units_and_round_trip():
    s = parse_state("rain:8mm/h + fog:60m+dusk:20lux+snow:1mm/h+film:0.5mm+lens:0.3+lensup:30s")
    assert (s.rain_mm_h, s.mor_m, s.illuminance_lux, s.snow_mm_h, s.water_film_mm, s.lens_wetness,
            s.lens_wet_up_s) == (8.0, 60.0, 20.0, 1.0, 0.5, 0.3, 30.0)
    assert parse_state(s.spec()) == s
    assert parse_state("clear") is CLEAR and parse_state(None) is CLEAR and CLEAR.is_clear
    assert parse_state("wet:0.2mm").water_film_mm == 0.2
    assert math.isclose(parse_state("fog:60m").beta, math.log(20) / 60)


@pytest.mark.parametrize("spec, error, words", [
    ("fog:5m", LimitError, ["5 m", "[12, inf]"]),
    ("rain:80mm/h", LimitError, ["80 mm/h", "[0, 50]"]),
    ("dusk:20000lux", LimitError, ["20000 lux", "10000"]),
    ("film:3mm", LimitError, ["3 mm", "[0, 2]"]),
    ("fog:60", InputError, ["'fog:60'", "m"]),
    ("rain:8mm", InputError, ["mm/h"]),
    ("hail:3mm/h", InputError, ["'hail'", "valid"]),
    ("rain:2mm/h+rain:3mm/h", InputError, ["twice"]),
    ("", InputError, ["empty"]),
    ("rain=8", InputError, ["NAME:VALUE"]),
])
def test_bad_specs_name_the_value_and_the_range(spec, error, words):
    with pytest.raises(error) as exc:
        parse_state(spec)
    for w in words:
        assert w in str(exc.value)


def test_film_from_rain_and_lens_equilibrium():
    assert parse_state("rain:1mm/h").film_mm() == 0.2
    assert parse_state("rain:5.05mm/h").film_mm() == pytest.approx(0.6)
    assert parse_state("rain:20mm/h").film_mm() == 1.0
    assert parse_state("rain:20mm/h+film:0mm").film_mm() == 0.0  # given wins
    assert CLEAR.film_mm() == 0.0 and CLEAR.lens_equilibrium() == 0.0
    assert parse_state("rain:5mm/h").lens_equilibrium() == 0.5
    assert parse_state("lens:0.4").lens_equilibrium() == 0.4  # no drying modelled


def test_the_dataclass_checks_its_fields():
    with pytest.raises(InputError, match="mor_m"):
        WeatherState(mor_m="far")  # type: ignore[arg-type]
    with pytest.raises(LimitError, match="lens wetness 1.5"):
        WeatherState(lens_wetness=1.5)
