"""The metrics of an episode, one registry entry each: what :func:`~weather_gym.lab.evaluation.evaluate.run_cell`
stores, what ``weather-gym lap`` prints and what the evaluation report tabulates and plots.

A :class:`Metric` has a name (the results column), a doc line, a label (axes and the report), a unit
and a ``compute`` from an :class:`Episode` (the episode driver's result, the agent, the track, the
perception mode and the detector's scores over the frames it saw, from :class:`DetectorScoring`).
``table`` / ``plot`` put it in the report's table / give it a plot; ``lap`` puts it in the lap summary
(``line``: its text there). Adding a metric is one :func:`register_metric` call.

Example:
    >>> from weather_gym.lab.evaluation.metrics import METRICS, plot_metrics
    >>> "lap_time_s" in METRICS, METRICS["cte_mean_m"].label
    (True, 'mean cross-track error (m)')
    >>> plot_metrics()[:3]
    ['completed', 'progress', 'lap_time_s']
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from weather_gym.core.errors import InputError
from weather_gym.core.registry import add_unique
from weather_gym.perception.cones import FIELD
from weather_gym.perception.lidar_scoring import LidarScores, LidarScoring
from weather_gym.perception.scoring import EvalResult, score_detections

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.pipeline.episode import EpisodeResult
    from weather_gym.pipeline.modes import PerceptionMode
    from weather_gym.tracks import Track

__all__ = ["CONE_LIST_BINS", "ConeListScoring", "cone_list_bins", "DetectorScoring", "Episode", "MAP_MATCH_RADIUS_M", "METRICS", "Metric", "episode_metrics",
           "lap_lines", "map_precision_recall", "plot_metrics", "register_metric", "table_metrics"]

MAP_MATCH_RADIUS_M = 0.5
"""A mapped cone counts as correct within this distance of a true cone (and vice versa for recall)."""


class DetectorScoring:
    """Episode observer (``run_episode``'s ``on_step``): collects ``info["gt"]`` and
    ``info["detections"]`` of each frame a scored mode's detector saw, then scores them (pycocotools).

    ``final_frame``: also score the frame of the last step (seen, but not acted on).

    Example:
        >>> import numpy as np
        >>> from weather_gym.pipeline.modes import perception_mode
        >>> obs = DetectorScoring(perception_mode("detector"))
        >>> gt = {"boxes": np.array([[10, 10, 30, 50.]]), "classes": np.array([1]), "ranges": np.array([6.0])}
        >>> det = {"boxes": np.array([[11, 10, 30, 49.]]), "scores": np.array([0.9]), "classes": np.array([1])}
        >>> obs(0, None, {"gt": gt, "detections": det}, False)
        >>> round(obs.scores().map50, 3), obs.scores().n_images
        (1.0, 1)
    """

    def __init__(self, mode: PerceptionMode, *, final_frame: bool = False) -> None:
        self.enabled = bool(mode.is_scored)
        self.final_frame = final_frame
        self.gts: list[Any] = []
        self.dets: list[Any] = []
        self._scores: EvalResult | None = None

    def __call__(self, step: int, obs: Any, info: Mapping[str, Any], done: bool) -> None:
        if not self.enabled or (done and not self.final_frame):
            return
        if info.get("gt") is not None and info.get("detections") is not None:
            self.gts.append(info["gt"])
            self.dets.append(info["detections"])
            self._scores = None

    def scores(self) -> EvalResult | None:
        """The detector's scores over the frames collected (None when none were)."""
        if self._scores is None and self.gts:
            self._scores = score_detections(self.gts, self.dets)
        return self._scores


CONE_LIST_BINS: tuple[float, ...] = (0.0, 5.0, 10.0, 20.0, math.inf)
"""Range bins (m, from the camera) of the stack's cone recall (``cone_recall_*`` metrics)."""


class ConeListScoring:
    """Episode observer: the cone list the agent reads (``obs["cones"]``, any sensor or fusion) against the
    track's true cones, every ``every`` steps, so camera, LiDAR and fused stacks are scored alike.

    The truth of a step: the track's cones in the field ahead, within ``half_fov`` of the camera's axis
    and ``max_range`` of it (the camera's view: what the planner steers by); cones of the list in that
    field are the detections. Matched one to one within ``radius`` (1 m: a camera's range from a box is
    less exact than a LiDAR's), in the car frame (``info["pose"]``, the true pose). Occlusion is not
    checked (a cone behind another counts as visible).

    Example:
        >>> import numpy as np
        >>> s = ConeListScoring(np.array([[5.0, 0.0], [15.0, 1.0], [-5.0, 0.0]]), half_fov=0.8, mount_x=0.0)
        >>> cones = np.zeros((4, 14), np.float32); cones[0, 11] = 5.2   # one cone at (5.2, 0) in the car frame
        >>> s(0, {"cones": cones, "mask": np.array([1, 0, 0, 0])}, {"pose": np.zeros(3)}, False)
        >>> r = s.scores(); r.recall, r.precision, r.recall_by_range["10-20 m"]
        (0.5, 1.0, (0.0, 1))
    """

    def __init__(self, cones_xy: np.ndarray, *, half_fov: float, mount_x: float, max_range: float = 25.0,
                 every: int = 3, radius: float = 1.0) -> None:
        self.cones_xy = np.asarray(cones_xy, np.float64).reshape(-1, 2)
        self.half_fov, self.mount_x, self.max_range = float(half_fov), float(mount_x), float(max_range)
        self.every = int(every)
        self._scoring = LidarScoring(radius=radius, range_bins=CONE_LIST_BINS)

    def _field(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rx = x - self.mount_x
        r = np.hypot(rx, y)
        return (rx > 0) & (np.abs(np.arctan2(y, rx)) <= self.half_fov) & (r <= self.max_range), r

    def __call__(self, step: int, obs: Any, info: Mapping[str, Any], done: bool) -> None:
        if done or step % self.every or not isinstance(obs, Mapping) or "cones" not in obs or "pose" not in info:
            return
        x0, y0, yaw = (float(v) for v in info["pose"])
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = self.cones_xy[:, 0] - x0, self.cones_xy[:, 1] - y0
        gx, gy = c * dx + s * dy, -s * dx + c * dy
        g_in, g_r = self._field(gx, gy)
        rows = np.asarray(obs["cones"])[np.asarray(obs["mask"]).astype(bool)]
        dxb, dyb = rows[:, FIELD["x_body"]].astype(np.float64), rows[:, FIELD["y_body"]].astype(np.float64)
        d_in, d_r = self._field(dxb, dyb)
        self._scoring.add(det_xy=np.c_[dxb[d_in], dyb[d_in]], gt_xy=np.c_[gx[g_in], gy[g_in]], gt_ranges=g_r[g_in],
                          det_ranges=d_r[d_in])

    def scores(self) -> LidarScores | None:
        """Recall and precision (overall and by range) over the steps scored (None when none were)."""
        return self._scoring.result() if self._scoring.frames else None


@dataclass(frozen=True)
class Episode:
    """What a metric is computed from: one driven episode.

    Attributes:
        result: the episode driver's ``EpisodeResult``. agent: the agent that drove. track: the track.
        mode: the perception mode. detector: the detector's scores over the frames it saw (None
        unless the mode is scored). weathered: the env had weather (``info["weather"]``). cone_list:
        the scores of the cone list the agent read (:class:`ConeListScoring`; None for an image agent).
    """

    result: EpisodeResult
    agent: Any
    track: Track
    mode: PerceptionMode
    detector: EvalResult | None = None
    weathered: bool = True
    cone_list: LidarScores | None = None


@dataclass(frozen=True)
class Metric:
    """One metric.

    Attributes:
        name: the results column. doc: what it means (the report's metrics list). label: axis and
            table label. unit: its unit (for the lap summary's default line).
        compute: ``Episode -> value`` (a number, a string, or None where it is not defined).
        table: a column of the report's table. plot: a plot in the report (metric vs severity).
        lap: printed in ``weather-gym lap``'s summary; ``line``: its text there from the lap's values
            (default: ``label: value unit``; None to print nothing for this episode).
        applies: ``Episode -> bool``: whether the lap reports it for this episode (None: always).
        fmt: format spec of the default lap line.
    """

    name: str
    doc: str
    compute: Callable[[Episode], Any]
    label: str = ""
    unit: str = ""
    table: bool = False
    plot: bool = False
    lap: bool = True
    line: Callable[[Mapping[str, Any]], str | None] | None = None
    applies: Callable[[Episode], bool] | None = None
    fmt: str = ".3f"

    def lap_line(self, values: Mapping[str, Any]) -> str | None:
        """This metric's line of the lap summary (None: nothing to print)."""
        if not self.lap:
            return None
        if self.line is not None:
            return self.line(values)
        v = values.get(self.name)
        if v is None:
            return None
        text = format(v, self.fmt) if isinstance(v, float) else str(v)
        return f"{self.label or self.name}: {text}{' ' + self.unit if self.unit else ''}"


METRICS: dict[str, Metric] = {}
"""Every metric by name, in column order."""


def register_metric(metric: Metric) -> Metric:
    """Add ``metric`` (a name may be registered once)."""
    return add_unique(METRICS, "metric", metric.name, metric)


def table_metrics() -> list[str]:
    """The report table's metric columns, in registry order."""
    return [m.name for m in METRICS.values() if m.table]


def plot_metrics() -> list[str]:
    """The metrics the report plots, in registry order."""
    return [m.name for m in METRICS.values() if m.plot]


def episode_metrics(episode: Episode, *, lap: bool = False) -> dict[str, Any]:
    """Every registered metric of ``episode``; with ``lap``, None where a metric does not apply."""
    return {m.name: (None if lap and m.applies is not None and not m.applies(episode) else m.compute(episode))
            for m in METRICS.values()}


def lap_lines(values: Mapping[str, Any]) -> list[str]:
    """The lap summary's metric lines for ``values`` (from ``episode_metrics(..., lap=True)``)."""
    return [line for m in METRICS.values() if (line := m.lap_line(values)) is not None]


# ------------------------------------------------------------------------------------ the map's quality
def map_precision_recall(mapped_xy: np.ndarray, true_xy: np.ndarray,
                         radius: float = MAP_MATCH_RADIUS_M) -> tuple[float, float]:
    """Share of mapped cones within ``radius`` of a true cone, and of true cones within ``radius`` of
    a mapped one (class-agnostic; NaN precision for an empty map).

    Example:
        >>> import numpy as np
        >>> map_precision_recall(np.array([[0, 0.3], [5, 5]]), np.array([[0, 0], [1, 0], [2, 0], [3, 0.]]))
        (0.5, 0.25)
    """

    mapped_xy = np.asarray(mapped_xy, dtype=np.float64).reshape(-1, 2)
    true_xy = np.asarray(true_xy, dtype=np.float64).reshape(-1, 2)
    if len(true_xy) == 0:
        raise InputError("the track has no cones to compare the map with")
    if len(mapped_xy) == 0:
        return math.nan, 0.0
    d_map, _ = cKDTree(true_xy).query(mapped_xy)
    d_true, _ = cKDTree(mapped_xy).query(true_xy)
    return float(np.mean(d_map <= radius)), float(np.mean(d_true <= radius))


def _map_xy(ep: Episode) -> np.ndarray | None:
    """Confirmed map cones (odometry frame, which starts at the true start pose) of a mapping agent."""
    mapper = getattr(ep.agent, "mapper", None)
    if mapper is None or not hasattr(mapper, "map"):
        return None
    return np.asarray(mapper.map(confirmed_only=True).xy, dtype=np.float64).reshape(-1, 2)


def _map_score(which: int) -> Callable[[Episode], float | None]:
    def compute(ep: Episode) -> float | None:
        mapped = _map_xy(ep)
        return None if mapped is None else map_precision_recall(mapped, ep.track.cones_xy)[which]

    return compute


def _det(attr: str, kind: type) -> Callable[[Episode], Any]:
    def compute(ep: Episode) -> Any:
        return None if ep.detector is None else kind(getattr(ep.detector, attr))

    return compute


def _cone_list(attr: str) -> Callable[[Episode], float | None]:
    def compute(ep: Episode) -> float | None:
        return None if ep.cone_list is None else float(getattr(ep.cone_list, attr))

    return compute


def _cone_bin(label: str) -> Callable[[Episode], float | None]:
    def compute(ep: Episode) -> float | None:
        if ep.cone_list is None:
            return None
        v, n = ep.cone_list.recall_by_range[label]
        return float(v) if n else None

    return compute


def cone_list_bins() -> list[tuple[str, str]]:
    """(metric name suffix, the scoring's label) of each range bin of :data:`CONE_LIST_BINS`.

    Example:
        >>> cone_list_bins()[-1]
        ('20m_plus', '>20 m')
    """
    return [((f"{lo:g}_{hi:g}m" if math.isfinite(hi) else f"{lo:g}m_plus"),
             (f"{lo:g}-{hi:g} m" if math.isfinite(hi) else f">{lo:g} m"))
            for lo, hi in zip(CONE_LIST_BINS[:-1], CONE_LIST_BINS[1:])]


def _added_line(v: Mapping[str, Any]) -> str | None:
    parts = [f"{name} {v[key]:.1f} ms" for name, key in (("weather", "weather_latency_ms"),
                                                          ("detector", "detector_latency_ms"))
             if v.get(key) is not None]
    return "added per step: " + ", ".join(parts) if parts else None


def _detector_line(v: Mapping[str, Any]) -> str | None:
    if not v.get("det_frames"):
        return None
    return (f"detector: mAP@0.5 {v['det_map50']:.3f}, recall {v['det_recall']:.3f} on the {v['det_frames']} "
            "frames it saw")


for _metric in (
    Metric("laps_completed", "laps finished in the episode", lambda e: e.result.laps_completed,
           "laps completed", lap=False),
    Metric("completed", "1 if all requested laps were finished, else 0", lambda e: int(e.result.completed),
           "lap completion (share of seeds)", table=True, plot=True, lap=False),
    Metric("progress", "distance driven along the centre line / (track length x laps), 0..1",
           lambda e: e.result.progress, "progress along the lap (0..1)", table=True, plot=True, lap=False),
    Metric("lap_time_s", "mean time of the finished laps (s; empty if none)",
           lambda e: float(np.mean(e.result.lap_times_s)) if e.result.lap_times_s else None, "lap time (s)", "s",
           table=True, plot=True, lap=False),
    Metric("cones_hit", "distinct cones touched", lambda e: e.result.cones_hit, "cones hit", table=True, plot=True,
           line=lambda v: f"cones hit: {v['cones_hit']}   off-track events: {v['off_track_events']}"),
    Metric("off_track_events", "times the car left the track", lambda e: e.result.off_track_events,
           "off-track events", table=True, plot=True, lap=False),  # in cones_hit's lap line
    Metric("cte_mean_m", "mean cross-track error over the steps (m)", lambda e: e.result.cte_mean_m,
           "mean cross-track error (m)", "m", table=True, plot=True,
           line=lambda v: f"cross-track error: mean {v['cte_mean_m']:.3f} m, max {v['cte_max_m']:.3f} m"),
    Metric("cte_max_m", "max cross-track error (m)", lambda e: e.result.cte_max_m, "max cross-track error (m)", "m",
           table=True, lap=False),  # in cte_mean_m's lap line
    Metric("end_reason", "laps | off_track | time_limit (weather_gym.envs.END_REASONS)",
           lambda e: e.result.end_reason, "end reason", lap=False),
    Metric("steps", "env steps driven", lambda e: e.result.steps, "steps", lap=False),
    Metric("sim_time_s", "simulated time (s)", lambda e: e.result.sim_time_s, "simulated time (s)", "s", lap=False),
    Metric("map_cones", "confirmed cones in the agent's map at the end (empty if the agent has no map)",
           lambda e: None if (xy := _map_xy(e)) is None else len(xy), "map cones", lap=False),
    Metric("map_precision", f"share of mapped cones within {MAP_MATCH_RADIUS_M} m of a true cone", _map_score(0),
           f"map precision ({MAP_MATCH_RADIUS_M} m)", table=True, plot=True, lap=False),
    Metric("map_recall", f"share of the track's cones within {MAP_MATCH_RADIUS_M} m of a mapped cone",
           _map_score(1), f"map recall ({MAP_MATCH_RADIUS_M} m)", table=True, plot=True, lap=False),
    Metric("det_map50", "detector mAP@0.5 (pycocotools) pooled over the frames seen (empty unless the perception "
           "mode is scored: detector)", _det("map50", float), "detector mAP@0.5 on frames seen", table=True,
           plot=True, line=_detector_line),
    Metric("det_recall", "detector recall at its operating threshold over the frames seen", _det("recall", float),
           "detector recall", lap=False),  # in det_map50's lap line
    Metric("det_frames", "frames scored for det_map50", lambda e: 0 if e.detector is None else int(e.detector.n_images),
           "frames scored", lap=False),
    Metric("weather_latency_ms", "mean time the weather added per step (ms)", lambda e: e.result.weather_latency_ms,
           "weather latency per step (ms)", "ms", line=_added_line,
           applies=lambda e: e.weathered and e.mode.renders_frames),
    Metric("detector_latency_ms", "mean time the detector added per step (ms; 0 without a detector)",
           lambda e: e.result.detector_latency_ms, "detector latency per step (ms)", "ms", lap=False,
           applies=lambda e: e.mode.runs_detector),  # in weather_latency_ms's lap line
    Metric("added_latency_ms", "weather_latency_ms + detector_latency_ms",
           lambda e: e.result.weather_latency_ms + e.result.detector_latency_ms, "added latency per step (ms)", "ms",
           table=True, plot=True, lap=False),
    Metric("cone_recall", "share of the true cones ahead (camera's field, 25 m) the agent's cone list held, "
           "within 1 m (ConeListScoring, every 3rd step)", _cone_list("recall"), "cone list recall (ahead)",
           table=True, plot=True, lap=False),
    Metric("cone_precision", "share of the cone list's cones ahead within 1 m of a true cone",
           _cone_list("precision"), "cone list precision (ahead)", table=True, lap=False),
    *(Metric(f"cone_recall_{suffix}", f"cone_recall of the true cones {label} from the camera", _cone_bin(label),
             f"cone list recall {label}", lap=False)
      for suffix, label in cone_list_bins()),
):
    register_metric(_metric)
