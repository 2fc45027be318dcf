"""The embedded, offline Scenario Generator backend ``rules``: description -> Scenic script.

:func:`generate_rules` parses a description with :mod:`dv2s_gym.pipeline.semantics.text`
into a :class:`ScenarioFrame` (road, ego, actors with counts, actions, triggers and
relations to the ego), then composes a Scenic script in the paper's four sections
from the building blocks of :mod:`dv2s_gym.pipeline.sg.blocks`:

1. map and global parameters (map chosen by road type, weather, randomized speeds,
   gaps, trigger distances and spawn offsets as ``param`` ranges);
2. adversarial behaviours (one block per actor type and action);
3. road geometry (lane tuples on straight maps, maneuver tuples at junctions);
4. spawn positions (one placement per relation to the ego).

Whatever it cannot place (an unknown kind of actor, an action a type cannot do,
a relation the map cannot realise) goes into ``warnings``; nothing
is dropped silently: every phrase the parser could not place is a ``could not place``
warning, and every parsed element the composed script does not mean to show is a
``not built: <element> ('<words>')`` warning (:func:`unbuilt_warnings`). ``elements``
lists what the script is meant to show; :func:`unshown_warnings` names what of it a
simulated run did not show (``Generation.note_simulated`` adds those after a run).
The output is deterministic for a given description and seed.
"""

from __future__ import annotations

import math
import random
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from dv2s_gym.pipeline.sg import blocks
from dv2s_gym.pipeline.errors import GenerationError
from dv2s_gym.pipeline.semantics.text import Entity, ParsedDescription, parse_description
from scenario_bank.elements import ACTIONS, PARTICIPANTS, RELATIONS, ROADS, normalize_elements
from scenario_bank.maps.build_maps import LANE_WIDTH, ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS

__all__ = ["ActorFrame", "ScenarioFrame", "SGResult", "generate_rules", "build_frame", "ROAD_MAPS", "unbuilt_warnings",
           "unshown_warnings"]

ROAD_MAPS = {
    "highway": "highway_straight",
    "merge": "highway_onramp",
    "straight_road": "urban_two_way",
    "intersection": "urban_crossroads",
    "t_junction": "urban_t_junction",
    "three_way": "urban_t_junction",
    "roundabout": "urban_roundabout",
}
MAP_ROADS = {"highway_straight": "highway", "highway_onramp": "merge", "urban_two_way": "straight_road",
             "urban_parking": "straight_road",
             "urban_multilane": "straight_road", "urban_crossroads": "intersection", "urban_t_junction": "t_junction",
             "urban_roundabout": "roundabout"}
JUNCTION_MAPS = ("urban_crossroads", "urban_t_junction", "urban_roundabout")
HIGHWAY_MAPS = ("highway_straight", "highway_onramp")
MULTILANE_STREET = "urban_multilane"
"""The town street with two lanes per direction (and oncoming traffic), for streets that need a lane beside the
ego's; ``urban_two_way`` (one lane per direction) is the plain town street."""
STREET_LANES = 2
"""Lanes per direction of :data:`MULTILANE_STREET`."""
RING_MAP = "urban_roundabout"
PARKING_STREET = "urban_parking"
"""``urban_two_way`` with a parking lane at each kerb: the street of vehicles parked at the kerb, pulling out
of a parking space or backing out of one."""
STREET_MAPS = ("urban_two_way", PARKING_STREET)
"""The town streets with one lane per direction."""
SHOULDER_HIGHWAY = "highway_straight"
"""The highway with a hard shoulder (3 m, right of the rightmost lane): the ego parked on it pulls out from it."""
_SHOULDER_KERB = "Range(2.15, 2.35)"
"""``right of <rightmost lane centre point> by`` this puts a car on the centre of :data:`SHOULDER_HIGHWAY`'s
hard shoulder (3.25 m right of the lane centre)."""
_PARKING_KERB = "Range(1.9, 2.1)"
"""``right of <lane centre point> by`` this puts a car on the centre of the kerbside parking lane of
:data:`PARKING_STREET` (the car's left side ``LANE_WIDTH / 2 + 0.25`` m from the lane centre, give or take)."""
_PARKING_FAR_KERB = "Range(5.4, 5.6)"
"""``left of <ego's lane centre point> by`` this puts a car on the far (oncoming side's) parking lane."""


def _at_kerb(var: str, cls: str, along: str, kerb: str, behavior: str) -> List[str]:
    """Scenic lines for ``var``, a standing ``cls`` at the right kerb of the ego's lane: ``along`` metres down
    the lane's centre line, its left side ``kerb`` metres right of it (off the driving lane, so the lane
    containment requirement is lifted), facing the lane's direction."""
    return [f"{var}Spot = new OrientedPoint at egoLane.centerline.pointAlongBy({along}), facing roadDirection",
            f"{var} = new {cls} right of {var}Spot by {kerb}, facing {var}Spot.heading,",
            "    with regionContainedIn everywhere,",
            "    with speed 0,",
            f"    with behavior {behavior}"]


def _ring_lengths() -> Tuple[float, float]:
    """On :data:`RING_MAP`, the length along the lane centre of an entry curve (arm end to where it joins the
    ring) and of a quarter of the ring: a vehicle entering from the arm left of the ego's passes the ego's entry
    after both."""
    d, r, half = ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS, LANE_WIDTH / 2
    entry_radius = (d * d - r * r) / (2 * r)
    entry_turn = math.pi / 2 - math.atan2(entry_radius, d)
    return (entry_radius - half) * entry_turn, (r + half) * math.pi / 2


RING_ENTRY, RING_QUARTER = _ring_lengths()
VEHICLES = ("car", "truck", "bus", "motorcycle", "bicycle")
_CLASS = {"car": "Car", "truck": "Truck", "bus": "Bus", "motorcycle": "Motorcycle", "bicycle": "Bicycle",
          "pedestrian": "Pedestrian", "obstacle": "Obstacle"}
_KIND_SPEEDS = {"bicycle": "Range(4, 6)"}
"""Cruise speed (m/s) of a kind slower than the road's traffic; it replaces the road's speed range."""
_MAX_COUNT = 4
_ACTIONS_BY_KIND = {
    "car": {"brake", "stop", "accelerate", "lane_change_left", "lane_change_right", "cut_in", "merge", "turn_left",
            "turn_right", "cross", "collide", "keep_lane", "go_straight", "overtake", "drift", "swerve", "pull_out",
            "reverse", "u_turn"},
    "pedestrian": {"cross", "stop", "collide"},
    "obstacle": set(),
}
_ACTIONS_BY_KIND["truck"] = _ACTIONS_BY_KIND["car"]
_ACTIONS_BY_KIND["bus"] = _ACTIONS_BY_KIND["car"]
_ACTIONS_BY_KIND["motorcycle"] = _ACTIONS_BY_KIND["car"]
_ACTIONS_BY_KIND["bicycle"] = _ACTIONS_BY_KIND["car"]
_ACTIONS_BY_KIND["ego"] = _ACTIONS_BY_KIND["car"] - {"cross"}


@dataclass
class ActorFrame:
    """One actor (or a group of same-type actors) the script places."""

    name: str
    kind: str
    count: int = 1
    actions: List[str] = field(default_factory=list)
    details: Dict[str, Dict[str, Any]] = field(default_factory=dict)
    relations: List[str] = field(default_factory=list)
    lane: Optional[str] = None
    sudden: bool = False
    state_stop: bool = False
    cross_dirs: List[Tuple[str, int]] = field(default_factory=list)
    role: str = ""
    side: int = 0
    parked: bool = False

    def has(self, action: str) -> bool:
        return action in self.actions


@dataclass
class ScenarioFrame:
    """What the script has to show: road/map, the ego and the other actors."""

    description: str
    road: Optional[str]
    map: str
    ego: ActorFrame
    actors: List[ActorFrame]
    ego_mentioned: bool
    weather: str = "any"


@dataclass
class SGResult:
    """A generated script with its frame, what could not be placed and what it is meant to show."""

    script: str
    frame: ScenarioFrame
    warnings: List[str]
    elements: Dict[str, Any]
    backend: str = "rules"
    context_hash: str = ""


# --------------------------------------------------------------------------- frame

_COLLISION_HINTS = {"collide_rear_end": ["ahead_of", "same_lane"], "collide_head_on": ["oncoming"],
                    "collide_side": []}
"""Placement (relations to the ego) that gives a collision its geometry when the text places the actor nowhere."""


def _directed_actions(actor: ActorFrame, warnings: List[str]) -> None:
    """Turn the parser's undirected/typed actions into ones the composer builds.

    An undirected ``lane_change`` takes the side the text gives, else the side away from where the actor is
    (a car left of the ego changes right), else left. A typed collision (``collide_rear_end|side|head_on``)
    becomes ``collide``; an actor the text does not place is placed so that the collision has that geometry
    (behind-in-lane for rear-end, oncoming for head-on); the trace judges the geometry that really happened."""
    out: List[str] = []
    for action in actor.actions:
        detail = actor.details.get(action, {})
        if action == "lane_change":
            side = detail.get("side") or detail.get("target")
            if side not in ("left", "right"):
                side = "right" if "left_of" in actor.relations else "left"
            action = f"lane_change_{side}"
            actor.details.setdefault(action, dict(detail))
        elif action in _COLLISION_HINTS:
            if actor.kind != "ego" and not actor.relations:
                actor.relations.extend(_COLLISION_HINTS[action])
            actor.details.setdefault("collide", dict(detail))
            actor.details["collide"]["type"] = action
            action = "collide"
        if action not in out:
            out.append(action)
    actor.actions = out


def _actor_from(entity: Entity, name: str) -> ActorFrame:
    actor = ActorFrame(name=name, kind=entity.kind, count=entity.count, lane=entity.lane)
    for action, detail in entity.actions:
        if action.endswith("_pending"):
            continue
        actor.actions.append(action)
        actor.details[action] = dict(detail)
        actor.sudden = actor.sudden or bool(detail.get("sudden"))
    actor.cross_dirs = list(entity.attrs.get("cross_dirs", []))
    for d in actor.details.get("cross", {}).get("directions", []) or []:
        if d and d not in [c[0] for c in actor.cross_dirs]:
            actor.cross_dirs.append((d, 0))
    actor.state_stop = bool(entity.attrs.get("state_stop"))
    actor.parked = "parked" in entity.descriptors
    return actor


def _weather(text: str) -> str:
    low = text.lower()
    if re.search(r"\b(?:rain|raining|rainy|wet|storm)\b", low):
        return "rain"
    if re.search(r"\b(?:night|dark|evening)\b", low):
        return "night"
    if re.search(r"\b(?:fog|foggy|mist|overcast|cloudy)\b", low):
        return "fog"
    if re.search(r"\b(?:sunny|clear|daylight|day)\b", low):
        return "clear"
    return "any"


def build_frame(description: str, parsed: Optional[ParsedDescription] = None,
                warnings: Optional[List[str]] = None) -> ScenarioFrame:
    """The scenario frame of a description (map chosen, roles not yet assigned)."""
    parsed = parsed or parse_description(description)
    warnings = warnings if warnings is not None else []
    ego_entity = parsed.ego
    ego = _actor_from(ego_entity, "ego") if ego_entity is not None else ActorFrame("ego", "ego")
    _directed_actions(ego, warnings)
    actors: List[ActorFrame] = []
    names: Dict[str, int] = {}
    for entity in parsed.entities:
        if entity.kind == "ego":
            continue
        if entity.kind not in _CLASS:
            warnings.append(f"could not place the {entity.attrs.get('noun', entity.kind)}: no participant type "
                            f"'{entity.kind}' ({', '.join(sorted(_CLASS))})")
            continue
        base = entity.kind
        names[base] = names.get(base, 0) + 1
        actor = _actor_from(entity, f"{base}{names[base]}")
        for rel, other in entity.relations:
            if other.kind == "ego":
                actor.relations.append(rel)
            else:
                warnings.append(f"relation '{entity.kind} {rel} {other.kind}' between two non-ego "
                                "actors is not placed (actors are placed relative to the ego)")
        for rel in entity.attrs.get("pending_relations", []):
            actor.relations.append(rel)
        _directed_actions(actor, warnings)
        if actor.count > _MAX_COUNT:
            warnings.append(f"{actor.count} {actor.kind}s described; the script places {_MAX_COUNT}")
            actor.count = _MAX_COUNT
        actors.append(actor)
    for word in parsed.unknown_actors:
        warnings.append(f"could not place '{word}': no participant type for it (car, truck, pedestrian, obstacle)")
    for note in parsed.unresolved:
        warnings.append(f"could not resolve: {note}")
    for phrase in getattr(parsed, "unplaced", []) or []:
        warnings.append(f"could not place: '{phrase}'")
    road = parsed.road
    map_name = _choose_map(road, ego, actors, warnings)
    if map_name == "urban_two_way" and _at_the_kerb(ego, actors, getattr(parsed, "features", None) or {}):
        map_name = PARKING_STREET
    return ScenarioFrame(description=description, road=road, map=map_name, ego=ego, actors=actors,
                         ego_mentioned=ego_entity is not None, weather=_weather(description))


