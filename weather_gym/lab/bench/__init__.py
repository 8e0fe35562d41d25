"""Benchmark targets for ``weather-gym bench``; ``benchmarks/*.py`` are thin scripts over these.

Example:
    >>> import pkgutil, weather_gym.lab.bench
    >>> sorted(m.name for m in pkgutil.iter_modules(weather_gym.lab.bench.__path__) if not m.name.startswith("_"))
    ['detector', 'env', 'gap', 'gt', 'lidar', 'resolve', 'sensors', 'sim', 'surrogate', 'train', 'weather']
"""
