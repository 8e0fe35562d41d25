"""Training the cone detector: the torch network (``conenet``), the loop and export (``train``), pictures
and k sweeps of a detector (``plots``). Needs the ``train`` extra (torch, onnx).

Example:
    >>> import pkgutil, weather_gym.lab.training.detector
    >>> sorted(m.name for m in pkgutil.iter_modules(weather_gym.lab.training.detector.__path__))
    ['conenet', 'plots', 'train']
"""
