"""Measured data with a known, hidden weather: how the gap workflow is proven (tests, demo).

:func:`degrade_dataset` copies a COCO folder and applies weather to every frame with the frame's
depth and vehicle state, the way the workflow applies a model, but with its own seed (so the
random parts, e.g. sensor noise, differ from the workflow's). Nothing about the weather is written
into the copy: the workflow is not told what was applied. ``strip_poses=True`` removes the car
poses (and looks), which makes the copy look like a real recording (unpaired mode).

Example:
    >>> from weather_gym.lab.gap.synthetic import degrade_dataset
    >>> degrade_dataset("data/clean", "data/measured", "blur:0.6,noise:0.3", seed=99)  # doctest: +SKIP

On a one-frame COCO set made on the spot:
    >>> import numpy as np, tempfile
    >>> from pathlib import Path
    >>> from weather_gym.lab.datasets.coco_writer import CocoWriter
    >>> root = Path(tempfile.mkdtemp())
    >>> with CocoWriter(root / "clean") as w:
    ...     w.add(np.full((36, 64, 3), 128, np.uint8), {"track": "demo"},
    ...           {"boxes": np.array([[1, 1, 5, 7.]]), "classes": np.array([0])})
    0
    >>> degrade_dataset(root / "clean", root / "measured", "blur:0.6,noise:0.3", seed=99).relative_to(root)
    PosixPath('measured/annotations.json')
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.core._io import atomic_write, atomic_write_json, check_output, resolve_inside, write_image
from weather_gym.core.errors import InputError
from weather_gym.lab.datasets.coco import ANNOTATIONS, load_coco, record_path
from weather_gym.lab.gap.simulate import frame_state
from weather_gym.lab.gap.weather_model import apply_chain
from weather_gym.weather import Compose, KnobEffect, parse_weather

__all__ = ["degrade_dataset"]


def _effects(weather: Any) -> list:
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


    ds = load_coco(src)  # every file name is checked to stay inside src (record_path)
    dst = Path(dst)
    if dst.resolve() == Path(src).resolve():
        raise InputError(f"{dst}: the copy must go to another folder than its source")
    check_output(dst / ANNOTATIONS, overwrite=overwrite)
    effects = _effects(weather)
    data = json.loads((Path(src) / ANNOTATIONS).read_text())
    for i in tqdm(range(len(ds)), desc="degrade", unit="frame", disable=not progress):
        rec = ds.record(i)
        img = apply_chain(effects, ds.image(i), depth=ds.depth(i), state=frame_state(rec), seed=seed,
                          frame_id=int(rec["id"]))
        # the same relative names (as lossless PNG: no compression on top of the weather), confined to dst
        name = str(Path(rec["file_name"]).with_suffix(".png"))
        data["images"][i]["file_name"] = name
        write_image(resolve_inside(dst, name, what=f"{src}: image {rec.get('id')!r} 'file_name'"), img,
                    overwrite=overwrite)
        for key in ("depth_file", "ignore_mask"):
            if rec.get(key):
                atomic_write(record_path(dst, rec, key), record_path(src, rec, key).read_bytes(), overwrite=overwrite)
    mask = (data.get("info") or {}).get("ignore_mask")
    if mask:
        where = f"{src}: info.ignore_mask"
        atomic_write(resolve_inside(dst, mask, what=where), resolve_inside(src, mask, what=where).read_bytes(),
                     overwrite=overwrite)
    if strip_poses:
        for rec in data["images"]:
            for key in ("pose", "look", "seed", "episode", "step"):
                rec.pop(key, None)
    data.setdefault("info", {})["description"] = "weather-gym frames with weather applied (degrade_dataset)"
    return atomic_write_json(dst / ANNOTATIONS, data, overwrite=overwrite)
