"""Vehicles that change lanes or come from elsewhere on a straight road: merging from the on-ramp, oncoming,
cutting in, overtaking the ego."""

from __future__ import annotations

from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.manoeuvres import longitudinal_behavior
from dv2s_gym.pipeline.sg.rules.placement import Placement
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = ["place_ramp", "place_oncoming", "place_cutter", "place_overtaker"]


def place_ramp(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """The merger reaches the acceleration lane lead metres ahead of where the ego gets to it."""
    n, ego_speed = actor.name, p.speed
    speeding = actor.has("accelerate")
    lead = s.param(f"{n}_merge_lead", ("Range(14, 22)" if actor.sudden else "Range(18, 30)") if speeding
                   else ("Range(6, 12)" if actor.sudden else "Range(10, 22)"))
    p.position = f"Uniform(accelLane).centerline.pointAlongBy(egoS + {lead})"
    s.use("MergeFromRamp")
    target = f"{ego_speed} + Range(0, 2)"
    if speeding:
        p.speed = f"{ego_speed} - " + s.param(f"{n}_speed_deficit", "Range(5, 8)")
    delay = "Range(0.8, 1.5)" if speeding else "Range(0.3, 1.0)"
    p.behavior = f"MergeFromRamp({target}, accelLane, {delay}, Range(1.8, 2.6))"
    p.relations = [r for r in p.relations if r not in (Relation.LEFT_OF, Relation.RIGHT_OF)]
    if Relation.AHEAD_OF not in p.relations:
        p.relations.append("ahead_of")
    p.actions = [a for a in p.actions if a in (Action.MERGE, Action.CUT_IN, Action.ACCELERATE, Action.BRAKE)]
    if Action.CUT_IN not in p.actions:
        p.actions.append("merge")


def place_oncoming(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """In the oncoming lane, coming toward the ego; drifting over the centre line when described."""
    n = actor.name
    dist = s.param(f"{n}_distance", "Range(85, 115)" if actor.has("drift") else "Range(40, 90)")
    p.speed = s.param(f"{n}_speed", "Range(9, 13)")
    p.position = f"oncomingLane.centerline.pointAlongBy(-(egoS + {dist}))"
    if actor.has("drift") and actor.has("collide"):
        # it drifts a whole lane over and stays there: the head-on collision the text describes
        s.use("DriftAndReturn")
        p.behavior = (f"DriftAndReturn({p.speed}, Range(45, 60), Range(3.3, 3.7), Range(1.5, 2.2), "
                      "-1, Range(1.2, 2.0))")
    elif actor.has("drift"):
        s.use("DriftAndReturn")
        p.behavior = (f"DriftAndReturn({p.speed}, Range(55, 75), Range(2.3, 3.2), Range(1.5, 2.5), "
                      f"Range(22, 32), Range(1.2, 2.0))")
    else:
        p.behavior = longitudinal_behavior(s, actor, p.speed)
    if Relation.ONCOMING not in p.relations:
        p.relations.append("oncoming")


def place_cutter(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """From the lane at its side into the ego's lane ahead of the ego: a slow truck pulls in when the ego comes
    close, anything else overtakes a little and cuts in."""
    lane = ctx.lane_of(actor.side)
    if actor.kind == ActorKind.TRUCK and not actor.has("accelerate") and Relation.BEHIND not in p.relations:
        _truck_pulls_in(s, actor, lane, p)
    else:
        _cuts_in(s, actor, lane, p)
    # it changes lanes toward the ego (from the left: to the right)
    p.actions = [a for a in p.actions if a not in (Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT)]
    p.actions.append("lane_change_right" if actor.side > 0 else "lane_change_left")
    if Action.CUT_IN not in p.actions:
        p.actions.append("cut_in")


def _truck_pulls_in(s: Script, actor: ActorFrame, lane: str, p: Placement) -> None:
    n, side = actor.name, actor.side
    gap = s.param(f"{n}_gap", "Range(45, 65)")
    p.speed = s.param(f"{n}_speed", "Range(14, 18)")
    trigger = s.param(f"{n}_trigger", "Range(22, 32)" if actor.sudden else "Range(30, 42)")
    p.position = f"{lane}.centerline.pointAlongBy(egoS + {gap})"
    s.use("PullInWhenClose")
    p.behavior = f"PullInWhenClose({-side}, {p.speed}, {trigger}, Range(2.8, 4.0))"


def _cuts_in(s: Script, actor: ActorFrame, lane: str, p: Placement) -> None:
    n, side, ego_speed = actor.name, actor.side, p.speed
    behind = Relation.BEHIND in p.relations or actor.has("overtake")
    start = s.param(f"{n}_start", "Range(-14, -8)" if behind else
                    "Range(-3, 0)" if actor.has("collide") else "Range(7, 11)")
    hits = actor.has("collide")  # it cuts in beside the ego's front and makes contact
    extra = s.param(f"{n}_extra_speed", "Range(1, 2)" if hits else "Range(4, 7)")
    gap = s.param(f"{n}_cut_gap", "Range(0, 1.5)" if hits else "Range(5, 9)" if actor.sudden
                  else "Range(10, 15)")
    dur = s.param(f"{n}_change_duration", "Range(1.3, 2.0)" if actor.sudden else "Range(2.0, 2.8)")
    after = (f"{ego_speed} - Range(3, 6)" if actor.has("brake") or actor.has("stop")
             else f"{ego_speed} + Range(-1, 2)")
    p.speed = f"{ego_speed} + {extra}"
    p.position = f"{lane}.centerline.pointAlongBy(egoS + {start})"
    s.use("CutInWhenAhead")
    p.behavior = f"CutInWhenAhead({-side}, {p.speed}, {gap}, {dur}, {after})"
    if not behind and Relation.AHEAD_OF not in p.relations:
        p.relations.append("ahead_of")


def place_overtaker(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """From behind the ego in its lane, past it on its side and back in ahead of it."""
    n, ego_speed = actor.name, p.speed
    start = s.param(f"{n}_start", "Range(-42, -32)")
    extra = s.param(f"{n}_extra_speed", "Range(5, 8)")
    ret = s.param(f"{n}_return_gap", "Range(3, 6)" if actor.sudden else "Range(6, 11)")
    p.speed = f"{ego_speed} + {extra}"
    after = f"{ego_speed} - Range(3, 6)" if actor.has("brake") else f"{ego_speed} + Range(0, 2)"
    p.position = f"egoLane.centerline.pointAlongBy(egoS + {start})"
    s.use("OvertakeAndReturn")
    p.behavior = (f"OvertakeAndReturn(ego, {actor.side}, {p.speed}, Range(22, 28), {ret}, Range(1.8, 2.4), "
                  f"{after})")
    rels = p.relations
    p.relations = [r for r in rels if r != Relation.AHEAD_OF] + (["behind"] if Relation.BEHIND not in rels else [])
    if Relation.SAME_LANE not in p.relations:
        p.relations.append("same_lane")
