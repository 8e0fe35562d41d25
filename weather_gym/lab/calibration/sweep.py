"""The k sweep: the detector's mAP on a fixed rendered set at each k of an effect, per seed.

One *cell* is (effect, k, seed): the effect at that k degrades every frame of the evaluation set
(frame ``i`` gets the weather realisation of ``seed_i``, spawned from ``seed``; see
:func:`weather_gym.perception.scoring.score_dataset`), the shipped detector runs on the result and
pycocotools scores it. Cells run on :func:`weather_gym.lab.evaluation.runner.run_cells` (parallel,
resumable, a progress bar), which writes one tidy row per cell to ``OUT/curves.csv``:

``effect, spec, k, seed, dataset_id, model_id, status, error, elapsed_s, map50, map, map50_blue_yellow,
ap50_blue, ...,
recall, recall_0_5m, ..., n_images, n_gt, n_detections``

``effect`` is the curve's label (``dim_physical`` for ``dim`` with ``mode="physical"``), ``spec`` the
effect's non-default parameters as JSON, ``dataset_id`` / ``model_id`` the first 12 hex digits of
the SHA-256 of the set's ``annotations.json`` and of the ONNX model: a sweep resumed with another
model or set runs its cells again instead of mixing results.

Example:
    >>> from weather_gym.lab.calibration.sweep import parse_effect, parse_k_range
    >>> parse_k_range("0:1:0.25")
    (0.0, 0.25, 0.5, 0.75, 1.0)
    >>> e = parse_effect("dim:mode=physical")
    >>> e.label, e.name, e.params
    ('dim_physical', 'dim', {'mode': 'physical'})
    >>> e.table(0.5)
    {'name': 'dim', 'k': 0.5, 'mode': 'physical'}
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import replace as _replace
from pathlib import Path
from typing import Any

from weather_gym.core._io import atomic_write_json, derived_outputs_replaceable, file_id
from weather_gym.core.errors import InputError
from weather_gym.lab.calibration.curve import load_curves
from weather_gym.lab.calibration.report import plot_curves
from weather_gym.lab.calibration.sweep_effect import SweepEffect, parse_effect
from weather_gym.lab.datasets.coco import ANNOTATIONS, load_coco
from weather_gym.lab.evaluation.runner import check_results_path, run_cells
from weather_gym.perception import score_dataset
from weather_gym.perception.detector_spec import detector_id, load_detector, parse_detector_spec
from weather_gym.weather import make

__all__ = [
    "CURVE_FILE",
    "KEY_FIELDS",
    "SweepCell",
    "SweepEffect",
    "file_id",
    "make_sweep_cells",
    "metric_by_cell",
    "parse_effect",
    "parse_k_range",
    "parse_seeds",
    "run_sweep",
    "run_sweep_cell",
    "score_cell",
]

CURVE_FILE = "curves.csv"
META_FILE = "sweep.json"
KEY_FIELDS = ("effect", "spec", "k", "seed", "dataset_id", "model_id")
"""Key fields of a curve file (the first columns, the identity of a cell)."""


# ------------------------------------------------------------------------------------------ parsing
def parse_k_range(text: str) -> tuple[float, ...]:
    """``START:STOP:STEP`` (both ends included), ``K1,K2,...`` or one ``K``; every k in [0, 1].

    Values are rounded to 10 decimals so ``0:1:0.05`` gives exactly 0.05, 0.1, ... (21 values).
    """
    if not isinstance(text, str) or not text.strip():
        raise InputError("--k must be START:STOP:STEP (e.g. 0:1:0.05) or a comma-separated list of k values")
    text = text.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise InputError(f"--k {text!r}: a range is START:STOP:STEP with three numbers, e.g. 0:1:0.05")
        try:
            start, stop, step = (float(p) for p in parts)
        except ValueError:
            raise InputError(f"--k {text!r}: START, STOP and STEP must be numbers, e.g. 0:1:0.05") from None
        if not all(math.isfinite(v) for v in (start, stop, step)):
            raise InputError(f"--k {text!r}: START, STOP and STEP must be finite numbers")
        if step <= 0:
            raise InputError(f"--k {text!r}: STEP must be > 0, got {step:g}")
        if stop < start:
            raise InputError(f"--k {text!r}: STOP ({stop:g}) is below START ({start:g})")
        n = int(math.floor((stop - start) / step + 1e-9)) + 1
        if n > 10_000:
            raise InputError(f"--k {text!r}: {n} values; use a larger STEP")
        ks = [round(start + i * step, 10) for i in range(n)]
    else:
        try:
            ks = [float(p) for p in text.split(",") if p.strip()]
        except ValueError:
            raise InputError(f"--k {text!r}: expected numbers separated by commas, e.g. 0,0.25,0.5") from None
        if not ks:
            raise InputError(f"--k {text!r}: no k values")
    bad = [k for k in ks if not (0.0 <= k <= 1.0)]
    if bad:
        raise InputError(f"--k {text!r}: k must lie in [0, 1], got {', '.join(f'{k:g}' for k in bad)}")
    out = tuple(sorted(set(ks)))
    if len(out) != len(ks):
        raise InputError(f"--k {text!r}: repeated k values")
    return out


def parse_seeds(n: int | None = None, seed_list: str | None = None) -> tuple[int, ...]:
    """``n`` seeds 0..n-1, or an explicit comma-separated list (non-negative, distinct)."""
    if seed_list is not None:
        try:
            seeds = [int(s) for s in seed_list.split(",") if s.strip()]
        except ValueError:
            raise InputError(f"--seed-list {seed_list!r}: expected integers separated by commas") from None
        if not seeds or any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
            raise InputError(f"--seed-list {seed_list!r}: expected distinct non-negative integers")
        return tuple(seeds)
    if n is None or n < 1:
        raise InputError(f"--seeds must be >= 1, got {n}")
    return tuple(range(int(n)))


# -------------------------------------------------------------------------------------------- cells
@dataclass(frozen=True)
class SweepCell:
    """One (effect, k, seed) measurement. Key fields: :data:`KEY_FIELDS`; ``dataset`` is a path, ``model``
    the detector (a :class:`~weather_gym.perception.detector_spec.DetectorSpec`, or a ConeNet ONNX path)."""

    effect: str
    spec: str
    k: float
    seed: int
    dataset_id: str
    model_id: str
    name: str = ""
    dataset: str = ""
    model: Any = ""


_CACHE: dict[tuple[str, Any], tuple[Any, Any]] = {}


def _dataset_and_detector(dataset: str, model: Any) -> tuple[Any, Any]:
    """Load once per worker process: the evaluation set (frames kept in memory) and the detector."""
    key = (dataset, model)
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = (load_coco(dataset, cache_images=True), load_detector(model or None, threads=1))
    return _CACHE[key]


def _metric_name(label: str) -> str:
    return "recall_" + label.replace("+ m", "plus_m").replace(" m", "m").replace("-", "_")


def run_sweep_cell(cell: SweepCell) -> dict[str, Any]:
    """Score the detector on the evaluation set under ``cell``'s effect at ``cell.k`` (the cell function)."""

    return score_cell(cell, make(cell.name, k=float(cell.k), **json.loads(cell.spec)))


