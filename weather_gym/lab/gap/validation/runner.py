"""Run the gap workflow on hidden effects it was never shown, and count how often it names them.

Scenes vary: every simulated case is drawn on one of its split's :data:`SCENES` (a track and a world,
random looks per episode; the plain world through the ideal camera, the realistic one through its
randomized camera models), with poses (``paired``) or with the poses stripped (``unpaired``: the
workflow renders the track itself and compares distributions); ``real`` hides the effect in a copy
of the shared real frames (read in place, never copied into the project) and gives the originals as
the clear reference (same-camera mode). Seeds are split: ``dev`` (looked at while developing) and
``held-out`` (run only to report; other seeds and other tracks).

Per family and setting it counts (:func:`summarize`, with Wilson 95 % intervals):

* **named first**: the first effect the workflow adds is of a hidden family (any of the parts of a
  composition); for the negative control: nothing added;
* **halved**: the held-out image gap at most halves;
* **spurious**: an effect added after the first that is of no hidden family;
* **clean** (negative controls only): nothing added.

Example:
    >>> wilson(9, 10)
    (0.5958, 0.9821)
    >>> case_seeds("dev", "noise", 2)
    [1001, 1009]
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2

from weather_gym.camera.config import CameraConfig
from weather_gym.camera.isp import CameraModel
from weather_gym.core.errors import InputError
from weather_gym.lab.datasets import render_dataset
from weather_gym.lab.datasets.coco import JOURNAL, load_coco
from weather_gym.lab.datasets.importers import import_dataset
from weather_gym.lab.datasets.masks import propose_mask, set_dataset_mask, write_mask
from weather_gym.lab.gap.validation.hidden import FAMILIES, HiddenCase, draw_case
from weather_gym.lab.gap.workflow import GapConfig, run_gap

__all__ = ["Scene", "SCENES", "SETTINGS", "SPLITS", "CaseResult", "case_seeds", "wilson", "hide_case",
           "run_case", "run_validation", "summarize", "table"]

SPLITS = ("dev", "held-out")
SETTINGS = ("paired", "unpaired", "real")
_SEED_BASE = {"dev": 1000, "held-out": 5000}


@dataclass(frozen=True)
class Scene:
    """A simulated recording: a track in a world (random looks per episode)."""

    track: str
    world: str

    @property
    def name(self) -> str:
        return f"{self.track}-{self.world}"


#: the scenes of each split: the held-out split's tracks are not the development split's
SCENES: dict[str, tuple[Scene, ...]] = {
    "dev": (Scene("small_track", "plain"), Scene("hairpin", "realistic")),
    "held-out": (Scene("peanut", "realistic"), Scene("jellybean", "plain")),
}


def case_seeds(split: str, family: str, n: int) -> list[int]:
    """The seeds of the first ``n`` cases of ``family`` in ``split`` (disjoint between splits)."""
    if split not in SPLITS:
        raise InputError(f"unknown split {split!r}; expected one of {SPLITS}")
    return [_SEED_BASE[split] + FAMILIES.index(family) + len(FAMILIES) * j for j in range(n)]


def scene_of(split: str, seed: int) -> Scene:
    """The scene of a case: the cases of one family take the split's scenes in turn."""
    return SCENES[split][(seed // len(FAMILIES)) % len(SCENES[split])]


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a rate ``k / n`` (95 % by default), rounded to 4 places."""
    if n <= 0:
        return (0.0, 1.0)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (round(max(c - h, 0.0), 4), round(min(c + h, 1.0), 4))


@dataclass
class CaseResult:
    """One run of the workflow on one hidden case."""

    split: str
    setting: str
    scene: str
    family: str
    seed: int
    label: str
    named: list[str]
    first_ok: bool
    halved: bool | None
    spurious: list[str]
    gap_before: float
    gap_after: float
    candidates: list[str]
    verdict: str
    seconds: float


def hide_case(src: Path, dst: Path, case: HiddenCase, *, strip_poses: bool) -> Path:
    """Copy the COCO folder ``src`` to ``dst`` (PNG frames) with ``case`` applied to every frame."""
    if (dst / "annotations.json").is_file():
        return dst
    ds = load_coco(src)
    data = json.loads((src / "annotations.json").read_text())
    for i, rec in enumerate(data["images"]):
        out = case.apply(ds.image(i), ds.depth(i), frame=i)
        name = str(Path(rec["file_name"]).with_suffix(".png"))
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(dst / name), cv2.cvtColor(out, cv2.COLOR_RGB2BGR)):
            raise OSError(f"could not write {dst / name}")
        rec["file_name"] = name
        for key in ("depth_file", "ignore_mask"):
            if rec.get(key):
                (dst / rec[key]).parent.mkdir(parents=True, exist_ok=True)
                (dst / rec[key]).write_bytes((src / rec[key]).read_bytes())
        if strip_poses:
            for key in ("pose", "look", "seed", "episode", "step"):
                rec.pop(key, None)
    mask = (data.get("info") or {}).get("ignore_mask")
    if mask:
        (dst / mask).write_bytes((src / mask).read_bytes())
    (dst / "annotations.json").write_text(json.dumps(data))
    return dst


def _scene_dir(root: Path, scene: Scene, frames: int, width: int, seed: int) -> Path:
    cam = CameraConfig().scaled(width, int(round(width * 9 / 16 / 2)) * 2)
    out = root / "scenes" / f"{scene.name}-{frames}x{width}-s{seed}-e3"
    if not (out / "annotations.json").is_file():
        render_dataset(out, tracks=[scene.track], frames=frames, seed=seed, randomize=True,
                       frames_per_episode=3, camera=cam, progress=False, scene=scene.world,
                       camera_model=CameraModel.ideal() if scene.world == "plain" else None,
                       resume=(out / JOURNAL).exists())
    return out


def real_clear(root: Path, shared: Path) -> Path | None:
    """The shared real frames imported (labels, the proposed ego mask) into ``root``; None when absent."""
    src = shared / "data" / "real" / "fskitti_estoril_autox2"
    if not (src / "images").is_dir():
        return None
    out = root / "real_clear"
    if not (out / "annotations.json").is_file():
        import_dataset("kitti", src, out, intrinsics="900.9,900.1,506.4,358.0", condition="clear")
        ds = load_coco(out)
        write_mask(root / "real_mask.png", propose_mask([ds.image(i) for i in range(len(ds))]))
        set_dataset_mask(out, root / "real_mask.png")
    return out


def run_case(root: Path, split: str, setting: str, case: HiddenCase, *, frames: int, width: int,
             shared: Path | None = None, fast: dict[str, Any] | None = None) -> CaseResult | None:
    """Hide ``case`` in a recording of ``setting`` and run the workflow on it (None: real frames absent)."""
    t0 = time.perf_counter()
    fast = dict(fit_frames=12, bootstrap=500, perception=False) if fast is None else fast
    tag = f"{split}-{setting}-{case.family}-{case.seed}"
    if setting == "real":
        clear = real_clear(root, shared or Path(os.environ.get("WEATHER_GYM_SHARED", "/work/shared")))
        if clear is None:
            return None
        scene = "real"
        measured = hide_case(clear, root / "data" / tag, case, strip_poses=False)
        report = run_gap(measured, None, root / "runs" / tag, GapConfig(compare_width=256, **fast), reference=clear,
                         plots=False, overwrite=True)
    else:
        sc = scene_of(split, case.seed)
        scene = sc.name
        clean = _scene_dir(root, sc, frames, width, seed=SCENES[split].index(sc) + 11)
        measured = hide_case(clean, root / "data" / tag, case, strip_poses=setting == "unpaired")
        report = run_gap(measured, None, root / "runs" / tag, GapConfig(**fast), cache_dir=root / "cache",
                         plots=False, overwrite=True)
    named = list(report["missing_effects"])
    ok = case.accepted
    first_ok = not named if case.family == "none" else bool(named) and named[0] in ok
    return CaseResult(split, setting, scene, case.family, case.seed, case.label(), named, first_ok,
                      None if case.family == "none" else report["gap_after"] <= 0.5 * report["gap_before"],
                      [n for n in named[1:] if n not in ok], float(report["gap_before"]), float(report["gap_after"]),
                      [c["name"] for c in report.get("candidates", [])], report["verdict"],
                      round(time.perf_counter() - t0, 1))


def run_validation(root: str | os.PathLike, *, split: str, settings: Sequence[str] = SETTINGS,
                   families: Sequence[str] = FAMILIES, per_family: int = 4, frames: int = 80, width: int = 224,
                   shared: Path | None = None, log: Callable[[str], None] | None = None) -> list[CaseResult]:
    """Run every case of ``split`` (``per_family`` per family) in every setting; resumes from
    ``root/results.jsonl`` (a case already there is not run again)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    done_path = root / "results.jsonl"
    done = {}
    if done_path.is_file():
        for line in done_path.read_text().splitlines():
            r = CaseResult(**json.loads(line))
            done[(r.split, r.setting, r.family, r.seed)] = r
    out = []
    for setting in settings:
        if setting not in SETTINGS:
            raise InputError(f"unknown setting {setting!r}; expected one of {SETTINGS}")
        for family in families:
            for seed in case_seeds(split, family, per_family):
                key = (split, setting, family, seed)
                if key in done:
                    out.append(done[key])
                    continue
                got = run_case(root, split, setting, draw_case(family, seed), frames=frames, width=width,
                               shared=shared)
                if got is None:
                    if log:
                        log(f"{setting}: real frames absent, skipped")
                    break
                out.append(got)
                with done_path.open("a") as f:
                    f.write(json.dumps(asdict(got)) + "\n")
                if log:
                    log(json.dumps(asdict(got)))
    return out


def summarize(results: Sequence[CaseResult]) -> list[dict[str, Any]]:
    """Rates per (setting, family) and per setting over all families: n, named first, halved, spurious,
    clean (negative controls), each ``[k, n, low, high]`` (Wilson 95 %)."""
    groups: dict[tuple[str, str], list[CaseResult]] = {}
    for r in results:
        groups.setdefault((r.setting, r.family), []).append(r)
        if r.family != "none":
            groups.setdefault((r.setting, "all hidden"), []).append(r)
    rows = []
    for (setting, family), rs in sorted(groups.items(), key=lambda t: (SETTINGS.index(t[0][0]), _order(t[0][1]))):
        def rate(flags: list[bool]) -> list[float]:
            k, n = sum(flags), len(flags)
            return [k, n, *wilson(k, n)]
        hidden = [r for r in rs if r.family != "none"]
        neg = [r for r in rs if r.family == "none"]
        rows.append({"setting": setting, "family": family, "n": len(rs),
                     "named_first": rate([r.first_ok for r in hidden]) if hidden else None,
                     "halved": rate([bool(r.halved) for r in hidden]) if hidden else None,
                     "first_and_halved": rate([r.first_ok and bool(r.halved) for r in hidden]) if hidden else None,
                     "spurious": rate([bool(r.spurious) for r in hidden]) if hidden else None,
                     "clean": rate([not r.named for r in neg]) if neg else None})
    return rows


def _order(family: str) -> int:
    return FAMILIES.index(family) if family in FAMILIES else len(FAMILIES)


def table(rows: Sequence[dict[str, Any]]) -> str:
    """The Markdown table of :func:`summarize`'s rows."""
    def cell(v: list[float] | None) -> str:
        if v is None:
            return "-"
        k, n, lo, hi = v
        return f"{int(k)}/{int(n)} ({100 * k / n:.0f} %, {100 * lo:.0f}-{100 * hi:.0f})"
    lines = ["| setting | family | n | named first | halved | named first and halved | spurious | negative clean |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['setting']} | {r['family']} | {r['n']} | {cell(r['named_first'])} | {cell(r['halved'])} | "
                     f"{cell(r['first_and_halved'])} | {cell(r['spurious'])} | {cell(r['clean'])} |")
    return "\n".join(lines)
