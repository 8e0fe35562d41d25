"""What :class:`~weather_gym.lab.gap.session.GapSession` gives the parts of it that live in other modules
(:class:`~weather_gym.lab.gap.session_search.SearchSteps`, :class:`~weather_gym.lab.gap.session_report.ReportSteps`),
declared once for type checkers; the class holds nothing at run time.

Example:
    >>> from weather_gym.lab.gap.session import GapSession
    >>> issubclass(GapSession, SessionHost), vars(SessionHost).get("data", "declared only")
    (True, 'declared only')
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from weather_gym.lab.gap.config import Comparison, GapConfig
    from weather_gym.lab.gap.fit import Evaluator
    from weather_gym.lab.gap.simulate import GapData
    from weather_gym.weather import KnobEffect


class SessionHost:
    """The session's attributes and methods its step classes read (declared, not defined, here)."""

    if TYPE_CHECKING:  # what GapSession provides
        data: GapData
        config: GapConfig
        input_model: list[KnobEffect]
        model: list[KnobEffect]
        steps: list[dict[str, Any]]
        refits: list[dict[str, Any]]
        history: list[tuple[str, list[KnobEffect]]]
        timings: dict[str, float]
        log: list[str]
        pruned: list[dict[str, Any]]
        flagged: list[dict[str, Any]]
        attempts: list[dict[str, Any]]
        candidates: list[dict[str, Any]]
        _floors: dict[tuple, float]
        _after_level_cache: dict[tuple, list[str]]
        measured_signals: np.ndarray
        reference_signals: np.ndarray | None
        scale: np.ndarray
        weights: np.ndarray
        _fit_idx: tuple[np.ndarray, np.ndarray]
        fit_ev: Evaluator
        held_ev: Evaluator
        _fixed_matches: dict[str, Any]

        @property
        def detector(self) -> Any: ...
        def _say(self, msg: str) -> None: ...
        def floor(self) -> float: ...
        def _match(self, images: Sequence[np.ndarray], gts: Sequence[dict]) -> Any: ...
        def _fixed(self, which: str) -> Any: ...
        def compare(self, model: Sequence[KnobEffect] | None = None, *, perception: bool | None = None
                    ) -> Comparison: ...
