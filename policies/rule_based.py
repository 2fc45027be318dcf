"""Rule-based ego drivers: baselines that need no training."""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from envs.safety_metrics import time_to_collision
from policies.state_driver import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, SLOWER, StateDriver

__all__ = ["CautiousDriver", "LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER"]


def _planned_path(ego, times: np.ndarray, speed: float) -> Optional[np.ndarray]:
    """Ego centre positions at ``times`` if it follows its lane and route at ``speed``.

    Walks highway-env's lane graph (on a copy of the route, with a fixed random state
    where the road forks without a route, so acting never changes the episode).
    """
    try:
        network = ego.road.network
        index = ego.lane_index
        lane = network.get_lane(index)
        start, _ = lane.local_coordinates(ego.position)
    except (AttributeError, KeyError, TypeError, ValueError):
        return None
    route = list(getattr(ego, "route", None) or [])
    fork = np.random.RandomState(0)
    offset = -start  # distance along the path where the current lane begins
    points = []
    for t in times:
        along = speed * float(t)
        while along - offset > lane.length:
            try:
                nxt = network.next_lane(index, route=route, position=lane.position(lane.length, 0.0), np_random=fork)
                nxt_lane = network.get_lane(nxt)
            except (KeyError, IndexError, ValueError):
                nxt = None
            if nxt is None or nxt == index:
                break
            offset += lane.length
            index, lane = nxt, nxt_lane
        s = along - offset
        if s <= lane.length:
            points.append(lane.position(s, 0.0))
        else:  # past the last lane of the graph: straight on along its end heading
            end = lane.heading_at(lane.length)
            points.append(lane.position(lane.length, 0.0) + (s - lane.length) * np.array([math.cos(end), math.sin(end)]))
    return np.asarray(points, dtype=float)

class CautiousDriver(StateDriver):
    """Keep lane, hold a cruise speed, slow down whenever something closes in or will cross its path.

    Reads the simulator state (privileged), so it works on any scenario without
    training; the SB3-style :meth:`predict` makes it usable wherever a trained
    policy is. Needs ``DiscreteMetaAction``.

    Args:
        env: the DV2S env (wrapped or not) this driver controls.
        cruise_speed: speed to hold on a free road [m/s]; ``None`` keeps the speed
            the scenario gave the ego at the start of the episode.
        ttc_brake: slow down when time-to-collision falls below this [s].
        headway: slow down when the gap ahead is shorter than this many seconds of travel.
        yield_horizon: slow down when another road user, moving at its current velocity,
            comes within ``conflict_radius`` of the ego's own planned path (its lane and
            route ahead, at its current speed) within this many seconds: how it yields to
            oncoming traffic when turning, to crossing traffic and to cars cutting in.
        conflict_radius: centre distance counted as a conflict [m] (under a lane width, so
            traffic passing in the next lane is not one).
    """

    def __init__(
        self, env, cruise_speed: Optional[float] = None, ttc_brake: float = 4.0, headway: float = 1.5,
        yield_horizon: float = 3.0, conflict_radius: float = 2.8,
    ) -> None:
        super().__init__(env)
        self.cruise_speed = cruise_speed
        self.ttc_brake = ttc_brake
        self.headway = headway
        self.yield_horizon = yield_horizon
        self.conflict_radius = conflict_radius
        self._cruise: Optional[float] = None

    def act(self) -> int:
        """The next action for the current state of the env."""
        base = self.env.unwrapped
        ego = base.vehicle
        others = base.road.vehicles + base.road.objects
        if base.steps == 0 or self._cruise is None:
            self._cruise = self.cruise_speed if self.cruise_speed is not None else max(ego.speed, 5.0)
        ttc, _ = time_to_collision(ego, others, horizon=10.0, ahead_only=True)
        gap = self._gap_ahead(ego, others)
        if ttc < self.ttc_brake or gap < max(6.0, self.headway * ego.speed):
            return SLOWER
        if self._path_conflict(ego, others):
            return SLOWER
        if ego.speed < self._cruise - 2.0:
            return FASTER
        if ego.speed > self._cruise + 2.0:
            return SLOWER
        return IDLE

    @staticmethod
    def _gap_ahead(ego, others) -> float:
        heading = np.array([math.cos(ego.heading), math.sin(ego.heading)])
        best = math.inf
        for other in others:
            if other is ego:
                continue
            rel = np.asarray(other.position) - ego.position
            ahead = float(rel @ heading)
            lateral = abs(float(rel[0] * heading[1] - rel[1] * heading[0]))
            if ahead > 0 and lateral < (ego.WIDTH + other.WIDTH) / 2 + 0.5:
                best = min(best, ahead - (ego.LENGTH + other.LENGTH) / 2)
        return best

    def _path_conflict(self, ego, others) -> bool:
        """Whether anything ahead of the ego's rear comes near the ego's planned path in time."""
        times = np.arange(0.0, self.yield_horizon + 1e-9, 0.25)
        path = _planned_path(ego, times, speed=max(ego.speed, 2.0))
        if path is None:
            return False
        heading = np.array([math.cos(ego.heading), math.sin(ego.heading)])
        for other in others:
            if other is ego:
                continue
            rel = np.asarray(other.position, dtype=float) - ego.position
            if float(rel @ heading) < -ego.LENGTH / 2:
                continue  # behind the ego: braking would not help
            future = np.asarray(other.position, dtype=float) + np.outer(times, np.asarray(other.velocity, dtype=float))
            if np.min(np.linalg.norm(future - path, axis=1)) < self.conflict_radius:
                return True
        return False
