"""Drive weather-gym with your own controller: anything with ``reset`` and ``act`` is an Agent.

``GapFollower`` below is a deliberately simple stack a user might bring: no map, no planner; each
frame it aims between the nearest blue and yellow cones ahead and holds a fixed speed. Registering
it in ``weather_gym.agents.AGENTS`` makes it interchangeable with ours (and with a trained
stable-baselines3 policy) everywhere an agent name is accepted, e.g. ``run_laps`` below, which is
what ``weather-gym lap`` runs.

    python examples/custom_controller.py                      # hairpin, oracle perception
    python examples/custom_controller.py --track small_track --weather droplets:0.55 --perception detector
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from weather_gym.agents import AGENTS, Agent
from weather_gym.perception.cones import unpack_cones


class GapFollower:
    """Aim at the middle of the nearest blue/yellow cones ahead; hold ``speed`` m/s.

    Reads only ``obs["cones"]``, ``obs["mask"]`` and ``obs["state"]`` (the cone-list observation
    that ``DetectorWrapper`` or ``GroundTruthConeWrapper`` produce).
    """

    def __init__(self, speed: float = 4.0, half_width: float = 1.75, wheelbase: float = 1.55,
                 max_steer: float = 0.45) -> None:
        self.speed, self.half_width = speed, half_width
        self.wheelbase, self.max_steer = wheelbase, max_steer

    def reset(self, seed: int | None = None, info: dict | None = None) -> None:
        self.last_target = np.array([5.0, 0.0])

    def act(self, obs: dict, info: dict | None = None) -> np.ndarray:
        cones = unpack_cones(obs["cones"], obs["mask"])
        xy = np.c_[cones["x_body"], cones["y_body"]]
        ahead = (xy[:, 0] > 2.0) & (np.hypot(xy[:, 0], xy[:, 1]) < 12.0)
        blue, yellow = xy[ahead & (cones["classes"] == 0)], xy[ahead & (cones["classes"] == 1)]
        nearest = lambda p: p[np.argmin(np.hypot(p[:, 0], p[:, 1]))] if len(p) else None  # noqa: E731
        b, y = nearest(blue), nearest(yellow)
        if b is not None and y is not None:
            target = (b + y) / 2
        elif b is not None:
            target = b - [0.0, self.half_width]
        elif y is not None:
            target = y + [0.0, self.half_width]
        else:
            target = self.last_target  # nothing seen: keep the last aim
        self.last_target = target
        # pure pursuit towards the target point (car frame), P control on speed
        d2 = max(float(target @ target), 1e-6)
        steer = math.atan2(2 * self.wheelbase * target[1], d2) / self.max_steer
        pedal = 0.5 * (self.speed - float(obs["state"][0]))
        return np.clip([steer, pedal], -1.0, 1.0).astype(np.float32)


AGENTS.register("gap_follower", lambda track, camera, **kw: GapFollower(**kw))


def main() -> None:
    from weather_gym.cli.lap import format_result, run_laps

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--track", default="hairpin")
    p.add_argument("--weather", default=None, help="e.g. droplets:0.55")
    p.add_argument("--perception", default="oracle", choices=("oracle", "detector"))
    p.add_argument("--laps", type=int, default=1)
    args = p.parse_args()
    assert isinstance(GapFollower(), Agent)  # the protocol is structural: two methods are enough
    for agent in ("gap_follower", "mapper_pure_pursuit"):
        result = run_laps(agent=agent, track=args.track, weather=args.weather, perception=args.perception,
                          laps=args.laps, env_id="WeatherGym/ConeTrackSmall-v0", progress=True)
        print(format_result(result), end="\n\n")


if __name__ == "__main__":
    main()
