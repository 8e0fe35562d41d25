"""``weather-gym bench train``: alternating training runs per vector env kind, SB3's fps, the table."""

from __future__ import annotations

import pytest

from weather_gym.cli import main
from weather_gym.core.errors import InputError

pytest.importorskip("stable_baselines3")


@pytest.mark.slow
def test_bench_train_times_each_kind_against_the_baseline(tmp_path, capsys):
    out = tmp_path / "train.md"
    assert main(["bench", "train", "--vecs", "dummy,split", "--pairs", "1", "--timesteps", "64", "--n-envs", "2",
                 "--train-args", "--n-steps 32 --batch-size 32 --track hairpin,oval",
                 "--out", str(out)]) == 0
    text = out.read_text()
    assert "baseline --vec dummy" in text and "| split vs dummy" in text.replace("|  ", "| ")
    rows = [line for line in text.splitlines() if line.startswith("| 1 ") or line.startswith("| median")]
    assert len(rows) == 2
    assert "round 1: --vec split:" in capsys.readouterr().out


@pytest.mark.parametrize("vecs", ["", "dummy,dummy", "dummy,threads"])
def test_bad_kinds_are_refused(vecs):
    from weather_gym.lab.bench.train import parse_vecs

    with pytest.raises(InputError, match="--vecs must be distinct kinds"):
        parse_vecs(vecs)


def test_a_run_without_logs_is_named(tmp_path):
    from weather_gym.lab.bench.train import final_fps

    with pytest.raises(InputError, match="progress.csv"):
        final_fps(tmp_path)
