"""Calibration: sweep an effect's k, measure the detector, and read off k per measured severity.

The reference study's method (Fursa et al., Sections 3.5 and 4) as a reusable tool:

* :mod:`~weather_gym.lab.calibration.sweep` - ``run_sweep``: mAP@0.5 (and per-class AP, recall by range)
  of the detector at each (effect, k, seed) on a fixed rendered set, on the evaluation runner
  (parallel, resumable, progress bar) -> a tidy ``curves.csv`` (``weather-gym sweep``);
* :mod:`~weather_gym.lab.calibration.curve` - ``load_curves``, ``invert``: the mean curve over seeds,
  inverted by interpolation with an interval from the seed spread; unreachable targets reported;
* :mod:`~weather_gym.lab.calibration.measured` - measured levels from a CSV table or labelled image sets;
* :mod:`~weather_gym.lab.calibration.shapes` - the study's two shapes (linear, exponential) fitted, R^2;
* :mod:`~weather_gym.lab.calibration.calibrate` - ``calibrate``, ``remeasure``, ``write_presets``
  (``weather-gym calibrate``), the format ``weather_gym.weather.presets`` reads;
* :mod:`~weather_gym.lab.calibration.report` - plots and the Markdown report;
* :mod:`~weather_gym.lab.calibration.resolve` - ``resolve_presets``: the calibrated presets resolved for one
  scenario (track, camera, world, detector), cached on disk (``weather-gym calibrate --track``,
  ``--presets resolved``); :mod:`~weather_gym.lab.calibration.frame_ap` - its bootstrap over frames.

``PHYSICAL_PRESETS`` is the alternative presets file whose ``low_light`` uses the physical dim mode
(pass it as ``path=`` to ``weather_gym.weather.preset_spec`` or ``--presets`` to ``weather-gym evaluate``).
See ``docs/calibration.md``.

Example:
    >>> from weather_gym.lab.calibration import invert
    >>> round(invert([0.0, 1.0], [1.0, 0.0], 0.25).k, 3)
    0.75
"""

from __future__ import annotations

from pathlib import Path

from weather_gym.core._lazy import lazy_exports

PHYSICAL_PRESETS = Path(__file__).with_name("presets_physical.toml")
"""Presets calibrated like the shipped ones, with ``low_light`` = ``dim`` in ``mode="physical"``."""

_LAZY = {
    "Curve": "weather_gym.lab.calibration.curve",
    "Inversion": "weather_gym.lab.calibration.curve",
    "invert": "weather_gym.lab.calibration.curve",
    "load_curves": "weather_gym.lab.calibration.curve",
    "monotone_decreasing": "weather_gym.lab.calibration.curve",
    "MeasuredLevel": "weather_gym.lab.calibration.measured",
    "load_measured": "weather_gym.lab.calibration.measured",
    "read_measured_table": "weather_gym.lab.calibration.measured",
    "measure_datasets": "weather_gym.lab.calibration.measured",
    "ShapeFit": "weather_gym.lab.calibration.shapes",
    "fit_shapes": "weather_gym.lab.calibration.shapes",
    "PresetCalibration": "weather_gym.lab.calibration.calibrate",
    "calibrate": "weather_gym.lab.calibration.calibrate",
    "remeasure": "weather_gym.lab.calibration.calibrate",
    "write_presets": "weather_gym.lab.calibration.calibrate",
    "SweepCell": "weather_gym.lab.calibration.sweep",
    "SweepEffect": "weather_gym.lab.calibration.sweep_effect",
    "make_sweep_cells": "weather_gym.lab.calibration.sweep",
    "parse_effect": "weather_gym.lab.calibration.sweep_effect",
    "parse_k_range": "weather_gym.lab.calibration.sweep",
    "run_sweep": "weather_gym.lab.calibration.sweep",
    "run_sweep_cell": "weather_gym.lab.calibration.sweep",
    "Scenario": "weather_gym.lab.calibration.resolve",
    "Resolution": "weather_gym.lab.calibration.resolve",
    "resolve_presets": "weather_gym.lab.calibration.resolve",
    "plot_curves": "weather_gym.lab.calibration.report",
    "write_report": "weather_gym.lab.calibration.report",
}

__all__ = sorted([*_LAZY, "PHYSICAL_PRESETS"])
__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