def _at_the_kerb(ego: ActorFrame, actors: Sequence[ActorFrame], features: Dict[str, Any]) -> bool:
    """A vehicle pulls out of (or backs out of) a parking space, or the street is said to have parking: the
    street gets its parking lanes (:data:`PARKING_STREET`)."""
    if features.get("parking_lane"):
        return True
    return any(a.has("pull_out") or a.has("reverse") for a in [ego, *actors] if a is ego or a.kind in VEHICLES)


_ON_SHOULDER = re.compile(r"\b(?:on|onto|in|into|along) (?:the |its |their )?(?:hard |right )?shoulder\b|"
                          r"\b(?:breakdown|emergency) lane\b")


def _standing_on_the_shoulder(frame: ScenarioFrame) -> Optional[ActorFrame]:
    """On :data:`SHOULDER_HIGHWAY`, the one vehicle that stands still (stopped, parked, broken down: no action but
    stopping) when the description puts a vehicle on the (hard) shoulder or in the breakdown lane; else None."""
    if frame.map != SHOULDER_HIGHWAY or frame.ego.lane not in (None, "right") or \
            not _ON_SHOULDER.search(frame.description.lower()):
        return None
    still = [a for a in frame.actors if a.kind in VEHICLES and not (set(a.actions) - {"stop", "keep_lane"})
             and not ({"left_of", "oncoming", "behind"} & set(a.relations))]
    return still[0] if len(still) == 1 else None


def _needs_same_direction_lanes(ego: ActorFrame, actors: Sequence[ActorFrame]) -> bool:
    if ego.has("lane_change_left") or ego.has("lane_change_right") or ego.has("merge"):
        return True
    for a in actors:
        if a.kind not in VEHICLES:
            continue
        if a.has("cut_in") or a.has("lane_change_left") or a.has("lane_change_right"):
            return True
        static = not (set(a.actions) - {"stop", "keep_lane"}) or a.has("pull_out") or a.has("reverse")
        if ("left_of" in a.relations or "right_of" in a.relations) and "oncoming" not in a.relations \
                and not a.has("drift") and not static:
            return True
    return False


def _needs_three_lanes(ego: ActorFrame, actors: Sequence[ActorFrame]) -> bool:
    """The ego in a middle lane, or vehicles of its direction on both sides of it: more lanes than the
    multi-lane town street has per direction."""
    if ego.lane == "middle":
        return True
    sides = set()
    for a in actors:
        if a.kind in VEHICLES and "oncoming" not in a.relations:
            sides.update(r for r in a.relations if r in ("left_of", "right_of"))
            if a.lane == "adjacent" and a.count >= 2:
                sides.update(("left_of", "right_of"))
    return len(sides) == 2


def _choose_map(road: Optional[str], ego: ActorFrame, actors: Sequence[ActorFrame], warnings: List[str]) -> str:
    all_actions = set(ego.actions) | {x for a in actors for x in a.actions}
    turns = bool({"turn_left", "turn_right"} & set(ego.actions)) or any(
        a.kind in VEHICLES and ({"turn_left", "turn_right"} & set(a.actions)) for a in actors)
    if road in ROAD_MAPS:
        chosen = ROAD_MAPS[road]
        if chosen == "urban_two_way" and _needs_same_direction_lanes(ego, actors):
            if _needs_three_lanes(ego, actors):
                warnings.append("the described straight road needs three lanes in one direction; using the "
                                "4-lane straight highway map (highway_straight)")
                return "highway_straight"
            return MULTILANE_STREET  # a town street with a second lane in the ego's direction
        if chosen in ("highway_straight", "urban_two_way") and turns:
            warnings.append(f"turns were described on a {road.replace('_', ' ')}, which has no junction: "
                            "the turns are not placed")
        if chosen == "highway_straight" and "merge" in all_actions:
            warnings.append("a merge was described on a highway without an on-ramp: using the highway with an "
                            "on-ramp (highway_onramp)")
            return "highway_onramp"
        return chosen
    # no road type said: infer from what happens
    if turns or any(a.kind in VEHICLES and a.has("cross") for a in actors):
        return "urban_crossroads"  # a vehicle crossing the ego's path comes from a crossing road
    if "merge" in all_actions:
        return "highway_onramp"
    if any(a.kind == "pedestrian" for a in actors):
        if not _needs_same_direction_lanes(ego, actors):
            return "urban_two_way"
        return "highway_straight" if _needs_three_lanes(ego, actors) else MULTILANE_STREET
    if any("oncoming" in a.relations or a.has("drift") for a in actors):
        return "urban_two_way"
    if any(a.has("pull_out") or a.has("reverse") or a.has("u_turn") for a in [ego, *actors]):
        return "urban_two_way"  # out of a parking space or driveway, a turn round: a street
    return "highway_straight"


# --------------------------------------------------------------------------- composer

class _Script:
    """Accumulates the four sections and what the script is meant to show."""

    def __init__(self, frame: ScenarioFrame, rng: random.Random) -> None:
        self.frame = frame
        self.rng = rng
        self.params: List[Tuple[str, str]] = []
        self.behaviors: List[str] = []
        self.helpers: List[str] = []
        self.geometry: List[str] = []
        self.geometry_title = ""
        self.spawn: List[str] = []
        self.warnings: List[str] = []
        self.participants: List[str] = []
        self.actions: set = set()
        self.relations: set = set()
        self.merged_as_lane_change = False

    def param(self, name: str, value: str) -> str:
        kind = name.rstrip("_").split("_")[0].rstrip("0123456789")
        if name.endswith("_speed") and name.count("_") == 1 and kind in _KIND_SPEEDS:
            value = _KIND_SPEEDS[kind]
        if all(n != name for n, _ in self.params):
            self.params.append((name, value))
        return f"globalParameters.{name}"

    def use(self, *names: str) -> None:
        for n in names:
            if n not in self.behaviors:
                self.behaviors.append(n)

    def show(self, kind: str, actions: Sequence[str] = (), relations: Sequence[str] = (), count: int = 1) -> None:
        self.participants.extend([kind] * count)
        self.actions.update((kind, a) for a in actions)
        self.relations.update((kind, r, "ego") for r in relations)

    def render(self) -> str:
        frame = self.frame
        summary = " ".join(frame.description.split())
        summary = re.sub(r"[^\w\s.,;:!?'()/%-]", " ", summary)
        lines = ['"""Generated by dv2s-gym\'s rule-based Scenario Generator (backend: rules)."""', ""]
        wrapped = _wrap(summary, 96)
        lines += ["# Description:"] + [f"#   {w}" for w in wrapped] + [""]
        lines += ["# 1. Map and global parameters", f"param map = '{frame.map}'",
                  f"param weather = Uniform({', '.join(blocks.WEATHERS[frame.weather])})",
                  "model scenic.domains.driving.model", ""]
        lines += [f"param {n} = {v}" for n, v in self.params]
        lines += ["", "# 2. Adversarial behaviours"]
        text = blocks.behavior_text(self.behaviors).rstrip()
        lines += [text] if text else ["# (none: every actor keeps its lane)"]
        lines += ["", f"# 3. Road geometry: {self.geometry_title}"]
        helpers = blocks.helper_text(dict.fromkeys(self.helpers)).rstrip()
        lines += ([helpers, ""] if helpers else []) + self.geometry
        lines += ["", "# 4. Spawn positions"] + self.spawn
        return "\n".join(lines).rstrip() + "\n"


def _wrap(text: str, width: int) -> List[str]:
    out, line = [], ""
    for word in text.split():
        if len(line) + len(word) + 1 > width and line:
            out.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    if line:
        out.append(line)
    return out or [""]


_CAN_DO = {kind: set(ACTIONS) for kind in ("ego",) + VEHICLES}
_CAN_DO["pedestrian"] = {"cross", "stop", "collide", "collide_rear_end", "collide_side", "collide_head_on"}
"""Actions a participant of each kind can do at all (built or not by the rules SG)."""


def _main_event(parsed: ParsedDescription) -> Optional[Tuple[Entity, str]]:
    """The first action of the first non-ego actor that has one, else the ego's first action.

    Only actions a participant of that kind can do count (a parse such as 'pedestrian go straight' is already a
    warning, not an event)."""
    def first(entity: Entity) -> Optional[str]:
        for action, _ in entity.actions:
            if not action.endswith("_pending") and action in _CAN_DO.get(entity.kind, ()):
                return action
        return None

    for entity in parsed.entities:
        if entity.kind != "ego" and first(entity):
            return entity, first(entity)
    ego = parsed.ego
    if ego is not None and first(ego):
        return ego, first(ego)
    return None


def _check_main_event(parsed: ParsedDescription, s: _Script) -> None:
    """Raise :class:`GenerationError` when the script does not show the main event (what it was composed to
    show, :attr:`_Script.actions`)."""
    main = _main_event(parsed)
    if main is None:
        return
    entity, action = main
    kind = "ego" if entity.kind == "ego" else entity.kind
    shown = {a for k, a in s.actions if k == kind}
    if action == "lane_change" or action == "merge" and kind == "ego" and s.merged_as_lane_change:
        placed_it = bool(shown & {"lane_change_left", "lane_change_right"})
    elif action in _COLLISION_HINTS:
        placed_it = "collide" in shown
    elif action == "cut_in" and "swerve" in shown and "cut_in" not in shown:
        placed_it = True  # a swerve toward the ego and back, built as a swerve (warned)
    else:
        placed_it = action in shown
    if not placed_it:
        noun = entity.attrs.get("noun", entity.kind) if entity.kind != "ego" else "ego"
        raise GenerationError(
            f"cannot place the main event '{noun} {action.replace('_', ' ')}' of the description: the rules SG "
            f"has no block for it on the chosen road; describe it with a supported manoeuvre (e.g. brake, stop, "
            f"lane change, cut in, turn, cross, collide) or another road")


def _check_actions(actor: ActorFrame, s: _Script, supported: set) -> None:
    keep = []
    for a in actor.actions:
        if a not in _ACTIONS_BY_KIND.get(actor.kind, set()):
            s.warnings.append(f"a {actor.kind} cannot '{a.replace('_', ' ')}': not placed")
        elif a not in supported:
            s.warnings.append(f"'{actor.kind} {a.replace('_', ' ')}' cannot be realised on map {s.frame.map}: "
                              "not placed")
        else:
            keep.append(a)
    actor.actions = keep


# ---- shared parameter helpers

def _speed_ranges(map_name: str) -> Tuple[float, float]:
    return {"highway_straight": (20, 26), "highway_onramp": (18, 23), "urban_two_way": (8, 12), PARKING_STREET: (8, 12),
            MULTILANE_STREET: (8, 12)}.get(map_name, (6, 9))


def _brake_params(s: _Script, actor: ActorFrame) -> Tuple[str, str, str]:
    sudden = actor.sudden or actor.has("collide")
    stop = actor.has("stop")
    after = s.param(f"{actor.name}_brake_after", "Range(1.0, 2.2)" if sudden else "Range(2.0, 3.5)")
    strength = s.param(f"{actor.name}_brake_strength", "Range(0.8, 1.0)" if sudden else "Range(0.45, 0.7)")
    urban = s.frame.map not in HIGHWAY_MAPS
    low = "0" if stop else s.param(f"{actor.name}_low_speed", "Range(2, 4)" if urban else "Range(5, 10)")
    return after, low, strength


# --------------------------------------------------------------------------- lane maps

_LANE_ACTIONS = {"brake", "stop", "accelerate", "lane_change_left", "lane_change_right", "cut_in", "merge",
                 "collide", "keep_lane", "overtake", "drift", "cross", "go_straight", "swerve", "pull_out",
                 "reverse", "u_turn"}


