"""A scenario's ``[perception] detector``: a detector spec whose model file stays in the scenario's folder."""

from __future__ import annotations

import pytest


def test_a_scenario_names_its_detector_with_a_kind_prefix(tmp_path):
    """``detector = "yolov8:model.onnx"`` in a scenario: the file after the kind is confined to the
    scenario's folder (and a prefix is not taken for a path)."""
    from weather_gym.core.errors import OutsideRootError
    from weather_gym.envs.scenario import load_scenario

    (tmp_path / "model.onnx").write_bytes(b"")
    (tmp_path / "s.toml").write_text('id = "WeatherGym/S-v0"\n[perception]\nmode = "detector"\n'
                                     'detector = "yolov8:model.onnx"\n')
    assert load_scenario(tmp_path / "s.toml").perception["detector"] == f"yolov8:{tmp_path.resolve() / 'model.onnx'}"
    (tmp_path / "out.toml").write_text('id = "WeatherGym/S-v0"\n[perception]\nmode = "detector"\n'
                                       'detector = "yolo:../elsewhere.onnx"\n')
    with pytest.raises(OutsideRootError, match="detector"):
        load_scenario(tmp_path / "out.toml")
