"""Measured data with a known, hidden weather: how the gap workflow is proven (tests, demo).

:func:`degrade_dataset` copies a COCO folder and applies weather to every frame with the frame's
depth and vehicle state, the way the workflow applies a model, but with its own seed (so the
random parts, e.g. sensor noise, differ from the workflow's). Nothing about the weather is written
into the copy: the workflow is not told what was applied. ``strip_poses=True`` removes the car
poses (and looks), which makes the copy look like a real recording (unpaired mode).

Example:
    >>> from weather_gym.gap.synthetic import degrade_dataset
    >>> degrade_dataset("data/clean", "data/measured", "blur:0.6,noise:0.3", seed=99)  # doctest: +SKIP
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

import cv2

from weather_gym._io import atomic_write_json
from weather_gym.gap.model import apply_chain
from weather_gym.gap.simulate import frame_state

__all__ = ["degrade_dataset"]


def _effects(weather: Any) -> list:
    from weather_gym.weather import Compose, KnobEffect, parse_weather

    w = weather if isinstance(weather, list) and all(isinstance(e, KnobEffect) for e in weather) else None
    if w is not None:
        return w
    parsed = parse_weather(weather)
    return list(parsed.effects) if isinstance(parsed, Compose) else [parsed]


def degrade_dataset(src: str | os.PathLike, dst: str | os.PathLike, weather: Any, *, seed: int = 0,
                    strip_poses: bool = False, overwrite: bool = False, progress: bool = False) -> Path:
    """Copy the COCO folder ``src`` to ``dst`` with ``weather`` applied to every image.

    ``weather``: a list of effects or any weather spec (``"blur:0.6"``, ``[{"name": "dim", "k": 0.5}]``).
    Returns the path of the new ``annotations.json``.
    """
    from tqdm import tqdm

    from weather_gym.datasets.coco import ANNOTATIONS, load_coco

    ds = load_coco(src)
    dst = Path(dst)
    if (dst / ANNOTATIONS).exists() and not overwrite:
        raise FileExistsError(f"{dst / ANNOTATIONS} already exists; pass overwrite=True to replace it")
    effects = _effects(weather)
    (dst / "images").mkdir(parents=True, exist_ok=True)
    data = json.loads((Path(src) / ANNOTATIONS).read_text())
    for i in tqdm(range(len(ds)), desc="degrade", unit="frame", disable=not progress):
        rec = ds.record(i)
        img = apply_chain(effects, ds.image(i), depth=ds.depth(i), state=frame_state(rec), seed=seed,
                          frame_id=int(rec["id"]))
        name = str(Path(rec["file_name"]).with_suffix(".png"))  # lossless: no compression on top of the weather
        data["images"][i]["file_name"] = name
        out = dst / name
        out.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(out), cv2.cvtColor(img, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {out}")
        for key in ("depth_file", "ignore_mask"):
            if rec.get(key):
                (dst / rec[key]).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(Path(src) / rec[key], dst / rec[key])
    mask = (data.get("info") or {}).get("ignore_mask")
    if mask:
        shutil.copyfile(Path(src) / mask, dst / mask)
    if strip_poses:
        for rec in data["images"]:
            for key in ("pose", "look", "seed", "episode", "step"):
                rec.pop(key, None)
    data.setdefault("info", {})["description"] = "weather-gym frames with weather applied (degrade_dataset)"
    return atomic_write_json(dst / ANNOTATIONS, data)
