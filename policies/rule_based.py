"""Rule-based ego drivers: baselines that need no training."""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass
from typing import Any, Iterator, List, Optional, Tuple

import numpy as np

from envs.safety_metrics import time_to_collision
from envs.scenic_highway.actors import Pedestrian
from policies.state_driver import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, SLOWER, StateDriver

__all__ = [
    "CautiousDriver", "CautiousSettings", "ConflictZone", "conflict_zone", "gap_accepted", "road_left", "travel_time",
    "LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER",
]


def _route_lanes(ego) -> Optional[Iterator[Tuple[object, float]]]:
    """The lanes the ego will follow, each with the distance along its path where it begins
    (the first one's is negative: the ego is part-way along it); ``None`` off the lane graph.

    Starts on the lane the ego steers to (``target_lane_index``; its closest lane,
    ``lane_index``, can be another lane of the same junction entry) and walks highway-env's
    lane graph (on a copy of the route, with a fixed random state where the road forks
    without a route, so acting never changes the episode). Ends where the graph ends.
    """
    try:
        network = ego.road.network
        index = getattr(ego, "target_lane_index", None) or ego.lane_index
        lane = network.get_lane(index)
        start, _ = lane.local_coordinates(ego.position)
    except (AttributeError, KeyError, TypeError, ValueError):
        return None
    route = list(getattr(ego, "route", None) or [])

    def walk(index, lane, offset):
        fork = np.random.RandomState(0)
        while True:
            yield lane, offset
            try:
                nxt = network.next_lane(index, route=route, position=lane.position(lane.length, 0.0), np_random=fork)
                nxt_lane = network.get_lane(nxt)
            except (KeyError, IndexError, ValueError):
                return
            if nxt is None or nxt == index:
                return
            offset += lane.length
            index, lane = nxt, nxt_lane

    return walk(index, lane, -float(start))


def _planned_path(ego, times: np.ndarray, speed: float) -> Optional[np.ndarray]:
    """Ego centre positions at ``times`` if it follows its lane and route at ``speed``
    (along :func:`_route_lanes`, then straight on along the last lane's end heading)."""
    lanes = _route_lanes(ego)
    if lanes is None:
        return None
    lane, offset = next(lanes)
    points = []
    for t in times:
        along = speed * float(t)
        while along - offset > lane.length:
            following = next(lanes, None)
            if following is None:
                break
            lane, offset = following
        s = along - offset
        if s <= lane.length:
            points.append(lane.position(s, 0.0))
        else:  # past the last lane of the graph: straight on along its end heading
            end = lane.heading_at(lane.length)
            points.append(lane.position(lane.length, 0.0) + (s - lane.length) * np.array([math.cos(end), math.sin(end)]))
    return np.asarray(points, dtype=float)


def road_left(ego, limit: float) -> float:
    """Distance [m] from the ego to where its lane graph (its lane, then its route) ends;
    ``inf`` if the road goes on for at least ``limit`` metres or the ego is off the graph."""
    lanes = _route_lanes(ego)
    if lanes is None:
        return math.inf
    for lane, offset in lanes:
        if offset + lane.length > limit:
            return math.inf
        end = offset + lane.length
    return end


def travel_time(distance: float, speed: float, accel: float, max_speed: float) -> float:
    """Seconds to cover ``distance`` [m] from ``speed``, accelerating at ``accel`` up to ``max_speed``.

    ``0`` for a distance already covered; ``inf`` when standing with no acceleration.
    A speed above ``max_speed`` is held (never braked down).
    """
    if distance <= 0.0:
        return 0.0
    speed = max(float(speed), 0.0)
    top = max(float(max_speed), speed)
    if accel <= 0.0 or speed >= top:
        return distance / speed if speed > 1e-9 else math.inf
    ramp = (top * top - speed * speed) / (2.0 * accel)
    if distance <= ramp:
        return (math.sqrt(speed * speed + 2.0 * accel * distance) - speed) / accel
    return (top - speed) / accel + (distance - ramp) / top


