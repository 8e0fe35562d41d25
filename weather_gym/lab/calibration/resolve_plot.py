"""The picture of a resolution: each condition's measured relative mAP against k in the scenario, the
study's targets, the resolved k (with its bootstrap error) beside the shipped pool k.

Example:
    >>> from weather_gym.lab.calibration.resolve import Resolution, ResolvedRow
    >>> row = ResolvedRow("droplets", 4, 0.74, 0.69, 0.673, 0.739, 0.01, (0.72, 0.76), (0.68, 0.70), True,
    ...                   {"name": "droplets", "k": 0.69}, 2)
    >>> res = Resolution("track demo", "k", [row], 0.95, 500, 160, 1.0, None,
    ...                  points={"droplets": [[0.0, 1.0], [0.69, 0.739]]})
    >>> import tempfile, os
    >>> plot_resolution(res, os.path.join(tempfile.mkdtemp(), "r.png")).suffix
    '.png'
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib.pyplot as plt

from weather_gym.core._figures import save_figure
from weather_gym.lab.calibration.resolve import Resolution

__all__ = ["plot_resolution"]


def plot_resolution(res: Resolution, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """One panel per condition: measured points, targets (dotted), resolved k (solid, ± 1 se) and pool k (dashed)."""
    conds = list(res.points)
    fig, axes = plt.subplots(1, max(len(conds), 1), figsize=(5.2 * max(len(conds), 1), 3.8), squeeze=False)
    for ax, cond in zip(axes[0], conds, strict=False):
        pts = sorted(res.points[cond])
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color="0.3", ms=3, lw=0.8, label="measured here")
        for i, r in enumerate(r for r in res.rows if r.condition == cond and r.severity > 0):
            c = f"C{i}"
            ax.axhline(r.target, color=c, ls=":", lw=0.8)
            ax.axvline(r.k_pool, color=c, ls="--", lw=0.8)
            ax.errorbar([r.k], [r.achieved], yerr=[r.se], fmt="s", color=c, ms=5, capsize=3,
                        label=f"S{r.severity}: k {r.k:.3f} (pool {r.k_pool:.3f})")
        ax.set_title(cond)
        ax.set_xlabel("k")
        ax.set_ylabel("relative mAP@0.5 (blue, yellow)")
        ax.set_ylim(-0.02, 1.05)
        ax.legend(fontsize=7, loc="lower left")
    fig.suptitle(f"resolved for {res.scenario} ({res.n_frames} frames, clear mAP {res.clear_map:.3f})", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, overwrite=overwrite, dpi=110)
