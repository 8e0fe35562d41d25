"""An agent of your own by ``"module.path:Factory"``, wherever a registered name is taken."""

from __future__ import annotations

import sys

import pytest

from weather_gym.agents import agent_factory, agent_observes, make_agent
from weather_gym.cli import main
from weather_gym.core.errors import InputError

MODULE = '''
import numpy as np
from weather_gym.agents import observes

CALLS = []


class Creep:
    def __init__(self, track, camera, throttle=0.3):
        CALLS.append((track.name, throttle))
        self.throttle = throttle

    def reset(self, seed=None, info=None):
        pass

    def act(self, obs, info=None):
        return np.array([0.0, self.throttle], np.float32)


@observes(("state",))
def declared(track, camera, **kwargs):
    return Creep(track, camera, **kwargs)


NOT_CALLABLE = 3
'''


@pytest.fixture
def my_agents(tmp_path, monkeypatch):
    (tmp_path / "my_agents_mod.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_agents_mod"
    sys.modules.pop("my_agents_mod", None)  # each test imports its own copy


def test_a_module_factory_is_an_agent_with_what_it_declares(my_agents):
    assert agent_observes(f"{my_agents}:declared") == frozenset({"state"})
    assert agent_observes(f"{my_agents}:Creep") is None  # not declared: any perception is accepted
    agent = make_agent(f"{my_agents}:Creep", type("T", (), {"name": "t"})(), None, throttle=0.1)
    assert agent.throttle == 0.1 and agent_factory("gt_pure_pursuit") is not None


@pytest.mark.parametrize("spec, message", [
    ("no_such_module_xyz:Agent", "cannot import module 'no_such_module_xyz'"),
    ("{m}:Missing", "has no 'Missing'"),
    ("{m}:NOT_CALLABLE", "'NOT_CALLABLE' is a int, not a factory"),
    ("{m}:", "expected a registered name"),
    ("os.path;rm:x", "expected a registered name"),
])
def test_bad_specs_are_typed_errors(my_agents, spec, message):
    with pytest.raises(InputError, match=message):
        agent_factory(spec.format(m=my_agents))


def test_lap_drives_an_agent_of_your_own(my_agents, capsys):
    import my_agents_mod

    code = main(["lap", "--track", "acceleration", "--agent", f"{my_agents}:Creep", "--agent-arg", "throttle=0.6",
                 "--perception", "gt_cones"])
    out = capsys.readouterr().out
    assert my_agents_mod.CALLS == [("acceleration", 0.6)]
    assert f"agent {my_agents}:Creep" in out and code in (0, 1)
