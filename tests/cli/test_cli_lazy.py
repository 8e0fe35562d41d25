"""The command line imports only the sub-command it runs (weather_gym.cli.main, COMMANDS)."""

from __future__ import annotations

import argparse
import json
import pkgutil
import subprocess
import sys

import pytest

import weather_gym.cli as cli

NAMES = sorted(i.name for i in pkgutil.iter_modules(cli.__path__) if not i.name.startswith("_"))

PROBE = """
import json, sys
from weather_gym.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(json.dumps(sorted(m for m in sys.modules if m.startswith("weather_gym.cli.") and not m.split(".")[2].startswith("_"))))
"""


def _loaded(*argv: str) -> list[str]:
    run = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_every_command_has_its_summary_and_it_is_the_one_it_registers():
    assert sorted(cli.COMMANDS) == NAMES
    full = cli.build_parser()
    sub = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction))
    registered = {c.dest: c.help for c in sub._choices_actions}
    assert registered == cli.COMMANDS


def test_top_level_help_loads_no_sub_command():
    assert _loaded("--help") == []


@pytest.mark.parametrize("name", ["degrade", "train"])
def test_a_sub_commands_help_loads_only_that_sub_command(name):
    assert _loaded(name, "--help") == [f"weather_gym.cli.{name}"]


def test_the_lazy_parser_parses_as_the_full_one():
    argv = ["lap", "--track", "peanut", "--laps", "2"]
    lazy = vars(cli.build_parser(cli.command_of(argv)).parse_args(argv))
    full = vars(cli.build_parser().parse_args(argv))
    assert lazy == full
    assert cli.command_of(["--version"]) is None
    assert cli.command_of(["nope"]) is None


def test_an_unknown_command_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["nope"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert all(n in err for n in NAMES)
