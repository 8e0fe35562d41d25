"""Pool several COCO cone datasets into one: a calibration or evaluation set of many tracks and worlds.

``merge_coco(sources, out)`` copies every frame (image, depth map, ignore mask) of each source into
``out`` under a per-source prefix (``s0_``, ``s1_``, ...), renumbers image and annotation ids, and
writes ``annotations.json`` last (atomically): an interrupted merge leaves no dataset that loads.
Annotations are kept as they are (boxes, ranges, the too-small and ignore flags scoring reads); a
source's dataset-wide ignore mask becomes a per-frame mask of its frames. ``info.sources`` records
each source's folder, annotations id and frame count, so a merged set says what it pools.

The sources must agree on the categories (by name) and on the too-small rule
(``info.min_box_height_px``), or the pooled mAP would mix two definitions of a cone to find; a
disagreement is an :class:`~weather_gym.core.errors.InputError` naming both sources and values.

Example:
    >>> import tempfile, numpy as np
    >>> from pathlib import Path
    >>> from weather_gym.lab.datasets.coco import CocoWriter, load_coco
    >>> tmp = Path(tempfile.mkdtemp())
    >>> for name in ("a", "b"):
    ...     with CocoWriter(tmp / name) as w:
    ...         _ = w.add(np.zeros((8, 8, 3), np.uint8), {"track": name},
    ...                   {"boxes": np.array([[1.0, 1, 4, 7]]), "classes": np.array([0])})
    >>> merged = merge_coco([tmp / "a", tmp / "b"], tmp / "ab")
    >>> ds = load_coco(merged)
    >>> len(ds), [s["images"] for s in ds.info["sources"]]
    (2, [1, 1])
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core._io import (
    atomic_write_json,
    check_output,
    exclusive,
    file_id,
    resolve_inside,
)
from weather_gym.core.errors import InputError, OutputPathError
from weather_gym.lab.datasets import masks as _masks
from weather_gym.lab.datasets.coco import ANNOTATIONS, load_coco, record_path, record_track_file
from weather_gym.perception.labels import MIN_BOX_HEIGHT_PX

__all__ = ["merge_coco"]

_FILE_KEYS = ("file_name", "depth_file")


def _copy(src: Path, out: Path, rel: str) -> str:
    dst = out / rel
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    return rel


def _check_agree(sources: Sequence[Path], datasets: list[Any]) -> list[dict]:
    """The first source's categories; InputError when another source defines them or the too-small rule otherwise."""
    first = sorted(c["name"] for c in datasets[0].data["categories"])
    first_h = float(datasets[0].info.get("min_box_height_px", MIN_BOX_HEIGHT_PX))
    for src, ds in zip(sources[1:], datasets[1:], strict=True):
        names = sorted(c["name"] for c in ds.data["categories"])
        if names != first:
            raise InputError(f"{src}: categories {names} differ from {sources[0]}'s {first}; "
                             "merge datasets with the same cone classes")
        h = float(ds.info.get("min_box_height_px", MIN_BOX_HEIGHT_PX))
        if h != first_h:
            raise InputError(f"{src}: info.min_box_height_px {h:g} differs from {sources[0]}'s {first_h:g}: "
                             "the pooled mAP would mix two too-small rules")
    return list(datasets[0].data["categories"])


def _check_paths(srcs: list[Path], out: Path) -> None:
    """At least two distinct sources, and an output folder outside every one of them."""
    if len(srcs) < 2:
        raise InputError(f"merge needs at least two source datasets, got {len(srcs)}")
    seen: dict[Path, Path] = {}
    for s in srcs:
        r = s.resolve()
        if r in seen:
            raise InputError(f"source dataset {s} is given twice (also as {seen[r]})")
        seen[r] = s
    for s in srcs:
        if out.resolve() == s.resolve() or out.resolve().is_relative_to(s.resolve()):
            raise OutputPathError(f"output folder {out} is, or lies inside, the source dataset {s}")


def merge_coco(sources: Sequence[str | os.PathLike], out: str | os.PathLike, *,
               overwrite: bool = False) -> Path:
    """Pool the COCO folders ``sources`` (at least two) into the new folder ``out``; returns ``out``."""
    srcs, out = [Path(s) for s in sources], Path(out)
    _check_paths(srcs, out)
    datasets = [load_coco(s) for s in srcs]  # validates every source before anything is written
    categories = _check_agree(srcs, datasets)
    by_name = {c["name"]: c["id"] for c in categories}
    check_output(out / ANNOTATIONS, overwrite=overwrite, what="dataset")  # a file in the way, or no --overwrite
    out.mkdir(parents=True, exist_ok=True)
    images: list[dict] = []
    annotations: list[dict] = []
    info_sources: list[dict] = []
    with exclusive(out, message=f"another run is writing the dataset {out}; wait for it or choose another --out"):
        for i, (src, ds) in enumerate(zip(srcs, datasets, strict=True)):
            prefix = f"s{i}_"
            cat_map = {c["id"]: by_name[c["name"]] for c in ds.data["categories"]}
            wide, wide_rel = ds.info.get("ignore_mask"), None
            id_map: dict[int, int] = {}
            for n, rec in enumerate(ds.images):
                new = dict(rec)
                new["id"] = len(images) + 1
                id_map[rec["id"]] = new["id"]
                for key in _FILE_KEYS:
                    if rec.get(key) is not None:
                        new[key] = _copy(record_path(src, rec, key), out, f"{Path(rec[key]).parent}/{prefix}"
                                                                          f"{Path(rec[key]).name}")
                part = record_track_file(src, rec)
                if part is not None:
                    new["track"] = part[0] + _copy(part[2], out, f"tracks/{prefix}{Path(part[1]).name}")
                own, rel = rec.get("ignore_mask"), None
                if own is not None and wide is not None:  # both: one per-frame mask, their union
                    rel = f"masks/{prefix}{rec['id']}_ignore.png"
                    (out / "masks").mkdir(parents=True, exist_ok=True)
                    _masks.write_mask(out / rel, np.asarray(ds.ignore_mask(n)), overwrite=True)
                elif own is not None:
                    rel = _copy(record_path(src, rec, "ignore_mask"), out, f"masks/{prefix}{Path(own).name}")
                elif wide is not None:
                    if wide_rel is None:
                        wide_rel = _copy(resolve_inside(src, wide, what=f"{src / ANNOTATIONS}: info.ignore_mask"),
                                         out, f"masks/{prefix}{Path(wide).name}")
                    rel = wide_rel
                if rel is not None:
                    new["ignore_mask"] = rel
                new["source"] = i
                images.append(new)
            for a in ds.data["annotations"]:
                new_a = dict(a, id=len(annotations) + 1, image_id=id_map[a["image_id"]],
                             category_id=cat_map[a["category_id"]])
                annotations.append(new_a)
            info_sources.append({"path": str(src), "annotations_id": file_id(src / ANNOTATIONS),
                                 "images": len(ds.images), "info": dict(ds.info)})
        info = {"description": "weather-gym merged cone frames",
                "min_box_height_px": float(datasets[0].info.get("min_box_height_px", MIN_BOX_HEIGHT_PX)),
                "sources": info_sources}
        atomic_write_json(out / ANNOTATIONS, {"info": info, "images": images, "annotations": annotations,
                                              "categories": categories}, overwrite=True)
    return out
