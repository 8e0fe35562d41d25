"""Presets resolved per scenario: the k that makes *this* scenario's perception lose what the study measured.

A calibrated preset (``low_light@2``) carries its target: the relative mAP the study measured in real
weather (``measured_relative``, 0.344 at sunset) on its metric (mAP@0.5 over blue and yellow cones).
The shipped k (``presets.toml``) met it on the calibration pool of tracks for the shipped detector;
:func:`resolve_presets` finds the k that meets it in a given :class:`Scenario` (track or clear
recording, camera and camera model, world, detector, effect mode):

1. a deterministic reference set of the scenario is rendered once (``weather_gym.lab.datasets.render``;
   one frame from each of many start points drawn over the track) and shared by every row;
2. the detector runs on the clear frames once (clear mAP; too few visible cones or a clear mAP too low
   to measure a drop is a :class:`~weather_gym.core.errors.ResolutionError`);
3. per row, k is found by secant steps on the logit of the relative mAP (every frame degraded with its
   own seed, the same at every k), started at the shipped k: off one side of the target through the two
   nearest measured points (or along the shipped presets' curve), inside a bracket by regula falsi, until a
   measured k is within :data:`HIT`; every point measured serves every row of its condition
   (:func:`weather_gym.lab.calibration.curve.invert` reads the final k off them);
4. the damage at the resolved k is bootstrapped over the set's episodes (frames of an episode are not
   independent; each frame has its own weather draw, so the draws are resampled with them): when its 95 %
   interval is wider than ± ``tolerance`` (0.02: a standard error above 0.0102) the set is widened, in chunks
   of ``scenario.frames``, to about the frames the worst row needs (:func:`frames_needed`), up to
   ``scenario.max_frames``, and the search goes on from the k's found; still wider is a ``ResolutionError``
   naming the rows and the fix.

The result is written once to a disk cache (:func:`cache_dir`, ``$WEATHER_GYM_CACHE``) keyed by
everything that changes it (:func:`resolution_key`); concurrent processes computing the same key wait
for the first and read its result. The resolved table is an ordinary presets file (``k_source =
"resolved"``), so ``--presets FILE`` and ``presets=`` take it like the shipped one.

Example (nothing is rendered):
    >>> s = Scenario(tracks=("skidpad",))
    >>> s.describe()
    'track skidpad, plain world, default camera, shipped detector, 160 frames (seed 0)'
    >>> len(resolution_key(s))
    16
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import pickle
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Annotated, Any

import cv2
import numpy as np
from pydantic import BeforeValidator, InstanceOf
from tqdm import tqdm

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core._io import atomic_write, atomic_write_json
from weather_gym.core._lock import waiting_lock
from weather_gym.core._toml import toml_document
from weather_gym.core.errors import InputError, ResolutionError
from weather_gym.core.paths import PACKAGE
from weather_gym.core.schema import OneOf, PositiveInt, check_fields
from weather_gym.core.version import __version__
from weather_gym.envs.config import EnvConfig
from weather_gym.lab.calibration._resolve_worker import FrameBlock, render_part
from weather_gym.lab.calibration.curve import invert
from weather_gym.lab.calibration.frame_ap import FrameMatches, frame_matches
from weather_gym.lab.datasets.coco import load_coco
from weather_gym.perception.detector_spec import DEFAULT_MODEL, load_detector, parse_detector_spec
from weather_gym.perception.scoring import small_rule
from weather_gym.sim.config import SCENES
from weather_gym.weather.presets import DEFAULT_PRESETS, SEVERITIES, conditions, load_presets, nominal_rows
from weather_gym.weather.spec import preset_items

__all__ = ["CACHE_ENV", "MIN_CLEAR_MAP", "MIN_CONES", "Resolution", "ResolvedRow", "Scenario", "cache_dir",
           "code_version", "default_workers", "frames_needed", "presets_for_env", "resolution_key", "resolve_presets", "resolves"]

CACHE_ENV = "WEATHER_GYM_CACHE"
"""Environment variable naming the cache folder (``off``: no cache); default ``$XDG_CACHE_HOME/weather-gym``
or ``~/.cache/weather-gym``."""
MIN_CONES = 100
"""Fewest blue and yellow cones (that count: not too small) a reference set needs to measure a drop."""
MIN_CLEAR_MAP = 0.3
"""Lowest clear mAP@0.5 (blue and yellow) at which a relative drop is measured."""
HIT = 0.01
"""A measured point this close to the target ends a row's search (about one standard error of the damage
the bootstrap accepts, half the ``tolerance``: a closer search would chase the reference set's own sampling
error)."""
MAX_EVALS = 8
"""Most k values measured per row and set."""
EXTRAPOLATE = 1.0
"""A secant step off one side of the target reaches at most this many times the (logit) span of the two
points it is drawn through; further, the step follows the pool curve's local slope instead."""
Z95 = 1.959964
"""A damage is known within ``tolerance`` when its 95 % interval, ``Z95`` bootstrap standard errors either
side, is within ± ``tolerance``."""
BOOTSTRAP = 200
"""Bootstrap replicates (over episodes) of the damage at the resolved k."""
DETECT_BATCH = 1
"""Frames per detector call while resolving (CPU per frame grows with the batch: ``weather-gym bench resolve``)."""
PARTS = 2
"""Parts a chunk of the reference set is rendered in (each from its own seed; helper processes render
parts at the same time). Fixed, so the frames do not depend on the number of processes."""
RENDER_EVERY = 1
"""Env steps from a reference frame's start point to the frame (one: the car has moved 1/30 s, so its speed
and yaw rate are those of driving; each step renders the camera, so fewer steps render the set faster)."""
VERSION = 5
"""Version of this resolution method (part of the cache key)."""

