"""Section 4 of a junction script for the other vehicles and the obstacles."""

from __future__ import annotations

from typing import Callable, Dict, List, Tuple

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.junction_fit import RoleSpec
from dv2s_gym.pipeline.sg.rules.junction_roles import MANEUVER_TYPES
from dv2s_gym.pipeline.sg.rules.junction_timing import JunctionTiming
from dv2s_gym.pipeline.sg.rules.junction_vehicles import junction_longitudinal, spawn_circulating
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Relation

__all__ = ["spawn_junction_vehicle", "spawn_junction_obstacle"]


def spawn_junction_vehicle(s: Script, spec: RoleSpec, t: JunctionTiming, ring: bool, road_speed: str,
                           reckless: bool) -> None:
    """Place one vehicle (group) of the junction scenario on its maneuver; ``road_speed`` is the ego's speed
    range, which a vehicle ahead of it drives at."""
    actor, role, mtype = spec
    n = actor.name
    rels = list(actor.relations)
    circulating = ring and (role == JunctionRole.FROM_LEFT and mtype in ("STRAIGHT", "LEFT_TURN") or
                            role == JunctionRole.RING_CUT)
    if circulating:
        spawn_circulating(s, actor, mtype, t.ego_speed, t.ego_time, t.lead_first and role != JunctionRole.RING_CUT,
                          reckless, cuts_in=role == JunctionRole.RING_CUT)
        return
    speed = s.param(f"{n}_speed", "Range(7, 11)" if role != JunctionRole.AHEAD else road_speed)
    place = _STARTS.get(role, _timed_arrival)
    along, behavior, speed = place(s, actor, role, t, speed, rels, reckless)
    start_speed = "0" if behavior.startswith("HoldStill") else speed
    cls = CLASS[actor.kind]
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        extra = "" if i == 0 else (f" + {12 * i}" if role == JunctionRole.AHEAD else f" - {12 * i}")
        s.spawn += [f"{var} = new {cls} at {n}Maneuver.startLane.centerline.pointAlongBy({along}{extra}),",
                    f"    with speed {start_speed},",
                    f"    with behavior {behavior}"]
    acts = list(actor.actions)
    if mtype and not any(MANEUVER_TYPES.get(a) == mtype for a in acts):
        acts.append(str({v: k for k, v in MANEUVER_TYPES.items()}[mtype]))
    if role == JunctionRole.INTO_PATH and actor.has("merge") and Relation.AHEAD_OF not in rels:
        rels.append("ahead_of")  # it joins the ego's road in front of the ego
    s.show(actor.kind, acts, list(dict.fromkeys(rels)), actor.count)


Start = Tuple[str, str, str]
"""Where a junction vehicle starts (Scenic distance along its start lane), its behaviour and its start speed."""


def _in_the_ego_lane(s: Script, actor: ActorFrame, role: str, t: JunctionTiming, speed: str, rels: List[str],
                     reckless: bool) -> Start:
    """Ahead of (or behind) the ego on its approach."""
    gap = s.param(f"{actor.name}_gap", "Range(10, 16)")
    along = f"-({t.ego_dist} - {gap})" if role == JunctionRole.AHEAD else f"-({t.ego_dist} + {gap})"
    behavior = junction_longitudinal(s, actor, speed, f"{actor.name}Route", reckless)
    want = "ahead_of" if role == JunctionRole.AHEAD else "behind"
    if want not in rels:
        rels.append(want)
    return along, behavior, speed


def _waiting_to_pull_in(s: Script, actor: ActorFrame, role: str, t: JunctionTiming, speed: str, rels: List[str],
                        reckless: bool) -> Start:
    """Waiting at its entry, it pulls into the ego's way when the ego is near."""
    n = actor.name
    wait = s.param(f"{n}_wait_position", "Range(2, 5)")
    trigger = s.param(f"{n}_trigger_time", "Range(2.2, 3.2)" if actor.sudden else "Range(3.2, 4.5)")
    s.use("PullOutWhenEgoNear")
    return f"-{wait}", f"PullOutWhenEgoNear({speed}, {n}Route, egoEntry, {trigger})", "0"


def _timed_arrival(s: Script, actor: ActorFrame, role: str, t: JunctionTiming, speed: str, rels: List[str],
                   reckless: bool) -> Start:
    """From another approach, timed to get to the junction when the description says."""
    along = f"-(1 + {speed} * ({_arrival(s, actor, t)}))"
    behavior = junction_longitudinal(s, actor, speed, f"{actor.name}Route", reckless)
    if role == JunctionRole.ONCOMING and Relation.ONCOMING not in rels:
        rels.append("oncoming")
    return along, behavior, speed


_STARTS: Dict[str, Callable[..., Start]] = {
    JunctionRole.AHEAD: _in_the_ego_lane,
    JunctionRole.BEHIND: _in_the_ego_lane,
    JunctionRole.INTO_PATH: _waiting_to_pull_in,
}
"""Junction role -> where its vehicle starts and how it moves; every other role arrives timed
(:func:`_timed_arrival`)."""


def _arrival(s: Script, actor: ActorFrame, t: JunctionTiming) -> str:
    """When a crossing (or oncoming) vehicle reaches the junction: `offset` seconds after the ego would (negative:
    before it); a group arrives one after the other, the last one still ahead of the ego."""
    n = actor.name
    if t.misjudges and actor is t.conflict:
        # it gets to the junction after the ego has stopped at it
        return s.param(f"{n}_arrival", "Range(4.5, 5.5)")
    if t.lead_first:
        return f"{t.first} + Range(0, 0.4)"
    # (with a collision described, the ego reaches the junction in 2.4 s at least)
    offset = s.param(f"{n}_arrival_offset", "Range(-0.2, 0.2)" if actor.has("collide") else "Range(-1.9, -1.3)")
    return f"{t.ego_time} + {offset}"


def spawn_junction_obstacle(s: Script, actor: ActorFrame) -> None:
    """Obstacles on the lane the ego leaves the junction by."""
    gap = s.param(f"{actor.name}_gap", "Range(10, 20)")
    for i in range(actor.count):
        var = actor.name if actor.count == 1 else f"{actor.name}_{i + 1}"
        s.spawn += [f"{var} = new Obstacle at egoManeuver.endLane.centerline.pointAlongBy({gap} + {3 * i}),",
                    "    with width Range(0.8, 1.8), with length Range(0.6, 1.4)"]
    s.show("obstacle", [], ["ahead_of"], actor.count)