@dataclass(frozen=True)
class ConflictZone:
    """Where the ego's planned path crosses another road user's straight-ahead path.

    ``ego_entry``/``ego_exit``: distances [m] along the ego's path at which the ego's centre
    starts and stops overlapping the other's swept band (its footprint included);
    ``other_entry``/``other_exit``: the same along the other's heading, for its centre
    (negative: already past). Both footprints are counted, so the zone is free once
    ``ego_exit`` is reached by the ego or ``other_exit`` by the other.
    """

    ego_entry: float
    ego_exit: float
    other_entry: float
    other_exit: float


def conflict_zone(
    path: np.ndarray, arc: np.ndarray, ego_size: Tuple[float, float],
    position: np.ndarray, heading: float, size: Tuple[float, float],
    margin: float = 0.5, min_angle: float = math.radians(20.0),
) -> Optional[ConflictZone]:
    """The first zone where the ego's path (centres ``path`` at arc lengths ``arc``) crosses
    the band swept by a road user at ``position`` moving straight along ``heading``; ``ego_size``
    and ``size`` are the two footprints' ``(length, width)`` [m].

    Only *crossing* paths count: where the two headings differ by at least ``min_angle``
    and by at most ``pi - min_angle`` (traffic ahead in the same lane, traffic cutting in at a
    shallow angle and head-on traffic are left to car following and time-to-collision).
    ``margin`` [m] widens both footprints. ``None`` if the paths do not cross ahead of the
    road user's rear.
    """
    if len(path) < 2:
        return None
    (ego_length, ego_width), (length, width) = ego_size, size
    direction = np.array([math.cos(heading), math.sin(heading)])
    normal = np.array([-direction[1], direction[0]])
    rel = path - np.asarray(position, dtype=float)
    along = rel @ direction
    lateral = np.abs(rel @ normal)
    step = np.gradient(path, axis=0)
    ego_heading = np.arctan2(step[:, 1], step[:, 0])
    angle = ego_heading - heading
    sin_a, cos_a = np.abs(np.sin(angle)), np.abs(np.cos(angle))
    ego_across = sin_a * ego_length / 2 + cos_a * ego_width / 2  # ego half-extent across the other's band
    ego_along = cos_a * ego_length / 2 + sin_a * ego_width / 2  # ... and along the other's heading
    reach = length / 2 + ego_along + margin
    inside = (lateral < width / 2 + ego_across + margin) & (along + reach > 0.0) & (sin_a >= math.sin(min_angle))
    if not inside.any():
        return None
    first = int(np.argmax(inside))
    last = first
    while last + 1 < len(inside) and inside[last + 1]:
        last += 1
    zone = slice(first, last + 1)
    return ConflictZone(
        ego_entry=float(arc[first]), ego_exit=float(arc[last]),
        other_entry=float(np.min(along[zone] - reach[zone])), other_exit=float(np.max(along[zone] + reach[zone])),
    )


def gap_accepted(
    zone: ConflictZone, ego_speed: float, ego_accel: float, ego_max_speed: float,
    other_speed: float, other_accel: float, other_max_speed: float, margin: float,
) -> bool:
    """Whether the ego may go through ``zone`` now: the road user is past it, or the ego clears it
    (at ``ego_accel`` up to ``ego_max_speed``) at least ``margin`` seconds before the road user
    could reach it if it sped up at ``other_accel`` to ``other_max_speed`` (gap acceptance)."""
    if zone.other_exit <= 0.0:
        return True
    if zone.other_entry <= 0.0:
        return False  # it is in the zone now
    ego_clear = travel_time(zone.ego_exit, ego_speed, ego_accel, ego_max_speed)
    other_arrival = travel_time(zone.other_entry, other_speed, other_accel, other_max_speed)
    return ego_clear + margin <= other_arrival


