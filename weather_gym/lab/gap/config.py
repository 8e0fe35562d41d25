"""Settings of a gap run (:class:`GapConfig`), a model's comparison with the measured frames
(:class:`Comparison`) and the rules the workflow adds effects by (the evidence each effect needs, the
smallest gap cut worth an effect).

Example:
    >>> GapConfig().held_out, REQUIRES["dim"]
    (0.5, ('brightness', 'tone_p50'))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, Field, InstanceOf

from weather_gym.camera.isp import CameraModel
from weather_gym.core.schema import ListAsTuple, NonNegativeInt, OneOf, PositiveInt, check_fields
from weather_gym.lab.gap.compare import ALPHA, MIN_EFFECT
from weather_gym.lab.gap.diagnose import significant_signals
from weather_gym.lab.gap.measured import MEASURED
from weather_gym.lab.gap.simulate import COMPARE_WIDTH, MIN_FRAMES, MODES
from weather_gym.sim.config import SCENES
from weather_gym.weather import EFFECTS, KnobEffect

REPORT_VERSION = 2

MIN_GAP_CUT = 0.1
"""Smallest held-out gap cut (in scene-to-scene spreads) for which an effect is added or kept."""

CLIP_EXPLAINS = 0.5
"""A fit clipped by its family's range is still added (flagged :data:`BEYOND_RANGE`) when it takes the
held-out gap to at most this fraction of what it was: the family is right, the model needs more of it."""

BEYOND_RANGE = "the measured effect goes beyond this family's range"

#: the evidence an effect cannot be named without (its fingerprint): at least one of these signals or
#: signal families must disagree (a further effect without it is not added at all, only reported as
#: a candidate). ``dim`` darkens the frame, so noise alone (or noise that only moves
#: the extreme percentiles) is not dim; each kind's effects need their kind's signals; ``glare`` (a
#: veil and bloom) is never a fix for the noise signals alone
REQUIRES: dict[str, tuple[str, ...]] = {"dim": ("brightness", "tone_p50"), "exposure": ("tone",), "tone_curve": ("tone", "colour"),
                                        "noise": ("noise",), "noise_level": ("noise",), "vignette": ("vignette",),
                                        "radial_gain": ("vignette",), "glare": ("blobs", "tone", "haze"),
                                        "blur_kernel": ("sharpness", "motion", "cones")}
#: the evidence a further effect (after the first) cannot be added without, on top of :data:`REQUIRES`:
#: drops and streaks leave bright featureless tiles (``droplets`` and ``rain`` as the first effect are
#: ranked by their fit alone: on real frames their other signals name them)
FURTHER_REQUIRES: dict[str, tuple[str, ...]] = {"droplets": ("blobs",), "rain": ("blobs",)}
#: the parametric and measured effects of each kind
KIND_EFFECTS: dict[str, tuple[str, ...]] = {"tone": ("exposure", "tone_curve"), "noise": ("noise", "noise_level"),
                                            "sharpness": ("blur", "blur_kernel"), "motion": ("motion_blur",),
                                            "vignette": ("vignette", "radial_gain")}
#: the signal family that is each effect's main fingerprint (for the verdict's advice)
EFFECT_FAMILY: dict[str, str] = {"blur": "sharpness", "motion_blur": "motion", "noise": "noise", "noise_level": "noise",
                                 "exposure": "tone", "dim": "tone", "tone_curve": "tone", "fog": "haze",
                                 "vignette": "vignette", "radial_gain": "vignette", "jpeg": "block",
                                 "droplets": "blobs", "glare": "blobs", "rain": "blobs", "blur_kernel": "sharpness"}
#: signal families whose disagreement lets a measured member be measured (default: its kind)
MEASURED_KINDS: dict[str, tuple[str, ...]] = {"blur_kernel": ("sharpness", "motion"),
                                              # a curve per channel (a colour cast) may move only the colour signals
                                              "tone_curve": ("tone", "colour")}
#: effects that change every pixel alike (no dependence on the distance from the centre)
GLOBAL_TONE = ("exposure", "dim", "tone_curve")
#: effects that a radial one goes before when the fall-off to the corners disagrees: the global tone
#: changes, and the local bright-tile effects (a fall-off darkens the bright sky tiles of the corners,
#: which drops, streaks and a veil also change)
RADIAL_FIRST = (*GLOBAL_TONE, "droplets", "rain", "glare")
EVIDENCE_MARGIN = 2.0
"""A radial candidate within this factor of the penalised gap of a global tone change or a bright-tile
effect (:data:`RADIAL_FIRST`) is named before it when the fall-off to the corners disagrees."""

SECOND_SHARE = 0.15
"""A second (third, ...) effect is added only when, on its own, it cuts at least this share of the
remaining held-out gap above the floor (:meth:`~weather_gym.lab.gap.session.GapSession.floor`) and
cuts at least the floor itself (unpaired: less than two sets of clean frames differ by cannot be told
from the scene); otherwise it is reported as a candidate (``candidates``), not added."""

FLOOR_MARGIN = 1.0
"""Unpaired, the loop stops once the held-out gap is within this factor of the floor (clear against
clear): what is left cannot be told from two sets of different frames."""

#: what cannot be told without poses, and why (the unpaired report lists these)
UNPAIRED_LIMITS: dict[str, str] = {
    "blur": "without poses only the power spectrum of a blur is measurable (no per-frame phase): the kind "
            "(sharpness, motion) is named, the kernel's shape (disc, box, Gaussian, a line's direction) is not",
    "haze": "haze lifts far regions more than near ones; without poses the measured frames' depth is unknown "
            "and the rendered frames' depth stands in, so a weak haze is read as a tone change",
    "tone": "a tone curve is measured by matching distributions of other frames: scene differences between "
            "the two sets (looks, route) shift it by up to the floor",
    "falloff": "a radial fall-off is told from a tone curve by the corner / centre level at equal levels; "
               "without poses scene content in the corners differs between the sets, so a weak fall-off is "
               "within the floor",
}

PERCEPTION_MIN_MAP = 0.3
"""Below this mAP@0.5 on the measured clear frames the perception gap means nothing (the report says so)."""



def _known_effects(names: tuple[str, ...] | None) -> tuple[str, ...] | None:
    """``GapConfig.candidates``: registered effects or measured members (an unknown name lists the valid ones)."""
    for name in names or ():
        if name not in MEASURED:
            EFFECTS.get(name)
    return names


@dataclass(frozen=True)
class GapConfig:
    """Settings of a gap run (all have defaults; the CLI exposes the common ones).

    Attributes:
        seed: seeds the split, the bootstrap and every effect's random numbers.
        mode: ``auto`` / ``paired`` / ``unpaired`` / ``same-camera`` / ``did`` (the last two need a
            clear reference; see :func:`~weather_gym.lab.gap.simulate.simulate`).
        tracks: tracks to render in unpaired and did modes (default: the records' tracks).
        sim_frames: frames to render in unpaired / did mode (default: as many as measured).
        scene: the simulator world of unpaired / did renders (``"plain"`` or ``"realistic"``; default: the
            one the records name, else the default world).
        camera_model: the camera model of unpaired / did renders (a ``CameraModel``; default: the one the
            records name when they all agree, else the env's default ``CameraModel.realistic()``).
        compare_width: frames wider than this are scaled down once on loading.
        held_out: fraction of the frames held out for the reported gaps.
        fit_frames: at most this many fitting frames are used by the parameter search.
        max_steps: at most this many effects are added.
        candidates: effect names that may be added (default: every registered effect and every measured
            member, :mod:`~weather_gym.lab.gap.measured`).
        top: candidates fully fitted per step (the best of the k-grid screening).
        alpha: family-wise significance level (Holm) of disagreements and of a step.
        min_effect: smallest standardised bias reported as a disagreement.
        bootstrap: bootstrap resamples of the image signals (perception uses 300).
        perception: run the detector (the report's perception level).
        detector: a detector spec (``"yolov8:model.onnx"``, a ``DetectorSpec``; default: the shipped
            detector; see ``weather_gym.perception.load_detector``).
        prune: after the loop, drop every added effect whose removal does not worsen the held-out
            gap significantly.
    """

    seed: int = 0
    mode: Annotated[str, OneOf(MODES)] = "auto"
    tracks: Annotated[tuple[str, ...] | None, ListAsTuple] = None
    sim_frames: Annotated[int, Field(ge=MIN_FRAMES)] | None = None
    scene: Annotated[str, OneOf(SCENES)] | None = None
    camera_model: InstanceOf[CameraModel] | None = None
    held_out: Annotated[float, Field(gt=0, lt=1)] = 0.5
    fit_frames: Annotated[int, Field(ge=4)] = 32
    max_steps: NonNegativeInt = 4
    candidates: Annotated[tuple[str, ...] | None, ListAsTuple, AfterValidator(_known_effects)] = None
    top: PositiveInt = 2
    alpha: Annotated[float, Field(gt=0, lt=1)] = ALPHA
    min_effect: float = MIN_EFFECT
    bootstrap: Annotated[int, Field(ge=100)] = 1000
    perception: bool = True
    detector: Any = None
    prune: bool = True
    compare_width: Annotated[int, Field(ge=64)] | None = COMPARE_WIDTH
    progress: bool = False

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass
class Comparison:
    """A model compared with the measured frames on the held-out frames."""

    model: list[KnobEffect]
    signals: np.ndarray
    rows: list[dict[str, Any]]
    gap: float
    perception_rows: list[dict[str, Any]] | None = None
    perception: dict[str, Any] | None = None

    @property
    def significant(self) -> list[str]:
        """Image signals that disagree significantly, strongest first."""
        return significant_signals(self.rows)

    @property
    def perception_gap(self) -> float:
        return math.nan if self.perception is None else self.perception["abs_diff"]

    def disagreements(self) -> list[dict[str, Any]]:
        """Perception rows then image rows, each group strongest first (the report's list)."""
        def order(rows):
            return sorted(rows, key=lambda r: (not r["significant"], -_finite_abs(r["effect_size"])))

        return order(self.perception_rows or []) + order(self.rows)


def _finite_abs(v: float) -> float:
    return abs(v) if v is not None and math.isfinite(v) else -1.0
