"""The held-out drives that pick ``weather-gym train``'s model (weather_gym.lab.training.policy.selection)."""

from __future__ import annotations

import pytest

from weather_gym.core.errors import InputError
from weather_gym.lab.training.policy.selection import EpisodeRow, HeldOutConfig, HeldOutResult, held_out_laps


def _result(*rows):
    return HeldOutResult(rows=tuple(EpisodeRow("t", "clear", *r) for r in rows))


def test_laps_first_then_cones_then_time():
    clean_slow = _result((True, 0, 25.0, 1.0), (True, 0, 25.0, 1.0))
    dirty_fast = _result((True, 3, 20.0, 1.0), (True, 0, 20.0, 1.0))
    one_lap = _result((True, 0, 20.0, 1.0), (False, 0, 9.0, 0.4))
    assert clean_slow.score() > dirty_fast.score() > one_lap.score()
    assert _result((True, 0, 20.0, 1.0)).score() > _result((True, 0, 21.0, 1.0)).score()
    assert dirty_fast.cones_per_lap == 1.5 and one_lap.laps == 1 and one_lap.lap_time_s == 20.0


def test_every_track_in_every_weather_with_fixed_seeds():
    config = HeldOutConfig(tracks=("small_track", "mirror:hairpin"), weathers=("clear", "droplets@3"), episodes=2)
    drives = config.drives()
    assert len(drives) == 8 and drives == config.drives()
    assert drives[0][:2] == ("small_track", "clear") and drives[-1][:2] == ("mirror:hairpin", "droplets@3")
    assert {seed for _, _, seed in drives} == {drives[0][2], drives[0][2] + 1}
    # a perception without weather drives each track once per seed
    assert len(HeldOutConfig(tracks=("small_track",), perception="gt_cones", episodes=1).drives()) == 1
    assert HeldOutConfig.from_dict({"tracks": ["a"], "weathers": ["clear"], "perception": "surrogate",
                                    "max_steps": 9, "episodes": 1}).tracks == ("a",)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"tracks": ()}, r"--eval-track must be a list of at least 1 strings, got \(\)"),
    ({"weathers": ()}, r"--eval-weathers must be a list of at least 1 strings, got \(\)"),
    ({"max_steps": 0}, "--eval-max-steps must be an integer >= 1, got 0"),
    ({"episodes": True}, "--eval-episodes must be an integer >= 1, got True"),
    ({"perception": "telepathy"}, "telepathy"),
])
def test_bad_held_out_settings_are_refused(kwargs, message):
    with pytest.raises(InputError, match=message):
        HeldOutConfig(**{"tracks": ("small_track",), **kwargs})


def test_a_drive_from_the_start_line_is_recorded():
    config = HeldOutConfig(tracks=("small_track",), weathers=("clear",), perception="gt_cones", max_steps=40)
    result = held_out_laps(lambda obs: [0.0, 0.6], config, "WeatherGym/ConeTrack-v0", cone_memory={})
    (row,) = result.rows
    assert not row.lap and 0.0 < row.progress < 0.2 and row.time_s == pytest.approx(40 / 30, abs=0.05)
    assert result.score() == (0, -row.cones, 0.0) and "0/1 laps" in result.summary()
    again = held_out_laps(lambda obs: [0.0, 0.6], config, "WeatherGym/ConeTrack-v0", cone_memory={})
    assert again == result  # the same seeds: the same drive
