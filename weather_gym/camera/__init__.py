"""The camera model: pinhole intrinsics (``config``) and the camera's image pipeline (``isp``)."""
