"""Perception surrogate: a statistical model of what the shipped detector reports in each weather.

The full pipeline (render -> weather -> ONNX detector) is the reference; the surrogate replays its
statistics on the render-free ground truth (``perception="gt_cones"``'s geometry), thousands of
steps per second, for training controllers on cone lists.

* :mod:`~weather_gym.surrogate.conditions` - weather spec -> (condition, k) of the model; the
  clear-weather fallback for effects without a fit.
* :mod:`~weather_gym.surrogate.camera` - any camera size: box sizes at the detector's input.
* :mod:`~weather_gym.surrogate.log` - full-pipeline runs -> per-cone / false-positive logs (``.npz``).
* :mod:`~weather_gym.surrogate.model` - fit the model from logs, save / load it (validated).
* :mod:`~weather_gym.surrogate.sample` - draw one frame's cone list from the model.
* :mod:`~weather_gym.lab.training.surrogate.validate` - surrogate vs full pipeline on a held-out track.

The wrapper that uses it is :class:`weather_gym.wrappers.SurrogatePerceptionWrapper`
(``make_env(perception="surrogate", weather="droplets@3")``); see ``docs/surrogate.md``.

Example:
    >>> from weather_gym.surrogate.conditions import condition_of
    >>> condition_of({"droplets": 0.5})
    ('droplets', 0.5)
"""

from weather_gym.core.moved import moved_path

__path__.append(moved_path(__name__))  # the old module paths, deprecated (weather_gym.core.moved)
