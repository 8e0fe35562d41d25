"""The surrogate at any camera size: box sizes in the detector's input pixels.

The detector letterboxes every camera frame into its input, so what decides whether it finds a cone
is the cone's box size *at its input* (``box height x`` :func:`~weather_gym.perception.labels.input_scale`),
not in camera pixels. The model's box-height feature is fitted in the fitting camera's pixels; at another
camera each box height is multiplied by :func:`box_factor`, the ratio of the two cameras' input scales,
so the same cone at the detector's input gets the same feature. Range, bearing, visibility (a fraction of
the cone's height) and crowding (an IoU) are size-free. Boxes the model stores in pixels (the logged false
positives away from every cone) are rescaled to the camera; boxes relative to a cone's box are size-free.

The detector's input for a camera is :func:`detector_input_size`: the shipped detector's
``input_size_for(width, height)`` (its input follows the camera: 336x188 -> 256x160, 672x376 ->
512x288, 1280x720 -> 512x288: it does not follow a larger camera up).

Example:
    >>> box_factor((672, 376), (672, 376))
    1.0
    >>> detector_input_size(672, 376)
    (512, 288)
"""

from __future__ import annotations

from typing import Any

from weather_gym.perception import onnx_detector
from weather_gym.perception.labels import input_scale

__all__ = ["box_factor", "detector_input_size", "fitted_input_size"]


def detector_input_size(width: int, height: int) -> tuple[int, int]:
    """(W, H) of the shipped detector's input for a ``width`` x ``height`` camera (its input follows the
    camera: :func:`weather_gym.perception.onnx_detector.input_size_for`)."""
    return onnx_detector.input_size_for(int(width), int(height))


def fitted_input_size(meta: dict[str, Any]) -> tuple[int, int] | None:
    """The detector input the model was fitted at: ``meta["detector_input"]`` (recorded by ``surrogate log``),
    else the shipped detector's input for the fitting camera (None: the model names no camera)."""
    given = meta.get("detector_input")
    if isinstance(given, list | tuple) and len(given) == 2:
        return int(given[0]), int(given[1])
    cam = meta.get("camera") or {}
    if "width" not in cam or "height" not in cam:
        return None
    return detector_input_size(int(cam["width"]), int(cam["height"]))


def box_factor(fit_camera: tuple[int, int], camera: tuple[int, int], *,
               fit_input: tuple[int, int] | None = None, camera_input: tuple[int, int] | None = None) -> float:
    """What a box height in ``camera`` pixels is multiplied by to be the model's feature: the camera's
    input scale over the fitting camera's (1.0 at the fitting camera). Inputs default to
    :func:`detector_input_size`.

    Example:
        >>> round(box_factor((672, 376), (1280, 720), fit_input=(512, 288), camera_input=(512, 288)), 4)
        0.525
    """
    fit_input = fit_input or detector_input_size(*fit_camera)
    camera_input = camera_input or detector_input_size(*camera)
    return input_scale(tuple(camera), tuple(camera_input)) / input_scale(tuple(fit_camera), tuple(fit_input))  # type: ignore[arg-type]  # (w, h) pairs