@dataclass(frozen=True)
class CautiousSettings:
    """The thresholds of :class:`CautiousDriver` (its docstring says which rule uses which)."""

    cruise_speed: Optional[float] = None
    """Speed to hold on a free road [m/s]; ``None`` keeps the speed the scenario gave the ego at the start of the
    episode."""
    ttc_brake: float = 4.0
    """Slow down when time-to-collision falls below this [s]."""
    headway: float = 1.5
    """Slow down when the gap ahead is shorter than this many seconds of travel."""
    yield_horizon: float = 3.0
    """Prediction horizon of the yielding rule [s]."""
    conflict_radius: float = 2.8
    """Centre distance counted as a conflict by the yielding rule [m] (under a lane width, so traffic passing in
    the next lane is not one)."""
    gap_margin: float = 1.0
    """Seconds the ego must have cleared a crossing zone before a road user could reach it."""
    other_speed_up: float = 1.5
    """Factor on a crossing road user's speed for the fastest it may go."""
    vehicle_max_speed: float = 14.0
    """Speed a crossing vehicle may reach whatever its speed now [m/s]."""
    vehicle_accel: float = 3.0
    """Acceleration assumed for a crossing vehicle speeding up [m/s²]."""
    pedestrian_accel: float = 1.0
    """The same for a pedestrian [m/s²]."""
    ego_accel: float = 2.0
    """Acceleration the ego counts on to clear a zone [m/s²]."""
    comfort_braking: float = 3.0
    """Deceleration at which the ego starts braking for a stop [m/s²]."""
    max_braking: float = 6.0
    """Deceleration beyond which the ego can no longer stop before a zone and commits to it [m/s²]."""
    stop_buffer: float = 1.0
    """Distance kept between the ego's footprint and a zone it waits at [m]."""
    lookahead: float = 50.0
    """Length of the ego's planned path searched for crossing zones [m]."""


