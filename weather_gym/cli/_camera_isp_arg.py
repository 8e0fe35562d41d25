"""``--camera-model realistic|ideal|FILE.toml``: the camera's finishing stage, as commands take it.

Example:
    >>> from weather_gym.cli._camera_isp_arg import camera_model_arg
    >>> camera_model_arg("ideal").enabled, camera_model_arg("realistic").jpeg_quality
    (False, 90)
"""

from __future__ import annotations

from pathlib import Path

from weather_gym.camera.isp import CameraModel
from weather_gym.core._toml import read_toml
from weather_gym.core.errors import InputError

__all__ = ["add_camera_model_arg", "camera_model_arg"]


def add_camera_model_arg(parser, default_text: str, help_text: str) -> None:
    """Add ``--camera-model`` (default None: the command's own default, named in ``help_text``)."""
    parser.add_argument("--camera-model", default=None, metavar="realistic|ideal|FILE.toml",
                        help=f"{help_text} (default: {default_text})")


def camera_model_arg(value: str | None) -> CameraModel | None:
    """``--camera-model``: ``realistic``, ``ideal`` or a TOML file of ``CameraModel`` fields (top-level keys);
    None (not given): None, the command's own default."""
    if value is None:
        return None
    if value == "realistic":
        return CameraModel.realistic()
    if value == "ideal":
        return CameraModel.ideal()
    path = Path(value)
    if path.suffix.lower() != ".toml":
        raise InputError(f"--camera-model expects realistic, ideal or a .toml file of CameraModel fields, got {value!r}")
    table = read_toml(path, "--camera-model file")
    try:
        return CameraModel.from_dict(table.get("camera_model", table))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
