"""``weather-gym bench sim --naive``: the default camera env step beside a naive TinyRenderer frame
(runs and prints both rows; no timing is asserted)."""

from __future__ import annotations

from weather_gym.cli import main
from weather_gym.lab.bench import sim as bench_sim
from weather_gym.sim.egl import shadow_map as egl_shadow_map


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


def test_bench_sim_naive_times_the_opt_in_reuse_beside_the_default(monkeypatch, capsys):
    from weather_gym.sim.egl import shadow_reuse as egl_shadow_reuse
    monkeypatch.setattr(bench_sim, "NAIVE_SIZES", ((96, 54),))
    if egl_shadow_reuse._hook is not None:  # this process's hook (the suite runs with the reuse on)
        egl_shadow_reuse._hook._entry.release()
    monkeypatch.setattr(egl_shadow_reuse, "_hook", None)
    monkeypatch.setattr(egl_shadow_reuse, "_reason", None)
    monkeypatch.delenv("WEATHER_GYM_SHADOW_MAP_REUSE", raising=False)
    assert main(["bench", "sim", "--naive", "--repeats", "2"]) == 0
    out = capsys.readouterr().out
    assert "WEATHER_GYM_SHADOW_MAP_REUSE=1 (same bytes)" not in out  # off by default: no row, and why
    assert ("(no shadow-map reuse row: off (the default" in out) == ("renderer egl" in out)
    monkeypatch.setenv("WEATHER_GYM_SHADOW_MAP_REUSE", "1")
    try:
        assert main(["bench", "sim", "--naive", "--repeats", "2"]) == 0
    finally:
        if egl_shadow_reuse._hook is not None:
            egl_shadow_reuse._hook._entry.release()
    out = capsys.readouterr().out
    if "renderer egl" in out and egl_shadow_reuse.unavailable_reason() is None:
        assert any("WEATHER_GYM_SHADOW_MAP_REUSE=1 (same bytes)" in line for line in out.splitlines())