def score_cell(cell: SweepCell, effect: Any) -> dict[str, Any]:
    """The metrics row of ``cell``'s evaluation set and detector scored under ``effect`` (any effect
    :func:`~weather_gym.perception.scoring.score_dataset` takes) with ``cell.seed``."""
    ds, det = _dataset_and_detector(cell.dataset, cell.model)
    r = score_dataset(ds, det, effect, seed=int(cell.seed))
    row: dict[str, Any] = {"map50": r.map50, "map": r.map, "map50_blue_yellow": r.map50_blue_yellow}
    row.update({f"ap50_{c}": v for c, v in r.ap50_per_class.items()})
    row["recall"] = r.recall
    row.update({_metric_name(b): rec for b, (rec, _) in r.recall_by_range.items()})
    row.update(n_images=r.n_images, n_gt=r.n_gt, n_detections=r.n_detections)
    return row


def make_sweep_cells(effects: Sequence[SweepEffect], ks: Sequence[float], seeds: Sequence[int],
                     dataset: str | os.PathLike, model: Any = None) -> list[SweepCell]:
    """Every (effect, k, seed) cell, checking the dataset and the detector first.

    ``model``: a detector spec (``"yolov8:model.onnx"``, a ``DetectorSpec``, a ConeNet ``.onnx`` path;
    None: the shipped detector). ``model_id`` identifies its file and options.
    """


    ds_path = Path(dataset)
    load_coco(ds_path)  # validates (missing folder / annotations / images -> a clear error)
    spec = parse_detector_spec(model)  # a missing file or a bad spec -> a clear error
    if spec.path is not None:
        spec = _replace(spec, path=str(Path(spec.path).resolve()))
    spec.load(threads=1)  # the export's layout and class map are checked before any cell runs
    labels = [e.label for e in effects]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise InputError(f"effect(s) {', '.join(dup)} given twice")
    dsid, mid = file_id(ds_path / ANNOTATIONS), detector_id(spec)
    return [SweepCell(effect=e.label, spec=e.spec, k=float(k), seed=int(s), dataset_id=dsid, model_id=mid,
                      name=e.name, dataset=str(ds_path.resolve()), model=spec)
            for e in effects for k in ks for s in seeds]


