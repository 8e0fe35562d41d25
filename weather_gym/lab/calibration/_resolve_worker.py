"""The frames a resolution degrades and detects, and the helper process that takes a share of them.

:class:`FrameBlock` holds some frames of a reference set in memory (image, depth, the car's state, the
frame's weather seed) with the detector's clear detections, and runs the detector on them under an effect
at one k, one frame at a time (a frame whose degraded bytes equal the clear ones reuses the clear
detections). :func:`weather_gym.lab.calibration.resolve.resolve_presets` keeps one block in its own process
and hands the others to helper processes (``python -m weather_gym.lab.calibration._resolve_worker``, one per
further core): every frame's detections are the same whichever process computes them, so the resolved k does
not depend on the number of processes. A helper reads pickled requests on stdin and answers on its own
copy of stdout (anything it prints goes to stderr); it ends at the end of its input.

Example (one frame, no helper):
    >>> import numpy as np
    >>> block = FrameBlock([np.zeros((8, 8, 3), np.uint8)], [None], [{}], np.array([3], np.uint32))
    >>> dets = block.detect(lambda ims, score_threshold: [{"n": len(ims)}] * len(ims), None)
    >>> dets
    [{'n': 1}]
"""

from __future__ import annotations

import os
import pickle
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.camera.config import CameraConfig
from weather_gym.core._lock import waiting_lock
from weather_gym.core.errors import InputError
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.perception.detector_spec import load_detector
from weather_gym.weather import make

__all__ = ["FrameBlock", "frame_state", "main", "render_part"]

KEEP_THRESHOLD = 0.05
"""Detections are kept down to this score (low, so the AP curve is complete)."""


def frame_state(record: dict[str, Any]) -> dict[str, float]:
    """The car's state an effect reads for a frame of a rendered set (speed, yaw rate, exposure, focal length)."""
    st = {"speed": float(record.get("speed", 0.0)), "yaw_rate": float(record.get("yaw_rate", 0.0))}
    if record.get("camera"):
        c = CameraConfig(**record["camera"])
        st.update(exposure_s=c.exposure_s, fx=c.fx)
    return st


class FrameBlock:
    """Frames in memory with their depth, state and weather seed; their clear detections once computed."""

    def __init__(self, images: Sequence[np.ndarray], depths: Sequence[np.ndarray | None],
                 states: Sequence[dict[str, float]], seeds: np.ndarray) -> None:
        self.images, self.depths, self.states, self.seeds = list(images), list(depths), list(states), seeds
        self.clear: list[Any] | None = None

    @classmethod
    def load(cls, frames: Sequence[tuple[str, int]], seeds: np.ndarray) -> FrameBlock:
        """Frames ``(folder, index)`` of rendered COCO sets, with their weather seeds."""
        sets: dict[str, Any] = {}
        images, depths, states = [], [], []
        for folder, j in frames:
            ds = sets.get(folder)
            if ds is None:
                ds = sets[folder] = load_coco(folder)
            rec = ds.record(j)
            images.append(ds.image(j))
            depths.append(ds.depth(j) if rec.get("depth_file") else None)
            states.append(frame_state(rec))
        return cls(images, depths, states, seeds)

    def __len__(self) -> int:
        return len(self.images)

    def detect(self, detect_batch: Callable[..., list[Any]], table: dict[str, Any] | None,
               seeds: np.ndarray | None = None) -> list[Any]:
        """Detections on every frame, clear (``table`` None) or degraded by the effect ``table``
        (``{"name": ..., "k": ..., **params}``), each frame with ``reset(seed)`` and ``rng=default_rng(seed)``
        (the block's own weather seeds, or ``seeds``: one per frame)."""
        if table is None:
            if self.clear is None:
                self.clear = [detect_batch([im], score_threshold=KEEP_THRESHOLD)[0] for im in self.images]
            return self.clear
        effect = make(table["name"], **{k: v for k, v in table.items() if k != "name"})
        seeds = self.seeds if seeds is None else seeds
        out = []
        for j, im0 in enumerate(self.images):
            sd = int(seeds[j])
            effect.reset(sd)
            im = effect(im0, depth=self.depths[j], state=dict(self.states[j]), rng=np.random.default_rng(sd))
            if self.clear is not None and im.shape == im0.shape and np.array_equal(im, im0):
                out.append(self.clear[j])
            else:
                out.append(detect_batch([im], score_threshold=KEEP_THRESHOLD)[0])
        return out


def render_part(job: dict[str, Any]) -> None:
    """``render_dataset(**job)`` into ``job["out"]`` unless a finished set is there; processes rendering the
    same folder wait for the first (an interrupted render resumes)."""
    from weather_gym.lab.datasets.render import render_dataset

    out = Path(job["out"])
    with waiting_lock(str(out) + ".lock"):
        if not (out / "annotations.json").is_file():
            render_dataset(**{**job, "resume": out.exists()})


def _serve(inp: Any, out: Any) -> None:
    detector: Any = None
    blocks: dict[Any, FrameBlock] = {}
    while True:
        try:
            op, *args = pickle.load(inp)
        except EOFError:
            return
        try:
            if op == "init":
                detector = load_detector(args[0], threads=args[1])
                result: Any = None
            elif op == "render":
                render_part(args[0])
                result = None
            elif op == "frames":
                blocks[args[0]] = FrameBlock.load(args[1], args[2])
                result = len(blocks[args[0]])
            elif op == "detect":
                result = blocks[args[0]].detect(detector.detect_batch, *args[1:])
            else:
                raise InputError(f"resolve worker: unknown request {op!r} (expected init, render, frames or detect)")
            reply = ("ok", result)
        except Exception as e:  # reported to the parent, which raises it there
            reply = ("error", f"{type(e).__name__}: {e}")
        pickle.dump(reply, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()


def main() -> None:
    """Serve requests on stdin until it closes (stdout is the answers' own channel)."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # a print anywhere below goes to stderr, not into the answers
    _serve(sys.stdin.buffer, out)


if __name__ == "__main__":
    main()
