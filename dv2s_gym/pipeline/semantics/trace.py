"""Semantic elements of what a simulated episode actually did (from its trace).

This is the ``S_sc`` / ``S_o`` side of the paper's SP and E2E-SC metrics: the
elements are read off the per-step actor states and events of an
:class:`envs.trace.EpisodeTrace`, never off the script or its sidecar.

Frames: trace states are in highway-env's frame (y drawn downward; heading from
+x toward +y, so a growing heading is a clockwise, i.e. right, turn seen from above).

Every vehicle (the ego included) is judged by the same rules:

* ``brake`` / ``accelerate``: speed falls / rises by 3 m/s within 2 s; ``stop``: it
  ends below 0.5 m/s after moving, or never moves, or after driving stands still for
  :data:`STOP_HOLD_S` seconds and drives on (a stop at a stop line). All three are read from the steps before the
  vehicle's first collision: the speed a collision takes away is no braking and no stop of the vehicle.
* ``lane_change_left|right``: a lane-change event of the env for that actor.
* ``turn_left|right``: net heading change of at least 55 degrees while moving.
* ``go_straight``: on a junction road (intersection, T-junction, three-way,
  roundabout) the vehicle drives through the junction area of the map (the Scenic
  intersection polygons): it is outside the junction, then inside, then outside
  again, and does not turn; or it drives into the junction area and, still heading the
  way it came, collides there (the crash ends its way across; one that had turned 20
  degrees or more when it collided there turns). A vehicle that stops
  before the junction, or stays in it without a collision, does not go straight. Without a loadable map nothing goes straight.
* ``keep_lane``: the vehicle travels at least :data:`KEEP_LANE_MIN_M` metres along
  its path, has no lane-change event, does not turn, drift, cut in, merge or
  overtake, and (when the map can be loaded) its centre stays inside the lane it is
  on at every sampled step, never jumping to a parallel lane of the same road.
  A stopped or parked vehicle does not keep its lane.
* ``cut_in``, ``overtake``, ``merge``, ``drift``: judged pairwise. A non-ego actor is
  judged against the ego; the ego is judged against every nearby car and truck
  (and, for ``overtake``, obstacle), with the same rules.
* ``u_turn``: net heading change of at least 150 degrees while moving (it replaces the
  ``turn_left|right`` that the same heading change would give).
* ``reverse``: the vehicle travels at least :data:`REVERSE_MIN_M` metres against its own
  heading (negative speed, or displacement pointing backwards).
* ``drift``: the vehicle leaves its lane gradually without changing lanes (:func:`_drift_windows`): its centre is
  outside the lane it was last centred in for at least :data:`DRIFT_OUT_S` seconds of driving, and it does not
  settle in another lane (its centre never comes within :data:`DRIFT_SETTLE_M` of another lane's centre before
  it returns or the episode ends): into a neighbouring lane and back, onto the shoulder or off the road edge,
  or across the centre line. A completed lane change (or an overtaking pull-out into the next lane) reaches the
  new lane's centre and is no drift; the env's lane-change events during a drift are not lane changes. Also (pairwise) a vehicle that starts in the opposite direction to the
  reference and moves into its lane drifts.
* ``swerve``: without a lane-change event and without turning, the vehicle's centre moves
  at least :data:`SWERVE_MIN_M` sideways from the line it started on and comes back within
  half a lane of it.
* ``pull_out``: the vehicle starts standing still, then drives off at least
  :data:`PULL_OUT_MIN_M` metres and moves at least :data:`PULL_OUT_LATERAL_M` sideways
  (out of a parking spot or shoulder into the traffic lane) without turning; or it starts still, drives at least
  :data:`PULL_OUT_CRASH_M` metres with :data:`PULL_OUT_CRASH_LATERAL_M` sideways and collides (the crash cut the
  pull-out short).
* ``cross``: a pedestrian, or a cyclist starting across the ego's heading (45-135 degrees), that moves
  more than 2.5 m and more than 2 m sideways relative to the ego.
* ``collide`` for both actors of every collision event, plus its type
  (:func:`collision_type`): ``collide_rear_end``, ``collide_head_on`` or
  ``collide_side``.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, Dict, List, Optional, Set, Tuple

import numpy as np
import shapely
from shapely.affinity import scale

from dv2s_gym.pipeline.semantics.parsed import Lane
from scenario_bank.elements import Action, ActorKind, Elements, Road
from scenario_bank.maps import MAPS_DIR

__all__ = ["ego_frame", "elements_from_trace", "collision_type", "trace_actor_kind", "map_view", "MAP_ROAD_TYPES", "KEEP_LANE_MIN_M"]

MAP_ROAD_TYPES = {
    "highway_straight": "highway",
    "highway_onramp": "merge",
    "urban_two_way": "straight_road",
    "urban_multilane": "straight_road",
    "urban_parking": "straight_road",
    "urban_crossroads": "intersection",
    "urban_t_junction": "t_junction",
    "urban_roundabout": "roundabout",
}
"""Road type of each shipped map."""

LANE_HALF_WIDTH = 1.75
BRAKE_DROP = 3.0          # m/s lost ...
BRAKE_WINDOW = 2.0        # ... within this many seconds
STOP_SPEED = 0.5
STOP_HOLD_S = 0.4         # s standing still, after driving, for a ``stop`` the vehicle drives on from
TURN_ANGLE = math.radians(55)
MERGE_FROM = (math.radians(45), math.radians(135))   # heading gap to the ego's at the start ...
MERGE_ALIGNED = math.radians(20)                      # ... and at the end, for a merge
PATH_LOOKAHEAD_M = 12.0  # the ego's path is extended this far ...
PATH_LOOKAHEAD_S = 1.5   # ... or this many seconds at its last speed, whichever is longer
NEAR = 80.0               # m: actors never closer than this to the ego are background traffic
KEEP_LANE_MIN_M = 20.0    # m travelled along its path before a vehicle counts as keeping its lane
JUNCTION_ROADS = (Road.INTERSECTION, Road.T_JUNCTION, Road.THREE_WAY, Road.ROUNDABOUT)
VEHICLE_LENGTH, VEHICLE_WIDTH = 5.0, 2.0   # m, highway-env's vehicle box (collision faces)
FRONTAL_GAP = math.radians(45)   # heading gap up to which a front/back contact is rear-end ...
HEAD_ON_GAP = math.radians(135)  # ... and from which it is head-on
U_TURN_ANGLE = math.radians(150)
REVERSE_MIN_M = 2.0       # m driven backwards for ``reverse``
SWERVE_MIN_M = 1.0        # m of sideways excursion (and back) for ``swerve``
PULL_OUT_MIN_M = 8.0      # m driven after standing still for ``pull_out`` ...
PULL_OUT_LATERAL_M = 1.5  # ... with at least this sideways shift
PULL_OUT_CRASH_M = 1.5          # a pull-out a collision cut short: at least this far driven ...
PULL_OUT_CRASH_LATERAL_M = 0.2  # ... and this far sideways before the collision
LANE_WIDTH = 3.5          # m, every shipped map
DRIFT_OUT_S = 1.5         # s driven with the centre outside the lane it was centred in, for ``drift`` ...
DRIFT_SETTLE_M = 0.6      # ... without coming this close to another lane's centre (that is a lane change)
_LEAVES_LANE = {Action.U_TURN, Action.REVERSE, Action.SWERVE, Action.PULL_OUT, Action.DRIFT, Action.CUT_IN,
                Action.MERGE, Action.OVERTAKE, Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT, Action.TURN_LEFT,
                Action.TURN_RIGHT}
_MET_BY_EGO = (ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE, ActorKind.BICYCLE, ActorKind.OBSTACLE)
"""The kinds whose moves relative to the ego are the ego's interactions (an obstacle's: only an overtake)."""


def _kind(name: str, kinds: Dict[str, str]) -> str:
    if name in kinds:
        return kinds[name]
    if name == "ego":
        return "ego"
    lowered = name.lower()
    for word, kind in (("pedestrian", "pedestrian"), ("truck", "truck"), ("bus", "bus"), ("motorcycle", "motorcycle"),
                       ("bicycle", "bicycle"), ("obstacle", "obstacle"),
                       ("prop", "obstacle"), ("car", "car")):
        if word in lowered:
            return kind
    return "car"


def trace_actor_kind(trace, name: str) -> str:
    """The kind of actor ``name`` of ``trace`` (car, truck, pedestrian, obstacle...): the kind the trace recorded
    for it, else the one its name says (``car`` when it says none)."""
    return _kind(name, dict(getattr(trace, "kinds", {}) or {}))


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _heading_gap(a: float, b: float) -> float:
    """Absolute angle between two headings, in [0, pi]."""
    return abs(float(_wrap(np.array([a - b]))[0]))


def ego_frame(ego: np.ndarray, other: np.ndarray) -> Tuple[float, float]:
    """(longitudinal, leftward) position of ``other`` relative to ``ego`` = [x, y, heading, speed]."""
    dx, dy = other[0] - ego[0], other[1] - ego[1]
    c, s = math.cos(ego[2]), math.sin(ego[2])
    return dx * c + dy * s, dx * s - dy * c


def _road_type(trace, ego_track: np.ndarray) -> Optional[str]:
    map_path = str((trace.params or {}).get("map", ""))
    stem = Path(map_path).stem
    if stem in MAP_ROAD_TYPES:
        return MAP_ROAD_TYPES[stem]
    try:
        from envs.road_network import load_road_network

        converted = load_road_network(map_path)
    except (ValueError, OSError):  # no map, or not one the converter reads: the road type stays unknown
        return None
    network = converted.hw_network
    through_junction = False
    widest = 1
    for x, y, heading, _ in ego_track[:: max(1, len(ego_track) // 20)]:
        index = network.get_closest_lane_index(np.array([x, y]), heading)
        if converted.is_connecting(index):
            through_junction = True
        widest = max(widest, len(network.graph[index[0]][index[1]]))
    if through_junction:
        return "intersection"
    return "highway" if widest >= 3 else "straight_road"


class _MapView:
    """The bits of a map the semantics need: the lane network and the junction area (highway-env frame)."""

    def __init__(self, converted) -> None:
        self.network = converted.hw_network
        polygons = [scale(i.polygon, 1.0, -1.0, origin=(0, 0)) for i in converted.scenic_network.intersections]
        self.junction = shapely.union_all(polygons) if polygons else None
        if self.junction is not None:
            shapely.prepare(self.junction)

    def in_junction(self, track: np.ndarray) -> np.ndarray:
        """Per row of ``track``: whether the actor's centre is inside the junction area."""
        if self.junction is None:
            return np.zeros(len(track), dtype=bool)
        return shapely.contains_xy(self.junction, track[:, 0], track[:, 1])