_CODE = ("weather", "sim", "camera", "lab/datasets/render.py", "lab/datasets/coco.py",
         "lab/datasets/coco_writer.py", "perception/scoring.py", "perception/onnx_detector.py", "perception/yolo.py",
         "perception/preprocess.py", "perception/cones.py", "lab/calibration/resolve.py", "lab/calibration/frame_ap.py",
         "lab/calibration/curve.py",
         "lab/calibration/_resolve_worker.py")


# ------------------------------------------------------------------------------------------ scenario
def _tracks(value: Any) -> Any:
    """``Scenario.tracks``: one name or a list of names, as a tuple."""
    return (value,) if isinstance(value, str) else tuple(value) if isinstance(value, list) else value


def _path_text(value: Any) -> Any:
    """``Scenario.dataset``: a path as its text."""
    return os.fspath(value) if isinstance(value, os.PathLike) else value


@dataclass(frozen=True)
class Scenario:
    """What a preset is resolved for. ``dataset``: a clear COCO recording used as it is (no render);
    otherwise ``frames`` frames are rendered over ``tracks`` in ``scene`` through ``camera`` and
    ``camera_model`` (None: the env's default), in episodes of ``frames_per_episode`` (1: every frame from
    its own start point; frames of one episode, 1/30 s apart, tell about half as much as frames of different
    episodes), from ``seed``, widened in chunks of ``frames`` up to ``max_frames`` while a damage is not known
    within the tolerance.
    ``detector``: a detector spec (None: the shipped one; ``"yolov8:model.onnx"``, ...)."""

    tracks: Annotated[tuple[str, ...], BeforeValidator(_tracks)] = ("small_track",)
    scene: Annotated[str, OneOf(SCENES)] = "plain"
    camera: InstanceOf[CameraConfig] = field(default_factory=CameraConfig)
    camera_model: InstanceOf[CameraModel] | None = None
    detector: Any = None
    dataset: Annotated[str | None, BeforeValidator(_path_text)] = None
    frames: PositiveInt = 160
    max_frames: PositiveInt = 1600  # and >= frames
    seed: int = 0
    frames_per_episode: PositiveInt = 1

    def __post_init__(self) -> None:
        check_fields(self)  # each field against its annotation; then the relations
        if self.dataset is None and not self.tracks:
            raise InputError("a scenario needs a track (tracks=...) or a clear recording (dataset=...)")
        if self.max_frames < self.frames:
            raise InputError(f"Scenario.max_frames ({self.max_frames}) is below frames ({self.frames})")

    @property
    def model(self) -> CameraModel:
        return self.camera_model if self.camera_model is not None else EnvConfig().camera_model

    def identity(self) -> dict[str, Any]:
        """Everything about the scenario that changes its frames (JSON)."""
        if self.dataset is not None:
            ann = Path(self.dataset) / "annotations.json"
            return {"dataset": str(Path(self.dataset).resolve()), "annotations_sha256": _file_sha(ann)}
        return {"tracks": list(self.tracks), "scene": self.scene, "camera": self.camera.to_dict(),
                "camera_model": self.model.to_dict(), "frames": self.frames, "max_frames": self.max_frames,
                "seed": self.seed, "frames_per_episode": self.frames_per_episode, "every": RENDER_EVERY}

    def describe(self) -> str:
        spec = parse_detector_spec(self.detector) if self.detector is not None else None
        shipped = spec is None or (spec.kind == "conenet" and spec.path is None and spec == type(spec)())
        det = "shipped detector" if shipped else f"detector {spec}"
        if self.dataset is not None:
            return f"recording {self.dataset}, {det}"
        cam = "default camera" if self.camera == CameraConfig() and self.model == EnvConfig().camera_model else "given camera"
        return (f"track {'+'.join(self.tracks)}, {self.scene} world, {cam}, {det}, {self.frames} frames "
                f"(seed {self.seed})")


@dataclass
class ResolvedRow:
    """One preset resolved: its ``k`` for the scenario beside the shipped pool ``k_pool``, the relative mAP
    measured there (``achieved``) with its bootstrap standard error and 95 % interval, the ``k_interval``
    over which the damage stays within one standard error of the target, and the search's points."""

    condition: str
    severity: int
    target: float
    k: float
    k_pool: float
    achieved: float
    se: float
    ci95: tuple[float, float]
    k_interval: tuple[float, float]
    reachable: bool
    effect: dict[str, Any]
    evals: int
    note: str = ""


@dataclass
class Resolution:
    """The resolved presets of a scenario: rows, the clear mAP and cones they rest on, the presets file."""

    scenario: str
    key: str
    rows: list[ResolvedRow]
    clear_map: float
    n_cones: int
    n_frames: int
    seconds: float
    path: Path | None
    cached: bool = False
    points: dict[str, list[list[float]]] = field(default_factory=dict)
    note: str = ""

    def row(self, condition: str, severity: int) -> ResolvedRow:
        for r in self.rows:
            if r.condition == condition and r.severity == severity:
                return r
        raise InputError(f"no resolved row {condition}@{severity} (resolved: "
                         f"{', '.join(f'{r.condition}@{r.severity}' for r in self.rows)})")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["path"] = None if self.path is None else str(self.path)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Resolution:
        rows = [ResolvedRow(**{**r, "ci95": tuple(r["ci95"]), "k_interval": tuple(r["k_interval"])}) for r in d["rows"]]
        return cls(**{**d, "rows": rows, "path": None if d["path"] is None else Path(d["path"])})


