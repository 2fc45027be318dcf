"""When the vehicles at a junction get there: the ego's distance and time to its entry, who goes first, and
whether the ego waits for (or misjudges) a crossing vehicle."""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.junction_fit import RoleSpec
from dv2s_gym.pipeline.sg.rules.junction_vehicles import conflict_actor
from dv2s_gym.pipeline.sg.rules.roads import RING_MAP
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole
from dv2s_gym.pipeline.sg.rules.script import Script

__all__ = ["JunctionTiming", "junction_timing"]


@dataclass
class JunctionTiming:
    """The ego's approach and the order of arrival at the junction."""

    ego_speed: str
    ego_dist: str
    """Scenic expression: the ego's distance to its entry at the start."""
    ego_time: str
    """Scenic expression: the ego's time to its entry."""
    lead_first: bool
    """The crossing or oncoming vehicles get there before the ego (none of them collides)."""
    yields: bool
    """The ego stops at the entry until the vehicle it yields to has cleared the junction."""
    misjudges: bool
    """The ego stops, misjudges the gap and goes just before the vehicle it collides with gets there."""
    conflict: Optional[ActorFrame]
    """The vehicle the ego waits for (or goes into)."""
    first: str = ""
    """Scenic expression: when the first crossing vehicle gets there (when they go first)."""


def junction_timing(s: Script, roles: List[RoleSpec], ego_speed: str, default_ego: Optional[str],
                    ego_type: Optional[str], reckless: bool) -> JunctionTiming:
    """The timing of the junction scenario (writing its parameters and, when the others go first, the ego's
    time and distance into section 3)."""
    frame, ego = s.frame, s.frame.ego
    extra_ahead = 12 * max([a.count - 1 for a, r, _ in roles if r == JunctionRole.AHEAD], default=0)
    timed = [(a, r) for a, r, _ in roles if r not in (JunctionRole.AHEAD, JunctionRole.BEHIND, JunctionRole.INTO_PATH)]
    lead_first = bool(timed) and not any(a.has("collide") for a, _ in timed)
    nobody_ahead = not extra_ahead and not any(r == JunctionRole.AHEAD for _, r, _ in roles)
    # the ego stops at the junction (for a crossing vehicle, at a stop sign) and then goes on: it waits at the
    # entry until the vehicle it yields to has cleared the junction
    # (not on the roundabout: its circulating traffic is timed against the ego's own approach)
    yields = ego.has("stop") and not reckless and nobody_ahead \
        and (bool(timed) or default_ego is not None and ego_type is not None) and frame.map != RING_MAP
    # ... or it stops, misjudges the gap and goes just before the vehicle it collides with gets there
    hitters = [a for a, _ in timed if a.has("collide")]
    misjudges = ego.has("stop") and ego.has("collide") and bool(hitters) and nobody_ahead and frame.map != RING_MAP
    conflict = conflict_actor(ego, [a for a, _ in timed]) if yields else \
        conflict_actor(ego, hitters) if misjudges else None
    t = JunctionTiming(ego_speed=ego_speed, ego_dist="", ego_time="", lead_first=lead_first, yields=yields,
                       misjudges=misjudges, conflict=conflict)
    if misjudges:
        t.ego_dist = s.param("ego_distance", "Range(10, 14)")
        t.ego_time = f"{t.ego_dist} / {ego_speed}"
    elif yields and lead_first:
        # close to the junction: it stops there while the other vehicle (which gets there first) crosses
        t.first = s.param("first_arrival", "Range(0.3, 0.8)")
        t.ego_dist = s.param("ego_distance", "Range(12, 16)")
        t.ego_time = f"{t.ego_dist} / {ego_speed}"
    elif lead_first:
        # the crossing/oncoming vehicles reach the junction first (the last one `ego_gap_time` s
        # before the ego): the ego's distance follows from those times
        spread = 1.6 * max(a.count - 1 for a, _ in timed)
        t.first = s.param("first_arrival", "Range(0.8, 1.6)")
        gap_time = s.param("ego_gap_time", "Range(2.0, 2.8)")
        s.geometry.append(f"egoTime = {t.first} + {spread:.1f} + {gap_time}")
        s.geometry.append(f"egoDistance = {ego_speed} * egoTime" + (f" + {extra_ahead}" if extra_ahead else ""))
        t.ego_dist, t.ego_time = "egoDistance", "egoTime"
    else:
        t.ego_dist = s.param("ego_distance", f"Range({22 + extra_ahead}, {34 + extra_ahead})")
        t.ego_time = f"{t.ego_dist} / {ego_speed}"
    return t
