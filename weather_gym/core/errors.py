"""The errors weather-gym raises for things a user can fix: one small hierarchy.

Everything a user can cause (a bad value, argument, spec or file; an output that exists; a path
that leaves its folder; a parameter out of its physical range) raises a subclass of
:class:`WeatherGymError`. The command line prints those as ``error: MESSAGE`` and exits with
status 2; any other exception is a bug and keeps its traceback. The classes also derive from the
built-in exception a caller would expect (``ValueError``, ``FileNotFoundError``,
``FileExistsError``, ``OSError``), so ``except ValueError`` around the Python API keeps working.

::

    WeatherGymError
    ├── InputError (ValueError)                bad value, argument, spec
    │   ├── FileFormatError                    a file whose content is wrong (names the file)
    │   ├── OutsideRootError                   a path that escapes its root folder
    │   ├── LimitError                         a parameter outside its physical/allowed bounds
    │   ├── ResolutionError                    a preset cannot be resolved for a scenario (why, and the fix)
    │   └── MissingInputError (FileNotFoundError)  a named input file or folder is not there
    ├── OutputExistsError (FileExistsError)    refusing to overwrite without ``--overwrite``
    ├── OutputPathError (OSError)              an output that cannot be written there
    ├── StateError (RuntimeError)              an object used in the wrong state (step after close)
    └── MissingDependencyError (ImportError)   an optional extra is not installed

:func:`check_known` is the one check behind every "unknown key" error: a table, a dict of options or
keyword arguments that holds a name its reader does not know.

Example:
    >>> from weather_gym.core.errors import InputError, WeatherGymError
    >>> try:
    ...     raise InputError("--k must be in [0, 1], got 2.0")
    ... except ValueError as exc:          # still a ValueError for existing callers
    ...     isinstance(exc, WeatherGymError)
    True
    >>> check_known({"k": 1, "radius": 3}, ("k", "sigma"), what="blur", kind="parameter")
    Traceback (most recent call last):
    ...
    weather_gym.core.errors.InputError: blur: unknown parameter(s) ['radius']; valid parameters: ['k', 'sigma']
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "WeatherGymError",
    "InputError",
    "FileFormatError",
    "OutsideRootError",
    "LimitError",
    "ResolutionError",
    "MissingInputError",
    "OutputExistsError",
    "OutputPathError",
    "StateError",
    "MissingDependencyError",
    "check_known",
    "Terminated",
]


class WeatherGymError(Exception):
    """Base of every error a user can fix; the CLI prints it as ``error: ...`` and exits 2."""


class InputError(WeatherGymError, ValueError):
    """A bad value, argument or spec (the message names it and what was expected)."""


class FileFormatError(InputError):
    """A file whose content is wrong: malformed, wrong type, bad key or value (the message names the file)."""


class OutsideRootError(InputError):
    """A path read from a file (dataset, model, scenario) that leaves the folder it must stay in."""


class LimitError(InputError):
    """A parameter outside its physical or allowed range (checked before any work starts)."""


class ResolutionError(InputError):
    """A preset cannot be resolved for a scenario: too few visible cones, a clear mAP too low to measure a
    drop, a target out of the effect's reach, or a damage not known within the tolerance (the message
    names the scenario, the number and what would fix it)."""


class MissingInputError(InputError, FileNotFoundError):
    """A named input file or folder does not exist."""


class OutputExistsError(WeatherGymError, FileExistsError):
    """An output exists and would be replaced: refused unless ``--overwrite`` / ``overwrite=True``."""


class OutputPathError(WeatherGymError, OSError):
    """An output cannot be written where it was asked for (a folder in the way, no permission, ...)."""


class StateError(WeatherGymError, RuntimeError):
    """An object used in a state that does not allow it (e.g. ``step`` after ``close``)."""


class MissingDependencyError(WeatherGymError, ImportError):
    """An optional extra is needed (the message says which ``pip install`` brings it)."""


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM while a command runs (``weather_gym.cli.run_command``), so that
    cleanup runs and a long run saves what it has, as after Ctrl-C; not an error (exit status 143)."""


def check_known(given: Iterable[str], valid: Iterable[str], *, what: str, kind: str = "key",
                error: type[InputError] = InputError, hint: str = "") -> None:
    """Raise ``error`` when ``given`` (names, or a dict's keys) holds any name that is not in ``valid``.

    The message names the unknown ones (sorted) and the valid ones (in their order; a set sorted):
    ``WHAT: unknown KIND(s) [...]; valid KINDs: [...]HINT``.
    """
    names = list(valid)
    unknown = sorted(set(given) - set(names))
    if unknown:
        shown = sorted(names) if isinstance(valid, (set, frozenset)) else names
        raise error(f"{what}: unknown {kind}(s) {unknown}; valid {kind}s: {shown}{hint}")