def metric_by_cell(cells: Sequence[SweepCell], rows: Sequence[dict[str, Any]],
                   metric: str) -> dict[tuple[str, str, float], list[float]]:
    """``metric`` of the run ``cells`` (``rows`` in the same order, as the runner returns them), one value
    per seed, grouped by (dataset path, effect label, k).

    Example:
        >>> cells = [SweepCell("dim", "{}", 0.5, s, "d", "m", dataset="/sets/a") for s in (0, 1)]
        >>> metric_by_cell(cells, [{"map50": 0.8}, {"map50": 0.6}], "map50")
        {('/sets/a', 'dim', 0.5): [0.8, 0.6]}
    """
    by: dict[tuple[str, str, float], list[float]] = {}
    for cell, row in zip(cells, rows, strict=True):
        by.setdefault((cell.dataset, cell.effect, float(cell.k)), []).append(float(row[metric]))
    return by


def run_sweep(effects: Sequence[SweepEffect], ks: Sequence[float], seeds: Sequence[int],
              dataset: str | os.PathLike, out: str | os.PathLike, *, model: Any = None,
              workers: int | None = None, backend: str = "process", progress: bool = True,
              retry_failed: bool = True, ray_address: str | None = None, plot: bool = True,
              command: str | None = None, overwrite: bool = False) -> list[dict[str, Any]]:
    """Run the sweep into ``out/curves.csv`` (resumable), plot it, record ``out/sweep.json``; return the rows.

    When ``out`` holds no curves.csv yet, an existing plot or sweep.json there is refused before any
    cell runs, unless ``overwrite``."""

    cells = make_sweep_cells(effects, ks, seeds, dataset, model)
    out = Path(out)
    check_results_path(out / CURVE_FILE)
    derived = [out / META_FILE] + ([out / "curves.png", out / "curves_recall.png"] if plot else [])
    replace = derived_outputs_replaceable(out / CURVE_FILE, derived, overwrite=overwrite)
    rows = run_cells(cells, run_sweep_cell, out / CURVE_FILE, key_fields=KEY_FIELDS, workers=workers,
                     backend=backend, progress=progress, retry_failed=retry_failed, ray_address=ray_address,
                     desc="sweep")
    _write_meta(out, cells, effects, ks, seeds, dataset, model, rows, command, replace)
    if plot:
        curves = load_curves(out / CURVE_FILE, dataset_id=cells[0].dataset_id, model_id=cells[0].model_id)
        plot_curves(curves, out / "curves.png", recall_out=out / "curves_recall.png", overwrite=replace)
    return rows


def _write_meta(out: Path, cells: list[SweepCell], effects, ks, seeds, dataset, model, rows: list[dict],
                command: str | None, overwrite: bool) -> None:
    """Merge this run's description into ``out/sweep.json`` (per curve label), with the seconds its
    cells took to run (``cells_s``, summed over cells, whichever run ran them: a resumed sweep writes
    the same file)."""
    path = out / META_FILE
    meta: dict[str, Any] = {}
    if path.is_file():
        try:
            meta = json.loads(path.read_text())
        except json.JSONDecodeError:
            meta = {}
    c0 = cells[0]
    cells_s: dict[str, float] = {}
    for row in rows:
        cells_s[row["effect"]] = cells_s.get(row["effect"], 0.0) + float(row["elapsed_s"])

    info = load_coco(dataset).data.get("info", {})
    meta.setdefault("curves", {})
    for e in effects:
        meta["curves"][e.label] = {
            "effect": e.name, "params": e.params, "ks": list(ks), "seeds": list(seeds),
            "dataset": str(dataset), "dataset_id": c0.dataset_id, "dataset_info": info,
            "model": str(model) if model is not None else "weather_gym/perception/models/cone_detector.onnx",
            "model_id": c0.model_id, "command": command, "cells_s": round(cells_s.get(e.label, 0.0), 1),
        }
    atomic_write_json(path, meta, indent=2, sort_keys=True, overwrite=overwrite)