def _compose_lanes(s: _Script) -> None:
    frame = s.frame
    two_way = frame.map in STREET_MAPS
    multilane = frame.map == MULTILANE_STREET  # several lanes per direction and oncoming lanes
    onramp = frame.map == "highway_onramp"
    # the ego parked on the hard shoulder right of the rightmost lane, which it pulls out into
    on_shoulder = frame.map == SHOULDER_HIGHWAY and (frame.ego.has("pull_out") or frame.ego.has("reverse"))
    lo, hi = _speed_ranges(frame.map)
    ego_speed = s.param("ego_speed", f"Range({lo}, {hi})")
    ego = frame.ego
    if ego.has("merge") and not onramp:
        # merging into the next lane (a lane closed ahead, two lanes becoming one) without an on-ramp
        ego.actions.remove("merge")
        if not (ego.has("lane_change_left") or ego.has("lane_change_right")):
            side = ego.details.get("merge", {}).get("side") or ego.details.get("merge", {}).get("target")
            ego.actions.append("lane_change_right" if side == "right" else "lane_change_left")
        s.warnings.append("the ego's merge without an on-ramp is built as a lane change into the next lane")
        s.merged_as_lane_change = True
    _check_actions(ego, s, _LANE_ACTIONS - {"cross", "merge"} | ({"merge"} if onramp else set()))
    if ego.has("go_straight") and "keep_lane" not in ego.actions:
        ego.actions.append("keep_lane")
    reckless = ego.has("collide") or any(a.has("collide") for a in frame.actors)

    # "two other cars drive in the neighbouring lanes": one on each side
    split: List[ActorFrame] = []
    for actor in frame.actors:
        if actor.lane == "adjacent" and actor.count >= 2 and not two_way and actor.kind in VEHICLES:
            other = ActorFrame(name=f"{actor.name}b", kind=actor.kind, count=actor.count // 2,
                               actions=list(actor.actions), details=dict(actor.details),
                               relations=list(actor.relations), lane="adjacent", sudden=actor.sudden, side=-1)
            actor.count -= other.count
            actor.side = 1
            split.append(other)
    frame.actors.extend(split)

    # ---------------------------------------------------------------- roles
    need: Dict[int, bool] = {}  # lane offsets (+ left, - right) the ego's lane must have
    standing = _standing_on_the_shoulder(frame)
    for actor in frame.actors:
        if actor.kind == "bicycle" and actor.has("cross"):
            _check_actions(actor, s, {"cross", "collide"})  # a cyclist riding across the road, like a pedestrian
        elif actor.kind in VEHICLES:
            _check_actions(actor, s, _LANE_ACTIONS - {"cross"} | ({"merge"} if onramp else set()))
        elif actor.kind == "pedestrian":
            _check_actions(actor, s, {"cross", "stop", "collide"})
        else:
            actor.actions = []
        if "same_lane" in actor.relations and "oncoming" in actor.relations and "ahead_of" in actor.relations:
            # in the ego's lane and oncoming at once: the lane says where it is (a car parked in the ego's lane)
            actor.relations = [r for r in actor.relations if r != "oncoming"]
            s.warnings.append(f"the {actor.kind} is both in the ego's lane and oncoming: placed in the ego's lane")
        if actor.has("swerve") and actor.has("cut_in"):
            # it swerves toward the ego and returns: no cut-in happens
            actor.actions.remove("cut_in")
            s.warnings.append(f"the {actor.kind} swerves and returns to its lane: its cut-in is built as a swerve")
        rels = set(actor.relations)
        if actor.kind == "obstacle":
            actor.role = "obstacle"
            actor.side = 1 if "left_of" in rels and not two_way else -1 if "right_of" in rels and not two_way else 0
        elif actor.kind == "pedestrian":
            actor.role = "crosser" if actor.has("cross") or actor.has("collide") else "roadside"
        elif actor.kind == "bicycle" and actor.has("cross"):
            actor.role = "crosser"
        elif actor.has("pull_out") or actor.has("reverse"):
            actor.role = "puller"  # parked at the kerb (or on the shoulder) beside the ego's lane
        elif actor.has("merge") and onramp:
            actor.role = "ramp"
        elif actor.has("drift") or ("oncoming" in rels):
            if two_way or multilane and "oncoming" in rels:
                actor.role = "oncoming"
            else:
                if "oncoming" in rels:
                    s.warnings.append(f"an oncoming {actor.kind} cannot be placed on a one-way {frame.map}: it is "
                                      "placed in the next lane instead")
                    actor.relations = [r for r in actor.relations if r != "oncoming"]
                actor.role = "adjacent"
                right = "right_of" in rels or actor.lane == "right" and ego.lane in (None, "middle", "left")
                actor.side = -1 if right and "left_of" not in rels else 1
        elif actor.has("overtake") and not actor.details.get("overtake", {}).get("around"):
            actor.role = "overtaker"
        elif actor.has("cut_in") or (actor.has("merge") and not onramp):
            actor.role = "cutter"
        elif ego.has("overtake") and not (rels & {"left_of", "right_of", "behind"}) and not any(
                a.role == "slow_lead" for a in frame.actors):
            actor.role = "slow_lead"
        elif "left_of" in rels or "right_of" in rels or actor.lane == "adjacent" and not two_way or \
                actor.lane in ("left", "right", "middle") and \
                ego.lane in ("left", "right", "middle") and actor.lane != ego.lane or \
                actor.lane in ("left", "right") and ego.lane is None and not two_way and "same_lane" not in rels:
            actor.role = "adjacent"  # (in "the right lane", the ego's lane not said: beside the ego on that side)
        elif "behind" in rels:
            actor.role = "follower"
        elif actor.has("collide") and not (rels & {"ahead_of"}) and not actor.has("brake") and not actor.has("stop"):
            actor.role = "follower"
        else:
            actor.role = "lead"
        if not two_way and not onramp and not on_shoulder and (ego.has("pull_out") or ego.has("reverse")) and \
                actor.role in ("lead", "follower") and actor.kind in VEHICLES:
            # the ego is parked on the shoulder: the traffic it pulls out into drives in the lane left of it
            actor.role, actor.side = "adjacent", 1
        if actor is standing:
            actor.role = "shoulder"  # stopped on the hard shoulder right of the rightmost lane
        if frame.map == PARKING_STREET and actor.parked and actor.role == "lead" and actor.kind in VEHICLES and \
                not (set(actor.actions) - {"stop", "keep_lane"}) and not ({"oncoming", "left_of"} & rels):
            # a parked car (or a row of them) on the street with parking lanes: at the ego's kerb, not in its lane
            actor.role = "far_side"
            actor.relations = [r for r in actor.relations if r != "same_lane"] + ["right_of"]
        if on_shoulder and actor.role in ("lead", "follower") and actor.kind in VEHICLES and \
                "left_of" not in actor.relations:
            actor.relations.append("left_of")  # in the lane left of the ego parked on the shoulder
        if two_way and actor.role == "adjacent" and not (set(actor.actions) - {"stop", "keep_lane"}):
            actor.role = "far_side"  # parked or standing at the far kerb, in the other lane
        if two_way and actor.role in ("adjacent", "cutter"):
            s.warnings.append(f"the {actor.kind} {actor.role} role needs a second lane in the ego's direction, "
                              f"which {frame.map} does not have: placed in the ego's lane")
            actor.role = "lead"
    # lateral offsets
    order = {"left": 1, "middle": 0, "right": -1}
    for actor in frame.actors:
        rels = set(actor.relations)
        if actor.role == "adjacent" and actor.side == 0:
            if actor.lane in order and ego.lane in order and actor.lane != ego.lane:
                actor.side = order[actor.lane] - order[ego.lane]
                if multilane:  # a two-lane carriageway: its left and right lanes are neighbours
                    actor.side = max(-1, min(1, actor.side))
            elif actor.lane in ("left", "right") and ego.lane is None:
                actor.side = order[actor.lane]
            elif "left_of" in rels:
                actor.side = 1
            elif "right_of" in rels:
                actor.side = -1
            else:
                actor.side = 1
        if actor.role == "cutter":
            side = actor.details.get("cut_in", {}).get("side")
            if side is None and actor.has("lane_change_left"):
                side = "right"
            if side is None and actor.has("lane_change_right"):
                side = "left"
            if side is None and actor.lane in ("left", "right") and ego.lane in (None, "middle") and \
                    not (rels & {"left_of", "right_of"}):
                side = actor.lane  # "in the left lane", the ego's lane not said: it comes from that side
            if side is None:
                side = "left" if "left_of" in rels else "right" if "right_of" in rels else \
                    ("right" if actor.kind == "truck" else s.rng.choice(["left", "right"]))
            actor.side = 1 if side == "left" else -1
            if "left_of" not in rels and "right_of" not in rels:
                actor.relations.append(f"{side}_of")
        if actor.role in ("overtaker",):
            side = actor.details.get("overtake", {}).get("side") or "left"
            actor.side = 1 if side == "left" else -1
        if actor.role in ("adjacent", "cutter"):
            need[actor.side] = True
        if actor.role == "adjacent" and actor.has("lane_change_left"):
            need[actor.side + 1] = True
        if actor.role == "adjacent" and actor.has("lane_change_right"):
            need[actor.side - 1] = True
        if actor.role in ("lead", "follower") and (actor.has("lane_change_left") or actor.has("lane_change_right")):
            need[1 if actor.has("lane_change_left") else -1] = True
        if actor.role == "overtaker" and not two_way:
            need[actor.side] = True
        if actor.role == "obstacle" and actor.side:
            need[actor.side] = True
    if ego.has("lane_change_left"):
        need[1] = True
    if ego.has("lane_change_right"):
        need[-1] = True
    if ego.has("overtake") and not two_way:
        need[1] = True
    if (ego.has("pull_out") or ego.has("reverse")) and not two_way and not onramp and not on_shoulder:
        need[1] = True  # parked in the rightmost lane (the shoulder), it pulls out into the lane left of it
    around = [a for a in frame.actors if a.has("overtake") and a.details.get("overtake", {}).get("around")]
    if around and not two_way:
        need[1] = True

    # ---------------------------------------------------------------- road geometry
    if two_way:
        s.geometry_title = ("a two-way urban street, one lane per direction, with a parking lane and a sidewalk "
                            "at each kerb" if frame.map == PARKING_STREET else
                            "a two-way urban street, one lane per direction, with sidewalks")
        s.geometry += ["lanePairs = [(lane, other) for lane in network.lanes for other in network.lanes "
                       "if other is not lane]",
                       "lanePair = Uniform(*lanePairs)",
                       "egoLane = lanePair[0]",
                       "oncomingLane = lanePair[1]",
                       "egoS = Range(80, 330)"]
        lane_var = {0: "egoLane"}
    else:
        total = 3 if onramp else STREET_LANES if multilane else 4
        max_left = max([k for k in need if k > 0], default=0)
        max_right = -min([k for k in need if k < 0], default=0)
        if max_left + max_right + 1 > total:
            s.warnings.append(f"the described lanes need {max_left + max_right + 1} lanes side by side; "
                              f"{frame.map} has {total}: some actors share a lane")
            max_left = min(max_left, total - 1)
            max_right = min(max_right, total - 1 - max_left)
        conds = []
        if max_left >= 1:
            conds.append("t[1] is not None")
        if max_left >= 2:
            conds.append("t[2] is not None")
        if max_right >= 1:
            conds.append("t[3] is not None")
        if max_right >= 2:
            conds.append("t[4] is not None")
        ego_lane_word = ego.lane
        at_kerb = ego.has("pull_out") or ego.has("reverse") or any(a.role in ("puller", "shoulder")
                                                                    for a in frame.actors)
        if at_kerb and not onramp:
            # a vehicle parked at the kerb or on the shoulder: the ego's lane is the rightmost one
            conds.append("t[3] is None")
            if max_right:
                s.warnings.append("lanes to the right of the ego cannot be placed next to a vehicle parked at "
                                  "the kerb: they are not placed")
                max_right = 0
        if ego_lane_word == "left" and max_left == 0:
            conds.append("t[1] is None")
        elif ego_lane_word == "right" and max_right == 0:
            # next to an on-ramp the acceleration lane is the right neighbour of the rightmost main lane
            conds.append("t[0] is mainLanes[0]" if onramp else "t[3] is None")
        elif ego_lane_word == "middle":
            conds += ["t[1] is not None", "t[3] is not None"] if "t[1] is not None" not in conds or \
                "t[3] is not None" not in conds else []
        if multilane and any(a.role == "oncoming" and (a.has("drift") or a.has("collide")) for a in frame.actors):
            # an oncoming vehicle that comes over the centre line meets the ego in the lane next to it
            conds = [c for c in conds if not c.startswith("t[1]") and not c.startswith("t[2]")]
            conds.append("t[1] is None")
            if max_left:
                s.warnings.append("lanes to the left of the ego cannot be placed when an oncoming vehicle comes "
                                  "over the centre line into the ego's lane: they are not placed")
                max_left = 0
        ramp_merge = onramp and any(a.role == "ramp" for a in frame.actors)
        if ramp_merge:
            # the ego drives in the lane next to the acceleration lane the merger leaves
            conds = [c for c in conds if not c.startswith("t[3]") and not c.startswith("t[4]")]
            conds.append("t[0] is mainLanes[0]")
            if max_right:
                s.warnings.append("lanes to the right of the ego cannot be placed next to an on-ramp merge")
                max_right = 0
        s.helpers.append("laneSides")
        source = ("[network.elements['road2_lane1'], network.elements['road2_lane2'], "
                  "network.elements['road2_lane3']]" if onramp else "network.lanes")
        s.geometry_title = ("a three-lane highway with a one-lane on-ramp joining an acceleration lane" if onramp
                            else f"a straight two-way town street, {STREET_LANES} lanes per direction, with "
                                 "sidewalks" if multilane else "a straight four-lane one-way highway")
        oncoming = multilane and any(a.role == "oncoming" for a in frame.actors)
        if oncoming:
            # t[7]: the oncoming lane next to the centre line (left of the leftmost lane of the ego's direction)
            s.geometry += ["def oncomingOf(lane):",
                           "    inner = ([lane] + lanesLeftOf(lane))[-1].sections[0]._laneToLeft",
                           "    return None if inner is None else inner.lane",
                           ""]
        s.geometry += [f"mainLanes = {source}",
                       "laneTuples = [(lane, laneLeftOf(lane), laneLeftOf(laneLeftOf(lane)), laneRightOf(lane),",
                       "               laneRightOf(laneRightOf(lane)), len(lanesRightOf(lane)), "
                       "len(lanesLeftOf(lane))" + (", oncomingOf(lane)" if oncoming else "") +
                       ") for lane in mainLanes]",
                       "laneTuple = Uniform(*[t for t in laneTuples" + (f" if {' and '.join(dict.fromkeys(conds))}"
                                                                     if conds else "") + "])",
                       "egoLane = laneTuple[0]"]
        lane_var = {0: "egoLane"}
        names = {1: "leftLane", 2: "leftLane2", -1: "rightLane", -2: "rightLane2"}
        idx = {1: 1, 2: 2, -1: 3, -2: 4}
        for k in sorted(need):
            if k in names and (k > 0 and k <= max_left or k < 0 and -k <= max_right):
                s.geometry.append(f"{names[k]} = laneTuple[{idx[k]}]")
                lane_var[k] = names[k]
        if oncoming:
            s.geometry.append("oncomingLane = laneTuple[7]")
        s.geometry.append("egoS = " + ("Range(5, 50)" if onramp else "Range(80, 330)" if multilane
                                       else "Range(150, 1200)"))
        if onramp:
            s.geometry += ["rampLane = Uniform(network.elements['road4_lane0'])",
                           "accelLane = network.elements['road2_lane0']"]

    def lane_of(k: int) -> str:
        if k in lane_var:
            return lane_var[k]
        nearest = max([x for x in lane_var if (x > 0) == (k > 0) and abs(x) <= abs(k)], key=abs, default=0)
        return lane_var[nearest]

    # ---------------------------------------------------------------- ego
    ego_behavior, ego_first = _ego_lane_behavior(s, ego, ego_speed, reckless, two_way, frame)
    ego_lines = ["ego = new Car at egoLane.centerline.pointAlongBy(egoS),",
                 f"    with speed {ego_speed},",
                 f"    with behavior {ego_behavior}"]
    if (ego.has("pull_out") or ego.has("reverse")) and two_way:
        # parked at the kerb, still on the road surface (the env ends an episode whose ego leaves the road)
        kerb = _PARKING_KERB if frame.map == PARKING_STREET else "Range(1.0, 1.3)"
        ego_lines = _at_kerb("ego", "Car", "egoS", kerb, ego_behavior)
    elif on_shoulder:
        ego_lines = _at_kerb("ego", "Car", "egoS", _SHOULDER_KERB, ego_behavior)
    elif ego.has("pull_out") or ego.has("reverse"):
        target = lane_of(1)
        if target == "egoLane":
            s.warnings.append("the ego's pull-out needs a lane left of where it is parked: not placed")
        ego_behavior = ego_behavior.replace("egoLane.centerline", f"{target}.centerline")
        ego_lines = ["ego = new Car at egoLane.centerline.pointAlongBy(egoS),",
                     "    with speed 0,",
                     f"    with behavior {ego_behavior}"]
    if onramp and ego.has("merge"):
        ego_lines = ["ego = new Car at rampLane.centerline.pointAlongBy(Range(40, 120)),",
                     f"    with speed {ego_speed},",
                     f"    with behavior MergeFromRamp({ego_speed}, accelLane, Range(0.5, 1.5), Range(2.0, 3.0))"]
        s.use("MergeFromRamp")
    s.show("ego", _ego_shown(ego, frame))
    if ego_first:
        s.spawn += ego_lines

    # ---------------------------------------------------------------- actors
    used_offsets: Dict[int, int] = {}
    obstacle_names: List[str] = []
    for actor in frame.actors:
        _spawn_lane_actor(s, actor, ego, ego_speed, lane_of, two_way, onramp, used_offsets, obstacle_names,
                          reckless)
    if not ego_first:
        s.spawn += ego_lines


