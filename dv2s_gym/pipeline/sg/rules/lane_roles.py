"""Roles of the actors on a straight road: what each actor can do there, where it is placed (its
:class:`~.roles.Role` and side) and which lanes beside the ego's the road must have."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple, Union

from dv2s_gym.pipeline.semantics.parsed import Lane
from dv2s_gym.pipeline.sg.rules.frame import VEHICLES, ActorFrame, ScenarioFrame
from dv2s_gym.pipeline.sg.rules.roads import MULTILANE_STREET, PARKING_STREET, SHOULDER_HIGHWAY, STREET_MAPS
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script, check_actions
from scenario_bank.elements import CAN_DO, Action, ActorKind, Relation

__all__ = ["LANE_ACTIONS", "LaneRoad", "assign_lane_roles", "lanes_needed"]

LANE_ACTIONS = {"brake", "stop", "accelerate", "lane_change_left", "lane_change_right", "cut_in", "merge",
                "collide", "keep_lane", "overtake", "drift", "cross", "go_straight", "swerve", "pull_out",
                "reverse", "u_turn"}
"""Actions the straight-road composer builds (for some kind of actor)."""


@dataclass(frozen=True)
class LaneRoad:
    """The kind of straight road a scenario is composed on."""

    two_way: bool
    """A town street with one lane per direction."""
    multilane: bool
    """The town street with several lanes per direction and oncoming lanes."""
    onramp: bool
    """The highway with an on-ramp."""
    on_shoulder: bool
    """The ego parked on the hard shoulder right of the rightmost lane, which it pulls out into."""

    @classmethod
    def of(cls, frame: ScenarioFrame) -> "LaneRoad":
        return cls(two_way=frame.map in STREET_MAPS, multilane=frame.map == MULTILANE_STREET,
                   onramp=frame.map == "highway_onramp",
                   on_shoulder=frame.map == SHOULDER_HIGHWAY and (frame.ego.has("pull_out") or
                                                                  frame.ego.has("reverse")))


_ON_SHOULDER = re.compile(r"\b(?:on|onto|in|into|along) (?:the |its |their )?(?:hard |right )?shoulder\b|"
                          r"\b(?:breakdown|emergency) lane\b")


def standing_on_the_shoulder(frame: ScenarioFrame) -> Optional[ActorFrame]:
    """On :data:`SHOULDER_HIGHWAY`, the one vehicle that stands still (stopped, parked, broken down: no action but
    stopping) when the description puts a vehicle on the (hard) shoulder or in the breakdown lane; else None."""
    if frame.map != SHOULDER_HIGHWAY or frame.ego.lane not in (None, Lane.RIGHT) or \
            not _ON_SHOULDER.search(frame.description.lower()):
        return None
    still = [a for a in frame.actors if a.kind in VEHICLES and not (set(a.actions) - {Action.STOP, Action.KEEP_LANE})
             and not ({Relation.LEFT_OF, Relation.ONCOMING, Relation.BEHIND} & set(a.relations))]
    return still[0] if len(still) == 1 else None


def assign_lane_roles(s: Script, road: LaneRoad) -> None:
    """Give every actor of the frame its role (and side) on the straight road, dropping (with a warning) what it
    cannot do there."""
    frame = s.frame
    standing = standing_on_the_shoulder(frame)
    for actor in frame.actors:
        _check_lane_actions(s, actor, road)
        _reconcile(s, actor)
        rels = set(actor.relations)  # (as described: a relation dropped while choosing the role still counts)
        actor.role = _first_role(s, actor, road, rels)
        _adjust_role(s, actor, road, standing, rels)


def _check_lane_actions(s: Script, actor: ActorFrame, road: LaneRoad) -> None:
    if actor.kind == ActorKind.BICYCLE and actor.has("cross"):
        check_actions(actor, s, {"cross", "collide"})  # a cyclist riding across the road, like a pedestrian
    elif actor.kind in VEHICLES:
        check_actions(actor, s, LANE_ACTIONS - {"cross"} | ({"merge"} if road.onramp else set()))
    elif actor.kind == ActorKind.PEDESTRIAN:
        check_actions(actor, s, set(CAN_DO[ActorKind.PEDESTRIAN]))
    else:
        actor.actions = []


def _reconcile(s: Script, actor: ActorFrame) -> None:
    """Settle relations and actions that contradict each other."""
    if {Relation.SAME_LANE, Relation.ONCOMING, Relation.AHEAD_OF} <= set(actor.relations):
        # in the ego's lane and oncoming at once: the lane says where it is (a car parked in the ego's lane)
        actor.relations = [r for r in actor.relations if r != Relation.ONCOMING]
        s.warnings.append(f"the {actor.kind} is both in the ego's lane and oncoming: placed in the ego's lane")
    if actor.has("swerve") and actor.has("cut_in"):
        # it swerves toward the ego and returns: no cut-in happens
        actor.actions.remove("cut_in")
        s.warnings.append(f"the {actor.kind} swerves and returns to its lane: its cut-in is built as a swerve")


@dataclass(frozen=True)
class _Asked:
    """What :data:`_ROLE_RULES` look at for one actor: the script, the actor, the road and its relations as
    described."""

    s: Script
    actor: ActorFrame
    road: LaneRoad
    rels: frozenset


def _obstacle_role(q: _Asked) -> Role:
    two_way, rels = q.road.two_way, q.rels
    q.actor.side = 1 if Relation.LEFT_OF in rels and not two_way else \
        -1 if Relation.RIGHT_OF in rels and not two_way else 0
    return Role.OBSTACLE


def _slow_lead(q: _Asked) -> bool:
    """The ego overtakes: the first actor ahead in its lane (no other said to be placed) is the one it passes."""
    frame = q.s.frame
    return frame.ego.has("overtake") and not (q.rels & {Relation.LEFT_OF, Relation.RIGHT_OF, Relation.BEHIND}) \
        and not any(a.role == Role.SLOW_LEAD for a in frame.actors)


def _beside(q: _Asked) -> bool:
    """Said to be left or right of the ego, or in a lane the text names that is not the ego's (in "the right
    lane", the ego's lane not said: beside the ego on that side)."""
    actor, ego, two_way, rels = q.actor, q.s.frame.ego, q.road.two_way, q.rels
    return Relation.LEFT_OF in rels or Relation.RIGHT_OF in rels or actor.lane == Lane.ADJACENT and not two_way or \
        actor.lane in (Lane.LEFT, Lane.RIGHT, Lane.MIDDLE) and \
        ego.lane in (Lane.LEFT, Lane.RIGHT, Lane.MIDDLE) and actor.lane != ego.lane or \
        actor.lane in (Lane.LEFT, Lane.RIGHT) and ego.lane is None and not two_way and Relation.SAME_LANE not in rels


