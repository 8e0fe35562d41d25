"""The ranking of candidates by the evidence each kind leaves (no rendering: the session is a stub)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from weather_gym.lab.gap.fit import Candidate, FitResult
from weather_gym.lab.gap.session_search import SearchSteps


class _Stub(SearchSteps):
    """A session whose held-out comparison says ``significant`` and whose global-curve checks say
    ``level_explains``; no frames."""

    def __init__(self, significant: list[str], *, position: bool, depth: bool) -> None:
        self._sig, self._pos, self._depth = significant, position, depth

    def compare(self, model=None, *, perception=True):  # type: ignore[override]
        return SimpleNamespace(significant=list(self._sig))

    def _disagreeing_kinds(self) -> list[str]:
        fam = {"vignette": "vignette", "bright_flat": "blobs", "haze_lift": "haze", "tone_p50": "tone",
               "brightness": "tone"}
        return list(dict.fromkeys(fam[s] for s in self._sig))

    def _level_explains_position(self) -> bool:
        return self._pos

    def _level_explains_depth(self) -> bool:
        return self._depth


def _found(name: str, gap: float) -> dict:
    f = FitResult(Candidate(name), None, 0, gap, 1)  # type: ignore[arg-type]  # the effect is not read
    f.effect = SimpleNamespace(name=name)  # type: ignore[assignment]
    return {"fit": f, "penalized": gap, "held_gap": gap}


@pytest.mark.parametrize("position, first", [(False, "vignette"), (True, "droplets")],
                         ids=["corners-beyond-level", "corners-by-level"])
def test_a_radial_fall_off_goes_before_droplets_when_the_corners_disagree_beyond_their_level(position, first):
    """A fall-off darkens the bright sky tiles of the corners, which droplets also change: when the corner /
    centre signal disagrees beyond what a global curve explains, the radial candidate (within a factor 2)
    is named first; when a global curve explains it, the radial one is not evidenced at all."""
    s = _Stub(["bright_flat", "vignette"], position=position, depth=True)
    ranked = s.rank([_found("droplets", 2.1), _found("vignette", 2.9)])
    assert ranked[0]["fit"].effect.name == first


@pytest.mark.parametrize("depth, first", [(False, "fog"), (True, "tone_curve")],
                         ids=["far-beyond-level", "far-by-level"])
def test_a_haze_goes_before_a_global_curve_when_far_and_near_disagree_beyond_their_level(depth, first):
    """A haze lifts far regions more than near ones at equal levels: when the far / near signals still
    disagree after a global curve, ``fog`` (within a factor 2) is named before the global tone change."""
    s = _Stub(["haze_lift", "tone_p50"], position=True, depth=depth)
    ranked = s.rank([_found("tone_curve", 1.2), _found("fog", 1.4)])
    assert ranked[0]["fit"].effect.name == first


def test_fog_far_behind_a_global_curve_is_not_promoted():
    """Outside the margin the better fit keeps its place."""
    s = _Stub(["haze_lift", "tone_p50"], position=True, depth=False)
    ranked = s.rank([_found("tone_curve", 0.5), _found("fog", 1.4)])
    assert ranked[0]["fit"].effect.name == "tone_curve"