def _ego_shown(ego: ActorFrame, frame: ScenarioFrame) -> List[str]:
    return [a for a in ego.actions]


def _ego_lane_behavior(s: _Script, ego: ActorFrame, speed: str, reckless: bool, two_way: bool,
                       frame: ScenarioFrame) -> Tuple[str, bool]:
    """The ego's behaviour (used with ego_policy='scenic') and whether it can be spawned first."""
    cruise = "Cruise" if reckless else "CautiousCruise"
    if ego.has("overtake"):
        target = next((a for a in frame.actors if a.role == "slow_lead"), None)
        if target is None:  # bypassing something that stands in the ego's lane
            target = next((a for a in frame.actors if a.role == "obstacle" and a.side == 0 and a.count == 1), None)
        if target is not None:
            s.use("OvertakeAndReturn")
            side = -1 if ego.details.get("overtake", {}).get("side") == "right" and not two_way else 1
            return (f"OvertakeAndReturn({target.name}, {side}, {speed}, Range(20, 26), Range(8, 12), "
                    f"Range(2.0, 2.8), {speed})"), False
        s.warnings.append("the ego overtakes, but nothing to overtake was described: the overtake is not placed")
        ego.actions.remove("overtake")
    passer = next((a for a in frame.actors if a.role == "follower" and a.has("collide") and a.count == 1), None)
    if (ego.has("pull_out") or ego.has("reverse")) and ego.has("collide") and passer is not None and two_way:
        # it backs up, then pulls out into the side of the vehicle coming along the lane from behind
        s.use("BackUpThenPullOutInto")
        back = "Range(2.5, 3.5)" if ego.has("reverse") else "0.2"
        trigger = "Range(5.5, 7.0)" if passer.kind not in _KIND_SPEEDS else "Range(3.0, 4.0)"
        return (f"BackUpThenPullOutInto(egoLane.centerline, {speed}, {back}, {passer.name}, {trigger}, "
                "Range(2.5, 3.5))"), False
    if ego.has("pull_out") or ego.has("reverse"):
        s.use("PullOutWhenNear")
        back = "Range(2.5, 3.5)" if ego.has("reverse") else "0"
        return (f"PullOutWhenNear(egoLane.centerline, 0, {speed}, -Range(0.8, 1.5), {back}, "
                "Range(2.5, 3.5))"), False
    if ego.has("u_turn"):
        return _u_turn(s, speed), True
    if (ego.has("lane_change_left") or ego.has("lane_change_right")) and ego.has("drift"):
        # it changes lanes and overshoots: on past the new lane's centre and out of that lane too
        sign = "" if ego.has("lane_change_left") else "-"
        s.use("DriftLater")
        return (f"DriftLater({speed}, Range(0.8, 1.6), {sign}(3.5 + Range(2.1, 2.6)), Range(3.5, 4.5), -1, "
                "Range(1.8, 2.4))"), True
    if ego.has("lane_change_left") or ego.has("lane_change_right"):
        side = 1 if ego.has("lane_change_left") else -1
        after = s.param("ego_change_after", "Range(0.5, 1.5)" if ego.sudden else "Range(1.0, 2.5)")
        dur = s.param("ego_change_duration", "Range(1.5, 2.2)" if ego.sudden else "Range(2.2, 3.2)")
        s.use("ChangeLanesLater")
        return f"ChangeLanesLater({side}, {speed}, {after}, {dur})", True
    if ego.has("swerve"):
        return _swerve(s, speed, ego), True
    if ego.has("drift"):
        oncoming = any(a.role == "oncoming" for a in frame.actors)
        if two_way and oncoming and ego.details.get("drift", {}).get("side") != "right":
            # across the centre line into the oncoming vehicle's path
            s.use("DriftAndReturn")
            return (f"DriftAndReturn({speed}, 1000, Range(2.0, 2.8), Range(1.5, 2.5), -1, Range(1.2, 2.0))", True)
        side = ego.details.get("drift", {}).get("side") or ("left" if oncoming else "right")
        return _drift(s, speed, side, hold=None), True
    if ego.has("brake") or ego.has("stop") and not _something_stops_ego(frame):
        s.use("CautiousBrakeLater" if not reckless else "BrakeLater")
        after, low, strength = _brake_params(s, ego)
        name = "CautiousBrakeLater" if not reckless else "BrakeLater"
        return f"{name}({speed}, {after}, {low}, {strength})", True
    if ego.has("accelerate"):
        s.use("SpeedUpLater")
        return f"SpeedUpLater({speed}, Range(1.0, 2.0), {speed} + Range(5, 8))", True
    s.use(cruise)
    return f"{cruise}({speed})", True


def _u_turn(s: _Script, speed: str) -> str:
    """Drive on for 1-2 s, slow to 3-4 m/s and turn round to the left (>= 150 degrees), then follow the lane
    it ends in (the opposite lane on a two-way street)."""
    s.use("UTurnLater")
    return f"UTurnLater({speed}, Range(1.0, 2.0), Range(3, 4), Range(0.9, 1.0))"


def _swerve(s: _Script, speed: str, actor: Optional[ActorFrame] = None) -> str:
    """A quick sideways move inside the lane and back: no lane change happens.

    The side is the one the text gives, else toward the ego for an actor beside it, else left. At highway
    speed the move is smaller and slower (1.1-1.3 m in 1.2-1.6 s) so that the car does not overshoot into the
    next lane. The ego swerves when something blocks its path (at the latest after 4 s)."""
    detail = actor.details.get("swerve", {}) if actor is not None else {}
    side = detail.get("side") or detail.get("target")
    if side not in ("left", "right") and actor is not None:
        side = "left" if "right_of" in actor.relations else "right" if "left_of" in actor.relations else None
    sign = "-" if side == "right" else ""
    fast = s.frame.map in HIGHWAY_MAPS
    depth = f"{sign}Range(1.1, 1.3)" if fast else f"{sign}Range(1.2, 1.5)"
    duration = "Range(1.2, 1.6)" if fast else "Range(0.8, 1.2)"
    if actor is not None and actor.kind == "ego":
        s.use("SwerveWhenBlocked")
        return f"SwerveWhenBlocked({speed}, {depth}, {duration})"
    s.use("SwerveAndBack")
    return f"SwerveAndBack({speed}, Range(1.0, 2.0), {depth}, {duration})"


def _drift(s: _Script, speed: str, side: str, hold: Optional[str]) -> str:
    """A slow drift out of the lane to ``side`` (about 2.1-2.6 m: the centre leaves the lane, the vehicle does not
    reach the next lane's centre), held ``hold`` seconds and steered back, or held for good (``hold`` None)."""
    sign = "-" if side == "right" else ""
    s.use("DriftLater")
    return (f"DriftLater({speed}, Range(0.8, 1.6), {sign}Range(2.1, 2.6), Range(2.5, 3.5), "
            f"{hold if hold is not None else -1}, Range(1.8, 2.4))")


def _something_stops_ego(frame: ScenarioFrame) -> bool:
    return any(a.kind == "obstacle" and a.side == 0 or a.role == "lead" and a.has("stop") for a in frame.actors)


