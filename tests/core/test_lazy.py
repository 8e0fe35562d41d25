"""Lazy package exports (weather_gym.core._lazy, on lazy_loader): names, dir(), errors."""

import importlib

import pytest


def test_lazy_names_resolve_and_are_listed():
    import weather_gym
    import weather_gym.wrappers as wrappers

    assert weather_gym.make_env.__module__ == "weather_gym.pipeline.builder"
    assert {"make_env", "register_envs", "__version__"} <= set(dir(weather_gym))  # lazy and own names
    assert wrappers.RecordVideo.__module__ == "weather_gym.viz.record_video"  # defined outside the package


def test_a_missing_name_is_an_attribute_error_naming_it():
    import weather_gym.lab.datasets as datasets

    with pytest.raises(AttributeError, match="module 'weather_gym.lab.datasets' has no attribute 'no_such_name'"):
        datasets.no_such_name  # noqa: B018


def test_a_function_named_like_its_module_stays_the_function():
    importlib.import_module("weather_gym.lab.gap.fit")  # importing the module binds `fit` on the package
    from weather_gym.lab.gap import fit

    assert callable(fit) and fit.__module__ == "weather_gym.lab.gap.fit" and not hasattr(fit, "__path__")
