"""Constants shared by the gap tests (imported as ``gap_cases``, like ``weather_cases``)."""

from __future__ import annotations

from weather_gym.camera.config import CameraConfig

GAP_CAMERA = CameraConfig().scaled(336, 188)
CLEAN_FRAMES = 40
#: a faster search than the defaults: 12 fitting frames, 500 bootstrap resamples
FAST = dict(fit_frames=12, bootstrap=500)
#: the "real world" draws other random numbers than the workflow (seed 0)
MEASURED_SEED = 4242
#: frames per domain-shifted clear set
SHIFTED_FRAMES = 24
#: the real frames (1024x768) are compared at 256x192 in the tests (scaled once by 4)
REAL_WIDTH = 256