def _spawn_lane_actor(s: _Script, actor: ActorFrame, ego: ActorFrame, ego_speed: str, lane_of: Callable,
                      two_way: bool, onramp: bool, used: Dict[int, int], obstacles: List[str],
                      reckless: bool) -> None:
    cls = _CLASS[actor.kind]
    n = actor.name
    urban = s.frame.map not in HIGHWAY_MAPS  # town speeds and distances
    if actor.kind in _KIND_SPEEDS:  # a slow kind does not ride at the ego's speed
        ego_speed = s.param(f"{n}_speed", _KIND_SPEEDS[actor.kind])
    rels = list(actor.relations)
    shown_actions = list(actor.actions)
    if actor.role == "obstacle":
        lane = lane_of(actor.side)
        gap = s.param(f"{n}_gap", "Range(35, 50)" if urban else "Range(55, 85)")
        for i in range(actor.count):
            var = n if actor.count == 1 else f"{n}_{i + 1}"
            s.spawn += [f"{var} = new Obstacle at {lane}.centerline.pointAlongBy(egoS + {gap} + {3.0 * i}),",
                        "    with width Range(0.8, 1.8), with length Range(0.6, 1.4)"]
            obstacles.append(var)
        rel = ["ahead_of"] + (["same_lane"] if actor.side == 0 else ["left_of" if actor.side > 0 else "right_of"])
        s.show("obstacle", [], [r for r in rel if r in rels or r == "ahead_of"], actor.count)
        return
    if actor.role == "shoulder":
        gap = s.param(f"{n}_gap", "Range(55, 85)")
        for i in range(actor.count):
            var = n if actor.count == 1 else f"{n}_{i + 1}"
            s.spawn += _at_kerb(var, cls, f"egoS + {gap} + {14 * i}", _SHOULDER_KERB, "HoldStill()")
        s.use("HoldStill")
        s.show(actor.kind, [a for a in actor.actions if a == "stop"], ["ahead_of", "right_of"], actor.count)
        return
    if actor.role == "far_side":
        gap = s.param(f"{n}_gap", "Range(25, 40)")
        near = "right_of" in actor.relations  # parked at the ego's own (right) kerb
        for i in range(actor.count):
            var = n if actor.count == 1 else f"{n}_{i + 1}"
            parking = s.frame.map == PARKING_STREET  # on the parking lane at either kerb
            place = (f"right of {var}Spot by {_PARKING_KERB if parking else 'Range(1.4, 1.7)'}, "
                     f"facing {var}Spot.heading,\n    with regionContainedIn everywhere," if near else
                     f"left of {var}Spot by {_PARKING_FAR_KERB}, facing roadDirection,\n"
                     "    with regionContainedIn everywhere," if parking else
                     f"left of {var}Spot by Range(2.5, 2.7), facing roadDirection,")
            s.spawn += [f"{var}Spot = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + {gap} + {12 * i}), "
                        "facing roadDirection",
                        f"{var} = new {cls} {place}",
                        "    with speed 0,", "    with behavior HoldStill()"]
        s.use("HoldStill")
        s.show(actor.kind, [a for a in actor.actions if a == "stop"], ["ahead_of", "right_of" if near else "left_of"],
               actor.count)
        return
    if actor.role in ("crosser", "roadside"):
        _spawn_lane_pedestrians(s, actor, ego_speed, two_way, reckless)
        return
    if actor.role == "puller":
        _spawn_puller(s, actor, ego_speed, two_way)
        return
    speed_expr = ego_speed
    lines: List[str] = []
    behavior = None
    position = None
    if actor.role == "ramp":
        # the merger reaches the acceleration lane lead metres ahead of where the ego gets to it
        speeding = actor.has("accelerate")
        lead = s.param(f"{n}_merge_lead", ("Range(14, 22)" if actor.sudden else "Range(18, 30)") if speeding
                       else ("Range(6, 12)" if actor.sudden else "Range(10, 22)"))
        position = f"Uniform(accelLane).centerline.pointAlongBy(egoS + {lead})"
        s.use("MergeFromRamp")
        target = f"{ego_speed} + Range(0, 2)"
        if speeding:
            speed_expr = f"{ego_speed} - " + s.param(f"{n}_speed_deficit", "Range(5, 8)")
        delay = "Range(0.8, 1.5)" if speeding else "Range(0.3, 1.0)"
        behavior = f"MergeFromRamp({target}, accelLane, {delay}, Range(1.8, 2.6))"
        rels = [r for r in rels if r not in ("left_of", "right_of")]
        if "ahead_of" not in rels:
            rels.append("ahead_of")
        shown_actions = [a for a in shown_actions if a in ("merge", "cut_in", "accelerate", "brake")]
        if "cut_in" not in shown_actions:
            shown_actions.append("merge")
    elif actor.role == "oncoming":
        dist = s.param(f"{n}_distance", "Range(85, 115)" if actor.has("drift") else "Range(40, 90)")
        speed_expr = s.param(f"{n}_speed", "Range(9, 13)")
        position = f"oncomingLane.centerline.pointAlongBy(-(egoS + {dist}))"
        if actor.has("drift") and actor.has("collide"):
            # it drifts a whole lane over and stays there: the head-on collision the text describes
            s.use("DriftAndReturn")
            behavior = (f"DriftAndReturn({speed_expr}, Range(45, 60), Range(3.3, 3.7), Range(1.5, 2.2), "
                        "-1, Range(1.2, 2.0))")
        elif actor.has("drift"):
            s.use("DriftAndReturn")
            behavior = (f"DriftAndReturn({speed_expr}, Range(55, 75), Range(2.3, 3.2), Range(1.5, 2.5), "
                        f"Range(22, 32), Range(1.2, 2.0))")
        else:
            behavior = _longitudinal_behavior(s, actor, speed_expr)
        if "oncoming" not in rels:
            rels.append("oncoming")
    elif actor.role == "cutter":
        side = actor.side
        lane = lane_of(side)
        if actor.kind == "truck" and not actor.has("accelerate") and "behind" not in rels:
            gap = s.param(f"{n}_gap", "Range(45, 65)")
            speed_expr = s.param(f"{n}_speed", "Range(14, 18)")
            trigger = s.param(f"{n}_trigger", "Range(22, 32)" if actor.sudden else "Range(30, 42)")
            position = f"{lane}.centerline.pointAlongBy(egoS + {gap})"
            s.use("PullInWhenClose")
            behavior = f"PullInWhenClose({-side}, {speed_expr}, {trigger}, Range(2.8, 4.0))"
        else:
            behind = "behind" in rels or actor.has("overtake")
            start = s.param(f"{n}_start", "Range(-14, -8)" if behind else
                            "Range(-3, 0)" if actor.has("collide") else "Range(7, 11)")
            hits = actor.has("collide")  # it cuts in beside the ego's front and makes contact
            extra = s.param(f"{n}_extra_speed", "Range(1, 2)" if hits else "Range(4, 7)")
            gap = s.param(f"{n}_cut_gap", "Range(0, 1.5)" if hits else "Range(5, 9)" if actor.sudden
                          else "Range(10, 15)")
            dur = s.param(f"{n}_change_duration", "Range(1.3, 2.0)" if actor.sudden else "Range(2.0, 2.8)")
            after = (f"{ego_speed} - Range(3, 6)" if actor.has("brake") or actor.has("stop")
                     else f"{ego_speed} + Range(-1, 2)")
            speed_expr = f"{ego_speed} + {extra}"
            position = f"{lane}.centerline.pointAlongBy(egoS + {start})"
            s.use("CutInWhenAhead")
            behavior = f"CutInWhenAhead({-side}, {speed_expr}, {gap}, {dur}, {after})"
            if not behind and "ahead_of" not in rels:
                rels.append("ahead_of")
        # it changes lanes toward the ego (from the left: to the right)
        shown_actions = [a for a in shown_actions if a not in ("lane_change_left", "lane_change_right")]
        shown_actions.append("lane_change_right" if actor.side > 0 else "lane_change_left")
        if "cut_in" not in shown_actions:
            shown_actions.append("cut_in")
    elif actor.role == "overtaker":
        start = s.param(f"{n}_start", "Range(-42, -32)")
        extra = s.param(f"{n}_extra_speed", "Range(5, 8)")
        ret = s.param(f"{n}_return_gap", "Range(3, 6)" if actor.sudden else "Range(6, 11)")
        speed_expr = f"{ego_speed} + {extra}"
        after = f"{ego_speed} - Range(3, 6)" if actor.has("brake") else f"{ego_speed} + Range(0, 2)"
        lane = "egoLane"
        position = f"{lane}.centerline.pointAlongBy(egoS + {start})"
        s.use("OvertakeAndReturn")
        behavior = f"OvertakeAndReturn(ego, {actor.side}, {speed_expr}, Range(22, 28), {ret}, Range(1.8, 2.4), {after})"
        rels = [r for r in rels if r != "ahead_of"] + (["behind"] if "behind" not in rels else [])
        if "same_lane" not in rels:
            rels.append("same_lane")
    else:
        # lead / follower / adjacent / slow_lead
        k = actor.side if actor.role == "adjacent" else 0
        lane = lane_of(k)
        ahead = "ahead_of" in rels
        behind = "behind" in rels
        if actor.role == "follower":
            gap = s.param(f"{n}_gap", "-Range(14, 22)" if actor.has("collide") else "-Range(15, 30)")
        elif actor.role == "slow_lead":
            gap = s.param(f"{n}_gap", "Range(30, 45)" if not urban else "Range(25, 35)")
            speed_expr = f"{ego_speed} - " + s.param(f"{n}_speed_deficit", "Range(6, 9)" if not urban else "Range(4, 6)")
        elif actor.role == "adjacent":
            changing = actor.has("lane_change_left") or actor.has("lane_change_right")
            # side by side, unless it changes lanes: then a little ahead, so the two never collide
            gap = s.param(f"{n}_offset", "Range(12, 28)" if ahead else "-Range(12, 28)" if behind
                          else ("Range(0, 2.5)" if actor.has("collide") else "Range(9, 14)") if changing
                          else "Range(6, 10)" if actor.has("swerve") and not actor.has("collide")
                          else "Range(8, 14)" if actor.has("drift") and not actor.has("collide")
                          else "Range(-4, 4)")
        elif actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
            gap = s.param(f"{n}_gap", "Range(30, 50)" if urban else "Range(55, 90)")
        elif actor.has("brake") or actor.has("stop") or actor.has("collide"):
            gap = s.param(f"{n}_gap", ("Range(12, 20)" if urban else "Range(15, 26)") if actor.sudden
                          or actor.has("collide") else ("Range(15, 25)" if urban else "Range(20, 35)"))
        elif actor.has("accelerate"):
            gap = s.param(f"{n}_gap", "Range(10, 20)")
        else:
            gap = s.param(f"{n}_gap", "Range(18, 30)" if urban else "Range(22, 40)")
        slot = used.get(k, 0)
        used[k] = slot + actor.count
        position = f"{lane}.centerline.pointAlongBy(egoS + {gap})"
        parked_ego = two_way and (ego.has("pull_out") or ego.has("reverse")) and ego.has("collide")
        if actor.role == "follower" and actor.has("collide") and parked_ego:
            # it comes along the lane past the parked ego, which pulls out into its side
            if actor.kind not in _KIND_SPEEDS:
                speed_expr = s.param(f"{n}_speed", "Range(6, 8)")
            position = f"{lane}.centerline.pointAlongBy(egoS - " + s.param(f"{n}_distance", "Range(28, 36)") + ")"
            s.use("Cruise")
            behavior = f"Cruise({speed_expr})"
        elif actor.role == "follower" and actor.has("collide"):
            speed_expr = f"{ego_speed} + " + s.param(f"{n}_extra_speed", "Range(5, 8)")
            s.use("Cruise")
            behavior = f"Cruise({speed_expr})"
        elif actor.role == "lead" and actor.has("overtake") and actor.details.get("overtake", {}).get("around") \
                and obstacles:
            side = 1
            s.use("OvertakeAndReturn")
            gap_expr = s.param(f"{n}_gap", "Range(10, 16)")
            position = f"egoLane.centerline.pointAlongBy(egoS + {gap_expr})"
            behavior = (f"OvertakeAndReturn({obstacles[0]}, {side}, {ego_speed}, Range(12, 16), Range(5, 9), "
                        f"Range(1.6, 2.2), {ego_speed})")
        elif actor.has("overtake") and actor.details.get("overtake", {}).get("around"):
            s.warnings.append(f"the {actor.kind} goes around something that was not placed: the manoeuvre is "
                              "not placed")
            shown_actions.remove("overtake")
            behavior = _longitudinal_behavior(s, actor, speed_expr)
        else:
            behavior = _longitudinal_behavior(s, actor, speed_expr)
        if actor.role == "lead" and not ahead:
            rels.append("ahead_of")
        if actor.role == "follower" and not behind:
            rels.append("behind")
        if actor.role == "adjacent":
            want = "left_of" if k > 0 else "right_of"
            if want not in rels:
                rels.append(want)
        if actor.role == "slow_lead" and "ahead_of" not in rels:
            rels.append("ahead_of")
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        pos = position
        if i:
            # further members of a group: the same manoeuvre, one vehicle length and a gap further on
            step = (18 if actor.kind == "truck" else 12) * i
            sign = "+" if actor.role in ("lead", "slow_lead") else "-"
            pos = re.sub(r"pointAlongBy\((.*)\)$", lambda m: f"pointAlongBy({m.group(1)} {sign} {step})", position)
        start_speed = "0" if behavior and behavior.startswith("HoldStill") else speed_expr
        if actor.has("accelerate") and behavior and not behavior.startswith(("SpeedUpLater", "MergeFromRamp")):
            start_speed = f"{speed_expr} - Range(5, 7)"  # it speeds up to its target speed
        lines += [f"{var} = new {cls} at {pos},",
                  f"    with speed {start_speed},",
                  f"    with behavior {behavior}"]
    s.spawn += lines
    s.show(actor.kind, list(shown_actions),
           [r for r in dict.fromkeys(rels)], actor.count)


def _spawn_puller(s: _Script, actor: ActorFrame, ego_speed: str, two_way: bool) -> None:
    """A vehicle parked at the kerb (shoulder) right of the ego's lane, ahead of the ego: once the ego is near
    it backs up (when it reverses) and steers into the lane ahead of the ego."""
    n = actor.name
    urban = s.frame.map not in HIGHWAY_MAPS  # town speeds and distances; parked at a kerb, not on a shoulder
    gap = s.param(f"{n}_gap", ("Range(54, 60)" if urban else "Range(100, 110)") if actor.has("collide") and
                  actor.has("reverse") else "Range(30, 42)" if urban else "Range(55, 75)")
    backing = actor.has("reverse")
    if actor.has("collide"):
        # it is still half in the lane when the ego gets there (backing out first takes about 2 s more)
        trigger = s.param(f"{n}_trigger", ("Range(47, 53)" if urban else "Range(85, 100)") if backing
                          else ("Range(20, 26)" if urban else "Range(40, 50)"))
    else:
        trigger = s.param(f"{n}_trigger", ("Range(20, 26)" if urban else "Range(40, 50)") if actor.sudden
                          else ("Range(26, 34)" if urban else "Range(50, 62)"))
    # (`right of` puts the vehicle's left side that far from the lane centre)
    kerb = _PARKING_KERB if s.frame.map == PARKING_STREET else "Range(1.4, 1.7)" if urban else "Range(1.8, 2.2)"
    speed = s.param(f"{n}_speed", "Range(6, 9)" if urban else "Range(12, 16)")
    back = "Range(2.5, 3.5)" if actor.has("reverse") else "0"
    s.use("PullOutWhenNear")
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        s.spawn += _at_kerb(var, _CLASS[actor.kind], f"egoS + {gap} + {12 * i}", kerb,
                            f"PullOutWhenNear(egoLane.centerline, -{kerb}, {speed}, {trigger}, {back}, Range(2.2, 3.0))")
    shown = [a for a in actor.actions if a in ("pull_out", "reverse", "collide")]
    if "pull_out" not in shown:
        shown.append("pull_out")
    rels = ["ahead_of", "right_of"] + [r for r in actor.relations if r == "crossing_path"]
    s.show(actor.kind, shown, rels, actor.count)


