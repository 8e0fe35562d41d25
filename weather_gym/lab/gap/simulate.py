"""Simulate the measured frames: clean renders of the same views (paired) or the same track (unpaired).

**Paired mode** needs, in every image record of the measured COCO folder, the ``track`` and the car
``pose`` (``look`` and ``camera`` too, as ``weather-gym dataset render`` writes them; without them
the default look and the default camera at the image size are used, and a note says so). Each view
is re-rendered with :meth:`~weather_gym.lab.datasets.CocoDataset.render_view`.

**Unpaired mode** (no poses, e.g. a real dataset of the same track) renders as many frames of the
same track(s) with the ground-truth driver (:func:`~weather_gym.lab.datasets.render_dataset`), in the world
the records name (``scene``; the default world for a real recording, ``--scene`` to choose); the
comparison then works on distributions over the two sets.

The clean renders are written once into ``cache_dir`` as a COCO folder (an interrupted render
resumes) and reused by every candidate model: weather is post-processing on the same clean frames.
The frame sets, their loading and the split are in :mod:`~weather_gym.lab.gap.frames`.

Example:
    >>> from weather_gym.lab.gap.simulate import split_indices
    >>> fit, held = split_indices(10, held_out=0.5, seed=0)
    >>> len(fit), len(held), sorted(fit.tolist() + held.tolist()) == list(range(10))
    (5, 5, True)
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from tqdm import tqdm

from weather_gym.camera.isp import CameraModel
from weather_gym.core.errors import InputError
from weather_gym.envs.config import EnvConfig
from weather_gym.lab.datasets.coco import ANNOTATIONS, JOURNAL, CocoWriter, load_coco
from weather_gym.lab.datasets.render import ViewRenderer, render_dataset
from weather_gym.lab.gap.frames import (
    COMPARE_WIDTH,
    MIN_FRAMES,
    FrameSet,
    GapData,
    frame_state,
    is_real,
    load_frames,
    paired_check,
    same_views,
    split_indices,
)
from weather_gym.sim.config import SimConfig
from weather_gym.sim.look import DEFAULT_LOOK

__all__ = ["FrameSet", "GapData", "MIN_FRAMES", "COMPARE_WIDTH", "MODES", "load_frames", "paired_check", "simulate",
           "split_indices", "frame_state", "same_views", "is_real"]

_CACHE_VERSION = 2  # 2: views carry scene, camera model and step


MODES = ("auto", "paired", "unpaired", "same-camera", "did")


def _key(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def _camera_of(ds: Any) -> Any:
    rec = ds.images[0]
    cam = ds.camera(0)
    if (cam.width, cam.height) != (rec["width"], rec["height"]):
        raise InputError(f"{ds.annotations_path}: image {rec['id']} is {rec['width']}x{rec['height']} but its "
                         f"camera record says {cam.width}x{cam.height}")
    return cam


def _view_record(rec: dict, camera: Any, notes: set[str]) -> dict:
    # everything render_view needs to reproduce the frame: the world ("scene"), its camera model and the
    # frame's place in its episode ("step": its sensor noise)
    view = {k: rec[k] for k in ("track", "pose", "speed", "yaw_rate", "seed", "look", "camera", "scene",
                                "camera_model", "step") if k in rec}
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


def _scene_of(ds: Any) -> str:
    """The world the records say they were rendered in, when they all agree; otherwise (a real recording)
    the default world."""
    scenes = {rec.get("scene") for rec in ds.images}
    return str(scenes.pop()) if len(scenes) == 1 and None not in scenes else SimConfig().scene


def _camera_model_of(ds: Any) -> CameraModel:
    """The camera model the records name, when they all agree; otherwise (a real recording, or records
    rendered before they carried one) the env's default camera model."""
    models = {json.dumps(rec.get("camera_model"), sort_keys=True) for rec in ds.images}
    if len(models) == 1 and isinstance(ds.images[0].get("camera_model"), dict):
        return CameraModel.from_dict(ds.images[0]["camera_model"])
    return EnvConfig().camera_model


