"""The old import paths of the restructure still work for one release, with a warning, as the same objects."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from weather_gym.core.moved import MOVED

TOP = sorted(old for old in MOVED if old.count(".") == 1)


@pytest.mark.parametrize("old", TOP)
def test_an_old_top_level_path_names_the_new_module(old):
    new = importlib.import_module(MOVED[old])
    with pytest.warns(DeprecationWarning, match=f"{old} moved to {MOVED[old]}"):
        sys.modules.pop(old, None)
        module = importlib.import_module(old)
    assert module is new


def test_a_module_of_a_moved_package_is_the_same_object_under_both_names():
    probe = ("import warnings; warnings.simplefilter('ignore')\n"
             "from weather_gym.evaluation.runner import run_cells as old\n"
             "import weather_gym.evaluation.results_store as store\n"
             "from weather_gym.lab.evaluation.runner import run_cells as new\n"
             "import weather_gym.lab.evaluation.results_store as store_new\n"
             "assert old is new and store is store_new\n"
             "import weather_gym.lab.gap.fit\n")
    run = subprocess.run([sys.executable, "-W", "error::DeprecationWarning:weather_gym", "-c", probe],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-1500:]


def test_the_new_paths_warn_nothing_and_touch_no_import_hook():
    probe = ("import sys, warnings\n"
             "warnings.simplefilter('error', DeprecationWarning)\n"
             "import weather_gym, weather_gym.core.errors, weather_gym.pipeline, weather_gym.lab.evaluation\n"
             "ours = [h for h in sys.meta_path if getattr(type(h), '__module__', '').startswith('weather_gym')]\n"
             "assert ours == [], ours\n"
             "assert 'weather_gym.errors' not in sys.modules\n")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-1500:]


def test_the_episode_driver_left_agents_with_a_warning():
    import weather_gym.agents as agents
    from weather_gym.pipeline import run_episode

    with pytest.warns(DeprecationWarning, match="pipeline.episode"):
        assert agents.run_episode is run_episode
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        agents.nothing  # noqa: B018


@pytest.mark.parametrize("old", sorted(old for old in MOVED if old.count(".") == 2))
def test_a_module_that_left_a_package_keeps_its_old_path(old):
    probe = (f"import warnings, importlib\n"
             f"with warnings.catch_warnings(record=True) as w:\n"
             f"    warnings.simplefilter('always')\n"
             f"    import {old} as old\n"
             f"import {MOVED[old]} as new\n"
             f"assert old is new, (old, new)\n"
             f"assert any(issubclass(x.category, DeprecationWarning) and 'moved to' in str(x.message) for x in w)\n")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-1500:]