def _longitudinal_behavior(s: _Script, actor: ActorFrame, speed: str) -> str:
    """Behaviour of a vehicle that stays in its lane: brake, stop, accelerate, change lanes or cruise."""
    if actor.has("u_turn"):
        return _u_turn(s, speed)
    if actor.has("swerve"):
        return _swerve(s, speed, actor)
    if actor.has("drift"):
        # a vehicle beside the ego drifts toward the ego's lane; one in the ego's lane to the side the text says
        side = "left" if actor.side < 0 else "right" if actor.side > 0 else \
            actor.details.get("drift", {}).get("side") or "right"
        return _drift(s, speed, side, hold=None if actor.has("collide") else "Range(2.0, 3.0)")
    if actor.has("lane_change_left") or actor.has("lane_change_right"):
        side = 1 if actor.has("lane_change_left") else -1
        after = s.param(f"{actor.name}_change_after", "Range(0.5, 1.5)" if actor.sudden else "Range(1.0, 2.5)")
        dur = s.param(f"{actor.name}_change_duration", "Range(1.5, 2.2)" if actor.sudden else "Range(2.2, 3.2)")
        s.use("ChangeLanesLater")
        return f"ChangeLanesLater({side}, {speed}, {after}, {dur})"
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        s.use("HoldStill")
        return "HoldStill()"
    if actor.has("brake") or actor.has("stop") or (actor.has("collide") and actor.role == "lead"):
        after, low, strength = _brake_params(s, actor)
        s.use("BrakeLater")
        return f"BrakeLater({speed}, {after}, {low}, {strength})"
    if actor.has("accelerate"):
        s.use("SpeedUpLater")
        return f"SpeedUpLater({speed}, Range(0.8, 1.8), {speed} + Range(5, 8))"
    s.use("Cruise")
    return f"Cruise({speed})"


def _directions(actor: ActorFrame, rng: random.Random) -> List[str]:
    """One crossing direction per pedestrian of the group."""
    out: List[str] = []
    explicit = [(d, n) for d, n in actor.cross_dirs if d in ("left_to_right", "right_to_left")]
    unsized = [d for d, n in explicit if not n]
    for d, n in explicit:
        out += [d] * n
    remaining = actor.count - len(out)
    if remaining > 0 and unsized:
        # directions without sizes: the first one for one pedestrian, the last one for the rest
        if len(unsized) > 1:
            out.append(unsized[0])
            remaining -= 1
        out += [unsized[-1]] * max(0, remaining)
    elif remaining > 0:
        # no direction said: from the side the text puts the pedestrian (or what it steps out from behind) on
        sides = list(actor.relations)
        hidden = actor.details.get("cross", {}).get("from_behind")
        if hidden is not None:
            sides += [r for r, other in getattr(hidden, "relations", []) if getattr(other, "kind", "") == "ego"]
        said = "right_to_left" if "right_of" in sides else "left_to_right" if "left_of" in sides else None
        default = out[-1] if out else said or rng.choice(["right_to_left", "left_to_right"])
        out += [default] * remaining
    return out[:actor.count]


def _spawn_lane_pedestrians(s: _Script, actor: ActorFrame, ego_speed: str, two_way: bool, reckless: bool) -> None:
    n = actor.name
    crossing = actor.role == "crosser"
    hit_any = actor.has("collide") or reckless and s.frame.ego.has("collide")
    dist = s.param(f"{n}_distance", "Range(55, 65)" if hit_any and crossing else "Range(30, 42)")
    parked = next((a for a in s.frame.actors if a.role == "far_side"), None)
    if crossing and parked is not None:
        # a parked vehicle on the far kerb: the pedestrian steps out just in front of it, not through it
        dist = s.param(f"{parked.name}_gap", "Range(25, 40)") + " + Range(6.5, 8.0)"
    riding = actor.kind == "bicycle"
    if crossing and riding:
        walk = s.param(f"{n}_riding_speed", "Range(4, 5.5)")
        hit = actor.has("collide") or reckless and s.frame.ego.has("collide")
        trigger = s.param(f"{n}_trigger_time", "Range(1.6, 2.0)" if hit else "Range(2.2, 2.8)")
        s.use("RideAcrossWhenEgoNear")
    elif crossing:
        walk = s.param(f"{n}_walking_speed", "Range(1.7, 2.3)" if actor.sudden else "Range(1.2, 1.8)")
        hit = actor.has("collide") or reckless and s.frame.ego.has("collide")
        trigger = s.param(f"{n}_trigger_time",
                          "Range(1.9, 2.3)" if hit else
                          "Range(2.4, 3.0)" if actor.sudden else "Range(3.2, 4.2)")
        s.use("CrossWhenEgoNear")
    else:
        s.use("StandStill")
    dirs = _directions(actor, s.rng) if crossing else ["right_to_left"] * actor.count
    if two_way:
        # (a pedestrian who gets hit starts further out, so the crossing shows before the impact)
        right = "Range(2.8, 3.3)" if hit_any else "Range(2.0, 2.7)"
        left = "Range(5.5, 6.2)"
    else:
        s.helpers.append("laneSides")
        right = "1.75 + 3.5 * laneTuple[5] + Range(0.4, 1.0)"
        # (on the multi-lane street the far kerb is beyond the oncoming lanes too)
        far = f"(laneTuple[6] + {STREET_LANES})" if s.frame.map == MULTILANE_STREET else "laneTuple[6]"
        left = f"1.75 + 3.5 * {far} + Range(0.4, 1.0)"
    for i, d in enumerate(dirs):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        shift = ["0", "Range(1.2, 2.2)", "-Range(1.2, 2.2)", "Range(3.0, 4.0)"][i % 4]
        s.spawn.append(f"{var}Spot = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + {dist} + {shift}), "
                       "facing roadDirection")
        if d == "left_to_right":
            place, facing = f"left of {var}Spot by {left}", f"{var}Spot.heading - 90 deg"
        else:
            place, facing = f"right of {var}Spot by {right}", f"{var}Spot.heading + 90 deg"
        behavior = "StandStill()"  # a pedestrian who does not cross stands where placed
        if crossing:
            jitter = "" if i == 0 else " + Range(-0.4, 0.4)"
            if d == "left_to_right":
                jitter += " + Range(1.2, 1.8)"  # the far side is a lane further away: start earlier
            when = f"{trigger}{jitter}"
            if hit_any and not riding:
                # step out so as to reach the middle of the ego's lane when the ego gets there
                when = f"{'3.3' if d != 'left_to_right' else '6.0'} / {walk} + Range(-0.2, 0.2)"
            behavior = f"{'RideAcrossWhenEgoNear' if riding else 'CrossWhenEgoNear'}({walk}, {when})"
        # (on the parking street a pedestrian at the near or far kerb stands between the parked cars, on the
        # parking lane, which is not walkable region)
        contained = "" if two_way and not riding and s.frame.map != PARKING_STREET else \
            ",\n    with regionContainedIn everywhere"
        s.spawn += [f"{var} = new {_CLASS[actor.kind]} {place},", f"    facing {facing}{contained},"] + \
            (["    with speed 0,"] if riding else []) + [f"    with behavior {behavior}"]
    rels = ["ahead_of"] + [r for r in actor.relations if r in ("crossing_path",)]
    shown = [a for a in actor.actions if a in ("cross", "collide")]
    if not crossing and actor.has("stop"):
        shown.append("stop")
    s.show(actor.kind, shown, rels if ("ahead_of" in actor.relations or crossing) else
           [r for r in actor.relations if r == "ahead_of"], actor.count)


# --------------------------------------------------------------------------- junction maps

_JUNCTION_ACTIONS = {"brake", "stop", "accelerate", "turn_left", "turn_right", "go_straight", "cross", "collide",
                     "keep_lane", "cut_in", "merge"}
_TYPE = {"turn_left": "LEFT_TURN", "turn_right": "RIGHT_TURN", "go_straight": "STRAIGHT"}


class _Maneuvers:
    """The shipped junction map's maneuvers, to check which combinations exist before writing them."""

    _cache: Dict[str, Any] = {}

    def __init__(self, map_name: str) -> None:
        if map_name not in self._cache:
            from scenario_bank.map_cache import load_network
            from scenario_bank.maps import resolve_map

            self._cache[map_name] = load_network(resolve_map(map_name))
        self.network = self._cache[map_name]
        self.maneuvers = [m for j in self.network.intersections for m in j.maneuvers]

    @staticmethod
    def direction(lane):
        d = lane.centerline[-1] - lane.centerline[-2]
        return d.x, d.y, (d.x ** 2 + d.y ** 2) ** 0.5

    def side(self, a, b) -> float:
        ax, ay, an = self.direction(a)
        bx, by, bn = self.direction(b)
        return (ax * by - ay * bx) / max(1e-6, an * bn)

    def opposite(self, a, b) -> bool:
        ax, ay, an = self.direction(a)
        bx, by, bn = self.direction(b)
        return ax * bx + ay * by < -0.7 * an * bn


# role -> (python predicate(e, m, net), scenic condition text with e/m names)
def _role_condition(role: str, mtype: Optional[str]) -> Tuple[Callable, str]:
    type_py = (lambda m: True) if mtype is None else (lambda m, t=mtype: m.type.name == t)
    type_sc = "" if mtype is None else f"m.type is ManeuverType.{mtype}"
    if role == "oncoming":
        py = lambda e, m, net: net.opposite(e.startLane, m.startLane)
        sc = "opposite(e.startLane, m.startLane)"
    elif role == "from_left":
        py = lambda e, m, net: net.side(e.startLane, m.startLane) < -0.7
        sc = "sideOf(e.startLane, m.startLane) < -0.7 * approachDir(e.startLane).norm() * approachDir(m.startLane).norm()"
    elif role == "from_right":
        py = lambda e, m, net: net.side(e.startLane, m.startLane) > 0.7
        sc = "sideOf(e.startLane, m.startLane) > 0.7 * approachDir(e.startLane).norm() * approachDir(m.startLane).norm()"
    elif role == "crossing":
        py = lambda e, m, net: m in e.conflictingManeuvers and abs(net.side(e.startLane, m.startLane)) > 0.7
        sc = ("m in e.conflictingManeuvers and abs(sideOf(e.startLane, m.startLane)) > 0.7 * "
              "approachDir(e.startLane).norm() * approachDir(m.startLane).norm()")
    elif role == "into_path":
        py = lambda e, m, net: m.endLane is e.endLane and m.startLane is not e.startLane
        sc = "m.endLane is e.endLane and m.startLane is not e.startLane"
    elif role == "ring_cut":  # on a roundabout: circulating from the left toward the ego's exit, ahead of it
        py = lambda e, m, net: net.side(e.startLane, m.startLane) < -0.7 and m.endLane is e.endLane
        sc = ("sideOf(e.startLane, m.startLane) < -0.7 * approachDir(e.startLane).norm() * "
              "approachDir(m.startLane).norm() and m.endLane is e.endLane")
    elif role in ("ahead", "behind"):
        py = lambda e, m, net: m.startLane is e.startLane
        sc = "m.startLane is e.startLane"
    else:  # any other approach
        py = lambda e, m, net: m.startLane is not e.startLane
        sc = "m.startLane is not e.startLane"
    full_py = lambda e, m, net, p=py, t=type_py: p(e, m, net) and t(m)
    full_sc = sc + (f" and {type_sc}" if type_sc else "")
    return full_py, full_sc


def _junction_role(actor: ActorFrame, ego: ActorFrame, rng: random.Random) -> Tuple[str, Optional[str]]:
    rels = set(actor.relations)
    mtype = next((_TYPE[a] for a in ("turn_left", "turn_right", "go_straight") if actor.has(a)), None)
    if (actor.has("cross") or "crossing_path" in rels and not ego.has("turn_left")) and mtype is None:
        mtype = "STRAIGHT"  # across the ego's path
    if actor.has("cut_in") or actor.has("merge"):
        return "into_path", mtype
    if "oncoming" in rels:
        return "oncoming", mtype or "STRAIGHT"
    if "same_lane" not in rels and ("left_of" in rels or "right_of" in rels):
        side = "from_left" if "left_of" in rels else "from_right"
        if (side, mtype) in (("from_right", "RIGHT_TURN"), ("from_left", "LEFT_TURN")) and not ego.has("turn_left") \
                and not ego.has("turn_right"):
            return "into_path", mtype  # it turns into the lane the ego drives on in
        return side, mtype
    if "ahead_of" in rels or "same_lane" in rels:
        return "ahead", mtype
    if "behind" in rels:
        return "behind", mtype
    if "crossing_path" in rels or actor.has("cross"):
        return "crossing", mtype or "STRAIGHT"
    if mtype == "LEFT_TURN" and not ego.has("turn_left"):
        return "oncoming", mtype
    if mtype == "RIGHT_TURN" and not ego.has("turn_right"):
        return "into_path", mtype
    if mtype == "STRAIGHT" and ego.has("turn_left"):
        return "oncoming", mtype
    if mtype == "STRAIGHT":
        return "crossing", mtype
    if actor.has("brake") or actor.has("stop") or actor.has("keep_lane") or actor.has("accelerate") \
            or not actor.actions:
        return "ahead", mtype
    return "any", mtype


