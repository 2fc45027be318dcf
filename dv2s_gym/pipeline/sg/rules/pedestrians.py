"""Pedestrians (and cyclists riding across) at the roadside: crossing in front of the ego or standing, on
straight roads and at junctions."""

from __future__ import annotations

import random
from typing import List

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.roads import MULTILANE_STREET, PARKING_STREET, STREET_LANES
from dv2s_gym.pipeline.sg.rules.roles import Role
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = ["crossing_directions", "spawn_lane_pedestrians", "spawn_junction_pedestrians"]


def crossing_directions(actor: ActorFrame, rng: random.Random) -> List[str]:
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
        hidden = actor.details.get(Action.CROSS, {}).get("from_behind")
        if hidden is not None:
            sides += [r for r, other in getattr(hidden, "relations", []) if getattr(other, "kind", "") == ActorKind.EGO]
        said = "right_to_left" if Relation.RIGHT_OF in sides else "left_to_right" if Relation.LEFT_OF in sides else None
        default = out[-1] if out else said or rng.choice(["right_to_left", "left_to_right"])
        out += [default] * remaining
    return out[:actor.count]


def spawn_lane_pedestrians(s: Script, actor: ActorFrame, ego_speed: str, two_way: bool, reckless: bool) -> None:
    n = actor.name
    crossing = actor.role == Role.CROSSER
    hit_any = actor.has("collide") or reckless and s.frame.ego.has("collide")
    dist = s.param(f"{n}_distance", "Range(55, 65)" if hit_any and crossing else "Range(30, 42)")
    parked = next((a for a in s.frame.actors if a.role == Role.FAR_SIDE), None)
    if crossing and parked is not None:
        # a parked vehicle on the far kerb: the pedestrian steps out just in front of it, not through it
        dist = s.param(f"{parked.name}_gap", "Range(25, 40)") + " + Range(6.5, 8.0)"
    riding = actor.kind == ActorKind.BICYCLE
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
    dirs = crossing_directions(actor, s.rng) if crossing else ["right_to_left"] * actor.count
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
        s.spawn += [f"{var} = new {CLASS[actor.kind]} {place},", f"    facing {facing}{contained},"] + \
            (["    with speed 0,"] if riding else []) + [f"    with behavior {behavior}"]
    rels = ["ahead_of"] + [r for r in actor.relations if r == Relation.CROSSING_PATH]
    shown = [a for a in actor.actions if a in (Action.CROSS, Action.COLLIDE)]
    if not crossing and actor.has("stop"):
        shown.append("stop")
    s.show(actor.kind, shown, rels if (Relation.AHEAD_OF in actor.relations or crossing) else
           [r for r in actor.relations if r == Relation.AHEAD_OF], actor.count)


def spawn_junction_pedestrians(s: Script, actor: ActorFrame, map_name: str, reckless: bool) -> None:
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
    dirs = crossing_directions(actor, s.rng) if crossing else ["right_to_left"] * actor.count
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
    s.show("pedestrian", [a for a in actor.actions if a in (Action.CROSS, Action.COLLIDE)], ["ahead_of"], actor.count)
