"""Every docstring example in the package runs and prints what it says (``doctest``).

The module docs promise "a runnable example"; this keeps them true as the code (and the calibrated
presets) change. Examples that need a display, a long run or files outside the repository are
marked ``# doctest: +SKIP`` in place.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import weather_gym

MODULES = sorted(m.name for m in pkgutil.walk_packages(weather_gym.__path__, "weather_gym.")
                 if not m.name.endswith("__main__"))


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.failed == 0, f"{result.failed} docstring example(s) of {name} failed (run python -m doctest -v)"
