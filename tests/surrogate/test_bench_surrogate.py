"""``weather-gym bench surrogate``: gt_cones and the surrogate timed in interleaved blocks, the
surrogate's time per step against gt_cones paired block by block (no timing is asserted)."""

from __future__ import annotations

import pytest

from weather_gym.cli import main
from weather_gym.lab.bench import surrogate as bench_surrogate


def test_paired_rates_interleave_the_blocks_of_both_envs(monkeypatch):
    calls = []
    block = bench_surrogate._TimedLap.block

    def spy(self, r):
        calls.append((self.perception, r))
        return block(self, r)

    monkeypatch.setattr(bench_surrogate._TimedLap, "block", spy)
    out = bench_surrogate.paired_steps_per_s([("gt_cones", None), ("surrogate", "droplets@3")], "small_track", 5, 3)
    assert calls == [("gt_cones", 0), ("surrogate", 0), ("surrogate", 1), ("gt_cones", 1),
                     ("gt_cones", 2), ("surrogate", 2), ("surrogate", 3), ("gt_cones", 3)]
    for wall, cpu, blocks in out:
        assert len(blocks) == 3 and wall > 0 and cpu > 0  # the warm-up block is not counted
        assert wall == pytest.approx(sorted(blocks)[1])


def test_bench_surrogate_prints_the_paired_column(capsys):
    assert main(["bench", "surrogate", "--block", "5", "--repeats", "1", "--full-block", "1", "--full-repeats", "1",
                 "--num-envs", ""]) == 0
    out = capsys.readouterr().out
    assert "time per step vs gt_cones (paired blocks)" in out
    rows = [line for line in out.splitlines() if line.startswith("| surrogate (droplets@3)")]
    assert len(rows) == 1
