"""Long writers take their output for themselves: a second run into the same output is refused up front.

``dataset render``, ``gap``, ``surrogate log`` and ``detector train`` hold a lock on their output
(``weather_gym.core._io.exclusive``) for the whole run; here the lock is held by this test, as a first run
would, and the command must stop at once with exit status 2 and leave the output alone.
"""

from __future__ import annotations

import pytest

from weather_gym.cli import main
from weather_gym.core._io import exclusive


def _refused(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("what", ["render", "gap", "surrogate-log", "detector-train"])
def test_a_second_writer_is_refused_up_front(what, tmp_path, capsys):
    (tmp_path / "ds").mkdir()
    out = tmp_path / "out"
    argv, lock = {
        "render": (["dataset", "render", "--track", "oval", "--frames", "2", "--quiet", "--out", str(out)], out),
        "gap": (["gap", str(tmp_path / "ds"), "--quiet", "--out", str(out)], out),
        "surrogate-log": (["surrogate", "log", "--steps", "5", "--out", str(out / "l.npz")], out / "l.npz"),
        "detector-train": (["detector", "train", "--data", str(tmp_path / "ds"), "--out", str(out / "m.onnx")],
                           out / "m.onnx"),
    }[what]
    out.mkdir()
    with exclusive(lock):
        before = sorted(p.name for p in out.iterdir())
        err = _refused(argv, capsys)
        assert sorted(p.name for p in out.iterdir()) == before
    assert "error: another" in err and "is writing" in err

