"""``weather-gym bench sim --naive``: the default camera env step beside a naive TinyRenderer frame
(runs and prints both rows; no timing is asserted)."""

from __future__ import annotations

from weather_gym.bench import sim as bench_sim
from weather_gym.cli import main
from weather_gym.sim import egl_shadow_map


def test_bench_sim_naive_prints_the_baseline_and_the_default_env(monkeypatch, capsys):
    monkeypatch.setattr(bench_sim, "NAIVE_SIZES", ((96, 54),))
    assert main(["bench", "sim", "--naive", "--repeats", "2"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| 96x54")]
    assert any("naive TinyRenderer frame (baseline)" in r for r in rows)
    assert any("default camera env step, renderer" in r for r in rows)
    if "renderer egl" in out:  # where EGL loads, the TinyRenderer fallback and the step without the shadow map get rows
        assert any("default camera env step, renderer tiny (no EGL)" in r for r in rows)
        has_switch = egl_shadow_map.unavailable_reason() is None  # a stripped plugin has none: no row
        assert any("camera env step, shadows=False (EGL without its shadow map)" in r for r in rows) == has_switch
    assert "speed-up vs naive frame" in out


def test_bench_sim_naive_says_why_the_shadow_map_row_is_missing(monkeypatch, capsys):
    monkeypatch.setattr(bench_sim, "NAIVE_SIZES", ((96, 54),))
    monkeypatch.setattr(egl_shadow_map, "unavailable_reason", lambda: "a stripped build of the plugin")
    assert main(["bench", "sim", "--naive", "--repeats", "2"]) == 0
    out = capsys.readouterr().out
    assert "shadows=False (EGL without its shadow map)" not in out
    assert ("(no shadows=False row: a stripped build of the plugin)" in out) == ("renderer egl" in out)
