import numpy as np
import pytest

from weather_gym.conditions import grip_ratio, table_mu
from weather_gym.conditions.grip import BOSCH_FILMS_MM, BOSCH_NEW_TYRE
from weather_gym.core.errors import LimitError


def test_the_table_at_its_points():
    for film, (mu50, mu90) in zip(BOSCH_FILMS_MM, BOSCH_NEW_TYRE):
        assert table_mu(film, 50 / 3.6) == pytest.approx(mu50)
        assert table_mu(film, 90 / 3.6) == pytest.approx(mu90)
    assert table_mu(0.2, 70 / 3.6) == pytest.approx(0.625)  # halfway between 0.65 and 0.60


@pytest.mark.parametrize("speed", [0.0, 5.0, 14.0, 20.0, 25.0, 40.0])
def test_grip_falls_monotonically_with_the_water_film(speed):
    films = np.linspace(0.0, 2.0, 81)
    g = np.array([grip_ratio(f, speed) for f in films])
    assert g[0] == 1.0
    assert np.all(np.diff(g) < 0), g


def test_grip_falls_with_speed_on_water_and_holds_outside_the_table():
    speeds = np.linspace(50 / 3.6, 90 / 3.6, 20)
    for film in (0.2, 1.0, 2.0):
        g = [grip_ratio(film, v) for v in speeds]
        assert np.all(np.diff(g) < 0)
    assert grip_ratio(1.0, 3.0) == grip_ratio(1.0, 50 / 3.6)  # below 50 km/h: the 50 km/h column
    with pytest.raises(LimitError, match="2.5 mm"):
        grip_ratio(2.5, 10.0)
    with pytest.raises(LimitError, match="speed"):
        grip_ratio(0.2, -1.0)
