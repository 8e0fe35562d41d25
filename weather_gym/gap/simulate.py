"""Simulate the measured frames: clean renders of the same views (paired) or the same track (unpaired).

**Paired mode** needs, in every image record of the measured COCO folder, the ``track`` and the car
``pose`` (``look`` and ``camera`` too, as ``weather-gym dataset render`` writes them; without them
the default look and the default camera at the image size are used, and a note says so). Each view
is re-rendered with :meth:`~weather_gym.datasets.CocoDataset.render_view`.

**Unpaired mode** (no poses, e.g. a real dataset of the same track) renders as many frames of the
same track(s) with the ground-truth driver (:func:`~weather_gym.datasets.render_dataset`); the
comparison then works on distributions over the two sets.

The clean renders are written once into ``cache_dir`` as a COCO folder (an interrupted render
resumes) and reused by every candidate model: weather is post-processing on the same clean frames.

Example:
    >>> from weather_gym.gap.simulate import split_indices
    >>> fit, held = split_indices(10, held_out=0.5, seed=0)
    >>> len(fit), len(held), sorted(fit.tolist() + held.tolist()) == list(range(10))
    (5, 5, True)
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.errors import InputError

__all__ = ["FrameSet", "GapData", "load_frames", "paired_check", "simulate", "split_indices", "frame_state"]

_PAIRED_KEYS = ("track", "pose")
_CACHE_VERSION = 1


@dataclass
class FrameSet:
    """Frames in memory: RGB images, depth (metres or None), ground truth, effect state, image ids."""

    images: list[np.ndarray]
    depths: list[np.ndarray | None]
    gts: list[dict[str, np.ndarray]]
    states: list[dict[str, float]]
    ids: list[int]
    root: str

    def __len__(self) -> int:
        return len(self.images)

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` of the frames."""
        h, w = self.images[0].shape[:2]
        return w, h


@dataclass
class GapData:
    """Measured frames and their clean simulated counterparts, with the fitting / held-out split.

    In paired mode frame ``i`` of ``sim`` is the view of frame ``i`` of ``measured``, and the split
    indexes both. In unpaired mode each set has its own split.
    """

    mode: str
    mode_reason: str
    measured: FrameSet
    sim: FrameSet
    fit: np.ndarray
    held: np.ndarray
    sim_fit: np.ndarray
    sim_held: np.ndarray
    notes: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def paired(self) -> bool:
        return self.mode == "paired"

    def signal_depths(self, which: str) -> list[np.ndarray | None]:
        """Depth maps the image signals use for ``which`` ("measured"/"sim").

        Paired: the rendered depth of the view for both sets (the same geometry for both sides).
        Unpaired: each set's own depth when both have it for every frame, else None (rows).
        """
        if self.paired:
            return self.sim.depths
        have = all(d is not None for d in self.measured.depths) and all(d is not None for d in self.sim.depths)
        frames = self.measured if which == "measured" else self.sim
        return frames.depths if have else [None] * len(frames)

    def signal_boxes(self, which: str) -> list[np.ndarray]:
        """Cone boxes for the cone signals: the measured ground truth for both sets when paired."""
        frames = self.measured if (self.paired or which == "measured") else self.sim
        return [g["boxes"] for g in frames.gts]


def frame_state(record: dict) -> dict[str, float]:
    """The weather ``state`` of a frame: ``speed``, ``yaw_rate`` and ``fx`` from its record.

    The exposure time is deliberately left out: it is a parameter of the weather model (what the
    gap workflow fits), so ``motion_blur`` uses its own ``exposure_s``.
    """
    state = {"speed": float(record.get("speed", 0.0) or 0.0), "yaw_rate": float(record.get("yaw_rate", 0.0) or 0.0)}
    cam = record.get("camera")
    if cam:
        from weather_gym.camera import CameraConfig

        state["fx"] = CameraConfig(**cam).fx
    else:
        state["fx"] = record["width"] / 2.0  # 90 degree field of view
    return state