RANDOM_LOOK_FRAMES = 3
"""Frames per episode (per random look) of unpaired renders whose measured set drew random looks."""


def _randomized(ds: Any) -> bool:
    """Whether the measured set says its looks were drawn at random (``info.randomize``, as
    ``weather-gym dataset render --randomize`` writes it)."""
    return bool((getattr(ds, "info", None) or {}).get("randomize"))


def _render_unpaired(camera: Any, cache_dir: Path, tracks: list[str], frames: int, seed: int,
                     progress: bool, scene: str, camera_model: CameraModel, randomize: bool = False) -> Path:
    spec = {"v": _CACHE_VERSION, "tracks": tracks, "frames": frames, "seed": seed, "camera": camera.to_dict(),
            "scene": scene, "camera_model": camera_model.to_dict()}
    key = _key({**spec, "randomize": True} if randomize else spec)
    out = cache_dir / f"unpaired-{key}"
    if not (out / ANNOTATIONS).is_file():
        # random looks: a new one every few frames, so that the set spans them (not two or three)
        episodes: dict[str, Any] = {"randomize": True, "frames_per_episode": RANDOM_LOOK_FRAMES} if randomize else {}
        render_dataset(out, tracks=tracks, frames=frames, seed=seed, camera=camera, progress=progress,
                       resume=(out / JOURNAL).exists(), scene=scene, camera_model=camera_model, **episodes)
    return out


def _check_count(ds: Any, what: str) -> None:
    if len(ds) < MIN_FRAMES:
        raise InputError(f"{ds.root}: the gap workflow needs at least {MIN_FRAMES} {what} frames (half to fit, half "
                         f"held out), found {len(ds)}")


def _resolve_mode(mode: str, reference: Any, can_pair: bool, why: str, ds: Any) -> tuple[str, str]:
    if mode not in MODES:
        raise InputError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if reference is not None:
        if mode in ("paired", "unpaired"):
            raise InputError(f"--reference (measured clear frames) goes with mode same-camera or did, not {mode}")
        if mode == "did":
            return "did", ("difference-in-differences: the change from the measured clear reference to the measured "
                           "frames is compared with the change the model makes to clean simulator frames; what "
                           "already differs between the clear reference and the simulator is a domain difference, "
                           "reported apart and never fitted as weather")
        return "same-camera", ("a measured clear reference of the same camera was given: the model's effects are "
                               "applied to the clear frames and compared with the measured frames; scene and camera "
                               "cancel, no simulator in the loop")
    if mode in ("same-camera", "did"):
        raise InputError(f"mode {mode} needs --reference CLEAR_DIR: measured clear frames of the same camera")
    if mode == "paired" and not can_pair:
        raise InputError(f"{ds.annotations_path}: paired mode needs 'track' and 'pose' in every image record; {why}")
    use_paired = can_pair if mode == "auto" else mode == "paired"
    if mode == "unpaired" and can_pair:
        why = "unpaired mode was asked for: distributions over the whole sets are compared"
    return ("paired" if use_paired else "unpaired"), why


def _tracks_of(ds: Any, tracks: list[str] | None) -> list[str]:
    if tracks is None:
        tracks = sorted({ds.track_spec(i) for i, r in enumerate(ds.images) if r.get("track")})
    if not tracks:
        raise InputError(f"{ds.annotations_path}: the records name no track; the simulator needs one to render "
                         "(--track NAME)")
    return list(tracks)


