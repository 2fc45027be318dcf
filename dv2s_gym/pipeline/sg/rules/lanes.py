"""The composer for straight roads (highways, the on-ramp, town streets): roles, lanes, the ego, the actors."""

from __future__ import annotations

from typing import List

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.frame import VEHICLES, ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.lane_ego import ego_lane_behavior
from dv2s_gym.pipeline.sg.rules.lane_geometry import LaneNames, lane_geometry
from dv2s_gym.pipeline.sg.rules.lane_roles import LANE_ACTIONS, LaneRoad, assign_lane_roles, lanes_needed
from dv2s_gym.pipeline.sg.rules.lane_spawn import spawn_lane_actor
from dv2s_gym.pipeline.sg.rules.roads import PARKING_KERB, PARKING_STREET, SHOULDER_KERB, at_kerb, speed_ranges
from dv2s_gym.pipeline.sg.rules.script import Script, check_actions
from scenario_bank.elements import Action

__all__ = ["compose_lanes"]


def compose_lanes(s: Script) -> None:
    """Compose the script of a scenario on a straight road."""
    frame = s.frame
    road = LaneRoad.of(frame)
    lo, hi = speed_ranges(frame.map)
    ego_speed = s.param("ego_speed", f"Range({lo}, {hi})")
    ego = frame.ego
    _ego_actions(s, road)
    reckless = ego.has("collide") or any(a.has("collide") for a in frame.actors)
    _split_pairs(frame.actors, road)
    assign_lane_roles(s, road)
    need = lanes_needed(s, road)
    lane_of = lane_geometry(s, road, need)
    ego_behavior, ego_first = ego_lane_behavior(s, ego, ego_speed, reckless, road.two_way, frame)
    ego_lines = _ego_lines(s, road, lane_of, ego_speed, ego_behavior)
    s.show("ego", [a for a in ego.actions])
    if ego_first:
        s.spawn += ego_lines
    ctx = LaneContext(ego_speed=ego_speed, lane_of=lane_of, road=road, reckless=reckless)
    for actor in frame.actors:
        spawn_lane_actor(s, actor, ctx)
    if not ego_first:
        s.spawn += ego_lines


def _ego_actions(s: Script, road: LaneRoad) -> None:
    """The ego's actions the straight road can show (a merge without an on-ramp becomes a lane change)."""
    ego = s.frame.ego
    if ego.has("merge") and not road.onramp:
        # merging into the next lane (a lane closed ahead, two lanes becoming one) without an on-ramp
        ego.actions.remove("merge")
        if not (ego.has("lane_change_left") or ego.has("lane_change_right")):
            side = ego.details.get(Action.MERGE, {}).get("side") or ego.details.get(Action.MERGE, {}).get("target")
            ego.actions.append("lane_change_right" if side == Lane.RIGHT else "lane_change_left")
        s.warnings.append("the ego's merge without an on-ramp is built as a lane change into the next lane")
        s.merged_as_lane_change = True
    check_actions(ego, s, LANE_ACTIONS - {"cross", "merge"} | ({"merge"} if road.onramp else set()))
    if ego.has("go_straight") and Action.KEEP_LANE not in ego.actions:
        ego.actions.append("keep_lane")


def _split_pairs(actors: List[ActorFrame], road: LaneRoad) -> None:
    """"two other cars drive in the neighbouring lanes": one on each side."""
    split: List[ActorFrame] = []
    for actor in actors:
        if actor.lane == Lane.ADJACENT and actor.count >= 2 and not road.two_way and actor.kind in VEHICLES:
            other = ActorFrame(name=f"{actor.name}b", kind=actor.kind, count=actor.count // 2,
                               actions=list(actor.actions), details=dict(actor.details),
                               relations=list(actor.relations), lane="adjacent", sudden=actor.sudden, side=-1)
            actor.count -= other.count
            actor.side = 1
            split.append(other)
    actors.extend(split)


def _ego_lines(s: Script, road: LaneRoad, lane_of: LaneNames, ego_speed: str, ego_behavior: str) -> List[str]:
    """Section 4's lines for the ego: in its lane, parked at the kerb or on the shoulder, or on the on-ramp."""
    frame, ego = s.frame, s.frame.ego
    ego_lines = ["ego = new Car at egoLane.centerline.pointAlongBy(egoS),",
                 f"    with speed {ego_speed},",
                 f"    with behavior {ego_behavior}"]
    if (ego.has("pull_out") or ego.has("reverse")) and road.two_way:
        # parked at the kerb, still on the road surface (the env ends an episode whose ego leaves the road)
        kerb = PARKING_KERB if frame.map == PARKING_STREET else "Range(1.0, 1.3)"
        ego_lines = at_kerb("ego", "Car", "egoS", kerb, ego_behavior)
    elif road.on_shoulder:
        ego_lines = at_kerb("ego", "Car", "egoS", SHOULDER_KERB, ego_behavior)
    elif ego.has("pull_out") or ego.has("reverse"):
        target = lane_of(1)
        if target == "egoLane":
            s.warnings.append("the ego's pull-out needs a lane left of where it is parked: not placed")
        ego_behavior = ego_behavior.replace("egoLane.centerline", f"{target}.centerline")
        ego_lines = ["ego = new Car at egoLane.centerline.pointAlongBy(egoS),",
                     "    with speed 0,",
                     f"    with behavior {ego_behavior}"]
    if road.onramp and ego.has("merge"):
        ego_lines = ["ego = new Car at rampLane.centerline.pointAlongBy(Range(40, 120)),",
                     f"    with speed {ego_speed},",
                     f"    with behavior MergeFromRamp({ego_speed}, accelLane, Range(0.5, 1.5), Range(2.0, 3.0))"]
        s.use("MergeFromRamp")
    return ego_lines
