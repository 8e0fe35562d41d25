"""The lab: what makes or measures the library (datasets, training, evaluation, calibration, the gap workflow, benchmarks). Nothing in the library imports it."""