def load_frames(ds: Any, *, progress: bool = False, desc: str = "load") -> FrameSet:
    """Read every frame of a ``CocoDataset`` into memory."""
    from tqdm import tqdm

    images, depths, gts, states, ids = [], [], [], [], []
    for i in tqdm(range(len(ds)), desc=desc, unit="frame", disable=not progress):
        img = ds.image(i)
        images.append(np.ascontiguousarray(img))
        depths.append(ds.depth(i))
        gts.append(ds.gt(i))
        states.append(frame_state(ds.record(i)))
        ids.append(int(ds.record(i)["id"]))
    if images:
        shapes = {im.shape for im in images}
        if len(shapes) > 1:
            raise InputError(f"{ds.root}: frames have different sizes {sorted(shapes)}; the gap workflow "
                             "needs one camera resolution")
    return FrameSet(images, depths, gts, states, ids, str(ds.root))


def paired_check(ds: Any) -> tuple[bool, str]:
    """Whether every record of ``ds`` can be re-rendered, and why (not)."""
    missing: dict[str, int] = {}
    for rec in ds.images:
        for key in _PAIRED_KEYS:
            if rec.get(key) is None:
                missing[key] = missing.get(key, 0) + 1
    if missing:
        what = ", ".join(f"{k!r} missing in {n} of {len(ds)} records" for k, n in missing.items())
        return False, f"poses absent ({what}): distributions over the whole sets are compared"
    return True, f"every record has a track and a car pose: each of the {len(ds)} views is re-rendered"