def _rams_from_behind(q: _Asked) -> bool:
    actor = q.actor
    return actor.has("collide") and Relation.AHEAD_OF not in q.rels and not actor.has("brake") and not actor.has("stop")


_ROLE_RULES: Tuple[Tuple[Callable[[_Asked], bool], Union[Role, Callable[[_Asked], Role]]], ...] = (
    (lambda q: q.actor.kind == ActorKind.OBSTACLE, _obstacle_role),
    (lambda q: q.actor.kind == ActorKind.PEDESTRIAN and (q.actor.has("cross") or q.actor.has("collide")), Role.CROSSER),
    (lambda q: q.actor.kind == ActorKind.PEDESTRIAN, Role.ROADSIDE),
    (lambda q: q.actor.kind == ActorKind.BICYCLE and q.actor.has("cross"), Role.CROSSER),
    # parked at the kerb (or on the shoulder) beside the ego's lane
    (lambda q: q.actor.has("pull_out") or q.actor.has("reverse"), Role.PULLER),
    (lambda q: q.actor.has("merge") and q.road.onramp, Role.RAMP),
    (lambda q: q.actor.has("drift") or Relation.ONCOMING in q.rels,
     lambda q: _drifting_or_oncoming_role(q.s, q.actor, q.road, set(q.rels))),
    (lambda q: q.actor.has("overtake") and not q.actor.details.get(Action.OVERTAKE, {}).get("around"), Role.OVERTAKER),
    (lambda q: q.actor.has("cut_in") or (q.actor.has("merge") and not q.road.onramp), Role.CUTTER),
    (_slow_lead, Role.SLOW_LEAD),
    (_beside, Role.ADJACENT),
    (lambda q: Relation.BEHIND in q.rels, Role.FOLLOWER),
    (_rams_from_behind, Role.FOLLOWER),
)
"""The straight road's role rules, in order: (condition, role or the function that settles it); the first whose
condition holds gives the role, else :attr:`Role.LEAD`."""