# ---------------------------------------------------------------------------------------------- cache
def cache_dir() -> Path | None:
    """The cache folder (created), or None when there is none (``WEATHER_GYM_CACHE=off``, or no writable
    place: a read-only install with no writable home resolves every time)."""
    env = os.environ.get(CACHE_ENV)
    if env is not None and env.strip().lower() in ("", "off", "none", "0"):
        return None
    if env:
        root = Path(env)
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = Path(base) / "weather-gym"
    try:
        (root / "resolved").mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=root / "resolved", prefix=".probe", delete=True)
        probe.close()
    except OSError:
        return None
    return root


def _file_sha(path: Path) -> str:
    st = path.stat()
    return _sha_cached(str(path.resolve()), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=64)
def _sha_cached(path: str, mtime_ns: int, size: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@lru_cache(maxsize=1)
def code_version() -> str:
    """16 hex digits of the source of the pieces a resolution depends on (renderer, effects, camera,
    detector wrappers, scoring, this module) and the package version.

    The content hash is remembered in the cache folder under a hash of the files' names, sizes and
    modification times, so a new process (an env, a worker) stats the files instead of reading them."""
    pkg = PACKAGE
    files = []
    for part in _CODE:
        p = pkg / part
        files += sorted(p.rglob("*.py")) if p.is_dir() else [p]
    stats = [(str(f.relative_to(pkg)), f.stat().st_mtime_ns, f.stat().st_size) for f in files]
    sig = hashlib.sha256(json.dumps([__version__, VERSION, stats]).encode()).hexdigest()[:16]
    root = cache_dir()
    memo = None if root is None else root / "code" / f"{sig}.txt"
    if memo is not None and memo.is_file():
        with contextlib.suppress(OSError):
            text = memo.read_text().strip()
            if len(text) == 16:
                return text
    h = hashlib.sha256(f"{__version__}/{VERSION}".encode())
    for f in files:
        h.update(str(f.relative_to(pkg)).encode())
        h.update(f.read_bytes())
    out = h.hexdigest()[:16]
    if memo is not None:
        with contextlib.suppress(OSError):
            memo.parent.mkdir(exist_ok=True)
            atomic_write(memo, out + "\n", overwrite=True)
    return out


def _targets(presets: str | os.PathLike | None) -> list[tuple[str, int, dict[str, Any]]]:
    """The rows that can be resolved: calibrated, with a measured relative target and one effect."""
    table = load_presets(presets)["presets"]
    out = []
    for cond in conditions():
        for sev in SEVERITIES:
            t = table.get(cond, {}).get(sev)
            if (t and t.get("calibrated") and len(t["effects"]) == 1 and "measured_relative" in t
                    and t.get("target", "relative") == "relative" and t["effects"][0].get("name") not in ("ramp", "compose")):
                out.append((cond, sev, t))
    return out


def resolution_key(scenario: Scenario, presets: str | os.PathLike | None = None, tolerance: float = 0.02) -> str:
    """16 hex digits naming a resolution: scenario, detector file and options, the rows' targets and
    effects, the tolerance, :func:`code_version` and the versions of the libraries that compute frames and
    detections (OpenCV, numpy, onnxruntime, PyBullet)."""
    spec = parse_detector_spec(scenario.detector)
    rows = [[c, s, t["measured_relative"], {k: v for k, v in t["effects"][0].items() if k != "k"}]
            for c, s, t in _targets(presets)]
    model = Path(spec.path) if spec.path is not None else DEFAULT_MODEL  # its SHA-256, as detector_id, cached
    detector = [_file_sha(model), spec.kind, spec.classes, spec.resize, spec.input_size, spec.score_threshold]
    doc = {"scenario": scenario.identity(), "detector": detector, "detector_spec": str(spec),
           "rows": rows, "tolerance": float(tolerance), "code": code_version(), "libraries": _libraries()}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


@lru_cache(maxsize=1)
def _libraries() -> list[str]:
    """Versions of the libraries whose arithmetic is in the frames and detections (OpenCV's, with its
    optimised paths on or off: the night camera's bytes differ between its builds), and the machine type."""
    def dist(name: str) -> str:  # from the installed metadata: importing pybullet prints a banner
        try:
            return version(name)
        except PackageNotFoundError:
            return "?"

    return [f"opencv {cv2.__version__} optimized={cv2.useOptimized()} ipp={os.environ.get('OPENCV_IPP', '')}",
            f"numpy {np.__version__}", f"onnxruntime {dist('onnxruntime')}", f"pybullet {dist('pybullet')}",
            platform.machine()]


# ------------------------------------------------------------------------------------ the reference set
class Helper:
    """A helper process (:mod:`weather_gym.lab.calibration._resolve_worker`) taking a share of the frames:
    ``send(request...)`` then ``recv()`` its answer; ``close()`` ends it."""

    def __init__(self, detector: Any, threads: int) -> None:
        pkg_parent = str(PACKAGE.parent)
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([pkg_parent, *filter(None, [env.get("PYTHONPATH")])])
        self.proc = subprocess.Popen([sys.executable, "-m", "weather_gym.lab.calibration._resolve_worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        self.send("init", detector, threads)  # its answer is read before the first other one (it starts meanwhile)
        self._init_unread = True

    def send(self, *msg: Any) -> None:
        assert self.proc.stdin is not None
        pickle.dump(msg, self.proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
        self.proc.stdin.flush()

    def recv(self) -> Any:
        if self._init_unread:
            self._init_unread = False
            self.recv()
        assert self.proc.stdout is not None
        try:
            status, result = pickle.load(self.proc.stdout)
        except EOFError:
            raise RuntimeError(f"a resolution helper process ended (exit status {self.proc.wait()}); "
                               "its error is above on stderr") from None
        if status != "ok":
            raise RuntimeError(f"a resolution helper process failed: {result}")
        return result

    def close(self) -> None:
        with contextlib.suppress(OSError):
            if self.proc.stdin is not None:
                self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


class _ReferenceSet:
    """The scenario's frames (rendered in chunks of ``scenario.frames``, each chunk once, in :data:`PARTS`
    parts), the detector's clear detections and every degraded frame's detections, kept per (effect, k, chunk).

    With ``workers`` above 1, helper processes render parts of a chunk and degrade and detect their share
    of its frames while this process does its own (:mod:`weather_gym.lab.calibration._resolve_worker`);
    the frames and every detection are the same as with one process."""

    def __init__(self, scenario: Scenario, root: Path, detector: Any, progress: bool, workers: int = 1,
                 threads: int = 1) -> None:
        self.scenario, self.root, self.detector, self.progress = scenario, root, detector, progress
        self.chunks: list[dict[str, Any]] = []
        self._dets: dict[tuple[str, float, int], list[Any]] = {}
        self.helpers = [Helper(scenario.detector, threads) for _ in range(max(int(workers), 1) - 1)]

    def close(self) -> None:
        for h in self.helpers:
            h.close()
        self.helpers = []

    def _render(self, i: int) -> list[Path]:
        """Render chunk ``i``'s parts (each once; helpers render a part each), return their folders."""
        s = self.scenario
        sizes = [s.frames // PARTS + (1 if p < s.frames % PARTS else 0) for p in range(PARTS)]
        folders = [self.root / f"chunk{i}" / f"part{p}" for p in range(PARTS)]
        jobs: list[dict[str, Any]] = [dict(out=folders[p], tracks=list(s.tracks), frames=sizes[p], seed=s.seed + 7919 * i + 104729 * p,
                     camera=s.camera, camera_model=s.model, scene=s.scene, frames_per_episode=s.frames_per_episode,
                     every=RENDER_EVERY, progress=self.progress, resume=folders[p].exists()) for p in range(PARTS) if sizes[p] > 0]

        (self.root / f"chunk{i}").mkdir(parents=True, exist_ok=True)
        todo = [j for j in jobs if not (Path(j["out"]) / "annotations.json").is_file()]
        given = []
        for h, job in zip(self.helpers, todo[1:], strict=False):  # helpers render the later parts
            h.send("render", {**job, "progress": False})
            given.append(h)
        for job in todo[len(given) + 1:] + todo[:1]:
            render_part(job)
        for h in given:
            h.recv()
        return [Path(j["out"]) for j in jobs]

    def widen(self) -> None:
        i = len(self.chunks)
        s = self.scenario
        if s.dataset is not None:
            sets = [load_coco(s.dataset)]
        else:
            sets = [load_coco(f) for f in self._render(i)]
        frames = [(str(ds.root), j) for ds in sets for j in range(len(ds))]
        n = len(frames)
        seeds = np.random.SeedSequence([s.seed, i]).generate_state(max(n, 1), dtype=np.uint32)
        cuts = np.linspace(0, n, len(self.helpers) + 2).round().astype(int)
        for b, h in enumerate(self.helpers, start=1):
            h.send("frames", i, frames[cuts[b]:cuts[b + 1]], seeds[cuts[b]:cuts[b + 1]])
        own = FrameBlock.load(frames[:cuts[1]], seeds[:cuts[1]])
        for h in self.helpers:
            h.recv()
        rule = small_rule(sets[0], self.detector)
        self.chunks.append({
            "block": own, "cuts": cuts, "n": n,
            "gts": [ds.gt(j) for ds in sets for j in range(len(ds))],
            "groups": [(i, str(ds.root), rec.get("episode", j)) for ds in sets
                       for j, rec in ((j, ds.record(j)) for j in range(len(ds)))],
            "min_box_height": None if rule is None else rule.min_height_px,
        })

    @property
    def n_frames(self) -> int:
        return sum(c["n"] for c in self.chunks)

    def detections(self, label: str, table: dict[str, Any] | None, k: float, chunk: int) -> list[Any]:
        """The detector's detections on every frame of ``chunk`` degraded by the effect ``table`` at ``k``
        (None: clear), this process's share and the helpers' at the same time.

        Frames go through the detector one at a time, as they are degraded (:data:`DETECT_BATCH`: a batch of
        one costs the shipped detector about half the CPU per frame of a batch of 160, and no degraded set is
        held in memory); a degraded frame whose bytes equal its clear frame (an effect that leaves it as it is,
        e.g. at k = 0) reuses the clear frame's detections."""
        key = (label, round(float(k), 6), chunk)
        if key not in self._dets:
            c = self.chunks[chunk]
            for h in self.helpers:
                h.send("detect", chunk, table)
            out = list(c["block"].detect(self.detector.detect_batch, table))
            for h in self.helpers:
                out += h.recv()
            self._dets[key] = out
        return self._dets[key]

    def matches(self, label: str, table: dict[str, Any] | None, k: float) -> FrameMatches:
        gts, dets, groups = [], [], []
        rules = {c["min_box_height"] for c in self.chunks}
        for i, c in enumerate(self.chunks):
            gts += c["gts"]
            groups += c["groups"]
            dets += self.detections(label, table, k, i)
        return frame_matches(gts, dets, groups=groups, min_box_height=rules.pop() if len(rules) == 1 else None)


# ------------------------------------------------------------------------------------------ the search
def _pool_curve(points: Sequence[Sequence[float]]) -> tuple[np.ndarray, np.ndarray]:
    """``(k, relative)`` points of a condition (the shipped presets' or a smaller set's), from k = 0
    (relative 1), made a usable curve: sorted, never rising."""
    pts = sorted({(0.0, 1.0), *((float(k), float(r)) for k, r in points if k > 0)})
    ks = np.array([p[0] for p in pts])
    rel = np.minimum.accumulate(np.array([p[1] for p in pts]))
    return ks, rel


def _logit(r: float) -> float:
    """log(r / (1 - r)), ``r`` held inside [0.002, 0.998]: a relative-mAP curve falls from 1 to 0 in an S, and
    its logit is close to a straight line in k, so secant steps on it land closer than on the mAP itself."""
    r = min(max(float(r), 0.002), 0.998)
    return math.log(r / (1.0 - r))


def _pool_k(ks: np.ndarray, rel: np.ndarray, r: float) -> float:
    """k at which the shipped curve reaches relative ``r`` (linear in logit between its points, extended
    linearly past its ends)."""
    lg = np.array([_logit(x) for x in rel])
    y = _logit(r)
    if r >= rel[0]:
        return float(ks[0])
    if y <= lg[-1]:
        slope = (lg[-1] - lg[-2]) / max(ks[-1] - ks[-2], 1e-6)
        return float(ks[-1] + (y - lg[-1]) / min(slope, -1e-3))
    return float(np.interp(-y, -lg, ks))


def _secant(k1: float, r1: float, k2: float, r2: float, target: float) -> float | None:
    """k where the line through (k1, logit r1) and (k2, logit r2) reaches logit ``target`` (None: not falling)."""
    y1, y2 = _logit(r1), _logit(r2)
    if k1 == k2 or (y2 - y1) / (k2 - k1) >= 0:
        return None
    return k1 + (_logit(target) - y1) * (k2 - k1) / (y2 - y1)


def _next_k(points: dict[float, float], target: float, pool: tuple[np.ndarray, np.ndarray], k0: float,
            recent: Sequence[float] = ()) -> float | None:
    """The next k to measure (None: nothing new to learn), from the measured ``points`` {k: relative}.

    No point yet: the pool k. One side of the target only: a secant step (in logit) through the two measured
    points nearest the target, or with one point a step along the pool curve's local slope; bracketed:
    regula falsi (in logit) between the bracket's ends, or the bracket's middle when the last two k's this
    row measured (``recent``, in order) fell on the same side of the target (regula falsi creeps from one end
    where the curve bends)."""
    if not points:
        return k0
    ks = sorted(points)
    above = [k for k in ks if points[k] > target]
    below = [k for k in ks if points[k] < target]
    if above and below and max(above) < min(below):
        lo, hi = max(above), min(below)
        if hi - lo <= 0.0015:
            return None
        k = _secant(lo, points[lo], hi, points[hi], target)
        last = [points[x] for x in recent[-2:]]
        if k is None or (len(last) == 2 and (last[0] > target) == (last[1] > target)):
            k = lo + 0.5 * (hi - lo)  # the same end moved twice (a curve bent in logit): bisect (Illinois' cure)
        k = min(max(k, lo + 0.1 * (hi - lo)), hi - 0.1 * (hi - lo))  # keep the bracket shrinking
    elif above and not below or below and not above:
        side = above if above else below
        k_cur = max(side) if above else min(side)
        if (above and k_cur >= 1.0) or (below and k_cur <= 0.0):
            return None
        pool_step = abs(_pool_k(*pool, target) - _pool_k(*pool, points[k_cur]))
        k_far = (side[-2] if above else side[1]) if len(side) >= 2 else None
        k = None
        if k_far is not None and 0.002 < points[k_far] < 0.998:  # not a saturated point (k = 0 keeps 1)
            span = abs(_logit(points[k_cur]) - _logit(points[k_far]))
            if abs(_logit(target) - _logit(points[k_cur])) <= EXTRAPOLATE * span:  # no far leap off a short chord
                k = _secant(k_far, points[k_far], k_cur, points[k_cur], target)
        step = pool_step if k is None else abs(k - k_cur)
        step = min(max(step, 0.002), 0.5)
        k = min(1.0, k_cur + step) if above else max(0.0, k_cur - step)
    else:  # not monotone between the bracketing points: bisect the widest gap around the target
        lo = max(k for k in ks if points[k] >= target) if any(points[k] >= target for k in ks) else 0.0
        hi = min((k for k in ks if k > lo and points[k] < target), default=1.0)
        k = 0.5 * (lo + hi)
    k = round(k, 3)
    return None if k in points else k


def _bootstrap(clear: FrameMatches, hit: FrameMatches, seed: int) -> tuple[float, tuple[float, float]]:
    """Standard error and 95 % interval of relative mAP over episodes (``BOOTSTRAP`` replicates, all at once)."""
    rng = np.random.default_rng(seed)
    n = clear.n_groups
    w = rng.multinomial(n, np.full(n, 1.0 / n), size=BOOTSTRAP).astype(np.float64)
    c = clear.map50_many(w)
    ok = c > 0
    v = hit.map50_many(w[ok]) / c[ok]
    return float(np.std(v, ddof=1)), (float(np.percentile(v, 2.5)), float(np.percentile(v, 97.5)))


class _Search:
    """The measured points of one condition's effect (shared by its rows) and the search for each row's k."""

    def __init__(self, ref: _ReferenceSet, items, clear: FrameMatches, clear_map: float, scenario: Scenario,
                 tick: Callable[[], None], curve: Sequence[Sequence[float]] | None = None) -> None:
        table = {k: v for k, v in items[0][1]["effects"][0].items() if k != "k"}
        self.name, self.params = table.pop("name"), table
        self.label = json.dumps([self.name, self.params], sort_keys=True)
        # the curve a first step follows: the points a smaller set measured, else the shipped presets'
        self.pool = _pool_curve(curve or [(t["effects"][0]["k"], t["measured_relative"]) for _, t in items])
        self.ref, self.clear, self.clear_map, self.scenario, self.tick = ref, clear, clear_map, scenario, tick
        self.points: dict[float, float] = {}
        self.matches: dict[float, FrameMatches] = {}

    def measure(self, k: float) -> None:
        m = self.ref.matches(self.label, {"name": self.name, "k": k, **self.params}, k)
        self.matches[k] = m
        self.points[k] = m.map50() / self.clear_map
        self.tick()

    def _hit(self, target: float) -> bool:
        return any(abs(v - target) <= HIT for v in self.points.values())

    def row(self, cond: str, sev: int, t: dict[str, Any], k_start: float | None = None) -> ResolvedRow:
        target, k_pool = float(t["measured_relative"]), float(t["effects"][0]["k"])
        k0 = k_pool if k_start is None else k_start
        points, evals, note, reachable = self.points, 0, "", True
        if target >= 1.0 and 0.0 not in points:
            self.measure(0.0)
            evals += 1
        recent: list[float] = []
        while evals < MAX_EVALS and not self._hit(target):
            k = _next_k(points, target, self.pool, k0, recent)
            if k is None:
                break
            self.measure(k)
            recent.append(k)
            evals += 1
        ks = sorted(points)
        if all(points[k] > target for k in ks) and max(ks) >= 1.0:
            raise ResolutionError(
                f"{cond}@{sev} cannot be resolved for {self.scenario.describe()}: its target relative mAP "
                f"{target:.3f} is out of the effect's reach (at k = 1 the detector keeps {points[1.0]:.3f} of its "
                f"clear mAP {self.clear_map:.3f}); use the shipped pool presets (--presets pool) or a stronger effect mode")
        if all(points[k] < target for k in ks) and min(ks) <= 0.0:
            reachable = False
            note = (f"the target {target:.3f} is above what k = 0 keeps ({points[0.0]:.3f}): the effect only "
                    "lowers it; k = 0 comes closest")
        elif len(ks) >= 2 and not self._hit(target):
            k_inv = round(invert(ks, [points[k] for k in ks], target, what="the relative mAP").k, 3)
            if k_inv not in points:  # measure where the search ended, so the damage is known there
                self.measure(k_inv)
                evals += 1
        k_res = min(points, key=lambda k: (abs(points[k] - target), k))
        if reachable and abs(points[k_res] - target) > HIT:
            note = (f"closest measured point after {evals} steps ({points[k_res]:.3f} against {target:.3f}): "
                    "the curve is steep or noisy here")
        return _row(cond, sev, target, k_res, k_pool, points, self.matches, self.clear, self.name, self.params,
                    evals, reachable=reachable, note=note)


def _resolve_rows(ref: _ReferenceSet, targets, clear: FrameMatches, clear_map: float, scenario: Scenario,
                  tick: Callable[[], None], start: dict[tuple[str, int], float] | None = None,
                  curves: dict[str, list[list[float]]] | None = None,
                  ) -> tuple[list[ResolvedRow], dict[str, list[list[float]]]]:
    """Every row searched on the set as it is now; ``start``: the k each row starts from (a smaller set's
    resolved k; default the pool k); ``curves``: per condition, the (k, relative) points a smaller set measured,
    whose local slope sizes a row's first step (default the shipped presets' curve)."""
    by_cond: dict[str, list] = {}
    for cond, sev, t in targets:
        by_cond.setdefault(cond, []).append((sev, t))
    rows: list[ResolvedRow] = []
    points_out: dict[str, list[list[float]]] = {}
    for cond, items in by_cond.items():
        search = _Search(ref, items, clear, clear_map, scenario, tick, (curves or {}).get(cond))
        rows += [search.row(cond, sev, t, (start or {}).get((cond, sev))) for sev, t in items]
        points_out[cond] = [[k, search.points[k]] for k in sorted(search.points)]
    return rows, points_out


def _row(cond, sev, target, k, k_pool, points, matches, clear, name, params, evals, *, reachable, note) -> ResolvedRow:
    se, ci = _bootstrap(clear, matches[k], seed=1000 * SEVERITIES.index(sev) + len(cond))
    ks = sorted(points)
    vals = np.array([points[x] for x in ks])
    i = ks.index(k)
    nb = [j for j in (i - 1, i + 1) if 0 <= j < len(ks)]
    slopes = [(vals[j] - vals[i]) / (ks[j] - ks[i]) for j in nb if ks[j] != ks[i]]
    slope = min(slopes) if slopes else -math.inf
    dk = se / abs(slope) if slope < 0 else 0.0
    k_int = (round(max(0.0, k - dk), 3), round(min(1.0, k + dk), 3))
    effect = {"name": name, "k": float(k), **params}
    return ResolvedRow(cond, int(sev), float(target), float(k), float(k_pool), float(points[k]), round(se, 4),
                       (round(ci[0], 4), round(ci[1], 4)), k_int, bool(reachable), effect, int(evals), note)


# ------------------------------------------------------------------------------------------- resolving
def resolve_presets(scenario: Scenario | None = None, *, presets: str | os.PathLike | None = None,
                    tolerance: float = 0.02, cache: bool = True, progress: bool = True,
                    threads: int = 1, workers: int | None = None) -> Resolution:
    """The shipped (or ``presets``) calibrated rows resolved for ``scenario`` (see module doc).

    Cached: a second call with the same key reads the result (tens of ms); ``cache=False`` or no cache
    folder (:func:`cache_dir`) resolves anew, in a temporary folder. ``tolerance``: the half-width of the
    95 % interval (bootstrap) within which a row's damage must be known. ``workers``: processes that share the frames (None:
    :func:`default_workers`; the result does not depend on it). Raises :class:`~weather_gym.core.errors.ResolutionError`
    where the scenario does not allow it.
    """
    scenario = scenario or Scenario()
    workers = default_workers() if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    if not (isinstance(tolerance, float | int) and 0 < tolerance < 1):
        raise InputError(f"tolerance must be a number in (0, 1), got {tolerance!r}")
    key = resolution_key(scenario, presets, tolerance)
    root = cache_dir() if cache else None
    if root is None:  # frames in a temporary folder; the presets file beside them in the temp dir, if it is writable
        out = Path(tempfile.gettempdir()) / f"weather-gym-resolved-{key}.toml"
        with tempfile.TemporaryDirectory(prefix="weather-gym-resolve-") as tmp:
            res = _compute(scenario, presets, tolerance, key, Path(tmp), None, progress, threads, workers)
        with contextlib.suppress(OSError):
            res.path = write_resolved(res, out, presets=presets, scenario=scenario, overwrite=True)
        res.note = ("no cache folder (set WEATHER_GYM_CACHE to a writable folder to keep resolutions)" if cache
                    else "cache off")
        return res
    entry = root / "resolved" / f"{key}.json"
    hit = _read_entry(entry)
    if hit is not None:
        return hit
    with waiting_lock(str(root / "resolved" / f".{key}.lock")):
        hit = _read_entry(entry)  # another process may have computed it while we waited
        if hit is not None:
            return hit
        frames = root / "frames" / hashlib.sha256(json.dumps(scenario.identity(), sort_keys=True,
                                                             default=str).encode()).hexdigest()[:16]
        frames.mkdir(parents=True, exist_ok=True)
        res = _compute(scenario, presets, tolerance, key, frames, root / "resolved" / f"{key}.toml", progress, threads,
                       workers)
        atomic_write_json(entry, res.to_dict(), indent=1, overwrite=True)
    return res


def frames_needed(n_frames: int, se: float, tolerance: float) -> int:
    """Frames at which a damage with standard error ``se`` on ``n_frames`` frames is known within
    ``tolerance`` (95 %), with a tenth to spare: the error falls as one over the square root of the frames.

    Example:
        >>> frames_needed(160, 0.019, 0.02)
        611
    """
    return int(math.ceil(n_frames * (Z95 * se / tolerance) ** 2 * 1.1))


def default_workers() -> int:
    """Processes a resolution uses by default: the cores this process may run on, at most 4."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(4, n))


def _read_entry(entry: Path) -> Resolution | None:
    if not entry.is_file():
        return None
    try:
        res = Resolution.from_dict(json.loads(entry.read_text()))
    except (OSError, ValueError, TypeError, KeyError):
        return None  # a damaged entry is computed again (and replaced)
    if res.path is not None and not res.path.is_file():
        return None
    res.cached = True
    return res


def _compute(scenario: Scenario, presets, tolerance: float, key: str, frames_root: Path, out: Path | None,
             progress: bool, threads: int, workers: int = 1) -> Resolution:
    t0 = time.perf_counter()
    targets = _targets(presets)
    if not targets:
        raise InputError(f"presets file {presets or DEFAULT_PRESETS} has no calibrated rows with a relative target to resolve")
    detector = load_detector(scenario.detector, threads=threads)
    ref = _ReferenceSet(scenario, frames_root, detector, progress, workers, threads)
    bar = tqdm(desc="resolve presets", unit="k", disable=not progress)
    try:
        ref.widen()
        start: dict[tuple[str, int], float] = {}
        curves: dict[str, list[list[float]]] = {}
        while True:
            clear = ref.matches("clear", None, 0.0)
            n_cones = int(clear.npos.sum())
            if n_cones < MIN_CONES:
                raise ResolutionError(
                    f"{scenario.describe()}: only {n_cones} blue and yellow cones are big enough to count in "
                    f"{ref.n_frames} frames (at least {MIN_CONES} needed to measure a drop); use more frames "
                    f"(Scenario.frames / --frames), a longer track, or the shipped pool presets (--presets pool)")
            clear_map = clear.map50()
            if not clear_map >= MIN_CLEAR_MAP:
                raise ResolutionError(
                    f"{scenario.describe()}: the detector's clear mAP@0.5 (blue and yellow) is {clear_map:.3f}, "
                    f"below {MIN_CLEAR_MAP} at which a relative drop is measured; check the detector spec "
                    f"(classes, input size) or use the shipped pool presets (--presets pool)")
            rows, points = _resolve_rows(ref, targets, clear, clear_map, scenario, bar.update, start, curves)
            wide = [r for r in rows if Z95 * r.se > tolerance]
            if not wide:
                break
            worst = max(wide, key=lambda r: r.se)
            need = frames_needed(ref.n_frames, worst.se, tolerance)
            if scenario.dataset is not None or ref.n_frames + scenario.frames > scenario.max_frames:
                raise ResolutionError(
                    f"{scenario.describe()}: the damage of {', '.join(f'{r.condition}@{r.severity}' for r in wide)} is "
                    f"not known within ±{tolerance:g} (95 %) on {ref.n_frames} frames ({worst.condition}@{worst.severity}: "
                    f"relative mAP {worst.achieved:.3f}, bootstrap standard error {worst.se:.3f}); about {need} frames "
                    f"would do: raise max_frames (--max-frames), record a longer clear set, or loosen --tolerance")
            start, curves = {(r.condition, r.severity): r.k for r in rows}, points
            ref.widen()  # straight to about what the worst row needs, in chunks, up to max_frames
            while ref.n_frames < need and ref.n_frames + scenario.frames <= scenario.max_frames:
                ref.widen()
    finally:
        bar.close()
        ref.close()
    res = Resolution(scenario=scenario.describe(), key=key, rows=rows, clear_map=round(clear_map, 4), n_cones=n_cones,
                     n_frames=ref.n_frames, seconds=round(time.perf_counter() - t0, 1), path=None, points=points)
    if out is not None:
        res.path = write_resolved(res, out, presets=presets, scenario=scenario, overwrite=True)
    return res


def write_resolved(res: Resolution, path: str | os.PathLike, *, presets: str | os.PathLike | None = None,
                   scenario: Scenario | None = None, overwrite: bool = False) -> Path:
    """The presets file of ``res``: the base table (``presets``, default the shipped one) with the resolved
    rows' k replaced (``k_source = "resolved"``, the pool's k, the interval and the bootstrap beside it)."""
    base = load_presets(presets)
    done = {(r.condition, r.severity): r for r in res.rows}
    rows = []
    for cond, sevs in base["presets"].items():
        if sevs == nominal_rows(cond) and not any((cond, s) in done for s in SEVERITIES):
            continue  # its effect's own nominal rows: generated on load, not written
        for sev in SEVERITIES:
            t = dict(sevs[sev])
            r = done.get((cond, sev))
            if r is not None:
                t.update(effects=[r.effect], k_pool=r.k_pool, k_interval=list(r.k_interval), k_source="resolved",
                         achieved_relative=round(r.achieved, 4), achieved_se=r.se, achieved_ci95=list(r.ci95),
                         reachable=r.reachable, note=r.note, resolution_evals=r.evals)
                for k in ("achieved_map", "achieved_sd", "predicted", "k_absolute"):
                    t.pop(k, None)
            rows.append(t)
    meta = {k: v for k, v in base.items() if k not in ("presets", "calibrated", "calibrated_conditions")}
    meta.update(source=f"resolved by weather_gym.lab.calibration.resolve for {res.scenario}", k_source="resolved",
                resolution_key=res.key, scenario=res.scenario, clear_map=res.clear_map, n_frames=res.n_frames,
                n_cones=res.n_cones, base_presets=str(presets or DEFAULT_PRESETS.name))
    if scenario is not None and scenario.detector is not None:
        meta["detector"] = str(parse_detector_spec(scenario.detector))
    header = ("# weather-gym presets RESOLVED for one scenario (docs/calibration.md, 'Two meanings of a severity'):\n"
              "# each calibrated row's k makes this scenario's detector lose what the study measured.\n")
    text = header + toml_document({**meta, "presets": rows}, digits=4, none="")
    return atomic_write(path, text, check=load_presets, overwrite=overwrite)


def resolve_many(scenarios: Sequence[Scenario], **kwargs: Any) -> list[Resolution]:
    """:func:`resolve_presets` of each scenario in turn (their frames and results cached as each one's)."""
    return [resolve_presets(s, **kwargs) for s in scenarios]



def resolves(spec: Any, presets: str | os.PathLike | None = None) -> bool:
    """Whether ``spec`` names a preset that resolution changes: a ``CONDITION@SEVERITY`` item (severity above
    0) among the rows :func:`resolve_presets` resolves (calibrated, with a relative target).

    Example:
        >>> resolves("low_light@2"), resolves("low_light@0"), resolves("rain@2"), resolves("dim:0.8")
        (True, False, False, False)
    """
    rows = {(c, s) for c, s, _ in _targets(presets)}
    return any(sev > 0 and (cond, sev) in rows for cond, sev in preset_items(spec))


def presets_for_env(spec: Any, config: EnvConfig, detector: Any = None, *, progress: bool = True) -> str | None:
    """The presets file ``CONDITION@SEVERITY`` reads by default in an env of ``config`` with ``detector`` in
    the loop (None: the shipped one, which also stands for an env whose agent sees the images): resolved for
    its track, world, camera and camera model (cached), or None where ``spec`` names no preset that resolution
    changes. ``weather_gym.pipeline`` calls it by name (``RESOLVER``), as Gymnasium's ids name their entry point.
    A detector given as an object (not a spec or file) cannot be keyed: a ``ResolutionError`` says so."""
    if not resolves(spec):
        return None
    if detector is not None and not isinstance(detector, str | os.PathLike):
        raise ResolutionError(
            f"presets cannot be resolved for a detector given as a {type(detector).__name__} object (its file is "
            "what keys the cache): give the detector as a spec ('yolov8:model.onnx'), pass presets= (a file from "
            "`weather-gym calibrate`), or set WEATHER_GYM_PRESETS=pool for the shipped pool presets")
    sc = Scenario(tracks=(config.track,), scene=config.sim.scene, camera=config.camera,
                  camera_model=config.camera_model, detector=None if detector is None else os.fspath(detector))
    res = resolve_presets(sc, progress=progress)
    if res.path is None:
        raise ResolutionError(f"{res.scenario}: resolved, but there is no writable folder to keep the presets file "
                              "in; set WEATHER_GYM_CACHE to a writable folder")
    return str(res.path)
