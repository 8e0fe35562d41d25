"""Validation of the gap workflow on hidden effects it was never shown (:mod:`.hidden`: the generator,
independent of the weather library; :mod:`.runner`: scenes, splits, rates with Wilson intervals).

Example:
    >>> from weather_gym.lab.gap.validation import FAMILIES
    >>> FAMILIES[-1]
    'none'
"""

from weather_gym.lab.gap.validation.hidden import ACCEPTED, FAMILIES, HiddenCase, draw_case
from weather_gym.lab.gap.validation.runner import (
    SCENES,
    SETTINGS,
    SPLITS,
    CaseResult,
    run_validation,
    summarize,
    table,
    wilson,
)

__all__ = ["ACCEPTED", "FAMILIES", "HiddenCase", "draw_case", "SCENES", "SETTINGS", "SPLITS", "CaseResult",
           "run_validation", "summarize", "table", "wilson"]