def simulate(measured: str | os.PathLike | Any, *, cache_dir: str | os.PathLike, mode: str = "auto",
             reference: str | os.PathLike | Any | None = None, tracks: list[str] | None = None,
             sim_frames: int | None = None, scene: str | None = None, held_out: float = 0.5, seed: int = 0,
             progress: bool = False, compare_width: int | None = COMPARE_WIDTH,
             camera_model: CameraModel | None = None) -> GapData:
    """Load the measured frames and the frames the model is applied to (step 1 of the workflow).

    Args:
        measured: a COCO folder (or an open ``CocoDataset``).
        cache_dir: where the clean renders are kept (reused on the next run).
        mode: ``"auto"`` (same-camera with a ``reference``, else paired when every record has a track
            and a pose, else unpaired), ``"paired"``, ``"unpaired"``, ``"same-camera"`` or ``"did"``.
        reference: measured clear frames of the same camera (same-camera and did modes).
        tracks: tracks to render in unpaired and did modes (default: the records' ``track`` values).
        sim_frames: frames to render in unpaired / did mode (default: as many as measured / reference).
        scene: the world of unpaired / did renders (default: the records' ``scene``, else the default world).
        camera_model: the camera model of unpaired / did renders (default: the records' ``camera_model``
            when they all agree, else the env's default, ``CameraModel.realistic()``).
        held_out: fraction of frames held out for the final comparison.
        compare_width: frames wider than this are scaled down once on loading (None: never).
    """

    def opened(x: Any) -> Any:
        return x if hasattr(x, "render_view") else load_coco(x)

    if mode in ("same-camera", "did") and reference is None:
        raise InputError(f"mode {mode} needs --reference CLEAR_DIR: measured clear frames of the same camera")
    if mode in ("paired", "unpaired") and reference is not None:
        raise InputError(f"--reference (measured clear frames) goes with mode same-camera or did, not {mode}")
    ds = opened(measured)
    _check_count(ds, "measured")
    ref_ds = opened(reference) if reference is not None else None
    if ref_ds is not None:
        _check_count(ref_ds, "clear reference")
    can_pair, why = paired_check(ds)
    mode_name, why = _resolve_mode(mode, ref_ds, can_pair, why, ds)
    cache = Path(cache_dir)
    notes: set[str] = set()
    measured_frames = load_frames(ds, max_width=compare_width, progress=progress, desc="load measured")
    if measured_frames.scale != 1.0:
        w0, h0 = measured_frames.original_size  # type: ignore[misc]  # load_frames sets it
        notes.add(f"measured frames scaled once from {w0}x{h0} to {measured_frames.size[0]}x{measured_frames.size[1]} "
                  "(the comparison size)")
    fit, held = split_indices(len(ds), held_out=held_out, seed=seed)
    meta: dict[str, Any] = {"measured": str(ds.root), "size": list(measured_frames.size)}
    out: dict[str, Any] = dict(mode=mode_name, mode_reason=why, measured=measured_frames, fit=fit, held=held)
    ref_frames = None
    if ref_ds is not None:
        ref_frames = load_frames(ref_ds, max_width=compare_width, progress=progress, desc="load reference")
        if ref_frames.size != measured_frames.size:
            raise InputError(f"the clear reference {ref_ds.root} has {ref_frames.original_size[0]}x"  # type: ignore[index]  # load_frames sets it
                             f"{ref_frames.original_size[1]} frames but the measured {ds.root} has "  # type: ignore[index]  # load_frames sets it
                             f"{measured_frames.original_size[0]}x{measured_frames.original_size[1]}: a reference "  # type: ignore[index]  # load_frames sets it
                             "must come from the same camera at the same size")
        meta["reference"] = str(ref_ds.root)
        same, score = same_views(measured_frames, ref_frames)
        meta["same_views_score"] = score
        view_note = (f"every measured frame shows the view of its reference frame (patch correlation {score:.2f}): "
                     "frames are compared one to one" if same else
                     "the reference shows other views than the measured frames: distributions are compared")
    if mode_name == "same-camera":
        sim_frames_set = ref_frames
        if same:
            sim_fit, sim_held = fit, held
        else:
            sim_fit, sim_held = split_indices(len(ref_frames), held_out=held_out, seed=seed + 1)  # type: ignore[arg-type]  # same-camera: a reference
        out.update(sim=sim_frames_set, sim_fit=sim_fit, sim_held=sim_held, pairs=same,
                   mode_reason=f"{why}; {view_note}")
        meta["sim"] = str(ref_ds.root)  # type: ignore[union-attr]  # same-camera: a reference
    elif mode_name == "did":
        ref_fit, ref_held = (fit, held) if same else split_indices(len(ref_frames), held_out=held_out, seed=seed + 2)  # type: ignore[arg-type]  # DiD: a reference
        tr = _tracks_of(ref_ds if any(r.get("track") for r in ref_ds.images) else ds, tracks)  # type: ignore[union-attr]  # DiD: a reference
        camera = _camera_of(ref_ds).scaled(*measured_frames.size)
        n_sim = int(sim_frames or len(ref_ds))  # type: ignore[arg-type]  # DiD: a reference
        sim_root = _render_unpaired(camera, cache, tr, n_sim, seed, progress, scene or _scene_of(ref_ds),
                                    camera_model or _camera_model_of(ref_ds))
        sim_ds = load_coco(sim_root)
        sim_frames_set = load_frames(sim_ds, progress=progress, desc="load sim")
        sim_fit, sim_held = split_indices(len(sim_ds), held_out=held_out, seed=seed + 1)
        out.update(sim=sim_frames_set, sim_fit=sim_fit, sim_held=sim_held, pairs=False, reference=ref_frames,
                   ref_fit=ref_fit, ref_held=ref_held, ref_paired=same, mode_reason=f"{why}; {view_note}")
        meta.update(sim=str(sim_root), tracks=tr)
    elif mode_name == "paired":
        sim_root = _render_paired(ds, cache, progress, notes)
        sim_frames_set = load_frames(load_coco(sim_root), max_width=compare_width, progress=progress, desc="load sim")
        out.update(sim=sim_frames_set, sim_fit=fit, sim_held=held)
        meta["sim"] = str(sim_root)
    else:
        tr = _tracks_of(ds, tracks)
        camera = _camera_of(ds).scaled(*measured_frames.size)
        n_sim = int(sim_frames or len(ds))
        randomize = _randomized(ds)  # random looks measured: the rendered set draws its own (not one look)
        if randomize:
            notes.add("the measured set's looks were drawn at random (info.randomize): the unpaired renders draw "
                      "random looks too, so that a look is not read as weather")
        sim_root = _render_unpaired(camera, cache, tr, n_sim, seed, progress, scene or _scene_of(ds),
                                    camera_model or _camera_model_of(ds), randomize=randomize)
        sim_ds = load_coco(sim_root)
        sim_frames_set = load_frames(sim_ds, progress=progress, desc="load sim")
        sim_fit, sim_held = split_indices(len(sim_ds), held_out=held_out, seed=seed + 1)
        out.update(sim=sim_frames_set, sim_fit=sim_fit, sim_held=sim_held)
        meta.update(sim=str(sim_root), tracks=tr)
        if measured_frames.real:
            out.update(confounded=True, confounded_reason=(
                "the measured frames look like a real recording (another camera and scene than the simulator) and "
                "no clear reference of the same camera was given: a difference from the clean simulator may be "
                "weather or the camera, lens, scene, exposure or car - the data cannot tell them apart. Give "
                "--reference CLEAR_DIR (measured clear frames of the same camera) to name missing weather"))
    if sim_frames_set.size != measured_frames.size:  # type: ignore[union-attr]  # every mode sets it
        raise InputError(f"simulated frames are {sim_frames_set.size}, measured {measured_frames.size}")  # type: ignore[union-attr]  # every mode sets it
    meta.setdefault("tracks", sorted({str(r.get("track")) for r in ds.images if r.get("track")}))
    return GapData(notes=sorted(notes), meta=meta, **out)