def _first_role(s: Script, actor: ActorFrame, road: LaneRoad, rels: set) -> Role:
    """The role the actor's kind, actions and relations give it: the first of :data:`_ROLE_RULES` that applies."""
    asked = _Asked(s, actor, road, frozenset(rels))
    for applies, role in _ROLE_RULES:
        if applies(asked):
            return role if isinstance(role, Role) else role(asked)
    return Role.LEAD


def _drifting_or_oncoming_role(s: Script, actor: ActorFrame, road: LaneRoad, rels: set) -> Role:
    if road.two_way or road.multilane and Relation.ONCOMING in rels:
        return Role.ONCOMING
    if Relation.ONCOMING in rels:
        s.warnings.append(f"an oncoming {actor.kind} cannot be placed on a one-way {s.frame.map}: it is "
                          "placed in the next lane instead")
        actor.relations = [r for r in actor.relations if r != Relation.ONCOMING]
    ego = s.frame.ego
    right = Relation.RIGHT_OF in rels or actor.lane == Lane.RIGHT and ego.lane in (None, Lane.MIDDLE, Lane.LEFT)
    actor.side = -1 if right and Relation.LEFT_OF not in rels else 1
    return Role.ADJACENT


def _adjust_role(s: Script, actor: ActorFrame, road: LaneRoad, standing: Optional[ActorFrame], rels: set) -> None:
    """What the road and the ego's own manoeuvre change about the role the actor's own description gives."""
    frame, ego = s.frame, s.frame.ego
    two_way = road.two_way
    if not two_way and not road.onramp and not road.on_shoulder and (ego.has("pull_out") or ego.has("reverse")) \
            and actor.role in (Role.LEAD, Role.FOLLOWER) and actor.kind in VEHICLES:
        # the ego is parked on the shoulder: the traffic it pulls out into drives in the lane left of it
        actor.role, actor.side = Role.ADJACENT, 1
    if actor is standing:
        actor.role = Role.SHOULDER  # stopped on the hard shoulder right of the rightmost lane
    if frame.map == PARKING_STREET and actor.parked and actor.role == Role.LEAD and actor.kind in VEHICLES and \
            not (set(actor.actions) - {Action.STOP, Action.KEEP_LANE}) \
            and not ({Relation.ONCOMING, Relation.LEFT_OF} & rels):
        # a parked car (or a row of them) on the street with parking lanes: at the ego's kerb, not in its lane
        actor.role = Role.FAR_SIDE
        actor.relations = [r for r in actor.relations if r != Relation.SAME_LANE] + ["right_of"]
    if road.on_shoulder and actor.role in (Role.LEAD, Role.FOLLOWER) and actor.kind in VEHICLES and \
            Relation.LEFT_OF not in actor.relations:
        actor.relations.append("left_of")  # in the lane left of the ego parked on the shoulder
    if two_way and actor.role == Role.ADJACENT and not (set(actor.actions) - {Action.STOP, Action.KEEP_LANE}):
        actor.role = Role.FAR_SIDE  # parked or standing at the far kerb, in the other lane
    if two_way and actor.role in (Role.ADJACENT, Role.CUTTER):
        s.warnings.append(f"the {actor.kind} {actor.role} role needs a second lane in the ego's direction, "
                          f"which {frame.map} does not have: placed in the ego's lane")
        actor.role = Role.LEAD


