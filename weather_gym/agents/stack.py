"""``mapper_pure_pursuit``: the perception-only driving stack (cone list -> map -> path -> action).

Reads only ``obs["cones"]``, ``obs["mask"]`` and ``obs["state"]`` (speed, yaw rate, odometry x, y,
yaw); never the ground truth in ``info``. Each step:

1. :class:`~weather_gym.agents.mapper.ConeMapper` fuses the detections into a map (odometry frame);
2. :class:`~weather_gym.agents.planner.CenterlinePlanner` finds the centre line ahead from the
   confirmed cones;
3. :class:`~weather_gym.agents.pure_pursuit.PurePursuit` follows it with a speed profile that ends
   at a crawl where the mapped path ends (the car never plans faster than it can see).

On the skidpad (``mission="skidpad"``) step 2 is :class:`~weather_gym.agents.skidpad.SkidpadPlanner`,
the rule figure eight fitted to the mapped cones, until the car is in the exit lane.

Example:
    >>> import numpy as np
    >>> from weather_gym.camera.config import CameraConfig
    >>> from weather_gym.agents import AGENTS
    >>> agent = AGENTS.get("mapper_pure_pursuit")(None, CameraConfig())
    >>> agent.reset(seed=0)
    >>> obs = {"cones": np.zeros((64, 14), np.float32), "mask": np.zeros(64, np.int8),
    ...        "state": np.zeros(5, np.float32)}
    >>> agent.act(obs).tolist()            # nothing mapped yet: wait
    [0.0, 0.0]
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from weather_gym.agents.gt_pure_pursuit import config_with
from weather_gym.agents.mapper import ConeMap, ConeMapper, MapperConfig
from weather_gym.agents.planner import CenterlinePlanner, Plan, PlannerConfig
from weather_gym.agents.pure_pursuit import PurePursuit, PurePursuitConfig
from weather_gym.agents.skidpad import SkidpadConfig, SkidpadPlanner
from weather_gym.core.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from weather_gym.camera.config import CameraConfig
    from weather_gym.tracks import Track

__all__ = ["MapperPurePursuit", "STACK_DEFAULTS"]

MISSIONS = ("trackdrive", "acceleration", "skidpad")
"""Formula Student events (``weather_gym.tracks.EVENTS``) the stack can drive."""

EXIT_HANDOVER_M = 8.0
"""Skidpad: metres into the exit lane after which the centre-line planner takes over (at the junction
itself it would see the circles' cones)."""

STACK_DEFAULTS = {"v_max": 10.0, "a_lat_max": 4.0, "a_accel": 2.0, "lookahead_min": 3.0}
"""Controller defaults of the stack (same steady driver as ``gt_pure_pursuit``)."""


class MapperPurePursuit:
    """ConeMapper + centre-line planner + pure pursuit, through the ``Agent`` protocol.

    Args:
        track: only ``track.event`` is read (the FS mission, as a team is told which event it runs);
            the stack knows nothing of the track's geometry but what it sees.
        camera: the camera that produced the cone lists (field of view and mount for the mapper).
        mapper, planner: ``MapperConfig`` / ``PlannerConfig`` (defaults tuned for FS tracks).
        controller: a ``PurePursuitConfig``; keyword overrides (``v_max=...``) apply on top.
        v_path_end: speed (m/s) the profile allows at the end of the planned path.
        plan_max_age: the planner uses cones associated within this many steps (default 150 = 5 s at
            30 Hz): odometry drifts, so after a lap the old part of the map no longer lines up with
            what the camera sees (there is no loop closure).
        mission: the FS event being driven: ``"skidpad"`` drives the rule-defined figure eight fitted
            to the mapped cones (``SkidpadPlanner``); anything else follows the centre line found
            between the cones. Default: ``track.event`` (the event type only: the stack never reads
            the track's geometry).
        skidpad: a ``SkidpadConfig`` for the skidpad mission.
    """

    def __init__(self, track: Track | None = None, camera: CameraConfig | None = None, *,
                 mapper: MapperConfig | None = None, planner: PlannerConfig | None = None,
                 controller: PurePursuitConfig | None = None, v_path_end: float = 2.0, plan_max_age: int = 150,
                 mission: str | None = None, skidpad: SkidpadConfig | None = None, **overrides: Any) -> None:
        if mapper is None:
            mapper = MapperConfig()
            if camera is not None:
                mapper = dataclasses.replace(mapper, hfov_deg=camera.hfov_deg, mount_x=camera.mount_x)
        if not (np.isfinite(v_path_end) and v_path_end >= 0):
            raise InputError(f"mapper_pure_pursuit: v_path_end must be a finite speed >= 0, got {v_path_end!r}")
        if not (isinstance(plan_max_age, int) and plan_max_age >= 1):
            raise InputError(f"mapper_pure_pursuit: plan_max_age must be an integer >= 1, got {plan_max_age!r}")
        self.plan_max_age = plan_max_age
        merged = {**STACK_DEFAULTS, **overrides} if controller is None else overrides
        self.mapper = ConeMapper(mapper)
        self.planner = CenterlinePlanner(planner)
        self.controller = PurePursuit(config_with(controller, merged, "mapper_pure_pursuit"))
        self.v_path_end = float(v_path_end)
        self.mission = mission if mission is not None else getattr(track, "event", "trackdrive")
        if self.mission not in MISSIONS:
            raise InputError(f"mapper_pure_pursuit: unknown mission {self.mission!r}; expected one of {', '.join(MISSIONS)}")
        self.skidpad_config = skidpad
        self.skidpad: SkidpadPlanner | None = None
        self._skidpad_done = False
        self.last_plan: Plan | None = None
        self.last_map: ConeMap | None = None

    def reset(self, seed: int | None = None, info: dict | None = None) -> None:
        self.mapper.reset()
        self.planner.reset()
        self.controller.reset()
        self.skidpad = None
        self._skidpad_done = False
        self.last_plan = None
        self.last_map = None

    def act(self, obs: dict, info: dict | None = None) -> np.ndarray:
        self.last_map = self.mapper.update_from_obs(obs)
        state = np.asarray(obs["state"], dtype=np.float64).reshape(-1)
        speed, pose = float(state[0]), state[2:5]
        local = self.mapper.map(confirmed_only=True, max_age=self.plan_max_age)
        if self.mission == "skidpad" and not self._skidpad_done:
            action = self._skidpad(local, pose, speed)
            if action is not None:
                return action
        plan = self.planner.plan(local.xy, local.classes, pose)
        self.last_plan = plan
        if plan.length < 1.0:  # nothing to follow: brake to a stop (and wait for cones)
            return np.array([0.0, -1.0 if speed > 0.05 else 0.0], dtype=np.float32)
        self.controller.set_path(plan.path, closed=False, v_end=self.v_path_end)
        return self.controller.command(float(pose[0]), float(pose[1]), float(pose[2]), speed)

    def _skidpad(self, local: ConeMap, pose: np.ndarray, speed: float) -> np.ndarray | None:
        """The figure eight; None once both circles are done (the exit lane is a plain lane)."""
        if self.skidpad is None:  # the odometry frame starts where the car is put on the start line
            self.skidpad = SkidpadPlanner(pose, self.skidpad_config)
        path = self.skidpad.plan(local.xy, local.classes)
        s = self.controller.progress
        lengths = self.skidpad.lengths
        if s is not None and lengths["circles"] > 0 and s > lengths["approach"] + lengths["circles"] + EXIT_HANDOVER_M:
            self._skidpad_done = True
            self.controller.reset()
            return None
        self.last_plan = Plan(path=path)
        self.controller.set_path(path, closed=False, v_end=0.0)
        if s is not None:
            self.controller.set_progress(s)
        return self.controller.command(float(pose[0]), float(pose[1]), float(pose[2]), speed)
