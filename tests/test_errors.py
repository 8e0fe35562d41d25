"""The package raises its typed errors for user errors, never bare built-ins (``weather_gym.errors``).

A bare ``ValueError`` from weather-gym code would be shown by the CLI as a bug (traceback, exit 70)
although the user caused it; the typed classes are ``ValueError``/``FileNotFoundError``/
``FileExistsError`` too, so callers that catch the built-ins keep working.
"""

from __future__ import annotations

import ast
from pathlib import Path

import weather_gym

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
    assert found == [], "raise the typed errors of weather_gym.errors:\n" + "\n".join(found)
