"""The package raises its typed errors for user errors, never bare built-ins (``weather_gym.core.errors``).

A bare ``ValueError`` from weather-gym code would be shown by the CLI as a bug (traceback, exit 70)
although the user caused it; the typed classes are ``ValueError``/``FileNotFoundError``/
``FileExistsError`` too, so callers that catch the built-ins keep working.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import weather_gym
from weather_gym.core.errors import FileFormatError, InputError, check_known

BARE = {"ValueError": "InputError (or FileFormatError, LimitError, OutsideRootError)",
        "FileNotFoundError": "MissingInputError", "FileExistsError": "OutputExistsError",
        "IsADirectoryError": "OutputPathError", "PermissionError": "OutputPathError"}


def test_no_bare_builtin_raises_for_user_errors():
    root = Path(weather_gym.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.name == "paths.py":  # a missing data folder is a broken installation, not a user error
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
                name = getattr(node.exc.func, "id", None)
                if name in BARE:
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno}: raise {name} -> use {BARE[name]}")
    assert found == [], "raise the typed errors of weather_gym.core.errors:\n" + "\n".join(found)


def test_check_known_names_the_unknown_and_the_valid_names():
    check_known({"a": 1}, ("a", "b"), what="t")  # known names pass
    check_known([], (), what="t")
    with pytest.raises(InputError, match=re.escape("t: unknown key(s) ['c', 'z']; valid keys: ['b', 'a']")):
        check_known({"z": 1, "a": 2, "c": 3}, ("b", "a"), what="t")  # unknown sorted, valid in their order
    with pytest.raises(InputError, match=re.escape("valid options: ['a', 'b'] and more")):
        check_known(["x"], {"b", "a"}, what="t", kind="option", hint=" and more")  # a set is sorted
    with pytest.raises(FileFormatError, match=re.escape("f.toml: unknown key(s) ['x']")):
        check_known(["x"], ["a"], what="f.toml", error=FileFormatError)


def test_constructor_options_name_only_the_unknown_ones():
    """A wrapper given dataclass fields as keywords names the one that is wrong, not every one it got."""
    import gymnasium as gym

    from weather_gym.wrappers import GroundTruthConeWrapper, WeatherRandomizer

    with pytest.raises(InputError, match=r"unknown option\(s\) \['miss_prob_x'\]; valid options: \[.*'miss_prob'"):
        GroundTruthConeWrapper(gym.make("CartPole-v1"), miss_prob=0.1, miss_prob_x=0.2)
    with pytest.raises(InputError, match=r"WeatherRandomizer: unknown option\(s\) \['severity'\]; valid options: \['presets'"):
        WeatherRandomizer(gym.make("CartPole-v1"), presets=("droplets",), severity=(1, 2))
