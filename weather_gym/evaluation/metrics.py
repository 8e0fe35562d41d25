"""The metrics of one evaluation cell: names and what each means (the results CSV's columns).

Example:
    >>> from weather_gym.evaluation.metrics import METRICS
    >>> "lap_time_s" in METRICS
    True
"""

from __future__ import annotations

MAP_MATCH_RADIUS_M = 0.5
"""A mapped cone counts as correct within this distance of a true cone (and vice versa for recall)."""

METRICS: dict[str, str] = {
    "laps_completed": "laps finished in the episode",
    "completed": "1 if all requested laps were finished, else 0",
    "lap_time_s": "mean time of the finished laps (s; empty if none)",
    "progress": "distance driven along the centre line / (track length x laps), 0..1",
    "cones_hit": "distinct cones touched",
    "off_track_events": "times the car left the track",
    "cte_mean_m": "mean cross-track error over the steps (m)",
    "cte_max_m": "max cross-track error (m)",
    "end_reason": "laps | off_track | time_limit (weather_gym.envs.END_REASONS)",
    "steps": "env steps driven",
    "sim_time_s": "simulated time (s)",
    "map_cones": "confirmed cones in the agent's map at the end (empty if the agent has no map)",
    "map_precision": f"share of mapped cones within {MAP_MATCH_RADIUS_M} m of a true cone",
    "map_recall": f"share of the track's cones within {MAP_MATCH_RADIUS_M} m of a mapped cone",
    "det_map50": "detector mAP@0.5 (pycocotools) pooled over the frames seen (empty unless perception=detector)",
    "det_recall": "detector recall at its operating threshold over the frames seen",
    "det_frames": "frames scored for det_map50",
    "weather_latency_ms": "mean time the weather added per step (ms)",
    "detector_latency_ms": "mean time the detector added per step (ms; 0 without a detector)",
    "added_latency_ms": "weather_latency_ms + detector_latency_ms",
}
