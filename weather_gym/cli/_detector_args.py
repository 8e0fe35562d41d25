"""The detector options of every command that runs a detector (one definition, the same meaning everywhere).

``--detector SPEC`` (``conenet`` = the shipped model, ``conenet:PATH``, ``yolov8:PATH``,
``yolov5:PATH``, ``yolo:PATH``, or a bare ConeNet ``PATH.onnx``), ``--detector-classes``,
``--detector-resize``, ``--detector-input``, ``--detector-threshold``; see
``weather_gym.perception.detector_spec``. Commands that had ``--model PATH`` keep it as another
spelling of ``--detector conenet:PATH``.

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_detector_args(parser)
    >>> spec = detector_spec_from_args(parser.parse_args(["--detector", "conenet", "--detector-threshold", "0.4"]))
    >>> spec.kind, spec.path, spec.score_threshold
    ('conenet', None, 0.4)
"""

from __future__ import annotations

from typing import Any

from weather_gym.core._io import declare_inputs
from weather_gym.core.errors import InputError
from weather_gym.perception.detector_spec import parse_detector_spec


def add_detector_args(p, *, what: str | None = None, legacy_model: bool = False) -> None:
    """Add the detector options to the parser ``p`` (``legacy_model``: also accept ``--model PATH``)."""
    extra = f" ({what})" if what else ""
    p.add_argument("--detector", default=None, metavar="SPEC",
                   help="detector: conenet (the shipped model, default), conenet:PATH, yolov8:PATH (also v11), "
                        "yolov5:PATH or yolo:PATH (an ONNX export; layout recognised)" + extra)
    if legacy_model:
        p.add_argument("--model", dest="detector_model", default=None, metavar="PATH.onnx",
                       help="a ConeNet ONNX model (the same as --detector conenet:PATH)")
    p.add_argument("--detector-classes", default=None, metavar="ID=CLASS,...",
                   help="class map of a YOLO detector: output index or name = blue|yellow|orange|big_orange|ignore "
                        "(default: the export's class names, FSOCO style)")
    p.add_argument("--detector-resize", default=None, choices=("letterbox", "stretch"),
                   help="how a YOLO detector's input is made (default letterbox)")
    p.add_argument("--detector-input", default=None, metavar="WxH",
                   help="input size of a YOLO export with a dynamic input (e.g. 640x640); the ConeNet input "
                        "follows the camera (672x376 -> 512x288) unless pinned: WxH (multiples of 32) or native")
    p.add_argument("--detector-threshold", type=float, default=None,
                   help="operating score threshold (default: the detector's)")


def detector_spec_from_args(args) -> Any:
    """The :class:`~weather_gym.perception.detector_spec.DetectorSpec` the options describe (checked)."""

    spec = getattr(args, "detector", None)
    model = getattr(args, "detector_model", None)
    if model is not None:
        if spec is not None:
            raise InputError("give either --detector or --model, not both")
        spec = f"conenet:{model}"
    parsed = parse_detector_spec(spec, classes=getattr(args, "detector_classes", None),
                                 resize=getattr(args, "detector_resize", None),
                                 input_size=getattr(args, "detector_input", None),
                                 score_threshold=getattr(args, "detector_threshold", None))
    declare_inputs(parsed.path)  # the model is an input of the command: never one of its outputs
    return parsed


def detector_from_args(args, *, required: bool = True, threads: int = 1) -> Any:
    """The loaded detector (``required=False``: None when no detector option was given)."""
    given = any(getattr(args, k, None) is not None for k in ("detector", "detector_model", "detector_classes",
                                                            "detector_resize", "detector_input",
                                                            "detector_threshold"))
    if not required and not given:
        return None
    return detector_spec_from_args(args).load(threads=threads)
