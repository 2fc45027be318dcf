"""Which shipped map a described scenario is composed on (road type said, else inferred from what happens)."""

from __future__ import annotations

from typing import List, Optional, Sequence

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.frame import VEHICLES, ActorFrame
from dv2s_gym.pipeline.sg.rules.roads import MULTILANE_STREET, ROAD_MAPS
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = ["choose_map"]


def _needs_same_direction_lanes(ego: ActorFrame, actors: Sequence[ActorFrame]) -> bool:
    if ego.has("lane_change_left") or ego.has("lane_change_right") or ego.has("merge"):
        return True
    for a in actors:
        if a.kind not in VEHICLES:
            continue
        if a.has("cut_in") or a.has("lane_change_left") or a.has("lane_change_right"):
            return True
        static = not (set(a.actions) - {Action.STOP, Action.KEEP_LANE}) or a.has("pull_out") or a.has("reverse")
        if (Relation.LEFT_OF in a.relations or Relation.RIGHT_OF in a.relations) \
                and Relation.ONCOMING not in a.relations and not a.has("drift") and not static:
            return True
    return False


def _needs_three_lanes(ego: ActorFrame, actors: Sequence[ActorFrame]) -> bool:
    """The ego in a middle lane, or vehicles of its direction on both sides of it: more lanes than the
    multi-lane town street has per direction."""
    if ego.lane == Lane.MIDDLE:
        return True
    sides = set()
    for a in actors:
        if a.kind in VEHICLES and Relation.ONCOMING not in a.relations:
            sides.update(r for r in a.relations if r in (Relation.LEFT_OF, Relation.RIGHT_OF))
            if a.lane == Lane.ADJACENT and a.count >= 2:
                sides.update(("left_of", "right_of"))
    return len(sides) == 2


def choose_map(road: Optional[str], ego: ActorFrame, actors: Sequence[ActorFrame], warnings: List[str]) -> str:
    all_actions = set(ego.actions) | {x for a in actors for x in a.actions}
    turns = bool({Action.TURN_LEFT, Action.TURN_RIGHT} & set(ego.actions)) or any(
        a.kind in VEHICLES and ({Action.TURN_LEFT, Action.TURN_RIGHT} & set(a.actions)) for a in actors)
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
        if chosen == "highway_straight" and Action.MERGE in all_actions:
            warnings.append("a merge was described on a highway without an on-ramp: using the highway with an "
                            "on-ramp (highway_onramp)")
            return "highway_onramp"
        return chosen
    # no road type said: infer from what happens
    if turns or any(a.kind in VEHICLES and a.has("cross") for a in actors):
        return "urban_crossroads"  # a vehicle crossing the ego's path comes from a crossing road
    if Action.MERGE in all_actions:
        return "highway_onramp"
    if any(a.kind == ActorKind.PEDESTRIAN for a in actors):
        if not _needs_same_direction_lanes(ego, actors):
            return "urban_two_way"
        return "highway_straight" if _needs_three_lanes(ego, actors) else MULTILANE_STREET
    if any(Relation.ONCOMING in a.relations or a.has("drift") for a in actors):
        return "urban_two_way"
    if any(a.has("pull_out") or a.has("reverse") or a.has("u_turn") for a in [ego, *actors]):
        return "urban_two_way"  # out of a parking space or driveway, a turn round: a street
    return "highway_straight"
