"""Pictures and sweeps for people: detections under weather, mAP versus the severity knob k.

Example:
    >>> from weather_gym.lab.training.detector.plots import STUDY_POINTS
    >>> STUDY_POINTS["dim"]
    (0.78, 0.273)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from tqdm import tqdm

from weather_gym.core._figures import save_figure
from weather_gym.core._io import write_image
from weather_gym.perception.draw import draw_detections
from weather_gym.perception.scoring import score_dataset
from weather_gym.weather import make

STUDY_CLEAN_MAP = 0.715
"""The study's detector on its simulator, clean (Fursa et al., Fig. 7)."""
STUDY_POINTS: dict[str, tuple[float, float]] = {"droplets": (0.55, 0.490), "dim": (0.78, 0.273)}
"""effect -> (k, the study's simulator mAP at that k)."""


def sweep_map_vs_k(dataset, detector, ks: Sequence[float], effects: Sequence[str] = ("droplets", "dim"), seed: int = 0,
                   limit: int | None = None, progress: bool = True) -> dict[str, list[dict[str, Any]]]:
    """mAP@0.5 and COCO mAP of ``detector`` on ``dataset`` for each effect at each k."""


    out: dict[str, list[dict[str, Any]]] = {}
    jobs = [(e, float(k)) for e in effects for k in ks]
    for e, k in tqdm(jobs, desc="mAP vs k", disable=not progress):
        r = score_dataset(dataset, detector, None if k == 0 else make(e, k=k), seed=seed, limit=limit)
        out.setdefault(e, []).append({"k": k, "map50": r.map50, "map": r.map, "recall": r.recall})
    return out


def plot_map_vs_k(sweep: dict[str, list[dict[str, Any]]], out: str | os.PathLike, title: str = "", *,
                  overwrite: bool = False) -> Path:
    """Plot the sweep, relative to clean, with the study's relative drops at its two points."""

    matplotlib.use("Agg")

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    colors = {"droplets": "tab:blue", "dim": "tab:orange"}
    for e, rows in sweep.items():
        ks = [r["k"] for r in rows]
        clean = rows[0]["map50"] if rows[0]["k"] == 0 else np.nan
        ax.plot(ks, [r["map50"] for r in rows], "o-", color=colors.get(e), label=f"ours: {e} (mAP@0.5)")
        if e in STUDY_POINTS:
            k, m = STUDY_POINTS[e]
            ax.plot([k], [clean * m / STUDY_CLEAN_MAP], "*", ms=14, color=colors.get(e), mec="k",
                    label=f"study's relative drop at k={k} ({STUDY_CLEAN_MAP}->{m}), scaled to our clean")
    ax.set_xlabel("severity k")
    ax.set_ylabel("mAP@0.5")
    ax.set_ylim(0, 1.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out, overwrite=overwrite)


def detections_figure(image: np.ndarray, detector, out: str | os.PathLike, *, depth: np.ndarray | None = None,
                      state: dict | None = None, seed: int = 0, captions: dict[str, str] | None = None,
                      overwrite: bool = False) -> Path:
    """Three panels of one frame with detected boxes: clean | droplets k=0.55 | dim k=0.78."""


    panels = []
    for name, k in (("clean", 0.0), ("droplets", 0.55), ("dim", 0.78)):
        img = image
        if k:
            eff = make(name, k=k)
            eff.reset(seed)
            img = eff(image, depth=depth, state=state, rng=np.random.default_rng(seed))
        d = detector(img)
        pic = draw_detections(img, d)
        label = f"{name}" + (f" k={k}" if k else "") + f": {len(d)} cones"
        if captions and name in captions:
            label += f", {captions[name]}"
        cv2.rectangle(pic, (0, 0), (pic.shape[1], 18), (0, 0, 0), -1)
        cv2.putText(pic, label, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        panels.append(pic)
    grid = np.concatenate(panels, axis=1)
    return write_image(out, grid, overwrite=overwrite)
