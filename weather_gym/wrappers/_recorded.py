"""``Recorded``: a live object (a detector, a surrogate model) as a wrapper's ``env.spec`` records it.

Gymnasium rebuilds a stack from ``env.spec`` and checks that the rebuilt wrappers' arguments equal
the recorded ones; a model object compares by identity (or, holding arrays, not at all). ``Recorded``
compares by the object's pickled bytes (a detector pickles as its model file and options), so a copy
equals the original; an object that cannot be pickled equals only itself.

Example:
    >>> import numpy as np
    >>> Recorded({"w": np.arange(3)}) == Recorded({"w": np.arange(3)}), Recorded(1) == Recorded(2)
    (True, False)
"""

from __future__ import annotations

import hashlib
import pickle
from typing import Any

__all__ = ["Recorded", "recorded", "unrecorded"]


class Recorded:
    """A value of ``env.spec``'s wrapper arguments that equals any value with the same pickled bytes."""

    def __init__(self, value: Any) -> None:
        self.value = value

    def _key(self) -> Any:
        try:
            return hashlib.sha256(pickle.dumps(self.value, protocol=5)).hexdigest()
        except Exception:  # noqa: BLE001 - anything unpicklable (a session, a lambda) is itself only
            return id(self.value)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Recorded) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return f"Recorded({self.value!r})"


def recorded(value: Any, plain: tuple[type, ...] = ()) -> Any:
    """``value`` as a wrapper records it: None and ``plain`` types as they are, anything else ``Recorded``."""
    return value if value is None or isinstance(value, (*plain, Recorded)) else Recorded(value)


def unrecorded(value: Any) -> Any:
    """The value a wrapper rebuilt from ``env.spec`` receives back."""
    return value.value if isinstance(value, Recorded) else value