_MAP_VIEWS: Dict[str, Optional[_MapView]] = {}


def map_view(trace) -> Optional[_MapView]:
    """The map of a trace, for its actors' lanes and road positions (its recorded path, else the shipped map of
    that name); None if it cannot be loaded."""
    map_path = str((trace.params or {}).get("map", "") or "")
    if not map_path:
        return None
    if map_path not in _MAP_VIEWS:
        from envs.road_network import MapLoadError, load_road_network
        candidates = [Path(map_path), MAPS_DIR / Path(map_path).name]
        view = None
        for candidate in candidates:
            if candidate.is_file():
                try:
                    view = _MapView(load_road_network(candidate))
                except (MapLoadError, OSError) as error:  # what the loader raises for a map it cannot read
                    warnings.warn(f"the map {candidate} of a trace cannot be loaded ({error}); the rules that need "
                                  "the map (lanes kept, a junction crossed) are judged without it", stacklevel=2)
                break
        _MAP_VIEWS[map_path] = view
    return _MAP_VIEWS[map_path]


def _crosses_junction(track: np.ndarray, view: Optional[_MapView]) -> bool:
    """Outside the junction area, then inside it, then outside again."""
    if view is None or len(track) < 3:
        return False
    inside = np.flatnonzero(view.in_junction(track))
    return inside.size > 0 and inside[0] > 0 and inside[-1] < len(track) - 1


