"""The package's version, in one place (``pyproject.toml`` reads it from here through hatch).

Example:
    >>> from weather_gym.core.version import __version__
    >>> __version__.count(".")
    2
"""

__version__ = "0.1.0"
