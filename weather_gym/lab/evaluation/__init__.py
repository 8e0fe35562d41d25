"""Robustness evaluation: a generic resumable cell runner, the evaluation grid, and its reports.

* :mod:`~weather_gym.lab.evaluation.runner` - ``run_cells(cells, cell_fn, results_path, ...)``: parallel
  (joblib: local processes or Ray), resumable, one stored row per cell
  (:mod:`~weather_gym.lab.evaluation.results_store`: SQLite, exported as a tidy CSV); reused by the calibration sweep.
* :mod:`~weather_gym.lab.evaluation.evaluate` - ``EvalConfig``, ``make_cells``, ``run_cell``, ``evaluate``:
  agents x tracks x effects x severities x seeds through weather presets.
* :mod:`~weather_gym.lab.evaluation.report` - ``write_report``: Markdown table and metric-vs-severity plots.

See ``docs/evaluation.md``. The heavy layers (sim, detector, agents) are imported inside functions.

Example:
    >>> from weather_gym.lab.evaluation import EvalConfig, make_cells
    >>> len(make_cells(EvalConfig(effects=("dim",), severities=(0, 4), seeds=(0, 1))))
    4
"""

from __future__ import annotations

# (the function ``evaluate`` is not re-exported: it would shadow the module of the same name)
from weather_gym.lab.evaluation.evaluate import EvalCell, EvalConfig, make_cells, run_cell
from weather_gym.lab.evaluation.report import aggregate, write_report
from weather_gym.lab.evaluation.runner import read_results, run_cells

__all__ = [
    "EvalCell", "EvalConfig", "aggregate", "make_cells", "read_results", "run_cell",
    "run_cells", "write_report",
]
