"""How the command line reports errors: user errors briefly, bugs with their traceback."""

from __future__ import annotations

import pytest

from weather_gym.cli import INTERNAL_ERROR, main, run_command
from weather_gym.core.errors import (
    FileFormatError,
    InputError,
    LimitError,
    MissingInputError,
    OutputExistsError,
    OutputPathError,
    OutsideRootError,
    WeatherGymError,
)


@pytest.mark.parametrize("exc", [InputError("bad --k"), FileFormatError("f.csv: line 3"), LimitError("too big"),
                                 OutsideRootError("leads outside"), MissingInputError("x not found"),
                                 OutputExistsError("exists"), OutputPathError("a folder")])
def test_user_errors_print_one_line_and_exit_2(exc, capsys):
    def fail():
        raise exc

    assert run_command(fail) == 2
    err = capsys.readouterr().err
    assert err == f"error: {exc}\n"


def test_a_bug_keeps_its_traceback_and_asks_for_a_report(capsys):
    def bug():
        return {}["missing"]  # a KeyError from our own code is a bug, not a user error

    assert run_command(bug) == INTERNAL_ERROR
    err = capsys.readouterr().err
    assert "Traceback" in err and "KeyError" in err and "please report it" in err


def test_plain_value_errors_are_not_hidden_as_user_errors(capsys):
    def bug():
        raise ValueError("operands could not be broadcast together")

    assert run_command(bug) == INTERNAL_ERROR
    assert "Traceback" in capsys.readouterr().err


def test_the_hierarchy_keeps_the_builtin_types():
    assert issubclass(InputError, ValueError) and issubclass(FileFormatError, InputError)
    assert issubclass(MissingInputError, FileNotFoundError) and issubclass(OutputExistsError, FileExistsError)
    assert all(issubclass(c, WeatherGymError) for c in (InputError, OutputExistsError, OutputPathError))


def test_force_is_a_deprecated_alias_of_overwrite(tmp_path, capsys):
    out = tmp_path / "t.csv"
    assert main(["tracks", "export", "oval", "--out", str(out)]) == 0
    assert main(["tracks", "export", "oval", "--out", str(out)]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    assert main(["tracks", "export", "oval", "--out", str(out), "--overwrite"]) == 0
    assert main(["tracks", "show", "oval", "--out", str(tmp_path / "t.png")]) == 0
    assert main(["tracks", "show", "oval", "--out", str(tmp_path / "t.png"), "--force"]) == 0
    assert "--force is deprecated; use --overwrite" in capsys.readouterr().err


def test_every_writing_command_takes_overwrite():
    from weather_gym.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    missing = []
    for name, p in sub.choices.items():
        leaves = [(name, p)]
        while leaves:
            label, q = leaves.pop()
            nested = [a for a in q._actions if getattr(a, "choices", None) and isinstance(a.choices, dict)]
            if nested:
                leaves += [(f"{label} {n}", c) for n, c in nested[0].choices.items()]
                continue
            writes = any(a.dest in ("out", "output", "json", "plot", "video", "strip") for a in q._actions)
            if writes and not any("--overwrite" in a.option_strings for a in q._actions):
                missing.append(label)
    assert missing == []


def test_a_closed_pipe_ends_the_command_quietly():
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "weather_gym.cli", "tracks", "list"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.readline()  # `| head -1`: the reader takes one line and goes away
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err and "bug" not in err
