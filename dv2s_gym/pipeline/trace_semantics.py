"""Semantic elements of what a simulated episode actually did (from its trace).

This is the ``S_sc`` / ``S_o`` side of the paper's SP and E2E-SC metrics: the
elements are read off the per-step actor states and events of an
:class:`envs.trace.EpisodeTrace`, never off the script or its sidecar.

Frames: trace states are in highway-env's frame (y drawn downward; heading from
+x toward +y, so a growing heading is a clockwise, i.e. right, turn seen from above).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, List, Optional, Set, Tuple

import numpy as np

from scenario_bank.elements import normalize_elements

__all__ = ["elements_from_trace", "MAP_ROAD_TYPES"]

MAP_ROAD_TYPES = {
    "highway_straight": "highway",
    "highway_onramp": "merge",
    "urban_two_way": "straight_road",
    "urban_crossroads": "intersection",
    "urban_t_junction": "t_junction",
}
"""Road type of each shipped map."""

LANE_HALF_WIDTH = 1.75
BRAKE_DROP = 3.0          # m/s lost ...
BRAKE_WINDOW = 2.0        # ... within this many seconds
STOP_SPEED = 0.5
TURN_ANGLE = math.radians(55)
MERGE_FROM = (math.radians(45), math.radians(135))   # heading gap to the ego's at the start ...
MERGE_ALIGNED = math.radians(20)                      # ... and at the end, for a merge
PATH_LOOKAHEAD_M = 12.0  # the ego's path is extended this far ...
PATH_LOOKAHEAD_S = 1.5   # ... or this many seconds at its last speed, whichever is longer
NEAR = 80.0               # m: actors never closer than this to the ego are background traffic


def _kind(name: str, kinds: Dict[str, str]) -> str:
    if name in kinds:
        return kinds[name]
    if name == "ego":
        return "ego"
    lowered = name.lower()
    for word, kind in (("pedestrian", "pedestrian"), ("truck", "truck"), ("obstacle", "obstacle"),
                       ("prop", "obstacle"), ("car", "car")):
        if word in lowered:
            return kind
    return "car"


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _heading_gap(a: float, b: float) -> float:
    """Absolute angle between two headings, in [0, pi]."""
    return abs(float(_wrap(np.array([a - b]))[0]))


def _ego_frame(ego: np.ndarray, other: np.ndarray) -> Tuple[float, float]:
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
    except Exception:
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


def elements_from_trace(trace) -> Dict[str, Any]:
    """Elements (vocabulary canonical form) of an episode: road, participants, actions, relations."""
    names = list(trace.states[0].keys()) if trace.states else []
    if "ego" not in names:
        return normalize_elements({})
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
    for event in trace.events:
        if event.get("kind") == "lane_change" and event.get("actors"):
            lane_changes.setdefault(event["actors"][0], []).append(event)
        if event.get("kind") == "collision":
            for actor in event.get("actors", []):
                actions.add((_kind(actor, kinds), "collide"))
    road = _road_type(trace, ego)

    for name, track in tracks.items():
        kind = _kind(name, kinds)
        if name != "ego":
            distances = [math.hypot(*_ego_frame(ego[min(i, len(ego) - 1)], track[i])) for i in range(len(track))]
            if min(distances) > NEAR:
                continue  # background traffic that never came near the ego
        participants.append(kind)
        actions.update((kind, a) for a in _motion_actions(track, dt, kind, lane_changes.get(name, []), road))
        if name == "ego":
            continue
        relations.update((kind, r, "ego") for r in _relations(ego, track))
        if _paths_cross(ego, track):
            relations.add((kind, "crossing_path", "ego"))
        actions.update((kind, a) for a in _interactions(ego, track, kind, lane_changes.get(name, []), road, dt))
    return normalize_elements({
        "road": road,
        "participants": participants,
        "actions": [list(a) for a in actions],
        "relations": [list(r) for r in relations],
    })


def _step_seconds(trace) -> float:
    config = trace.config or {}
    return 1.0 / float(config.get("policy_frequency", 5) or 5)


def _motion_actions(track: np.ndarray, dt: float, kind: str, changes: List[Dict[str, Any]], road) -> Set[str]:
    out: Set[str] = set()
    if len(track) < 2:
        return out
    speed = track[:, 3]
    if kind == "pedestrian":
        return out  # crossing is judged relative to the road/ego in _interactions
    if kind == "obstacle":
        return out
    window = max(1, int(round(BRAKE_WINDOW / dt)))
    drops = speed[:-window] - speed[window:] if len(speed) > window else np.array([speed[0] - speed[-1]])
    if drops.size and drops.max() >= BRAKE_DROP:
        out.add("brake")
    moving_before = speed.max() > 2.0
    if (moving_before and speed[-1] < STOP_SPEED) or speed.max() < STOP_SPEED:
        out.add("stop")
    rises = speed[window:] - speed[:-window] if len(speed) > window else np.array([speed[-1] - speed[0]])
    if rises.size and rises.max() >= BRAKE_DROP:
        out.add("accelerate")
    for change in changes:
        out.add("lane_change_left" if change.get("direction") == "left" else "lane_change_right")
    turn = float(_wrap(np.array([track[-1, 2] - track[0, 2]]))[0])
    if abs(turn) >= TURN_ANGLE and speed.max() > 1.0:
        out.add("turn_right" if turn > 0 else "turn_left")
    elif speed.max() > 1.0:
        if not changes:
            out.add("keep_lane")
        if road in ("intersection", "t_junction", "three_way"):
            out.add("go_straight")
    return out


def _relations(ego: np.ndarray, track: np.ndarray) -> Set[str]:
    """Relations to the ego at the start of the episode (the set-up the scenario describes)."""
    out: Set[str] = set()
    lon, left = _ego_frame(ego[0], track[0])
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
    ego: np.ndarray, track: np.ndarray, kind: str, changes: List[Dict[str, Any]], road, dt: float
) -> Set[str]:
    out: Set[str] = set()
    n = min(len(ego), len(track))
    rel = np.array([_ego_frame(ego[i], track[i]) for i in range(n)])
    if kind == "pedestrian":
        lateral_travel = abs(rel[-1, 1] - rel[0, 1]) if n else 0.0
        moved = float(np.hypot(*(track[-1, :2] - track[0, :2])))
        if moved > 2.5 and lateral_travel > 2.0:
            out.add("cross")
        return out
    if kind == "obstacle":
        return out
    for change in changes:
        step = min(n - 1, max(0, int(round(change.get("time", 0) / dt))))
        after = rel[min(n - 1, step + 5)]
        if abs(after[1]) <= LANE_HALF_WIDTH and 0 < after[0] < 50:
            out.add("cut_in")
            if road == "merge":
                out.add("merge")
    if rel[0, 0] < -2 and rel[-1, 0] > 2 and changes:
        out.add("overtake")
    if n and _joins_ego_lane_ahead(ego[n - 1], track[0], track[n - 1], rel[-1]):
        out.add("merge")
    started_opposite = _heading_gap(track[0, 2], ego[0, 2]) > math.radians(135)
    if started_opposite and n:
        inside = np.abs(rel[:, 1]) < LANE_HALF_WIDTH * 0.9
        if inside.any() and not inside[0]:
            out.add("drift")
    return out

