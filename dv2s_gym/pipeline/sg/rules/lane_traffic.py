"""Vehicles that keep to a lane on a straight road: ahead of the ego (lead, slow lead), behind it (follower),
beside it (adjacent); their gap to the ego and their behaviour."""

from __future__ import annotations

from dv2s_gym.pipeline.sg.rules.frame import KIND_SPEEDS, ActorFrame
from dv2s_gym.pipeline.sg.rules.lane_context import LaneContext
from dv2s_gym.pipeline.sg.rules.manoeuvres import longitudinal_behavior
from dv2s_gym.pipeline.sg.rules.placement import Placement
from dv2s_gym.pipeline.sg.rules.roads import HIGHWAY_MAPS
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script

__all__ = ["place_in_lane"]


def place_in_lane(s: Script, actor: ActorFrame, ctx: LaneContext, p: Placement) -> None:
    """A lead, follower, slow lead or adjacent vehicle: its lane, gap to the ego, behaviour and relations."""
    ego_speed = p.speed  # (a slow kind's own cruise speed)
    k = actor.side if actor.role == Role.ADJACENT else 0
    lane = ctx.lane_of(k)
    gap = _gap(s, actor, p)
    slot = ctx.used.get(k, 0)
    ctx.used[k] = slot + actor.count
    p.position = f"{lane}.centerline.pointAlongBy(egoS + {gap})"
    _behavior(s, actor, ctx, lane, ego_speed, p)
    rels = p.relations
    if actor.role == Role.LEAD and "ahead_of" not in actor.relations:
        rels.append("ahead_of")
    if actor.role == Role.FOLLOWER and "behind" not in actor.relations:
        rels.append("behind")
    if actor.role == Role.ADJACENT:
        want = "left_of" if k > 0 else "right_of"
        if want not in rels:
            rels.append(want)
    if actor.role == Role.SLOW_LEAD and "ahead_of" not in rels:
        rels.append("ahead_of")


def _gap(s: Script, actor: ActorFrame, p: Placement) -> str:
    """The gap (m, along the lane, negative behind) from the ego; a slow lead's speed."""
    n, ego_speed = actor.name, p.speed
    urban = s.frame.map not in HIGHWAY_MAPS  # town speeds and distances
    ahead = "ahead_of" in p.relations
    behind = "behind" in p.relations
    if actor.role == Role.FOLLOWER:
        return s.param(f"{n}_gap", "-Range(14, 22)" if actor.has("collide") else "-Range(15, 30)")
    if actor.role == Role.SLOW_LEAD:
        gap = s.param(f"{n}_gap", "Range(30, 45)" if not urban else "Range(25, 35)")
        p.speed = f"{ego_speed} - " + s.param(f"{n}_speed_deficit", "Range(6, 9)" if not urban else "Range(4, 6)")
        return gap
    if actor.role == Role.ADJACENT:
        changing = actor.has("lane_change_left") or actor.has("lane_change_right")
        # side by side, unless it changes lanes: then a little ahead, so the two never collide
        return s.param(f"{n}_offset", "Range(12, 28)" if ahead else "-Range(12, 28)" if behind
                       else ("Range(0, 2.5)" if actor.has("collide") else "Range(9, 14)") if changing
                       else "Range(6, 10)" if actor.has("swerve") and not actor.has("collide")
                       else "Range(8, 14)" if actor.has("drift") and not actor.has("collide")
                       else "Range(-4, 4)")
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        return s.param(f"{n}_gap", "Range(30, 50)" if urban else "Range(55, 90)")
    if actor.has("brake") or actor.has("stop") or actor.has("collide"):
        return s.param(f"{n}_gap", ("Range(12, 20)" if urban else "Range(15, 26)") if actor.sudden
                       or actor.has("collide") else ("Range(15, 25)" if urban else "Range(20, 35)"))
    if actor.has("accelerate"):
        return s.param(f"{n}_gap", "Range(10, 20)")
    return s.param(f"{n}_gap", "Range(18, 30)" if urban else "Range(22, 40)")


def _behavior(s: Script, actor: ActorFrame, ctx: LaneContext, lane: str, ego_speed: str, p: Placement) -> None:
    n, ego = actor.name, s.frame.ego
    parked_ego = ctx.road.two_way and (ego.has("pull_out") or ego.has("reverse")) and ego.has("collide")
    around = actor.has("overtake") and actor.details.get("overtake", {}).get("around")
    if actor.role == Role.FOLLOWER and actor.has("collide") and parked_ego:
        # it comes along the lane past the parked ego, which pulls out into its side
        if actor.kind not in KIND_SPEEDS:
            p.speed = s.param(f"{n}_speed", "Range(6, 8)")
        p.position = f"{lane}.centerline.pointAlongBy(egoS - " + s.param(f"{n}_distance", "Range(28, 36)") + ")"
        s.use("Cruise")
        p.behavior = f"Cruise({p.speed})"
    elif actor.role == Role.FOLLOWER and actor.has("collide"):
        p.speed = f"{ego_speed} + " + s.param(f"{n}_extra_speed", "Range(5, 8)")
        s.use("Cruise")
        p.behavior = f"Cruise({p.speed})"
    elif actor.role == Role.LEAD and around and ctx.obstacles:
        s.use("OvertakeAndReturn")
        gap_expr = s.param(f"{n}_gap", "Range(10, 16)")
        p.position = f"egoLane.centerline.pointAlongBy(egoS + {gap_expr})"
        p.behavior = (f"OvertakeAndReturn({ctx.obstacles[0]}, 1, {ego_speed}, Range(12, 16), Range(5, 9), "
                      f"Range(1.6, 2.2), {ego_speed})")
    elif around:
        s.warnings.append(f"the {actor.kind} goes around something that was not placed: the manoeuvre is "
                          "not placed")
        p.actions.remove("overtake")
        p.behavior = longitudinal_behavior(s, actor, p.speed)
    else:
        p.behavior = longitudinal_behavior(s, actor, p.speed)
