"""Declared config validation (weather_gym.core.schema): strict types, messages that name the class, key,
value and range, and configs that stay plain frozen dataclasses."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core.errors import InputError, LimitError
from weather_gym.envs.config import EnvConfig
from weather_gym.lab.gap.config import GapConfig
from weather_gym.sim.config import SimConfig


@pytest.mark.parametrize("config", [EnvConfig(), GapConfig(), SimConfig(), CameraConfig(), CameraModel()])
def test_a_declared_config_is_still_a_plain_frozen_dataclass(config):
    cls = type(config)
    assert config == cls() and hash(config) == hash(cls())
    assert pickle.loads(pickle.dumps(config)) == config
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.x = 1  # type: ignore[attr-defined]


def test_replace_checks_again():
    assert dataclasses.replace(EnvConfig(), laps=3).laps == 3
    with pytest.raises(InputError, match=r"EnvConfig.laps must be an integer >= 0, got -1"):
        dataclasses.replace(EnvConfig(), laps=-1)


@pytest.mark.parametrize("build, message", [
    (lambda: EnvConfig(laps=True), r"EnvConfig.laps must be an integer >= 0, got True"),  # a bool is no integer
    (lambda: SimConfig(physics_hz="240"), r"SimConfig.physics_hz must be a finite number > 0, got '240'"),
    (lambda: SimConfig(gravity=float("inf")), r"SimConfig.gravity must be a finite number > 0, got inf"),
    (lambda: SimConfig(shadows=1), r"SimConfig.shadows must be true or false or None, got 1"),
    (lambda: GapConfig(scene="cartoon"), r"GapConfig.scene must be one of plain, realistic or None, got 'cartoon'"),
    (lambda: GapConfig(candidates=("sharpen",)), r"GapConfig.candidates: unknown weather effect 'sharpen'"),
    (lambda: CameraModel(white_balance=(1.0, 1.0)), r"camera_model.white_balance must be 3 values, each a finite "
                                                     r"number in \[0.2, 5\], got \(1.0, 1.0\)"),
    (lambda: EnvConfig(sim={}), r"EnvConfig.sim must be a SimConfig, got \{\}"),
])
def test_a_bad_field_names_the_class_key_value_and_range(build, message):
    with pytest.raises(InputError, match=message):
        build()


def test_numbers_are_normalised_and_numpy_numbers_kept():
    assert EnvConfig(off_track_margin=1).off_track_margin == 1.0
    assert isinstance(EnvConfig(off_track_margin=1).off_track_margin, float)
    width = np.int64(64)
    assert CameraConfig(width=width, height=32).width is width  # a numpy number counts as its value, kept as given
    assert GapConfig(tracks=["a", "b"]).tracks == ("a", "b")    # a list (a TOML array) is the tuple it lists


def test_a_train_config_error_names_the_option_and_is_a_limit_error():
    from weather_gym.lab.training.detector.train.config import TrainConfig

    with pytest.raises(LimitError, match=r"TrainConfig.lr \(--lr\) must be a finite number in \(0, 1\], got 2"):
        TrainConfig(lr=2)