def _compose_junction(s: _Script) -> None:
    frame = s.frame
    ego = frame.ego
    net = _Maneuvers(frame.map)
    _check_actions(ego, s, _JUNCTION_ACTIONS - {"cross", "cut_in", "merge"})
    reckless = ego.has("collide") or any(a.has("collide") for a in frame.actors)
    lo, hi = _speed_ranges(frame.map)
    ego_speed = s.param("ego_speed", f"Range({lo}, {hi})")
    ego_type = next((_TYPE[a] for a in ("turn_left", "turn_right", "go_straight") if ego.has(a)), None)
    vehicles = [a for a in frame.actors if a.kind in VEHICLES]
    for a in frame.actors:
        if a.kind in VEHICLES:
            _check_actions(a, s, _JUNCTION_ACTIONS)
        elif a.kind == "pedestrian":
            _check_actions(a, s, {"cross", "stop", "collide"})
        else:
            a.actions = []
    roles: List[Tuple[ActorFrame, str, Optional[str]]] = [(a,) + _junction_role(a, ego, s.rng) for a in vehicles]
    ring = frame.map == RING_MAP
    if ring:
        # a vehicle coming from the left on a roundabout circulates past the ego's entry (not out at its arm)
        roles = [(a, r, "STRAIGHT" if r == "from_left" and t is None else t) for a, r, t in roles]
        # one already on the ring on the ego's left that cuts in: it passes the ego's entry just ahead of it
        roles = [(a, "ring_cut", None) if r == "into_path" and "left_of" in a.relations else (a, r, t)
                 for a, r, t in roles]

    def feasible(ego_t: Optional[str], specs: List[Tuple[ActorFrame, str, Optional[str]]]) -> bool:
        conds = [_role_condition(r, t)[0] for _, r, t in specs]
        for e in net.maneuvers:
            if ego_t is not None and e.type.name != ego_t:
                continue
            if all(any(c(e, m, net) for m in net.maneuvers) for c in conds):
                return True
        return False

    default_ego = ego_type
    if ego_type is None:
        default_ego = "STRAIGHT" if feasible("STRAIGHT", roles) else None
    if not feasible(default_ego, roles):
        relaxed = []
        for actor, role, mtype in roles:
            if not feasible(default_ego, [(actor, role, mtype)]):
                if mtype is not None and feasible(default_ego, [(actor, role, None)]):
                    s.warnings.append(f"no '{mtype.lower().replace('_', ' ')}' for a {actor.kind} coming "
                                      f"{role.replace('_', ' ')} exists on {frame.map}: its manoeuvre is not placed")
                    actor.actions = [x for x in actor.actions if _TYPE.get(x) != mtype]
                    mtype = None
                elif feasible(default_ego, [(actor, "any", mtype)]):
                    s.warnings.append(f"a {actor.kind} coming {role.replace('_', ' ')} cannot be placed on "
                                      f"{frame.map} with that manoeuvre: it comes from another approach")
                    actor.relations = [r for r in actor.relations if r not in ("oncoming", "left_of", "right_of")]
                    role = "any"
                else:
                    s.warnings.append(f"a {actor.kind} with '{', '.join(actor.actions)}' cannot be placed on "
                                      f"{frame.map}: it comes from another approach and drives straight or turns")
                    role, mtype = "any", None
            relaxed.append((actor, role, mtype))
        roles = relaxed
        if not feasible(default_ego, roles):
            s.warnings.append("the described manoeuvres do not fit together on this junction: the other vehicles "
                              "come from any approach")
            roles = [(a, "any", None) for a, _, _ in roles]
        if not feasible(default_ego, roles):
            if ego_type:
                s.warnings.append(f"the ego's {ego_type.lower().replace('_', ' ')} cannot be placed on {frame.map}")
                ego.actions = [x for x in ego.actions if _TYPE.get(x) != ego_type]
            default_ego = None

    # ---------------------------------------------------------------- geometry
    s.helpers.append("approach")
    ego_cond = f"e.type is ManeuverType.{default_ego}" if default_ego else "True"
    comp = [f"combos = [(e,{''.join(' m' + str(i) + ',' for i in range(len(roles)))})",
            "          for junction in network.intersections for e in junction.maneuvers",
            f"          if {ego_cond}"]
    for i, (actor, role, mtype) in enumerate(roles):
        cond = _role_condition(role, mtype)[1].replace("m.", f"m{i}.").replace("(m.", f"(m{i}.")
        cond = re.sub(r"\bm\b", f"m{i}", cond)
        comp.append(f"          for m{i} in junction.maneuvers if {cond}")
    comp[-1] += "]"
    title = {"urban_crossroads": "a four-way junction of two-way urban streets",
             "urban_t_junction": "a T-junction of two-way urban streets",
             "urban_roundabout": "a single-lane roundabout with four two-way arms (first exit right, second "
                                 "straight on, third left)"}[frame.map]
    s.geometry_title = title + (f"; the ego {default_ego.lower().replace('_', ' ')}" if default_ego else "")
    s.geometry += comp + ["combo = Uniform(*combos)", "egoManeuver = combo[0]",
                          "egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]",
                          "egoEntry = egoManeuver.startLane.centerline.end"]
    extra_ahead = 12 * max([a.count - 1 for a, r, _ in roles if r == "ahead"], default=0)
    timed = [(a, r) for a, r, _ in roles if r not in ("ahead", "behind", "into_path")]
    lead_first = bool(timed) and not any(a.has("collide") for a, _ in timed)
    # the ego stops at the junction (for a crossing vehicle, at a stop sign) and then goes on: it waits at the
    # entry until the vehicle it yields to has cleared the junction
    # (not on the roundabout: its circulating traffic is timed against the ego's own approach)
    yields = ego.has("stop") and not reckless and not extra_ahead and not any(r == "ahead" for _, r, _ in roles) \
        and (bool(timed) or default_ego is not None and ego_type is not None) and frame.map != RING_MAP
    # ... or it stops, misjudges the gap and goes just before the vehicle it collides with gets there
    hitters = [a for a, _ in timed if a.has("collide")]
    misjudges = ego.has("stop") and ego.has("collide") and bool(hitters) and not extra_ahead \
        and not any(r == "ahead" for _, r, _ in roles) and frame.map != RING_MAP
    conflict = _conflict_actor(ego, [a for a, _ in timed]) if yields else \
        _conflict_actor(ego, hitters) if misjudges else None
    if misjudges:
        ego_dist = s.param("ego_distance", "Range(10, 14)")
        ego_time = f"{ego_dist} / {ego_speed}"
    elif yields and lead_first:
        # close to the junction: it stops there while the other vehicle (which gets there first) crosses
        first = s.param("first_arrival", "Range(0.3, 0.8)")
        ego_dist = s.param("ego_distance", "Range(12, 16)")
        ego_time = f"{ego_dist} / {ego_speed}"
    elif lead_first:
        # the crossing/oncoming vehicles reach the junction first (the last one `ego_gap_time` s
        # before the ego): the ego's distance follows from those times
        spread = 1.6 * max(a.count - 1 for a, _ in timed)
        first = s.param("first_arrival", "Range(0.8, 1.6)")
        gap_time = s.param("ego_gap_time", "Range(2.0, 2.8)")
        s.geometry.append(f"egoTime = {first} + {spread:.1f} + {gap_time}")
        s.geometry.append(f"egoDistance = {ego_speed} * egoTime" + (f" + {extra_ahead}" if extra_ahead else ""))
        ego_dist = "egoDistance"
        ego_time = "egoTime"
    else:
        ego_dist = s.param("ego_distance", f"Range({22 + extra_ahead}, {34 + extra_ahead})")
        ego_time = f"{ego_dist} / {ego_speed}"
    for i, (actor, role, mtype) in enumerate(roles):
        s.geometry += [f"{actor.name}Maneuver = combo[{i + 1}]",
                       f"{actor.name}Route = [{actor.name}Maneuver.startLane, {actor.name}Maneuver.connectingLane, "
                       f"{actor.name}Maneuver.endLane]"]

    # ---------------------------------------------------------------- ego
    if misjudges and conflict is not None:
        s.use("StopThenGoInto")
        var = conflict.name if conflict.count == 1 else f"{conflict.name}_1"
        # a left turn meets the other vehicle in the far half of the junction: it goes earlier
        go_time = "Range(3.2, 3.6)" if default_ego == "LEFT_TURN" else "Range(2.6, 3.0)"
        ego_behavior = (f"StopThenGoInto({ego_speed}, egoRoute, egoEntry, {var}, "
                        f"{conflict.name}Maneuver.startLane.centerline.end, {go_time}, Range(0.6, 1.0))")
        if default_ego is not None and not any(_TYPE.get(a) == default_ego for a in ego.actions):
            ego.actions.append({v: k for k, v in _TYPE.items()}[default_ego])
    elif yields:
        s.use("StopForConflict")
        other, exit_lane = "None", "None"
        if conflict is not None:
            var = conflict.name if conflict.count == 1 else f"{conflict.name}_{conflict.count}"
            other, exit_lane = var, f"{conflict.name}Maneuver.endLane"
        ego_behavior = (f"StopForConflict({ego_speed}, egoRoute, egoEntry, {other}, {exit_lane}, Range(0.6, 1.0), "
                        "Range(4, 5))")
        if default_ego is not None and not any(_TYPE.get(a) == default_ego for a in ego.actions):
            # it goes on through the junction after the stop: straight unless the text says a turn
            ego.actions.append({v: k for k, v in _TYPE.items()}[default_ego])
    elif ego.has("brake") or ego.has("stop"):
        after, low, strength = _brake_params(s, ego)
        s.use("RouteThenBrake")
        ego_behavior = f"RouteThenBrake({ego_speed}, egoRoute, {after}, {low}, {strength})"
    else:
        name = "DriveRoute" if reckless else "CautiousRoute"
        s.use(name)
        ego_behavior = f"{name}({ego_speed}, egoRoute)"
    ego_lines = [f"ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-{ego_dist}),",
                 f"    with speed {ego_speed},",
                 "    with route egoRoute,",
                 f"    with behavior {ego_behavior}"]
    if not (yields or misjudges):
        s.spawn += ego_lines
    s.show("ego", list(ego.actions))

    # ---------------------------------------------------------------- vehicles
    for actor, role, mtype in roles:
        n = actor.name
        cls = _CLASS[actor.kind]
        rels = list(actor.relations)
        route = f"{n}Route"
        circulating = ring and (role == "from_left" and mtype in ("STRAIGHT", "LEFT_TURN") or role == "ring_cut")
        if circulating:
            _spawn_circulating(s, actor, mtype, ego_speed, ego_time, lead_first and role != "ring_cut", reckless,
                               cuts_in=role == "ring_cut")
            continue
        speed = s.param(f"{n}_speed", "Range(7, 11)" if role != "ahead" else f"Range({lo}, {hi})")
        if role in ("ahead", "behind"):
            gap = s.param(f"{n}_gap", "Range(10, 16)")
            along = f"-({ego_dist} - {gap})" if role == "ahead" else f"-({ego_dist} + {gap})"
            behavior = _junction_longitudinal(s, actor, speed, route, reckless)
            want = "ahead_of" if role == "ahead" else "behind"
            if want not in rels:
                rels.append(want)
        elif role == "into_path":
            wait = s.param(f"{n}_wait_position", "Range(2, 5)")
            along = f"-{wait}"
            trigger = s.param(f"{n}_trigger_time", "Range(2.2, 3.2)" if actor.sudden else "Range(3.2, 4.5)")
            s.use("PullOutWhenEgoNear")
            behavior = f"PullOutWhenEgoNear({speed}, {route}, egoEntry, {trigger})"
            speed = "0"
        else:
            # it reaches the junction `offset` seconds after the ego would (negative: before it); a
            # group arrives one after the other, the last one still ahead of the ego
            if misjudges and actor is conflict:
                # it gets to the junction after the ego has stopped at it
                arrival = s.param(f"{n}_arrival", "Range(4.5, 5.5)")
            elif lead_first:
                arrival = f"{first} + Range(0, 0.4)"
            else:
                # (with a collision described, the ego reaches the junction in 2.4 s at least)
                offset = s.param(f"{n}_arrival_offset", "Range(-0.2, 0.2)" if actor.has("collide") else
                                 "Range(-1.9, -1.3)")
                arrival = f"{ego_time} + {offset}"
            along = f"-(1 + {speed} * ({arrival}))"
            behavior = _junction_longitudinal(s, actor, speed, route, reckless)
            if role == "oncoming" and "oncoming" not in rels:
                rels.append("oncoming")
        start_speed = "0" if behavior.startswith("HoldStill") else speed
        for i in range(actor.count):
            var = n if actor.count == 1 else f"{n}_{i + 1}"
            extra = "" if i == 0 else (f" + {12 * i}" if role == "ahead" else f" - {12 * i}")
            s.spawn += [f"{var} = new {cls} at {n}Maneuver.startLane.centerline.pointAlongBy({along}{extra}),",
                        f"    with speed {start_speed},",
                        f"    with behavior {behavior}"]
        acts = list(actor.actions)
        if mtype and not any(_TYPE.get(a) == mtype for a in acts):
            acts.append({v: k for k, v in _TYPE.items()}[mtype])
        if role == "into_path" and actor.has("merge") and "ahead_of" not in rels:
            rels.append("ahead_of")  # it joins the ego's road in front of the ego
        s.show(actor.kind, acts, list(dict.fromkeys(rels)), actor.count)

    if yields or misjudges:
        s.spawn += ego_lines  # after the vehicle it waits for, which its behaviour names
    # ---------------------------------------------------------------- pedestrians and obstacles
    for actor in frame.actors:
        if actor.kind == "pedestrian":
            _spawn_junction_pedestrians(s, actor, frame.map, reckless)
        elif actor.kind == "obstacle":
            gap = s.param(f"{actor.name}_gap", "Range(10, 20)")
            for i in range(actor.count):
                var = actor.name if actor.count == 1 else f"{actor.name}_{i + 1}"
                s.spawn += [f"{var} = new Obstacle at egoManeuver.endLane.centerline.pointAlongBy({gap} + {3 * i}),",
                            "    with width Range(0.8, 1.8), with length Range(0.6, 1.4)"]
            s.show("obstacle", [], ["ahead_of"], actor.count)