def lanes_needed(s: Script, road: LaneRoad) -> Dict[int, bool]:
    """Set the side of every actor placed beside the ego and return the lane offsets (+ left, - right) the ego's
    lane must have next to it."""
    frame, ego = s.frame, s.frame.ego
    need: Dict[int, bool] = {}
    for actor in frame.actors:
        _set_side(s, actor, road)
        for k in _lanes_of(actor, road):
            need[k] = True
    if ego.has("lane_change_left"):
        need[1] = True
    if ego.has("lane_change_right"):
        need[-1] = True
    if ego.has("overtake") and not road.two_way:
        need[1] = True
    if (ego.has("pull_out") or ego.has("reverse")) and not road.two_way and not road.onramp and not road.on_shoulder:
        need[1] = True  # parked in the rightmost lane (the shoulder), it pulls out into the lane left of it
    around = [a for a in frame.actors if a.has("overtake") and a.details.get(Action.OVERTAKE, {}).get("around")]
    if around and not road.two_way:
        need[1] = True
    return need


_ORDER = {"left": 1, "middle": 0, "right": -1}


def _set_side(s: Script, actor: ActorFrame, road: LaneRoad) -> None:
    ego = s.frame.ego
    rels = set(actor.relations)
    order = _ORDER
    if actor.role == Role.ADJACENT and actor.side == 0:
        if actor.lane in order and ego.lane in order and actor.lane != ego.lane:
            actor.side = order[actor.lane] - order[ego.lane]
            if road.multilane:  # a two-lane carriageway: its left and right lanes are neighbours
                actor.side = max(-1, min(1, actor.side))
        elif actor.lane in (Lane.LEFT, Lane.RIGHT) and ego.lane is None:
            actor.side = order[actor.lane]
        elif Relation.LEFT_OF in rels:
            actor.side = 1
        elif Relation.RIGHT_OF in rels:
            actor.side = -1
        else:
            actor.side = 1
    if actor.role == Role.CUTTER:
        _set_cutter_side(s, actor, rels)
    if actor.role in (Role.OVERTAKER,):
        side = actor.details.get(Action.OVERTAKE, {}).get("side") or "left"
        actor.side = 1 if side == Lane.LEFT else -1


def _set_cutter_side(s: Script, actor: ActorFrame, rels: set) -> None:
    """The side a cutter comes from: the one the text gives, else away from its lane change, else its lane's,
    else the side it is said to be on, else right for a truck and either for the rest."""
    ego = s.frame.ego
    side = actor.details.get(Action.CUT_IN, {}).get("side")
    if side is None and actor.has("lane_change_left"):
        side = "right"
    if side is None and actor.has("lane_change_right"):
        side = "left"
    if side is None and actor.lane in (Lane.LEFT, Lane.RIGHT) and ego.lane in (None, Lane.MIDDLE) and \
            not (rels & {Relation.LEFT_OF, Relation.RIGHT_OF}):
        side = actor.lane  # "in the left lane", the ego's lane not said: it comes from that side
    if side is None:
        side = "left" if Relation.LEFT_OF in rels else "right" if Relation.RIGHT_OF in rels else \
            ("right" if actor.kind == ActorKind.TRUCK else s.rng.choice(["left", "right"]))
    actor.side = 1 if side == Lane.LEFT else -1
    if Relation.LEFT_OF not in rels and Relation.RIGHT_OF not in rels:
        actor.relations.append(f"{side}_of")


def _lanes_of(actor: ActorFrame, road: LaneRoad) -> List[int]:
    """The lane offsets beside the ego's that the actor drives in or changes into."""
    out: List[int] = []
    if actor.role in (Role.ADJACENT, Role.CUTTER):
        out.append(actor.side)
    if actor.role == Role.ADJACENT and actor.has("lane_change_left"):
        out.append(actor.side + 1)
    if actor.role == Role.ADJACENT and actor.has("lane_change_right"):
        out.append(actor.side - 1)
    if actor.role in (Role.LEAD, Role.FOLLOWER) and (actor.has("lane_change_left") or actor.has("lane_change_right")):
        out.append(1 if actor.has("lane_change_left") else -1)
    if actor.role == Role.OVERTAKER and not road.two_way:
        out.append(actor.side)
    if actor.role == Role.OBSTACLE and actor.side:
        out.append(actor.side)
    return out