def _stays_in_lane(track: np.ndarray, view: Optional[_MapView], samples: int = 40) -> bool:
    """The actor's centre stays inside a lane that runs its way and never jumps to a parallel lane of the
    same road.

    Without a map: it stays within half a lane of the line it started on (straight roads)."""
    if view is None:
        return all(abs(ego_frame(track[0], row)[1]) <= LANE_HALF_WIDTH for row in track)
    network = view.network
    previous = None
    for x, y, heading, _ in track[:: max(1, len(track) // samples)]:
        position = np.array([x, y])
        index = network.get_closest_lane_index(position, heading)
        lane = network.get_lane(index)
        s, lateral = lane.local_coordinates(position)
        if abs(lateral) > lane.width_at(s) / 2 or _heading_gap(lane.heading_at(s), heading) > math.pi / 2:
            return False
        if previous is not None and previous[:2] == index[:2] and previous[2] != index[2]:
            return False
        previous = index
    return True


def collision_type(a: Any, b: Any) -> str:
    """The type of a collision between two actors in states ``[x, y, heading, speed]`` at contact.

    Contact on a front/back face (the other's offset, scaled by the vehicle's length and width, is
    more longitudinal than lateral) is ``collide_rear_end`` when the headings differ by at most 45
    degrees and ``collide_head_on`` when they differ by at least 135; every other contact is
    ``collide_side`` (angle, T-bone, sideswipe). Pedestrians and obstacles are judged by the same rule.
    """
    lon, left = ego_frame(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    frontal = abs(lon) / VEHICLE_LENGTH > abs(left) / VEHICLE_WIDTH
    gap = _heading_gap(float(a[2]), float(b[2]))
    if frontal and gap <= FRONTAL_GAP:
        return "collide_rear_end"
    if frontal and gap >= HEAD_ON_GAP:
        return "collide_head_on"
    return "collide_side"


def _collision_actions(trace, event: Dict[str, Any], dt: float) -> Optional[str]:
    """The collision type of a two-actor collision event, from the states at its step."""
    actors = list(event.get("actors", []))
    if len(actors) != 2 or not trace.states:
        return None
    step = min(len(trace.states) - 1, max(0, int(round(float(event.get("time", 0.0)) / dt))))
    for k in range(step, -1, -1):
        states = trace.states[k]
        if all(name in states for name in actors):
            return collision_type(states[actors[0]], states[actors[1]])
    return None


def elements_from_trace(trace) -> Elements:
    """The elements of an episode: road, participants, actions, relations."""
    names = list(trace.states[0].keys()) if trace.states else []
    if "ego" not in names:
        return Elements()
    kinds = dict(getattr(trace, "kinds", {}) or {})
    dt = _step_seconds(trace)
    tracks: Dict[str, np.ndarray] = {}
    for name in names:
        rows = [step[name] for step in trace.states if name in step]
        tracks[name] = np.array(rows, dtype=float)
    ego = tracks["ego"]
    participants: List[str] = []
    actions: Set[Tuple[str, str]] = set()
    relations: Set[Tuple[str, str, str]] = set()
    lane_changes: Dict[str, List[Dict[str, Any]]] = {}
    crashed: Dict[str, float] = {}  # actor -> time of its first collision
    for event in trace.events:
        if event.get("kind") == Action.LANE_CHANGE and event.get("actors"):
            lane_changes.setdefault(event["actors"][0], []).append(event)
        if event.get("kind") == "collision":
            for actor in event.get("actors", []):
                crashed.setdefault(actor, float(event.get("time", 0.0)))
            typed = _collision_actions(trace, event, dt)
            for actor in event.get("actors", []):
                actions.add((_kind(actor, kinds), "collide"))
                if typed:
                    actions.add((_kind(actor, kinds), typed))
    road = _road_type(trace, ego)
    view = map_view(trace)
    for name, changes in list(lane_changes.items()):
        # a drift across a lane line is no lane change (the env logs one whenever the nearest lane changes)
        track = tracks.get(name)
        if track is not None and _kind(name, kinds) not in (ActorKind.PEDESTRIAN, ActorKind.OBSTACLE) and \
                abs(float(_wrap(np.array([track[-1, 2] - track[0, 2]]))[0])) < TURN_ANGLE:
            windows = _drift_windows(_until_crash(track, crashed.get(name), dt), dt, view)
            lane_changes[name] = [c for c in changes if not _during(windows, float(c.get("time", 0.0)))]

    near: Dict[str, str] = {}
    for name, track in tracks.items():
        if name != "ego":
            distances = [math.hypot(*ego_frame(ego[min(i, len(ego) - 1)], track[i])) for i in range(len(track))]
            if min(distances) > NEAR:
                continue  # background traffic that never came near the ego
        near[name] = _kind(name, kinds)

    ego_changes = lane_changes.get("ego", [])
    for name, kind in near.items():
        track = tracks[name]
        participants.append(kind)
        own = _motion_actions(track, dt, kind, lane_changes.get(name, []), road, view, crashed.get(name))
        if name == "ego":
            for other, other_kind in near.items():
                if other != "ego" and other_kind in _MET_BY_EGO:
                    found = _interactions(tracks[other], ego, "ego", ego_changes, road, dt, view)
                    own |= found if other_kind != ActorKind.OBSTACLE else {a for a in found if a == Action.OVERTAKE}
        else:
            relations.update((kind, r, "ego") for r in _relations(ego, track))
            if _paths_cross(ego, track):
                relations.add((kind, "crossing_path", "ego"))
            own |= _interactions(ego, track, kind, lane_changes.get(name, []), road, dt, view)
        if own & _LEAVES_LANE:
            own.discard("keep_lane")
        actions.update((kind, a) for a in own)
    return Elements(road, tuple(participants), tuple(actions), tuple(relations))


def _step_seconds(trace) -> float:
    config = trace.config or {}
    return 1.0 / float(config.get("policy_frequency", 5) or 5)


def _motion_actions(track: np.ndarray, dt: float, kind: str, changes: List[Dict[str, Any]], road,
                    view: Optional[_MapView] = None, crashed_at: Optional[float] = None) -> Set[str]:
    out: Set[str] = set()
    if len(track) < 2:
        return out
    if kind == ActorKind.PEDESTRIAN:
        return out  # crossing is judged relative to the road/ego in _interactions
    if kind == ActorKind.OBSTACLE:
        return out
    speed = _before_crash(track, crashed_at, dt)[:, 3]
    window = max(1, int(round(BRAKE_WINDOW / dt)))
    drops = speed[:-window] - speed[window:] if len(speed) > window else np.array([speed[0] - speed[-1]])
    if drops.size and drops.max() >= BRAKE_DROP:
        out.add("brake")
    moving_before = speed.max() > 2.0
    if (moving_before and speed[-1] < STOP_SPEED) or speed.max() < STOP_SPEED or _stops_and_goes(speed, dt):
        out.add("stop")
    rises = speed[window:] - speed[:-window] if len(speed) > window else np.array([speed[-1] - speed[0]])
    if rises.size and rises.max() >= BRAKE_DROP:
        out.add("accelerate")
    for change in changes:
        out.add("lane_change_left" if change.get("direction") == Lane.LEFT else "lane_change_right")
    out |= _special_motions(track, changes)
    if Action.PULL_OUT not in out and crashed_at is not None and _crashed_pulling_out(track, crashed_at, dt):
        out.add("pull_out")
    turn = float(_wrap(np.array([track[-1, 2] - track[0, 2]]))[0])
    windows = _drift_windows(_until_crash(track, crashed_at, dt), dt, view) if abs(turn) < TURN_ANGLE and not out & {Action.U_TURN, Action.PULL_OUT} else []
    if windows:
        out.add("drift")
        lateral = np.array([abs(ego_frame(track[0], row)[1]) for row in track])
        if Action.SWERVE in out and _during(windows, float(np.argmax(lateral)) * dt, margin=0.0):
            out.discard("swerve")  # its widest excursion is the drift: a slow drift and back is no swerve
    if Action.U_TURN in out:
        pass
    elif abs(turn) >= TURN_ANGLE and speed.max() > 1.0:
        out.add("turn_right" if turn > 0 else "turn_left")
    elif speed.max() > 1.0:
        travelled = float(np.hypot(*np.diff(track[:, :2], axis=0).T).sum())
        if not changes and travelled >= KEEP_LANE_MIN_M and _stays_in_lane(track, view):
            out.add("keep_lane")
        crashed_way = _crashed_in_junction(track, crashed_at, dt, view) if road in JUNCTION_ROADS else None
        if road in JUNCTION_ROADS and _crosses_junction(track, view) or crashed_way == Action.GO_STRAIGHT:
            out.add("go_straight")
        elif crashed_way:
            out.add(crashed_way)
    return out


def _crashed_in_junction(track: np.ndarray, crashed_at: Optional[float], dt: float,
                         view: Optional[_MapView]) -> Optional[str]:
    """The way across the junction of a vehicle that drove into the junction area from outside it and collided
    there (the crash ended its manoeuvre: a T-boned car does not leave the junction): ``go_straight`` while still
    heading within 10 degrees of the way it came in, ``turn_left|right`` once turned 20 degrees or more."""
    if view is None or crashed_at is None:
        return None
    step = min(len(track) - 1, max(0, int(round(crashed_at / dt))))
    inside = view.in_junction(track[: step + 1])
    if not inside.size or inside[0] or not inside[-1]:
        return None
    entered = int(np.flatnonzero(inside)[0])
    turned = float(_wrap(np.array([track[step, 2] - track[max(0, entered - 1), 2]]))[0])
    if abs(turned) < math.radians(10) and _heading_gap(track[step, 2], track[0, 2]) < math.radians(10):
        return "go_straight"
    if math.radians(20) <= abs(turned) < TURN_ANGLE:
        return "turn_right" if turned > 0 else "turn_left"
    return None


def _crashed_pulling_out(track: np.ndarray, crashed_at: float, dt: float) -> bool:
    """It started standing still, drove (forward or backward) at least :data:`PULL_OUT_CRASH_M` metres and moved at
    least :data:`PULL_OUT_CRASH_LATERAL_M` sideways out of where it stood, then collided: the crash cut its
    pull-out short (a car backing out of a parking space into a passing car)."""
    before = _until_crash(track, crashed_at, dt)
    if len(before) < 2 or abs(before[0, 3]) >= STOP_SPEED:
        return False
    travelled = float(np.hypot(*np.diff(before[:, :2], axis=0).T).sum())
    shift = max(abs(ego_frame(before[0], row)[1]) for row in before)
    return travelled >= PULL_OUT_CRASH_M and shift >= PULL_OUT_CRASH_LATERAL_M


def _before_crash(track: np.ndarray, crashed_at: Optional[float], dt: float) -> np.ndarray:
    """The track before the actor's first collision (the state logged at the collision's step already carries the
    impact's change of speed); the first state at least."""
    if crashed_at is None:
        return track
    return track[: min(len(track), max(1, int(round(crashed_at / dt))))]


def _until_crash(track: np.ndarray, crashed_at: Optional[float], dt: float) -> np.ndarray:
    """The track up to the actor's first collision (a crash ends its manoeuvre: where it ends up is no drift)."""
    if crashed_at is None:
        return track
    return track[: min(len(track), max(1, int(round(crashed_at / dt)) + 1))]


def _stops_and_goes(speed: np.ndarray, dt: float) -> bool:
    """After driving (above 2 m/s) the vehicle stands still (below 0.5 m/s) for :data:`STOP_HOLD_S` seconds or
    more, then drives on (a stop at a stop line, for a crossing vehicle)."""
    standing = 0.0
    moved = False
    for v in np.abs(speed):
        if v > 2.0:
            moved = True
        if moved and v < STOP_SPEED:
            standing += dt
            if standing >= STOP_HOLD_S:
                return True
        else:
            standing = 0.0
    return False


def _lateral_offsets(track: np.ndarray, view: Optional[_MapView]) -> np.ndarray:
    """Per row: the centre's signed lateral offset [m] from the centreline of the lane the vehicle is first
    centred in (NaN before that, and where it is past either end of that lane, e.g. inside a junction).

    Without a map: the offset from the line it starts on (straight roads)."""
    if view is None:
        return np.array([ego_frame(track[0], row)[1] for row in track])
    network = view.network
    out = np.full(len(track), np.nan)
    lane = None
    for i, (x, y, heading, _) in enumerate(track):
        position = np.array([x, y])
        if lane is None:
            candidate = network.get_lane(network.get_closest_lane_index(position, heading))
            s, lateral = candidate.local_coordinates(position)
            if abs(lateral) > DRIFT_SETTLE_M or _heading_gap(candidate.heading_at(s), heading) > math.pi / 4:
                continue  # not (yet) driving along a lane: parked at the kerb, standing across it
            lane = candidate
        s, lateral = lane.local_coordinates(position)
        if 0.0 <= s <= lane.length:
            out[i] = lateral
    return out


def _drift_windows(track: np.ndarray, dt: float, view: Optional[_MapView]) -> List[Tuple[float, float]]:
    """The times (start, end) [s] of the vehicle's drifts out of its lane (see the module's ``drift``): while
    driving (above 1 m/s) its centre is out of the lane it was last centred in for :data:`DRIFT_OUT_S` seconds
    or more, and it does not reach another lane's centre in between (reaching one makes that lane its own: a
    lane change). A drift ends when the vehicle is back in its lane, else with the episode."""
    offsets = _lateral_offsets(track, view)
    moving = np.abs(track[:, 3]) > 1.0
    windows: List[Tuple[float, float]] = []
    home = None       # offset of the centre of the lane it counts as its own
    out_time = 0.0    # seconds driven out of that lane in the current excursion ...
    left_at = 0.0     # ... which began then
    for i, (offset, drives) in enumerate(zip(offsets, moving)):
        if np.isnan(offset):
            continue
        nearest = LANE_WIDTH * round(offset / LANE_WIDTH)
        centred = abs(offset - nearest) <= DRIFT_SETTLE_M
        if home is None:
            if centred:
                home = nearest
            continue
        if centred and nearest != home:
            home, out_time = nearest, 0.0  # settled in another lane: a lane change, not a drift
        elif abs(offset - home) > LANE_WIDTH / 2:
            if out_time == 0.0:
                left_at = i * dt
            out_time += dt if drives else 0.0
        else:
            if out_time >= DRIFT_OUT_S:
                windows.append((left_at, i * dt))  # out of its lane for a while, then back in it
            out_time = 0.0
    if out_time >= DRIFT_OUT_S:  # still out of its lane (between lanes, on the shoulder, off the road)
        windows.append((left_at, len(track) * dt))
    return windows


def _during(windows: List[Tuple[float, float]], time: float, margin: float = 0.5) -> bool:
    return any(start - margin <= time <= end + margin for start, end in windows)


def _backward_metres(track: np.ndarray) -> float:
    """Metres the actor travelled against its own heading."""
    steps = np.diff(track[:, :2], axis=0)
    along = steps[:, 0] * np.cos(track[:-1, 2]) + steps[:, 1] * np.sin(track[:-1, 2])
    return float(-along[along < 0].sum())


def _special_motions(track: np.ndarray, changes: List[Dict[str, Any]]) -> Set[str]:
    """``u_turn``, ``reverse``, ``swerve`` and ``pull_out`` of a vehicle track ``[x, y, heading, speed]``."""
    out: Set[str] = set()
    speed = np.abs(track[:, 3])
    if speed.max() <= 1.0 and float(np.hypot(*(track[-1, :2] - track[0, :2]))) < 1.0:
        return out
    cumulative = float(np.sum(_wrap(np.diff(track[:, 2]))))
    if abs(cumulative) >= U_TURN_ANGLE:
        out.add("u_turn")
    if _backward_metres(track) >= REVERSE_MIN_M:
        out.add("reverse")
    net_turn = abs(float(_wrap(np.array([track[-1, 2] - track[0, 2]]))[0]))
    if net_turn >= TURN_ANGLE or Action.U_TURN in out:
        return out
    moving = np.flatnonzero(speed > STOP_SPEED)
    started_still = speed[0] < STOP_SPEED and moving.size > 0
    if started_still:
        first = int(moving[0])
        after = track[first:]
        travelled = float(np.hypot(*np.diff(after[:, :2], axis=0).T).sum()) if len(after) > 1 else 0.0
        shift = abs(ego_frame(track[0], track[-1])[1])
        if travelled >= PULL_OUT_MIN_M and shift >= PULL_OUT_LATERAL_M:
            out.add("pull_out")
            return out
    if not changes:
        lateral = np.array([ego_frame(track[0], row)[1] for row in track])
        peak = int(np.argmax(np.abs(lateral)))
        if abs(lateral[peak]) >= SWERVE_MIN_M and abs(lateral[-1]) <= LANE_HALF_WIDTH / 2 and peak < len(track) - 1:
            out.add("swerve")
    return out


def _relations(ego: np.ndarray, track: np.ndarray) -> Set[str]:
    """Relations to the ego at the start of the episode (the set-up the scenario describes)."""
    out: Set[str] = set()
    lon, left = ego_frame(ego[0], track[0])
    heading_gap = _heading_gap(track[0, 2], ego[0, 2])
    if heading_gap > math.radians(135) and track[:, 3].max() > 0.5:
        out.add("oncoming")
    if abs(left) <= LANE_HALF_WIDTH:
        out.add("same_lane")
    else:
        out.add("left_of" if left > 0 else "right_of")
    if lon > 2.0:
        out.add("ahead_of")
    elif lon < -2.0:
        out.add("behind")
    return out


def _paths_cross(ego: np.ndarray, track: np.ndarray, samples: int = 40) -> bool:
    """Whether the other's path crosses the ego's at an angle (30-150 degrees), at any times."""
    def thin(t: np.ndarray) -> np.ndarray:
        step = max(1, len(t) // samples)
        return t[::step]

    a, b = thin(ego), thin(track)
    # The ego's path runs on past where the episode ends (a car that stopped for a pedestrian still had
    # the pedestrian cross its path): extend it along its last heading.
    x, y, heading, speed = ego[-1][:4]
    reach = max(PATH_LOOKAHEAD_M, PATH_LOOKAHEAD_S * speed)
    a = np.vstack([a, [x + reach * math.cos(heading), y + reach * math.sin(heading), heading, speed]])
    if len(a) < 2 or len(b) < 2 or np.hypot(*(b[-1, :2] - b[0, :2])) < 1.0:
        return False
    for i in range(len(a) - 1):
        p, r = a[i, :2], a[i + 1, :2] - a[i, :2]
        if not r.any():
            continue
        for j in range(len(b) - 1):
            q, t = b[j, :2], b[j + 1, :2] - b[j, :2]
            denom = r[0] * t[1] - r[1] * t[0]
            if abs(denom) < 1e-9:
                continue
            u = ((q[0] - p[0]) * t[1] - (q[1] - p[1]) * t[0]) / denom
            v = ((q[0] - p[0]) * r[1] - (q[1] - p[1]) * r[0]) / denom
            if 0 <= u <= 1 and 0 <= v <= 1:
                angle = abs(math.atan2(denom, r[0] * t[0] + r[1] * t[1]))
                if math.radians(30) <= angle <= math.radians(150):
                    return True
    return False


def _joins_ego_lane_ahead(ego_end: np.ndarray, first: np.ndarray, last: np.ndarray, rel_end) -> bool:
    """A car that came from a crossing road (a side road, a ramp) and ends in the ego's lane, ahead of
    it, driving its way: it merged into the ego's traffic (lane changes are judged separately)."""
    return (MERGE_FROM[0] <= _heading_gap(first[2], ego_end[2]) <= MERGE_FROM[1]
            and _heading_gap(last[2], ego_end[2]) <= MERGE_ALIGNED
            and abs(rel_end[1]) <= LANE_HALF_WIDTH and rel_end[0] > 0)


def _interactions(
    ego: np.ndarray, track: np.ndarray, kind: str, changes: List[Dict[str, Any]], road, dt: float,
    view: Optional[_MapView] = None,
) -> Set[str]:
    """Actions of the actor moving along ``track`` judged against the reference actor ``ego``.

    ``ego`` is the reference (the ego for every other actor; another vehicle when the ego's own
    cut-in, overtake, merge or drift are judged), ``kind`` and ``changes`` belong to ``track``."""
    out: Set[str] = set()
    n = min(len(ego), len(track))
    rel = np.array([ego_frame(ego[i], track[i]) for i in range(n)])
    if kind == ActorKind.PEDESTRIAN:
        lateral_travel = abs(rel[-1, 1] - rel[0, 1]) if n else 0.0
        moved = float(np.hypot(*(track[-1, :2] - track[0, :2])))
        if moved > 2.5 and lateral_travel > 2.0:
            out.add("cross")
        return out
    if kind == ActorKind.OBSTACLE:
        return out
    if (kind == ActorKind.BICYCLE and n
            and math.radians(45) <= _heading_gap(track[0, 2], ego[0, 2]) <= math.radians(135)):
        # a cyclist riding across the reference's road (a crossing, a crosswalk), judged like a pedestrian
        moved = float(np.hypot(*(track[n - 1, :2] - track[0, :2])))
        if moved > 2.5 and abs(rel[-1, 1] - rel[0, 1]) > 2.0:
            out.add("cross")
    for change in changes:
        step = min(n - 1, max(0, int(round(change.get("time", 0) / dt))))
        after = rel[min(n - 1, step + 5)]
        if abs(after[1]) <= LANE_HALF_WIDTH and 0 < after[0] < 50:
            out.add("cut_in")
            if road == Road.MERGE:
                out.add("merge")
    if rel[0, 0] < -2 and rel[-1, 0] > 2:
        # passing it: with a lane-change event, or (into an oncoming lane, which has no event) starting in line
        # behind it and moving out by more than a lane half-width while alongside; a vehicle that drives by
        # in its own lane beside it is traffic, not an overtake
        alongside = np.abs(rel[:, 0]) <= 3.0
        swung_out = (abs(rel[0, 1]) <= LANE_HALF_WIDTH and alongside.any()
                     and np.abs(rel[alongside, 1]).min() > LANE_HALF_WIDTH)
        if changes or swung_out:
            out.add("overtake")
    if n and _joins_ego_lane_ahead(ego[n - 1], track[0], track[n - 1], rel[-1]):
        out.add("merge")
    started_opposite = _heading_gap(track[0, 2], ego[0, 2]) > math.radians(135)
    if started_opposite and n and road not in JUNCTION_ROADS:
        # (at a junction a left turn across the oncoming lane is no drift)
        inside = np.abs(rel[:, 1]) < LANE_HALF_WIDTH * 0.9
        # ... and it is the one that left its lane (the reference staying put is not drifting)
        if inside.any() and not inside[0] and not _stays_in_lane(track, view):
            out.add("drift")
    return out

