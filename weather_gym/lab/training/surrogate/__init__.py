"""The perception surrogate's workshop: recording full-pipeline episodes to fit it on (``record``) and
validating a fitted model against the full pipeline (``validate``); ``weather-gym surrogate log`` /
``validate``. The model and its sampler are in :mod:`weather_gym.surrogate`.

Example:
    >>> import pkgutil, weather_gym.lab.training.surrogate
    >>> sorted(m.name for m in pkgutil.iter_modules(weather_gym.lab.training.surrogate.__path__))
    ['record', 'validate']
"""
