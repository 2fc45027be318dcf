"""Vehicles at a junction besides the ego's: the one the ego waits for, those circulating on a roundabout, and
the route behaviour of one that drives through."""

from __future__ import annotations

from typing import Optional, Sequence

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.junction_roles import MANEUVER_TYPES
from dv2s_gym.pipeline.sg.rules.roads import RING_ENTRY, RING_QUARTER
from dv2s_gym.pipeline.sg.rules.script import Script, brake_params
from scenario_bank.elements import Action

__all__ = ["conflict_actor", "spawn_circulating", "junction_longitudinal"]


def conflict_actor(ego: ActorFrame, candidates: Sequence[ActorFrame]) -> Optional[ActorFrame]:
    """The vehicle the ego's stop waits for: the one its stop's trigger names (by kind), else the first
    vehicle crossing or meeting it at the junction."""
    trigger = ego.details.get(Action.STOP, {}).get("trigger") or {}
    other = trigger.get("with") if isinstance(trigger, dict) else None
    kind = getattr(other, "kind", None)
    return next((a for a in candidates if a.kind == kind), candidates[0] if candidates else None)


def spawn_circulating(s: Script, actor: ActorFrame, mtype: Optional[str], ego_speed: str, ego_time: str,
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
    behavior = junction_longitudinal(s, actor, speed, route, reckless)
    if behavior.startswith("CautiousRoute("):
        # it has the right of way on the ring: it does not stop for the ego that is about to enter
        s.use("DriveRoute")
        behavior = "DriveRoute(" + behavior[len("CautiousRoute("):]
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        ahead = f" + {12 * i}" if i else ""  # the rest of a group circulates ahead of it, past the entry sooner
        s.spawn += [f"{var} = new {CLASS[actor.kind]} at {n}Maneuver.connectingLane.centerline.pointAlongBy("
                    f"{start}{ahead}),",
                    f"    with speed {'0' if behavior.startswith('HoldStill') else speed},",
                    f"    with behavior {behavior}"]
    acts = list(actor.actions)
    if mtype and not any(MANEUVER_TYPES.get(a) == mtype for a in acts):
        acts.append(str({v: k for k, v in MANEUVER_TYPES.items()}[mtype]))
    s.show(actor.kind, acts, list(dict.fromkeys(actor.relations + (["ahead_of"] if cuts_in else []))), actor.count)


def junction_longitudinal(s: Script, actor: ActorFrame, speed: str, route: str, reckless: bool) -> str:
    if actor.has("stop") and not actor.has("brake") and (actor.state_stop or not actor.sudden):
        s.use("HoldStill")
        return "HoldStill()"
    if actor.has("brake") or actor.has("stop"):
        after, low, strength = brake_params(s, actor)
        s.use("RouteThenBrake")
        return f"RouteThenBrake({speed}, {route}, {after}, {low}, {strength})"
    name = "DriveRoute" if actor.has("collide") else "CautiousRoute"
    s.use(name)
    return f"{name}({speed}, {route})"
