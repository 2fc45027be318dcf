"""From a parsed description to a :class:`~.frame.ScenarioFrame`: actors, directed actions, map and weather."""

from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Sequence

from dv2s_gym.pipeline.semantics.parsed import Entity, Lane, ParsedDescription
from dv2s_gym.pipeline.semantics.text import parse_description
from dv2s_gym.pipeline.sg.rules.frame import CLASS, VEHICLES, ActorFrame, ScenarioFrame
from dv2s_gym.pipeline.sg.rules.map_choice import choose_map
from dv2s_gym.pipeline.sg.rules.roads import PARKING_STREET
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = ["COLLISION_HINTS", "MAX_COUNT", "build_frame"]

MAX_COUNT = 4
"""The most actors of one group a script places."""

COLLISION_HINTS = {Action.COLLIDE_REAR_END: [str(Relation.AHEAD_OF), str(Relation.SAME_LANE)],
                   Action.COLLIDE_HEAD_ON: [str(Relation.ONCOMING)], Action.COLLIDE_SIDE: []}
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
        if action == Action.LANE_CHANGE:
            side = detail.get("side") or detail.get("target")
            if side not in (Lane.LEFT, Lane.RIGHT):
                side = "right" if Relation.LEFT_OF in actor.relations else "left"
            action = f"lane_change_{side}"
            actor.details.setdefault(action, dict(detail))
        elif action in COLLISION_HINTS:
            if actor.kind != ActorKind.EGO and not actor.relations:
                actor.relations.extend(COLLISION_HINTS[action])
            actor.details.setdefault(str(Action.COLLIDE), dict(detail))
            actor.details[Action.COLLIDE]["type"] = action
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
    for d in actor.details.get(Action.CROSS, {}).get("directions", []) or []:
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
        if entity.kind == ActorKind.EGO:
            continue
        if entity.kind not in CLASS:
            warnings.append(f"could not place the {entity.attrs.get('noun', entity.kind)}: no participant type "
                            f"'{entity.kind}' ({', '.join(sorted(CLASS))})")
            continue
        base = entity.kind
        names[base] = names.get(base, 0) + 1
        actor = _actor_from(entity, f"{base}{names[base]}")
        for rel, other in entity.relations:
            if other.kind == ActorKind.EGO:
                actor.relations.append(rel)
            else:
                warnings.append(f"relation '{entity.kind} {rel} {other.kind}' between two non-ego "
                                "actors is not placed (actors are placed relative to the ego)")
        for rel in entity.attrs.get("pending_relations", []):
            actor.relations.append(rel)
        _directed_actions(actor, warnings)
        if actor.count > MAX_COUNT:
            warnings.append(f"{actor.count} {actor.kind}s described; the script places {MAX_COUNT}")
            actor.count = MAX_COUNT
        actors.append(actor)
    for word in parsed.unknown_actors:
        warnings.append(f"could not place '{word}': no participant type for it (car, truck, pedestrian, obstacle)")
    for note in parsed.unresolved:
        warnings.append(f"could not resolve: {note}")
    for phrase in getattr(parsed, "unplaced", []) or []:
        warnings.append(f"could not place: '{phrase}'")
    road = parsed.road
    map_name = choose_map(road, ego, actors, warnings)
    if map_name == "urban_two_way" and at_the_kerb(ego, actors, getattr(parsed, "features", None) or {}):
        map_name = PARKING_STREET
    return ScenarioFrame(description=description, road=road, map=map_name, ego=ego, actors=actors,
                         ego_mentioned=ego_entity is not None, weather=_weather(description))


def at_the_kerb(ego: ActorFrame, actors: Sequence[ActorFrame], features: Dict[str, Any]) -> bool:
    """A vehicle pulls out of (or backs out of) a parking space, or the street is said to have parking: the
    street gets its parking lanes (:data:`PARKING_STREET`)."""
    if features.get("parking_lane"):
        return True
    return any(a.has("pull_out") or a.has("reverse") for a in [ego, *actors] if a is ego or a.kind in VEHICLES)
