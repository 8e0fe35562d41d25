"""The camera model: pinhole intrinsics (``config``) and the camera's image pipeline (``isp``).

Example:
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.camera.isp import CameraModel
    >>> CameraConfig().width, CameraModel.ideal().distorts, CameraModel.realistic().distorts
    (672, False, True)
"""