def _conflict_actor(ego: ActorFrame, candidates: Sequence[ActorFrame]) -> Optional[ActorFrame]:
    """The vehicle the ego's stop waits for: the one its stop's trigger names (by kind), else the first
    vehicle crossing or meeting it at the junction."""
    trigger = ego.details.get("stop", {}).get("trigger") or {}
    other = trigger.get("with") if isinstance(trigger, dict) else None
    kind = getattr(other, "kind", None)
    return next((a for a in candidates if a.kind == kind), candidates[0] if candidates else None)


def _spawn_circulating(s: _Script, actor: ActorFrame, mtype: Optional[str], ego_speed: str, ego_time: str,
                       lead_first: bool, reckless: bool, cuts_in: bool = False) -> None:
    """A vehicle already on the roundabout's ring, coming from the ego's left: it starts just after its own entry
    and drives at the speed that brings it past the ego's entry (a quarter ring on) when the text says: 0.9-1.4 s
    ahead of the ego when it goes first (the ego, still on its approach, sees it cross its way), with the ego
    (``arrival_offset`` of +-0.2 s) when they collide, 1.3-1.9 s ahead otherwise; one that cuts in, 0.6-1.0 s
    ahead (0.1-0.4 s when it hits the ego)."""
    n = actor.name
    start = s.param(f"{n}_ring_start", "Range(2, 6)")
    if lead_first:
        arrival = f"{ego_time} - " + s.param(f"{n}_ring_gap", "Range(0.9, 1.4)")
    else:
        offset = s.param(f"{n}_arrival_offset",
                         ("Range(-0.4, -0.1)" if cuts_in else "Range(-0.2, 0.2)") if actor.has("collide") else
                         "Range(-1.0, -0.6)" if cuts_in else "Range(-1.9, -1.3)")
        arrival = f"{ego_time} + {offset}"
    # the ego is at its entry `ego_time` after the start, and where the ring meets it RING_ENTRY metres later
    speed = f"({RING_ENTRY + RING_QUARTER:.1f} - {start}) / ({arrival} + {RING_ENTRY:.1f} / {ego_speed})"
    route = f"[{n}Maneuver.connectingLane, {n}Maneuver.endLane]"
    behavior = _junction_longitudinal(s, actor, speed, route, reckless)
    if behavior.startswith("CautiousRoute("):
        # it has the right of way on the ring: it does not stop for the ego that is about to enter
        s.use("DriveRoute")
        behavior = "DriveRoute(" + behavior[len("CautiousRoute("):]
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        ahead = f" + {12 * i}" if i else ""  # the rest of a group circulates ahead of it, past the entry sooner
        s.spawn += [f"{var} = new {_CLASS[actor.kind]} at {n}Maneuver.connectingLane.centerline.pointAlongBy("
                    f"{start}{ahead}),",
                    f"    with speed {'0' if behavior.startswith('HoldStill') else speed},",
                    f"    with behavior {behavior}"]
    acts = list(actor.actions)
    if mtype and not any(_TYPE.get(a) == mtype for a in acts):
        acts.append({v: k for k, v in _TYPE.items()}[mtype])
    s.show(actor.kind, acts, list(dict.fromkeys(actor.relations + (["ahead_of"] if cuts_in else []))), actor.count)


def _junction_longitudinal(s: _Script, actor: ActorFrame, speed: str, route: str, reckless: bool) -> str:
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        s.use("HoldStill")
        return "HoldStill()"
    if actor.has("brake") or actor.has("stop"):
        after, low, strength = _brake_params(s, actor)
        s.use("RouteThenBrake")
        return f"RouteThenBrake({speed}, {route}, {after}, {low}, {strength})"
    name = "DriveRoute" if actor.has("collide") else "CautiousRoute"
    s.use(name)
    return f"{name}({speed}, {route})"


def _spawn_junction_pedestrians(s: _Script, actor: ActorFrame, map_name: str, reckless: bool) -> None:
    n = actor.name
    crossing = actor.has("cross") or actor.has("collide")
    pos = s.param(f"{n}_crossing_position", "Range(3, 7)")
    if crossing:
        walk = s.param(f"{n}_walking_speed", "Range(1.8, 2.4)" if actor.sudden else "Range(1.5, 2.0)")
        trigger = s.param(f"{n}_trigger_time", "Range(1.5, 2.2)" if actor.has("collide") else
                          "Range(3.0, 3.6)" if actor.sudden else "Range(3.6, 4.6)")
        s.use("CrossWhenEgoNear")
    else:
        s.use("StandStill")
    dirs = _directions(actor, s.rng) if crossing else ["right_to_left"] * actor.count
    s.spawn.append(f"{n}Spot = new OrientedPoint at egoManeuver.endLane.centerline.pointAlongBy({pos}), "
                   "facing roadDirection")
    for i, d in enumerate(dirs):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        along = f" + Range(0.8, 1.6) * {i}" if i else ""
        spot = f"{n}Spot" if not i else f"{var}Spot"
        if i:
            s.spawn.append(f"{var}Spot = new OrientedPoint at egoManeuver.endLane.centerline.pointAlongBy("
                           f"{pos}{along}), facing roadDirection")
        if d == "left_to_right":
            place, facing = f"left of {spot} by Range(6.2, 6.9)", f"{spot}.heading - 90 deg"
        else:
            place, facing = f"right of {spot} by Range(2.0, 2.7)", f"{spot}.heading + 90 deg"
        behavior = "StandStill()"
        if crossing:
            # the members of a group step out a little apart, as on the straight roads
            jitter = "" if i == 0 else " + Range(-0.4, 0.4)"
            behavior = f"CrossWhenEgoNear({walk}, {trigger}{jitter})"
        s.spawn += [f"{var} = new Pedestrian {place},", f"    facing {facing},", f"    with behavior {behavior}"]
    s.show("pedestrian", [a for a in actor.actions if a in ("cross", "collide")], ["ahead_of"], actor.count)


# --------------------------------------------------------------------------- what was not built

def _typed_collisions(s: _Script) -> None:
    """The script means the collision type the text gives wherever it means the collision itself."""
    for actor in [s.frame.ego, *s.frame.actors]:
        kind = "ego" if actor.name == "ego" else actor.kind
        typed = actor.details.get("collide", {}).get("type")
        if typed and (kind, "collide") in s.actions:
            s.actions.add((kind, typed))


def _words(element: Tuple) -> str:
    return " ".join(str(x) for x in element[1:] if not isinstance(x, int)).replace("_", " ")


def unbuilt_warnings(parsed: ParsedDescription, s: "_Script", said: Sequence[str] = ()) -> List[str]:
    """One ``not built: <element> (<phrase>)`` warning per element of the parsed description that the
    composed script does not mean to show (its :attr:`_Script.actions`, relations and participants), unless a
    warning in ``said`` already names it. The phrase is the text the parser read the element from (the actor's
    noun when it has none)."""
    from scenario_bank.elements import element_set, with_undirected

    meant = with_undirected(element_set({"road": MAP_ROADS.get(s.frame.map),
                                         "participants": s.participants,
                                         "actions": [list(a) for a in s.actions],
                                         "relations": [list(r) for r in s.relations]}))
    said_text = " ".join(w.lower().replace("_", " ") for w in said)
    phrases: Dict[Tuple, str] = {}
    for entity in parsed.entities:
        noun = "ego" if entity.kind == "ego" else str(entity.attrs.get("noun", entity.kind))
        for action, detail in entity.actions:
            phrases.setdefault(("action", entity.kind, action), str(detail.get("phrase") or noun))
        for rel, other in entity.relations:
            phrases.setdefault(("relation", entity.kind, rel, other.kind), noun)
    out: List[str] = []
    described = set()
    for entity in parsed.entities:
        if entity.kind not in PARTICIPANTS:
            continue  # an unknown kind is warned about already
        described.update(("participant", entity.kind, i + 1) for i in range(entity.count if entity.kind != "ego" else 1))
        described.update(("action", entity.kind, a) for a, _ in entity.actions if a in ACTIONS)
        described.update(("relation", entity.kind, r, o.kind) for r, o in entity.relations
                         if o is not entity and o.kind in PARTICIPANTS and r in RELATIONS)
    if parsed.road in ROADS:
        described.add(("road", parsed.road))
    for element in sorted(described, key=str):
        if element in meant:
            continue
        if element[0] == "road":
            phrase = " ".join(parsed.road_words) or str(element[1])
            built = MAP_ROADS.get(s.frame.map, s.frame.map).replace("_", " ")
            out.append(f"not built: road {_words(element)} ('{phrase}'): the script uses map {s.frame.map} "
                       f"(road type {built})")
            continue
        elif element[0] == "participant":
            phrase = element[1]
        else:
            phrase = phrases.get(element, element[1])
        words = _words(element)
        if words in said_text or element[0] == "action" and f"{element[1]} {element[2].replace('_', ' ')}" in \
                said_text or element[0] == "action" and f"'{element[2].replace('_', ' ')}'" in said_text:
            continue
        out.append(f"not built: {element[0]} {words} ('{phrase}')")
    return out


def _absent_warnings(parsed: ParsedDescription) -> List[str]:
    """What the script did with the participants the text says are not there ("no other vehicles")."""
    if not parsed.absent:
        return []
    said = ", ".join(f"'{p}'" for p in getattr(parsed, "absent_phrases", []) or []) or "absent"
    kinds = list(dict.fromkeys(parsed.absent))
    present = sorted({e.kind for e in parsed.entities if e.kind in kinds})
    note = (f"read {said}: the script adds no background traffic, so no {', '.join(k for k in kinds if k not in present)}"
            " is placed")
    if present:
        note += f"; the text also describes a {' and a '.join(present)}, which is placed"
    return [note]


def unshown_warnings(meant: Dict[str, Any], simulated: Dict[str, Any]) -> List[str]:
    """One ``not shown in the simulated run: <element>`` warning per element the script was composed to show
    (``meant``, :attr:`SGResult.elements`) that a simulated run of it did not show (``simulated``, from
    :func:`dv2s_gym.pipeline.semantics.trace.elements_from_trace`)."""
    from scenario_bank.elements import element_set, with_undirected

    shown = with_undirected(element_set(simulated or {}))
    return [f"not shown in the simulated run: {e[0]} {_words(e)}"
            for e in sorted(element_set(meant or {}), key=str) if e not in shown]


# --------------------------------------------------------------------------- entry point

def generate_rules(description: str, seed: Optional[int] = None) -> SGResult:
    """Compose a Scenic script (four sections) for ``description``; deterministic given ``seed``."""
    if not isinstance(description, str) or not description.strip():
        raise ValueError("the description is empty: describe the road, the ego and what the other actors do")
    rng = random.Random(0 if seed is None else int(seed))
    parsed = parse_description(description)
    warnings: List[str] = []
    frame = build_frame(description, parsed, warnings)
    s = _Script(frame, rng)
    s.warnings = warnings
    if not parsed.entities and not parsed.road:
        warnings.append("nothing in the description could be recognised (road, ego, cars, trucks, pedestrians, "
                        "obstacles): the script only has the ego driving")
    if frame.map in JUNCTION_MAPS:
        _compose_junction(s)
    else:
        _compose_lanes(s)
    script = s.render()
    _check_main_event(parsed, s)
    _typed_collisions(s)
    warnings.extend(unbuilt_warnings(parsed, s, warnings))
    warnings.extend(_absent_warnings(parsed))
    road = MAP_ROADS.get(frame.map)
    elements = normalize_elements({
        "road": road if frame.road in (None, road) or frame.road == "three_way" and road == "t_junction" else road,
        "participants": s.participants,
        "actions": [list(a) for a in sorted(s.actions)],
        "relations": [list(r) for r in sorted(s.relations)],
    })
    if frame.road == "three_way":
        elements["road"] = "t_junction"
    return SGResult(script=script, frame=frame, warnings=list(dict.fromkeys(warnings)), elements=elements,
                    backend="rules", context_hash=blocks.context_hash())