def split_indices(n: int, *, held_out: float = 0.5, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A seeded split of ``range(n)`` into (fitting, held-out) index arrays, each sorted."""
    if not 0.0 < held_out < 1.0:
        raise InputError(f"held_out must be a fraction in (0, 1), got {held_out}")
    if n < 4:
        raise InputError(f"the gap workflow needs at least 4 frames, got {n}")
    perm = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5917])).permutation(n)
    n_held = min(max(int(round(n * held_out)), 2), n - 2)
    return np.sort(perm[n_held:]), np.sort(perm[:n_held])


def _key(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def _camera_of(ds: Any) -> Any:
    from weather_gym.camera import CameraConfig

    rec = ds.images[0]
    cam = CameraConfig(**rec["camera"]) if rec.get("camera") else CameraConfig().scaled(rec["width"], rec["height"])
    if (cam.width, cam.height) != (rec["width"], rec["height"]):
        raise InputError(f"{ds.annotations_path}: image {rec['id']} is {rec['width']}x{rec['height']} but its "
                         f"camera record says {cam.width}x{cam.height}")
    return cam


def _view_record(rec: dict, camera: Any, notes: set[str]) -> dict:
    from weather_gym.sim.look import DEFAULT_LOOK

    view = {k: rec[k] for k in ("track", "pose", "speed", "yaw_rate", "seed", "look", "camera") if k in rec}
    if view.get("look") is None:
        view["look"] = DEFAULT_LOOK.to_dict()
        notes.add("some records have no 'look': the default look was rendered for them")
    if view.get("camera") is None:
        view["camera"] = camera.to_dict()
        notes.add("some records have no 'camera': the default camera at the image size was used")
    view["id"] = rec["id"]
    return view


def _render_paired(ds: Any, cache_dir: Path, progress: bool, notes: set[str]) -> Path:
    """Re-render every view of ``ds`` into a cached COCO folder; returns the folder."""
    from tqdm import tqdm

    from weather_gym.datasets.coco import ANNOTATIONS, JOURNAL, CocoWriter
    from weather_gym.datasets.render import ViewRenderer

    camera = _camera_of(ds)
    views = [_view_record(rec, camera, notes) for rec in ds.images]
    for i, view in enumerate(views):  # render from the track the record names, confined to the dataset folder
        if view.get("track") is not None:
            view["track"] = ds.track_spec(i)
        view["index"] = i
    key = _key({"v": _CACHE_VERSION, "views": [{k: v for k, v in view.items() if k not in ("id", "index")}
                                                for view in views]})
    out = cache_dir / f"paired-{key}"
    if (out / ANNOTATIONS).is_file():
        return out
    writer = CocoWriter(out, resume=(out / JOURNAL).exists(), info={"gap_cache": "paired clean renders",
                                                                      "source": str(ds.root)})
    renderer = ViewRenderer()
    try:
        for view in tqdm(views[writer.done:], desc="render views", unit="frame", disable=not progress,
                         initial=writer.done, total=len(views)):
            r = renderer.render(view)
            rec = {k: v for k, v in view.items() if k != "id"}
            rec["track"] = ds.images[view["index"]].get("track")  # as the measured record names it
            rec.pop("index")
            rec["measured_id"] = view["id"]
            writer.add(r["image"], rec, r["gt"], depth=r["depth"])
    except BaseException:
        writer.abort()
        raise
    finally:
        renderer.close()
    writer.close()
    return out


def _render_unpaired(ds: Any, cache_dir: Path, tracks: list[str], frames: int, seed: int,
                     progress: bool) -> Path:
    from weather_gym.datasets.coco import ANNOTATIONS, JOURNAL
    from weather_gym.datasets.render import render_dataset

    camera = _camera_of(ds)
    key = _key({"v": _CACHE_VERSION, "tracks": tracks, "frames": frames, "seed": seed, "camera": camera.to_dict()})
    out = cache_dir / f"unpaired-{key}"
    if not (out / ANNOTATIONS).is_file():
        render_dataset(out, tracks=tracks, frames=frames, seed=seed, camera=camera, progress=progress,
                       resume=(out / JOURNAL).exists())
    return out


def simulate(measured: str | os.PathLike | Any, *, cache_dir: str | os.PathLike, mode: str = "auto",
             tracks: list[str] | None = None, sim_frames: int | None = None, held_out: float = 0.5,
             seed: int = 0, progress: bool = False) -> GapData:
    """Load the measured frames and their clean simulated counterparts (step 1 of the workflow).

    Args:
        measured: a COCO folder (or an open ``CocoDataset``).
        cache_dir: where the clean renders are kept (reused on the next run).
        mode: ``"auto"`` (paired when every record has a track and a pose), ``"paired"`` or ``"unpaired"``.
        tracks: tracks to render in unpaired mode (default: the records' ``track`` values).
        sim_frames: frames to render in unpaired mode (default: as many as measured).
        held_out: fraction of frames held out for the final comparison.
    """
    from weather_gym.datasets.coco import load_coco

    if mode not in ("auto", "paired", "unpaired"):
        raise InputError(f"mode must be 'auto', 'paired' or 'unpaired', got {mode!r}")
    ds = measured if hasattr(measured, "render_view") else load_coco(measured)
    if len(ds) < 4:
        raise InputError(f"{ds.root}: the gap workflow needs at least 4 measured frames, found {len(ds)}")
    can_pair, why = paired_check(ds)
    if mode == "paired" and not can_pair:
        raise InputError(f"{ds.annotations_path}: paired mode needs 'track' and 'pose' in every image record; {why}")
    use_paired = can_pair if mode == "auto" else mode == "paired"
    if mode == "unpaired" and can_pair:
        why = "unpaired mode was asked for: distributions over the whole sets are compared"
    cache = Path(cache_dir)
    cache.mkdir(parents=True, exist_ok=True)
    notes: set[str] = set()
    measured_frames = load_frames(ds, progress=progress, desc="load measured")
    fit, held = split_indices(len(ds), held_out=held_out, seed=seed)
    if use_paired:
        sim_root = _render_paired(ds, cache, progress, notes)
        sim_ds = load_coco(sim_root)
        sim_fit, sim_held = fit, held
        mode_name = "paired"
    else:
        if tracks is None:
            tracks = sorted({ds.track_spec(i) for i, r in enumerate(ds.images) if r.get("track")})
        if not tracks:
            raise InputError(f"{ds.annotations_path}: the records name no track; unpaired mode needs one "
                             "(--track NAME)")
        n_sim = int(sim_frames or len(ds))
        sim_root = _render_unpaired(ds, cache, list(tracks), n_sim, seed, progress)
        sim_ds = load_coco(sim_root)
        sim_fit, sim_held = split_indices(len(sim_ds), held_out=held_out, seed=seed + 1)
        mode_name = "unpaired"
    sim_frames_set = load_frames(sim_ds, progress=progress, desc="load sim")
    if sim_frames_set.size != measured_frames.size:
        raise InputError(f"simulated frames are {sim_frames_set.size}, measured {measured_frames.size}")
    meta = {"measured": str(ds.root), "sim": str(sim_root), "tracks": sorted({str(r.get("track")) for r in sim_ds.images}),
            "size": list(measured_frames.size)}
    return GapData(mode_name, why, measured_frames, sim_frames_set, fit, held, sim_fit, sim_held,
                   notes=sorted(notes), meta=meta)
