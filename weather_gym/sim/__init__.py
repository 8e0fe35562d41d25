"""The PyBullet simulator: the world (:mod:`~weather_gym.sim.world`), the car, the camera sensor,
rendering and the geometric ground truth. No Gymnasium here: the env (``weather_gym.envs``) wraps it.

Example:
    >>> from weather_gym.sim.config import SimConfig
    >>> SimConfig(renderer="none").control_hz
    30.0
"""

from weather_gym.core.moved import moved_path

__path__.append(moved_path(__name__))  # the old module paths, deprecated (weather_gym.core.moved)
