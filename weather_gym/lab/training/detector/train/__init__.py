"""Train ``ConeNet`` on rendered COCO datasets and export it to ONNX (needs the ``train`` extra: torch, onnx).

Training is seeded and deterministic in its data order and augmentation (a ``numpy`` Generator per
sample from ``(seed, epoch, index)``, ``torch.manual_seed(seed)``); it checkpoints every epoch and
resumes from ``<out>.ckpt`` after an interruption. Augmentation is geometric (scale, shift,
left-right flip: colours keep their meaning) and photometric (small hue, saturation and brightness
jitter); the ``real`` recipe (:meth:`TrainConfig.recipe`) adds what a real camera and a real track
side do (``weather_gym.perception.augment``: exposure to blown-out, tone, blur, noise, JPEG, wide scale
jitter, unlabelled clutter in cone colours). Several COCO folders can be mixed at given ratios
(``mix``): rendered sets, and imported recordings of a team's own camera (their ignore regions and
ignore masks carry no loss). Training can start from a shipped ONNX model (``init``). The detector is trained on clean frames only - never on weather effects - so that, like the
reference study's detector, its accuracy falls when the weather degrades the image.

The parts: the settings and recipes (``train.config``), samples, augmentation and targets
(``train.data``), ONNX export and start weights (``train.export``), the loss and the loop (``train.loop``).

Example:
    >>> from weather_gym.lab.training.detector.train import TrainConfig, train_detector       # doctest: +SKIP
    >>> train_detector(["scratch/data/train"], "model.onnx", TrainConfig(epochs=1))  # doctest: +SKIP

The ``real`` recipe (torch is imported, nothing is trained):
    >>> config = TrainConfig.recipe("real", epochs=1)
    >>> config.epochs, config.input_size
    (1, (512, 288))
"""


from __future__ import annotations

from weather_gym.lab.training.detector.train.config import MAX_OBJECTS, RECIPES, TrainConfig
from weather_gym.lab.training.detector.train.data import HIDDEN_BOX_RADIUS, augment, build_targets
from weather_gym.lab.training.detector.train.export import count_flops, export_onnx, load_onnx_weights
from weather_gym.lab.training.detector.train.loop import detection_loss, train_detector

__all__ = ["TrainConfig", "train_detector", "export_onnx", "build_targets", "augment", "detection_loss",
           "load_onnx_weights", "RECIPES", "MAX_OBJECTS", "HIDDEN_BOX_RADIUS", "count_flops"]
