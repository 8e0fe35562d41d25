"""The perception-mode registry: properties instead of names, every CLI offers every mode, a new mode is one entry."""

from __future__ import annotations

import gymnasium as gym
import pytest

from weather_gym.cli import main
from weather_gym.core.errors import InputError
from weather_gym.pipeline.modes import (
    CONES,
    PERCEPTION_MODES,
    RENDER_FREE,
    PerceptionMode,
    auto_mode,
    check_agent_observes,
    modes_where,
    perception_mode,
)

SMALL = "WeatherGym/ConeTrackSmall-v0"


def _state_only(env: gym.Env, weather, kwargs: dict) -> gym.Env:
    """A toy mode: the render-free env's odometry state and nothing else (no perception at all)."""
    if kwargs:
        raise InputError(f"perception 'toy' takes no perception_kwargs, got {sorted(kwargs)}")
    return env


TOY = PerceptionMode("toy", "odometry only: no camera, no cones", _state_only, frozenset({"state"}),
                     renders_frames=False, takes_weather=False, can_record_video=False, env_overrides=RENDER_FREE)


@pytest.fixture
def toy_mode(monkeypatch):
    monkeypatch.setitem(PERCEPTION_MODES, "toy", TOY)
    return TOY


def test_modes_carry_their_properties():
    assert modes_where(renders_frames=False) == ["gt_cones", "surrogate", "lidar"]
    assert modes_where(takes_weather=False) == ["gt_cones"]
    assert modes_where(takes_lidar_weather=True) == ["lidar", "fused"]
    assert modes_where(is_scored=True) == ["detector", "fused"]
    assert modes_where(gives_detections=True) == ["detector", "surrogate", "fused"]
    assert modes_where(can_record_video=True) == ["camera", "detector", "oracle"]
    assert all(PERCEPTION_MODES[n].observation == CONES
               for n in ("detector", "oracle", "gt_cones", "surrogate", "lidar", "fused"))
    with pytest.raises(InputError, match="unknown perception 'sonar'; valid: camera, detector"):
        perception_mode("sonar")


def test_auto_picks_the_first_mode_that_gives_what_the_agent_reads():
    from weather_gym.agents import agent_observes

    assert auto_mode(agent_observes("mapper_pure_pursuit")).name == "detector"
    assert auto_mode(agent_observes("ppo_cones")).name == "detector"
    assert auto_mode(agent_observes("gt_pure_pursuit")).name == "camera"
    assert auto_mode(agent_observes("sb3")).name == "camera"  # undeclared: not checked


def test_an_agent_on_a_mode_without_its_observation_is_a_typed_error(tmp_path, capsys):
    from weather_gym.cli.lap import run_laps
    from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells

    with pytest.raises(InputError, match=r"agent 'mapper_pure_pursuit' reads obs\['cones', 'mask'\].*perception "
                                         r"'camera'.*modes for this agent: detector, oracle, gt_cones, surrogate, lidar"):
        check_agent_observes("mapper_pure_pursuit", CONES, "camera")
    with pytest.raises(InputError, match="reads obs"):
        make_cells(EvalConfig(agents=("mapper_pure_pursuit",), perception="camera", severities=(0,), seeds=(0,)))
    with pytest.raises(InputError, match="reads obs"):
        run_laps(agent="mapper_pure_pursuit", perception="camera", env_id=SMALL)
    assert main(["lap", "--agent", "ppo_cones", "--perception", "camera"]) == 2
    assert "reads obs" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["lap", "evaluate"])
def test_every_cli_offers_every_mode(command, toy_mode, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in PERCEPTION_MODES) and "toy" in text


def test_a_mode_registered_in_one_place_runs_through_pipeline_lap_and_evaluate(toy_mode):
    from weather_gym.cli.lap import format_result, run_laps
    from weather_gym.lab.evaluation.evaluate import EvalConfig, make_cells, run_cell
    from weather_gym.pipeline import make_env

    env = make_env(SMALL, perception="toy", max_episode_steps=10)
    try:
        obs, _ = env.reset(seed=0)
        assert set(obs) == {"state"} and env.unwrapped.renderer == "none"  # the mode's env_overrides applied
    finally:
        env.close()

    result = run_laps(env_id=SMALL, agent="gt_pure_pursuit", perception="toy", max_steps=30)
    assert result["perception"] == "toy" and result["steps"] == 30
    text = format_result(result)
    assert "perception toy" in text and "renderer none" in text and "detector:" not in text

    cells = make_cells(EvalConfig(agents=("gt_pure_pursuit",), effects=("dim",), severities=(0,), seeds=(0,),
                                  perception="toy", max_steps=30, env_id=SMALL))
    row = run_cell(cells[0])
    assert row["steps"] == 30 and row["det_frames"] == 0 and row["det_map50"] is None
    with pytest.raises(InputError, match="perception toy renders no camera frame.*dim@2"):
        make_cells(EvalConfig(agents=("gt_pure_pursuit",), effects=("dim",), severities=(2,), perception="toy"))
    with pytest.raises(InputError, match="reads obs"):  # a cone-list agent is refused on it
        make_cells(EvalConfig(agents=("mapper_pure_pursuit",), effects=("dim",), severities=(0,), perception="toy"))