class CautiousDriver(StateDriver):
    """A defensive reference driver: keep lane, hold a cruise speed, brake for what is ahead,
    and cross other road users' paths only with an accepted gap.

    Reads the simulator state (privileged), so it works on any scenario without
    training; the SB3-style :meth:`predict` makes it usable wherever a trained
    policy is. Needs ``DiscreteMetaAction``. Each step, in order:

    1. *Car following*: slow down when time-to-collision falls below ``ttc_brake`` or the
       gap ahead is shorter than ``headway`` seconds of travel.
    2. *Gap acceptance* at every zone where the ego's planned path (its lane and route)
       crosses the straight-ahead path of a moving road user (:func:`conflict_zone`): the ego
       may go only if it clears the zone ``gap_margin`` seconds before that road user could
       reach it even if it sped up (to ``other_speed_up`` times its speed, and a vehicle at
       least to ``vehicle_max_speed``; :func:`gap_accepted`). Otherwise it brakes to stop
       ``stop_buffer`` metres *before* the zone and waits there. Once committed (its footprint
       already in the zone, or too close to stop before it), it does not stop inside: it
       drives on to clear it.
    3. *Road end*: brake to stop ``stop_buffer`` metres before the end of its lane graph (a
       dead end, the edge of the map) instead of driving off it.
    4. *Yielding*: slow down when a road user, moving at its current velocity, comes within
       ``conflict_radius`` of the ego's planned path within ``yield_horizon`` seconds (cars
       cutting in, and crossing road users before the gap acceptance needs to act).
    5. *Cruise control* otherwise.

    Rules 1 and 4 leave out the road users whose crossing zone the ego is committed to
    (:meth:`_committed`): braking for them would leave it standing in their path.

    Args:
        env: the DV2S env (wrapped or not) this driver controls.
        settings: the driver's thresholds (:class:`CautiousSettings`; default: its defaults).
        **options: single settings by name, over ``settings`` (``CautiousDriver(env, cruise_speed=8.0)``;
            the options of the ``rule`` policy spec, ``rule?ttc_brake=3``).
    """

    SETTINGS = CautiousSettings
    """The settings the driver takes by name (the policy registry checks a spec's options against them)."""

    def __init__(self, env, settings: Optional[CautiousSettings] = None, **options: Any) -> None:
        super().__init__(env)
        self.settings = dataclasses.replace(settings or CautiousSettings(), **options)
        self._cruise: Optional[float] = None

    def act(self) -> int:
        """The next action for the current state of the env."""
        base = self.env.unwrapped
        ego = base.vehicle
        others = base.road.vehicles + base.road.objects
        if base.steps == 0 or self._cruise is None:
            cruise = self.settings.cruise_speed
            self._cruise = cruise if cruise is not None else max(ego.speed, 5.0)
        zones = self._crossing_zones(ego, others)
        committed = {id(other) for other, zone in zones if self._committed(ego, zone)}
        rest = [other for other in others if id(other) not in committed]
        ttc, _ = time_to_collision(ego, rest, horizon=10.0, ahead_only=True)
        gap = self._gap_ahead(ego, rest)
        if ttc < self.settings.ttc_brake or gap < max(6.0, self.settings.headway * ego.speed):
            return SLOWER
        if self._must_stop_for_road_end(ego):
            return SLOWER
        action = self._crossing_action(ego, zones)
        if action is not None:
            return action
        if self._path_conflict(ego, rest):
            return SLOWER
        if ego.speed < self._cruise - 2.0:
            return FASTER
        if ego.speed > self._cruise + 2.0:
            return SLOWER
        return IDLE

    def _crossing_zones(self, ego, others) -> List[Tuple[object, ConflictZone]]:
        """The moving road users whose straight-ahead path crosses the ego's planned path, with the zone."""
        arc = np.arange(0.0, self.settings.lookahead + 1e-9, 0.5)
        path = _planned_path(ego, arc, speed=1.0)
        if path is None:
            return []
        zones = []
        for other in others:
            if other is ego or float(getattr(other, "speed", 0.0)) <= 0.5:
                continue
            velocity = np.asarray(other.velocity, dtype=float)
            zone = conflict_zone(
                path, arc, (ego.LENGTH, ego.WIDTH), np.asarray(other.position, dtype=float),
                math.atan2(velocity[1], velocity[0]), (other.LENGTH, other.WIDTH),
            )
            if zone is not None:
                zones.append((other, zone))
        return zones

    def _crossing_action(self, ego, zones: List[Tuple[object, ConflictZone]]) -> Optional[int]:
        """Gap acceptance at the crossing ``zones``: the action it imposes (``None``: go on)."""
        blocking = []
        for other, zone in zones:
            pedestrian = isinstance(other, Pedestrian)
            speed = float(other.speed)
            accepted = gap_accepted(
                zone, ego.speed, self.settings.ego_accel, max(self._cruise, ego.speed),
                speed, self.settings.pedestrian_accel if pedestrian else self.settings.vehicle_accel,
                self.settings.other_speed_up * speed if pedestrian else max(self.settings.other_speed_up * speed, self.settings.vehicle_max_speed),
                self.settings.gap_margin,
            )
            if not accepted:
                blocking.append((zone.ego_entry, zone.other_entry <= 0.0, zone))
        if not blocking:
            return None
        entry, occupied, zone = min(blocking, key=lambda b: b[:2])  # the nearest zone the ego may not cross now
        clear = FASTER if ego.speed < self._cruise else IDLE
        if entry <= 0.0:  # already inside: clear it, unless the road user is in it too
            return SLOWER if occupied else clear
        if not occupied and self._committed(ego, zone):
            return clear  # too close to stop before the zone: never stop inside it
        stop_at = entry - self.settings.stop_buffer  # distance left to where the ego waits
        if stop_at < 0.5 or ego.speed ** 2 > 2.0 * self.settings.comfort_braking * stop_at:
            return SLOWER
        if ego.speed < 3.0 and stop_at > 4.0:  # creep up to where it waits
            return FASTER
        return IDLE

    def _committed(self, ego, zone: ConflictZone) -> bool:
        """Whether the ego is inside ``zone`` or too close to stop before it."""
        return zone.ego_entry <= 0.0 or ego.speed ** 2 / (2.0 * self.settings.max_braking) > zone.ego_entry

    def _must_stop_for_road_end(self, ego) -> bool:
        """Whether the ego must brake now to stop ``stop_buffer`` metres before the end of its road."""
        left = road_left(ego, self.settings.lookahead) - ego.LENGTH / 2 - self.settings.stop_buffer
        return left < 0.5 or ego.speed ** 2 > 2.0 * self.settings.comfort_braking * left

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
        times = np.arange(0.0, self.settings.yield_horizon + 1e-9, 0.25)
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
            if np.min(np.linalg.norm(future - path, axis=1)) < self.settings.conflict_radius:
                return True
        return False
