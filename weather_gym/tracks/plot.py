"""Drawing a track with matplotlib: cones in their colours, the centerline, the start pose (and the
finish of an open track). Only plotting callers import this module (``weather-gym tracks --plot``):
``import weather_gym`` does not load matplotlib.

Example:
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from weather_gym.tracks import load_track
    >>> ax = plot_track(load_track("small_track"))
    >>> ax.get_title()
    'small_track: 150 m, 77 cones (trackdrive)'
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from weather_gym.core.cone_spec import CONE_BODY_RGB, CONE_CLASSES
from weather_gym.tracks._track import Track

__all__ = ["plot_track"]


def plot_track(track: Track, ax=None, *, title: str | None = None):
    """Draw cones in their colours, the centerline and the start pose; returns the matplotlib axes."""

    if ax is None:
        _, ax = plt.subplots(figsize=(7, 7))
    line = np.concatenate([track.centerline, track.centerline[:1]]) if track.closed else track.centerline
    ax.plot(line[:, 0], line[:, 1], "--", color="0.45", lw=0.8, label="centerline")
    for cid, cname in enumerate(CONE_CLASSES):
        pts = track.cones_xy[track.cone_classes == cid]
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], s=22 if cname == "big_orange" else 12, color=CONE_BODY_RGB[cname],
                       edgecolors="k", linewidths=0.3, label=cname, zorder=3)
    x, y, yaw = track.start_pose
    scale = max(3.0, 0.06 * float(np.ptp(track.cones_xy, axis=0).max()))
    ax.annotate("", xy=(x + scale * math.cos(yaw), y + scale * math.sin(yaw)), xytext=(x, y),
                arrowprops=dict(arrowstyle="-|>", color="crimson", lw=1.8), zorder=4)
    ax.plot([x], [y], "o", color="crimson", ms=4, zorder=4, label="start")
    if not track.closed:
        fx, fy, _ = track.point_at(track.finish_s)
        ax.plot([fx], [fy], "x", color="crimson", ms=7, mew=2, zorder=4, label="finish")
    ax.set_aspect("equal")
    ax.set_title(title or f"{track.name}: {track.length:.0f} m, {len(track.cones_xy)} cones ({track.event})",
                 fontsize=9)
    ax.tick_params(labelsize=7)
    return ax
