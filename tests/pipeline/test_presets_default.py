"""The default meaning of a named severity in an env: presets resolved for the env's scenario.

The suite pins ``WEATHER_GYM_PRESETS=pool`` (tests/conftest.py); these tests unset it to test the default,
with the resolver replaced by one that records its call and hands back a resolved presets file (a real
resolution is tests/lab/calibration/test_resolve.py's).
"""

from __future__ import annotations

import pytest

from tests.conftest import SMALL_CAMERA
from weather_gym.core.errors import ResolutionError
from weather_gym.envs.config import EnvConfig
from weather_gym.lab.calibration import resolve as rs
from weather_gym.pipeline import make_env
from weather_gym.weather.presets import DEFAULT_PRESETS


@pytest.fixture
def fake_resolver(monkeypatch, tmp_path):
    path = tmp_path / "resolved.toml"
    path.write_text('k_source = "resolved"\n' + DEFAULT_PRESETS.read_text())
    calls = []

    def resolver(spec, config, detector=None):
        calls.append((spec, config, detector))
        return str(path) if rs.resolves(spec) else None

    monkeypatch.setattr(rs, "presets_for_env", resolver)
    monkeypatch.delenv("WEATHER_GYM_PRESETS", raising=False)
    return calls


def _source(env):
    _, info = env.reset(seed=0)
    env.close()
    return info["weather_source"]


def test_a_named_severity_is_resolved_for_the_env_by_default(fake_resolver):
    env = make_env(weather="low_light@2", track="skidpad", camera=SMALL_CAMERA, max_episode_steps=5)
    assert _source(env) == "resolved"
    (spec, config, detector), = fake_resolver
    assert spec == "low_light@2" and detector is None
    assert config.track == "skidpad" and config.camera == SMALL_CAMERA


def test_explicit_k_and_the_pool_switch_resolve_nothing(fake_resolver, monkeypatch):
    assert _source(make_env(weather="dim:0.8:mode=night", camera=SMALL_CAMERA, max_episode_steps=5)) == "given"
    assert _source(make_env(weather="low_light@2", presets="pool", camera=SMALL_CAMERA, max_episode_steps=5)) == "pool"
    monkeypatch.setenv("WEATHER_GYM_PRESETS", "pool")
    assert _source(make_env(weather="droplets@3", camera=SMALL_CAMERA, max_episode_steps=5)) == "pool"
    assert [c for c in fake_resolver if rs.resolves(c[0])] == []


def test_resolves_names_only_rows_resolution_changes():
    assert rs.resolves("low_light@2") and rs.resolves([("droplets", 3)]) and rs.resolves("dim:0.3,droplets@4")
    assert not rs.resolves("droplets@0") and not rs.resolves("rain@2") and not rs.resolves({"dim": 0.5})


def test_a_detector_object_cannot_be_keyed(monkeypatch):
    with pytest.raises(ResolutionError, match="object.*presets=.*WEATHER_GYM_PRESETS=pool"):
        rs.presets_for_env("low_light@2", EnvConfig(camera=SMALL_CAMERA), detector=object())


def test_the_cli_default_follows_the_switch(monkeypatch):
    from weather_gym.cli._presets_arg import default_choice

    monkeypatch.delenv("WEATHER_GYM_PRESETS", raising=False)
    assert default_choice(None, "low_light@2") == "resolved"
    assert default_choice(None, "rain@2") is None and default_choice(None, "dim:0.8") is None
    assert default_choice("pool", "low_light@2") == "pool"
    monkeypatch.setenv("WEATHER_GYM_PRESETS", "pool")
    assert default_choice(None, "low_light@2") == "pool"
    monkeypatch.setenv("WEATHER_GYM_PRESETS", "resolved")
    assert default_choice(None, [("low_light", 1)]) == "resolved"


def test_the_surrogate_keeps_the_pool_presets(fake_resolver):
    """The surrogate's table holds the pool presets' k's: its env resolves nothing."""
    env = make_env(perception="surrogate", weather="droplets@3", max_episode_steps=5)
    assert _source(env) == "pool" and fake_resolver == []


def test_evaluate_resolves_each_track_by_default(fake_resolver):
    """``evaluate`` writes every cell's k out: by default, each track's resolved k (``k_source`` resolved)."""
    from weather_gym.lab.evaluation.evaluate import EvalConfig, _cell_weather
    from weather_gym.pipeline.modes import perception_mode

    config = EvalConfig(tracks=("skidpad", "small_track"), effects=("low_light", "rain"), severities=(0, 2))
    weather, source = _cell_weather(config, perception_mode("detector"), config.tracks, config.effects,
                                    config.severities, EnvConfig(camera=SMALL_CAMERA))
    assert source == {"skidpad": "resolved", "small_track": "resolved"}
    assert sorted(c[1].track for c in fake_resolver) == ["skidpad", "small_track"]
    assert sorted(set(fake_resolver[0][0])) == [("low_light", 0), ("low_light", 2), ("rain", 0), ("rain", 2)]
