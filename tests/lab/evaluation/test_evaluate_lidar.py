"""The evaluation grid with perception ``lidar``: its cells carry the LiDAR's weather at severities 0-5."""

from __future__ import annotations

import json

import pytest

from weather_gym.core.errors import InputError
from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells


def test_lidar_cells_take_the_lidar_effects():
    cells = make_cells(EvalConfig(agents=("mapper_pure_pursuit",), perception="lidar", effects=("fog", "rain"),
                                  severities=(0, 5), seeds=(0,)))
    assert [(c.effect, c.severity, json.loads(c.weather)) for c in cells] == [
        ("fog", 0, "clear"), ("fog", 5, "fog@5"), ("rain", 0, "clear"), ("rain", 5, "rain@5")]


@pytest.mark.parametrize("kw, word", [({"effects": ("droplets",)}, "droplets"), ({"severities": (6,)}, "severity"),
                                      ({"perception_kwargs": {"lidar_weather": "fog@1"}}, "lidar_weather")])
def test_lidar_grid_refuses(kw, word):
    with pytest.raises(InputError, match=word):
        make_cells(EvalConfig(**{"agents": ("mapper_pure_pursuit",), "perception": "lidar", "effects": ("fog",),
                                 "severities": (0,), "seeds": (0,), **kw}))


def test_camera_grids_still_refuse_lidar_effects():
    with pytest.raises(InputError):
        make_cells(EvalConfig(agents=("mapper_pure_pursuit",), perception="detector", effects=("rain_lidar",),
                              severities=(0,), seeds=(0,)))
