"""Every module's docstring examples run and print what they say (``doctest``), and at least one runs.

The module docs promise "a runnable example"; this keeps them true as the code (and the calibrated
presets) change. Examples that need a display, a long run or files outside the repository are
marked ``# doctest: +SKIP`` in place, but every module keeps at least one example that runs
something: a module whose examples are all skipped, or only import names, fails (it would pass
without checking anything).
"""

from __future__ import annotations

import ast
import doctest
import importlib
import pkgutil

import pytest

import weather_gym
from weather_gym.core.moved import MOVED

MODULES = sorted(m.name for m in pkgutil.walk_packages(weather_gym.__path__[:1], "weather_gym.")
                 if not m.name.endswith("__main__") and m.name not in MOVED)  # old paths: aliases of new modules
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def only_imports(source: str) -> bool:
    """True when an example's source is nothing but ``import`` statements."""
    body = ast.parse(source).body
    return all(isinstance(stmt, (ast.Import, ast.ImportFrom)) for stmt in body)


def checked_examples(tests: list[doctest.DocTest]) -> int:
    """How many examples of ``tests`` run and check something (not skipped, not only imports)."""
    return sum(1 for test in tests for ex in test.examples
               if not ex.options.get(doctest.SKIP, False) and not only_imports(ex.source))


def test_the_rule_counts_neither_skipped_nor_import_only_examples():
    parse = doctest.DocTestParser().get_doctest
    vacuous = parse(">>> import math\n>>> from os import path\n>>> math.pi  # doctest: +SKIP\n3\n", {}, "p", None, 0)
    assert checked_examples([vacuous]) == 0
    assert checked_examples([parse(">>> import math\n>>> round(math.pi, 2)\n3.14\n", {}, "p", None, 0)]) == 1


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    tests = doctest.DocTestFinder().find(module, name)
    assert checked_examples(tests) > 0, (
        f"{name} has no docstring example that runs (all skipped, only imports, or none): give its module "
        "docstring one cheap example that runs")
    runner = doctest.DocTestRunner(optionflags=FLAGS, verbose=False)
    report: list[str] = []
    for test in sorted(tests, key=lambda t: t.name):
        runner.run(test, out=report.append)
    assert runner.failures == 0, f"{runner.failures} docstring example(s) of {name} failed:\n" + "".join(report)
