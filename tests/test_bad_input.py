"""Bad input, over every sub-command and the main Python entry points: each fails cleanly.

Clean means: exit status 2 (or a :class:`weather_gym.core.errors.WeatherGymError` from Python), an
``error:`` line that names the culprit (file, option, key or value), no input file changed, nothing
written outside the case's output folder, and no more than a few seconds spent. The cases are the
table in ``tests/bad_input_cases.py``; add yours there.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bad_input_cases import CASES, Case, World, build_world  # noqa: E402

try:
    from weather_gym.core.errors import WeatherGymError
except ModuleNotFoundError:  # an old checkout (the "before" count of docs/reliability.md)
    WeatherGymError = (ValueError, OSError)  # type: ignore[assignment,misc]  # the stand-in on an old checkout

CASE_TIMEOUT_S = 60
"""A case that runs longer has not refused its input up front (a hang counts as a failure)."""


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> World:
    return build_world(tmp_path_factory.mktemp("bad_input"))


def _snapshot(root: Path) -> dict[str, tuple]:
    """Every entry below ``root`` (links not followed): kind, size, mtime and content hash."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            if p.is_symlink():
                out[str(p.relative_to(root))] = ("link", os.readlink(p))
            elif p.is_file():
                out[str(p.relative_to(root))] = ("file", st.st_size, st.st_mtime_ns,
                                                 hashlib.sha1(p.read_bytes()).hexdigest())
            else:
                out[str(p.relative_to(root))] = ("dir",)
    return out


@contextlib.contextmanager
def _time_limit(seconds: int):
    def _raise(signum, frame):
        raise TimeoutError(f"still running after {seconds} s: the input was not refused up front")

    old = signal.signal(signal.SIGALRM, _raise)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _run_cli(argv: list[str], capsys) -> tuple[int, str]:
    from weather_gym.cli import main

    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code if isinstance(exc.code, int) else 2
    return rc, capsys.readouterr().err


def _changed(before: dict, after: dict, allowed: str | None) -> list[str]:
    keys = set(before) | set(after)
    bad = sorted(k for k in keys if before.get(k) != after.get(k))
    if allowed is not None:
        bad = [k for k in bad if not (k == allowed or k.startswith(allowed.rstrip("/") + "/"))]
    return bad


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_fails_cleanly(case: Case, world: World, capsys, monkeypatch):
    monkeypatch.chdir(world.root)
    before = _snapshot(world.root)
    try:
        _check(case, world, before, capsys)
    finally:  # what one case wrote (its output, or damage when it failed) never reaches the next case
        if case.out is not None:  # back to how it was: an existing output folder emptied, a new one removed
            out = world[case.out]
            if before.get(case.out) == ("dir",):
                for p in out.iterdir():
                    shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
            else:
                shutil.rmtree(out, ignore_errors=True)
        if _snapshot(world.root) != before:
            shutil.rmtree(world.root)
            world.root.mkdir()
            build_world(world.root)


def _check(case: Case, world: World, before: dict, capsys) -> None:
    culprit = case.culprit.replace("{w}", str(world.root))
    with _time_limit(CASE_TIMEOUT_S):
        if case.argv is not None:
            rc, err = _run_cli([a.replace("{w}", str(world.root)) for a in case.argv], capsys)
            lines = [ln for ln in err.splitlines() if "error:" in ln]
            assert rc == 2, f"exit status {rc}, expected 2; stderr:\n{err}"
            assert lines, f"no 'error:' line; stderr:\n{err}"
            assert "Traceback" not in err, err
            message = "\n".join(lines)
        else:
            with pytest.raises(WeatherGymError) as info:
                case.call(world)
            message = str(info.value)
    assert culprit in message, f"the error does not name {culprit!r}: {message}"
    if case.forbid:
        assert case.forbid not in message, f"the error quotes {case.forbid!r}"
    assert _changed(before, _snapshot(world.root), case.out) == []



def test_the_table_covers_every_sub_command():
    from weather_gym.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    covered = {c.argv[0] for c in CASES if c.argv}
    assert set(sub.choices) <= covered, f"no bad-input case for: {sorted(set(sub.choices) - covered)}"
    assert len(CASES) >= 60
