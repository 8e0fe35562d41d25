"""``ConeArrays``: the per-cone arrays of one frame (ground truth, detections) as one read-only object.

A frame's ground truth is a handful of arrays with one row per visible cone (``boxes`` (K, 4),
``classes`` (K,), ...); K changes every step. ``ConeArrays`` is a read-only ``Mapping`` of them and
deliberately *not* a ``dict``: Gymnasium's vector envs stack a dict's arrays key by key (which fails
as soon as two envs see a different number of cones) but keep any other object as it is, one per
env. ``gt["boxes"]``, ``gt.get(...)``, ``dict(gt)`` and ``gt.to_dict()`` work as on a dict;
``==`` compares the arrays (so ``gymnasium.utils.env_checker`` can check determinism).

Example:
    >>> import numpy as np
    >>> from weather_gym.core.cone_arrays import ConeArrays
    >>> gt = ConeArrays(boxes=np.zeros((2, 4), np.float32), classes=np.array([0, 1]))
    >>> len(gt), gt.count, sorted(gt)
    (2, 2, ['boxes', 'classes'])
    >>> gt == ConeArrays(boxes=np.zeros((2, 4), np.float32), classes=np.array([0, 1]))
    True
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from weather_gym.core.errors import InputError

__all__ = ["ConeArrays"]


class ConeArrays(Mapping):
    """Named numpy arrays with one row per cone (all the same length); read-only.

    ``len()`` is the number of arrays (as for a dict); ``count`` is the number of cones.
    """

    __slots__ = ("_arrays",)

    def __init__(self, arrays: Mapping[str, Any] | None = None, /, **named: Any) -> None:
        items = {**dict(arrays or {}), **named}
        out: dict[str, np.ndarray] = {}
        n = None
        for key, value in items.items():
            a = np.asarray(value)
            if a.ndim == 0:
                raise InputError(f"ConeArrays: {key!r} must have one row per cone, got a scalar")
            if n is None:
                n = a.shape[0]
            elif a.shape[0] != n:
                raise InputError(f"ConeArrays: {key!r} has {a.shape[0]} rows, the others {n}")
            a = a.view()
            a.flags.writeable = False
            out[key] = a
        self._arrays = out

    @classmethod
    def trusted(cls, arrays: dict[str, np.ndarray]) -> ConeArrays:
        """Wrap ``arrays`` (numpy arrays of one length, made by the caller: not checked) read-only;
        the per-step fast path of the env and the wrappers."""
        out = cls.__new__(cls)
        for a in arrays.values():
            a.flags.writeable = False
        out._arrays = arrays
        return out

    @property
    def count(self) -> int:
        """Number of cones (rows)."""
        for a in self._arrays.values():
            return int(a.shape[0])
        return 0

    def __getitem__(self, key: str) -> np.ndarray:
        return self._arrays[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._arrays)

    def __len__(self) -> int:
        return len(self._arrays)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ConeArrays):
            return NotImplemented
        return self.keys() == other.keys() and all(
            self[k].shape == other[k].shape and self[k].dtype == other[k].dtype and np.array_equal(self[k], other[k])
            for k in self)

    __hash__ = None  # type: ignore[assignment]  # holds arrays: not hashable

    def to_dict(self) -> dict[str, np.ndarray]:
        """A plain dict of (writable) copies of the arrays."""
        return {k: np.array(v) for k, v in self._arrays.items()}

    def select(self, rows: np.ndarray) -> ConeArrays:
        """The cones ``rows`` (an index or boolean array)."""
        return ConeArrays({k: v[rows] for k, v in self._arrays.items()})

    def __reduce__(self) -> tuple[type[ConeArrays], tuple[dict[str, np.ndarray]]]:
        return (ConeArrays, (self.to_dict(),))

    def __repr__(self) -> str:
        return f"ConeArrays({self.count} cones: {', '.join(self._arrays)})"
