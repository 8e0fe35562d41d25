"""What the frames depend on is pinned to tested ranges in pyproject.toml, and the tests run on them.

The frames (and so the calibrated presets, the detector's numbers and every rendered set) depend on
PyBullet's renderer and were tested on one Python; ``pyproject.toml`` pins both to what was tested.
A CI run on another Python or PyBullet fails here first, instead of somewhere deep in the frames.
"""

from __future__ import annotations

import platform
import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


@pytest.fixture(scope="module")
def project() -> dict:
    return tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]


def test_python_is_pinned_to_a_closed_range_and_this_one_is_in_it(project):
    spec = SpecifierSet(project["requires-python"])
    assert any(s.operator == "<" for s in spec), f"requires-python {spec} has no upper bound"
    assert spec.contains(platform.python_version()), (
        f"Python {platform.python_version()} is outside the tested range {spec} of pyproject.toml")


def test_pybullet_is_pinned_and_the_installed_build_is_the_tested_one(project):
    req = next(Requirement(d) for d in project["dependencies"] if Requirement(d).name == "pybullet")
    assert any(s.operator in ("<", "<=", "==") for s in req.specifier), f"{req} has no upper bound"
    assert req.specifier.contains(version("pybullet")), (
        f"PyBullet {version('pybullet')} is outside the tested range {req.specifier} of pyproject.toml")
