"""The lab: what makes or measures the library (datasets, training, evaluation, calibration, the gap
workflow, benchmarks). Nothing in the library imports it; the CLI sits on top of it.

Example:
    >>> import pkgutil, weather_gym.lab
    >>> sorted(m.name for m in pkgutil.iter_modules(weather_gym.lab.__path__))
    ['bench', 'calibration', 'datasets', 'evaluation', 'gap', 'training']
"""
