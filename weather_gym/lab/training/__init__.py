"""Training: the cone detector (``detector``), the PPO driver (``policy``), the perception surrogate's
episode logs and validation (``surrogate``).

Example:
    >>> import pkgutil, weather_gym.lab.training
    >>> sorted(m.name for m in pkgutil.iter_modules(weather_gym.lab.training.__path__))
    ['detector', 'policy', 'surrogate']
"""
