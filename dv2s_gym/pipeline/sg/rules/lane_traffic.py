"""Vehicles that keep to a lane on a straight road: ahead of the ego (lead, slow lead), behind it (follower),
beside it (adjacent). One function per role places its vehicle: its lane, its gap to the ego, its behaviour and
its relations."""

from __future__ import annotations

from dv2s_gym.pipeline.sg.rules.frame import KIND_SPEEDS, ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.manoeuvres import longitudinal_behavior
from dv2s_gym.pipeline.sg.rules.placement import Placement
from dv2s_gym.pipeline.sg.rules.roads import HIGHWAY_MAPS
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Action, Relation

__all__ = ["place_adjacent", "place_follower", "place_lead", "place_slow_lead"]


def place_lead(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """A lead vehicle, ahead in the ego's lane at a gap set by what it does; one that goes around something
    overtakes the first obstacle placed."""
    ego_speed = p.speed  # (a slow kind's own cruise speed)
    _in_lane(actor, ctx, p, 0, _lead_gap(s, actor))
    if _goes_around(actor) and ctx.obstacles:
        s.use("OvertakeAndReturn")
        gap_expr = s.param(f"{actor.name}_gap", "Range(10, 16)")
        p.position = f"egoLane.centerline.pointAlongBy(egoS + {gap_expr})"
        p.behavior = (f"OvertakeAndReturn({ctx.obstacles[0]}, 1, {ego_speed}, Range(12, 16), Range(5, 9), "
                      f"Range(1.6, 2.2), {ego_speed})")
    else:
        _drive_on(s, actor, p)
    if Relation.AHEAD_OF not in actor.relations:
        p.relations.append("ahead_of")


def place_follower(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """A follower, behind in the ego's lane; one that collides comes up faster than the ego, or, when the parked
    ego pulls out (or reverses) into its way, comes along the lane past it."""
    n, ego_speed = actor.name, p.speed
    lane = _in_lane(actor, ctx, p, 0, s.param(f"{n}_gap", "-Range(14, 22)" if actor.has("collide")
                                              else "-Range(15, 30)"))
    if actor.has("collide") and _parked_ego(s, ctx):
        if actor.kind not in KIND_SPEEDS:
            p.speed = s.param(f"{n}_speed", "Range(6, 8)")
        p.position = f"{lane}.centerline.pointAlongBy(egoS - " + s.param(f"{n}_distance", "Range(28, 36)") + ")"
        s.use("Cruise")
        p.behavior = f"Cruise({p.speed})"
    elif actor.has("collide"):
        p.speed = f"{ego_speed} + " + s.param(f"{n}_extra_speed", "Range(5, 8)")
        s.use("Cruise")
        p.behavior = f"Cruise({p.speed})"
    else:
        _drive_on(s, actor, p)
    if Relation.BEHIND not in actor.relations:
        p.relations.append("behind")


def place_slow_lead(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """A slow lead, well ahead in the ego's lane and slower than the ego by a few m/s."""
    n, urban = actor.name, _urban(s)
    gap = s.param(f"{n}_gap", "Range(30, 45)" if not urban else "Range(25, 35)")
    p.speed = f"{p.speed} - " + s.param(f"{n}_speed_deficit", "Range(6, 9)" if not urban else "Range(4, 6)")
    _in_lane(actor, ctx, p, 0, gap)
    _drive_on(s, actor, p)
    if Relation.AHEAD_OF not in p.relations:
        p.relations.append("ahead_of")


def place_adjacent(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """A vehicle in the lane beside the ego's (``actor.side``): side by side, or a little ahead when it changes
    lanes, so the two never collide unless it is meant to."""
    ahead, behind = Relation.AHEAD_OF in p.relations, Relation.BEHIND in p.relations
    changing = actor.has("lane_change_left") or actor.has("lane_change_right")
    offset = s.param(f"{actor.name}_offset", "Range(12, 28)" if ahead else "-Range(12, 28)" if behind
                     else ("Range(0, 2.5)" if actor.has("collide") else "Range(9, 14)") if changing
                     else "Range(6, 10)" if actor.has("swerve") and not actor.has("collide")
                     else "Range(8, 14)" if actor.has("drift") and not actor.has("collide")
                     else "Range(-4, 4)")
    _in_lane(actor, ctx, p, actor.side, offset)
    _drive_on(s, actor, p)
    side = "left_of" if actor.side > 0 else "right_of"
    if side not in p.relations:
        p.relations.append(side)


def _in_lane(actor: ActorFrame, ctx: LaneContext, p: Placement, k: int, gap: str) -> str:
    """Place ``actor`` ``gap`` m (negative: behind) along lane ``k`` (the offset from the ego's) from the ego,
    counting it among the lane's vehicles; the lane's Scenic name."""
    lane = ctx.lane_of(k)
    ctx.used[k] = ctx.used.get(k, 0) + actor.count
    p.position = f"{lane}.centerline.pointAlongBy(egoS + {gap})"
    return lane


def _urban(s: Script) -> bool:
    """Town speeds and distances (not a highway map)."""
    return s.frame.map not in HIGHWAY_MAPS


def _lead_gap(s: Script, actor: ActorFrame) -> str:
    """A lead's gap (m) from the ego: from what it does (stops, brakes, collides, speeds up)."""
    n, urban = actor.name, _urban(s)
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        return s.param(f"{n}_gap", "Range(30, 50)" if urban else "Range(55, 90)")
    if actor.has("brake") or actor.has("stop") or actor.has("collide"):
        return s.param(f"{n}_gap", ("Range(12, 20)" if urban else "Range(15, 26)") if actor.sudden
                       or actor.has("collide") else ("Range(15, 25)" if urban else "Range(20, 35)"))
    if actor.has("accelerate"):
        return s.param(f"{n}_gap", "Range(10, 20)")
    return s.param(f"{n}_gap", "Range(18, 30)" if urban else "Range(22, 40)")


def _goes_around(actor: ActorFrame) -> bool:
    """It overtakes around something (``overtake`` with ``around``)."""
    return bool(actor.has("overtake") and actor.details.get(Action.OVERTAKE, {}).get("around"))


def _parked_ego(s: Script, ctx: LaneContext) -> bool:
    """The ego is parked on a two-way street and pulls out (or reverses) into a collision."""
    ego = s.frame.ego
    return bool(ctx.road.two_way and (ego.has("pull_out") or ego.has("reverse")) and ego.has("collide"))


def _drive_on(s: Script, actor: ActorFrame, p: Placement) -> None:
    """Its behaviour along the lane; going around something that was not placed is warned of and dropped."""
    if _goes_around(actor):
        s.warnings.append(f"the {actor.kind} goes around something that was not placed: the manoeuvre is "
                          "not placed")
        p.actions.remove("overtake")
    p.behavior = longitudinal_behavior(s, actor, p.speed)
