"""One name per idea across the commands: docs/cli.md's table holds for the parsers, and the old
spellings are hidden from every help but still parse, with a note."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from weather_gym.cli import build_parser

DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def _parsers() -> dict[str, argparse.ArgumentParser]:
    out = {}

    def walk(parser, prefix):
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    out[" ".join([*prefix, name])] = sub
                    walk(sub, [*prefix, name])

    walk(build_parser(), [])
    return out


PARSERS = _parsers()


def _visible(parser) -> set[str]:
    return {o for a in parser._actions if a.help != argparse.SUPPRESS for o in a.option_strings}


def _rows(table: int) -> list[list[str]]:
    tables = re.findall(r"(\| idea .*?|\| old .*?)\n\n", DOC.read_text(encoding="utf-8") + "\n\n", flags=re.S)
    return [[c.strip() for c in line.strip("|").split(" | ")] for line in tables[table].splitlines()[2:]]


@pytest.mark.parametrize("row", _rows(0), ids=lambda r: r[0])
def test_each_idea_has_its_one_name_in_every_command_listed(row):
    options = re.findall(r"`(--[a-z-]+)", row[1])[:1]
    commands = [c.strip() for c in re.sub(r"\([^)]*\)", "", row[2]).split(",")]
    if "every command" in row[2]:
        commands = [c for c, p in PARSERS.items() if options[0] in _visible(p)]
        assert len(commands) >= 10
    for command in commands:
        assert command in PARSERS, f"docs/cli.md names a command {command!r} that does not exist"
        assert options[0] in _visible(PARSERS[command]), f"{command} has no {options[0]}"


@pytest.mark.parametrize("old, new", [("--env", "--env-id"), ("--tracks", "--track"), ("--agents", "--agent"),
                                      ("--no-progress", "--quiet"), ("--force", "--overwrite")])
def test_old_spellings_are_hidden_everywhere_but_still_parse_with_a_note(old, new, capsys):
    hidden_in = [c for c, p in PARSERS.items() if old in p._option_string_actions]
    assert hidden_in, old
    for command in hidden_in:
        parser = PARSERS[command]
        shown = re.search(rf"{old}(?![-\w])", parser.format_help())
        assert old not in _visible(parser) and not shown, (command, old)
        assert new in _visible(parser), (command, new)
        action = parser._option_string_actions[old]
        assert action.dest == parser._option_string_actions[new].dest, (command, old)


def test_an_old_spelling_gives_the_new_ones_value_and_a_note(capsys):
    parser = build_parser("evaluate")
    args = parser.parse_args(["evaluate", "--tracks", "peanut", "--agents", "gt_pure_pursuit", "--no-progress",
                              "--out", "x"])
    assert (args.tracks, args.agents, args.no_progress) == ("peanut", "gt_pure_pursuit", True)
    err = capsys.readouterr().err
    assert "note: --tracks is deprecated and goes in the next release; use --track" in err
    assert "use --agent" in err and "use --quiet" in err
    lap = build_parser("lap").parse_args(["lap", "--env", "WeatherGym/ConeTrackSmall-v0"])
    assert lap.env == "WeatherGym/ConeTrackSmall-v0"


def test_help_texts_show_one_default_each():
    for command in ("evaluate", "sweep", "calibrate"):
        text = PARSERS[command].format_help()
        assert "(default: None)" not in text, command
        for block in re.split(r"\n  (?=-)", text):
            assert block.count("default") <= 1 or "defaults" in block, (command, block)
