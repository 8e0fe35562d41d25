"""A second detector in a user's format: a YOLOv8-layout ONNX of another architecture and training.

What a team that plugs in its own model (``--detector yolov8:model.onnx``) hands weather-gym: one output
``(1, 4+nc, N)`` of ``cx cy w h`` (network-input pixels) and per-class scores, RGB in [0, 1], letterboxed
with grey 114 padding, class names in the metadata (``weather_gym/perception/yolo.py`` reads it). Made here,
on the CPU, in a few minutes:

1. render a training set of the project's own frames on tracks that none of the checks use (``hairpin``,
   ``jellybean``, ``b_shape``, ``oval``, ``random:7``; 400 frames, randomised looks, seed 77);
2. train a ConeNet of another architecture than the shipped one (output stride 4 instead of 2, no
   hidden-cone heads, blocks 1,1,2,1 instead of 1,2,2,1), from random weights (the shipped model was
   fine-tuned over several rounds), with the ``sim`` recipe (``weather_gym.lab.training.detector.train``; ``--steps`` optimiser steps);
3. export it with a YOLOv8 head on top: the sigmoid and 3x3 peak filter of the heatmaps as class scores,
   the cell's centre and size as ``cx cy w h``: one output ``(1, 8, 72*128)``, names
   ``blue_cone, yellow_cone, orange_cone, large_orange_cone`` and ``imgsz`` in the metadata.

    python docs/calibration/second_detector.py --out docs/calibration/second_detector/yolov8_conenet_s4.onnx

The training set and checkpoints go under ``--work`` (default ``scratch/second_detector``; not in the
repository). The result is scored on a clear set of held-out tracks and written beside the model (``.json``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from torch import nn

from weather_gym.lab.datasets.coco import load_coco
from weather_gym.lab.datasets.render import render_dataset
from weather_gym.lab.training.detector.conenet import ConeNet, _peaks
from weather_gym.lab.training.detector.train import TrainConfig, load_onnx_weights, train_detector
from weather_gym.perception.detector_spec import load_detector
from weather_gym.perception.scoring import score_dataset

TRAIN_TRACKS = ("hairpin", "jellybean", "b_shape", "oval", "random:7")
BLOCKS, STRIDE = (1, 1, 2, 1), 4
NAMES = {0: "blue_cone", 1: "yellow_cone", 2: "orange_cone", 3: "large_orange_cone"}
INPUT = (512, 288)  # W, H


class YoloV8Head(nn.Module):
    """A ConeNet's raw output as a YOLOv8 export's: ``(B, 4 + C, H/s * W/s)`` rows ``cx cy w h`` then
    the class scores (peak-filtered probabilities: 0 where a cell is not a local maximum)."""

    def __init__(self, net: ConeNet) -> None:
        super().__init__()
        self.net, self.c, self.s = net, net.num_classes, net.stride

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # x: RGB in [0, 1], as ultralytics feeds it
        raw = self.net(x)
        c, s = self.c, self.s
        scores = _peaks(torch.sigmoid(raw[:, :c]))
        size = torch.exp(raw[:, c : c + 2].clamp(max=6.0)) * s
        off = torch.sigmoid(raw[:, c + 2 : c + 4])
        h, w = raw.shape[2], raw.shape[3]
        gy = torch.arange(h, dtype=raw.dtype).view(1, h, 1).expand(1, h, w)
        gx = torch.arange(w, dtype=raw.dtype).view(1, 1, w).expand(1, h, w)
        cx = (gx + off[:, 0]) * s
        cy = (gy + off[:, 1]) * s
        boxes = torch.stack([cx, cy, size[:, 0], size[:, 1]], dim=1)
        return torch.cat([boxes, scores], dim=1).flatten(2)


def export_yolov8(net: ConeNet, path: Path) -> None:
    import onnx

    head = YoloV8Head(net.eval()).eval()
    dummy = torch.zeros(1, 3, INPUT[1], INPUT[0])
    torch.onnx.export(head, (dummy,), str(path), input_names=["images"], output_names=["output0"],
                      opset_version=17, dynamo=False)
    model = onnx.load(str(path))
    for k, v in (("names", str(NAMES)), ("imgsz", str([INPUT[1], INPUT[0]])), ("stride", str(STRIDE)),
                 ("description", "weather-gym second detector: ConeNet stride 4 under a YOLOv8 head "
                                 "(docs/calibration/second_detector.py)")):
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v
    onnx.save(model, str(path))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="the YOLOv8-layout ONNX to write")
    ap.add_argument("--work", type=Path, default=Path("scratch/second_detector"))
    ap.add_argument("--steps", type=int, default=900, help="optimiser steps (default %(default)s)")
    ap.add_argument("--frames", type=int, default=400, help="training frames (default %(default)s)")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    data = args.work / "train"
    if not (data / "annotations.json").is_file():
        render_dataset(data, tracks=list(TRAIN_TRACKS), frames=args.frames, seed=77, frames_per_episode=10,
                       randomize=True, resume=data.exists())
    cfg = TrainConfig(stride=STRIDE, blocks=BLOCKS, batch_size=8, epochs=100, max_steps=args.steps,
                      warmup_iters=100, seed=3)
    conenet = args.work / "conenet_s4.onnx"
    if not conenet.is_file():
        train_detector([data], conenet, cfg, overwrite=True)
    net = load_onnx_weights(ConeNet(blocks=BLOCKS, stride=STRIDE), conenet)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    export_yolov8(net, args.out)
    check = args.work / "check_clear"
    if not (check / "annotations.json").is_file():
        render_dataset(check, tracks=["skidpad", "random:90"], frames=80, seed=4242, frames_per_episode=4,
                       progress=False, overwrite=True)
    ds = load_coco(check, cache_images=True)
    summary = {"architecture": {"blocks": BLOCKS, "stride": STRIDE, "hidden": False},
               "training": {"tracks": TRAIN_TRACKS, "frames": args.frames, "steps": args.steps, "recipe": "sim",
                            "init": "random"},
               "clear_map50_blue_yellow": {}}
    for name, spec in (("this detector", f"yolov8:{args.out}"), ("shipped detector", None)):
        summary["clear_map50_blue_yellow"][name] = round(score_dataset(ds, load_detector(spec), None).map50_blue_yellow, 4)
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
