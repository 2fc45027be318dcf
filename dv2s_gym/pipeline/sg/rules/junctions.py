"""The composer for junctions (crossroads, T-junction, roundabout): roles, the maneuvers that realise them,
timing, the ego, the other actors."""

from __future__ import annotations

import re
from typing import List, Optional

from dv2s_gym.pipeline.sg.rules.frame import VEHICLES
from dv2s_gym.pipeline.sg.rules.junction_ego import junction_ego_lines
from dv2s_gym.pipeline.sg.rules.junction_fit import RoleSpec, fit_roles
from dv2s_gym.pipeline.sg.rules.junction_roles import JUNCTION_ACTIONS, MANEUVER_TYPES, Maneuvers, junction_role, \
    role_condition
from dv2s_gym.pipeline.sg.rules.junction_spawn import spawn_junction_obstacle, spawn_junction_vehicle
from dv2s_gym.pipeline.sg.rules.junction_timing import junction_timing
from dv2s_gym.pipeline.sg.rules.pedestrians import spawn_junction_pedestrians
from dv2s_gym.pipeline.sg.rules.roads import RING_MAP, speed_ranges
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole
from dv2s_gym.pipeline.sg.rules.script import Script, check_actions
from scenario_bank.elements import CAN_DO, ActorKind, Relation

__all__ = ["compose_junction"]

_TITLES = {"urban_crossroads": "a four-way junction of two-way urban streets",
           "urban_t_junction": "a T-junction of two-way urban streets",
           "urban_roundabout": "a single-lane roundabout with four two-way arms (first exit right, second "
                               "straight on, third left)"}


def compose_junction(s: Script) -> None:
    """Compose the script of a scenario at a junction."""
    frame = s.frame
    ego = frame.ego
    net = Maneuvers(frame.map)
    check_actions(ego, s, JUNCTION_ACTIONS - {"cross", "cut_in", "merge"})
    reckless = ego.has("collide") or any(a.has("collide") for a in frame.actors)
    lo, hi = speed_ranges(frame.map)
    ego_speed = s.param("ego_speed", f"Range({lo}, {hi})")
    ego_type = next((MANEUVER_TYPES[a] for a in ("turn_left", "turn_right", "go_straight") if ego.has(a)), None)
    roles = _roles(s)
    roles, default_ego = fit_roles(s, net, ego_type, roles)
    _maneuver_combos(s, roles, default_ego)
    timing = junction_timing(s, roles, ego_speed, default_ego, ego_type, reckless)
    for i, (actor, _, _) in enumerate(roles):
        s.geometry += [f"{actor.name}Maneuver = combo[{i + 1}]",
                       f"{actor.name}Route = [{actor.name}Maneuver.startLane, {actor.name}Maneuver.connectingLane, "
                       f"{actor.name}Maneuver.endLane]"]
    ego_lines = junction_ego_lines(s, timing, default_ego, reckless)
    waits = timing.yields or timing.misjudges
    if not waits:
        s.spawn += ego_lines
    s.show("ego", list(ego.actions))
    for spec in roles:
        spawn_junction_vehicle(s, spec, timing, frame.map == RING_MAP, f"Range({lo}, {hi})", reckless)
    if waits:
        s.spawn += ego_lines  # after the vehicle it waits for, which its behaviour names
    for actor in frame.actors:
        if actor.kind == ActorKind.PEDESTRIAN:
            spawn_junction_pedestrians(s, actor, frame.map, reckless)
        elif actor.kind == ActorKind.OBSTACLE:
            spawn_junction_obstacle(s, actor)


def _roles(s: Script) -> List[RoleSpec]:
    """Each vehicle's junction role and maneuver type (actions it cannot do at a junction dropped)."""
    frame = s.frame
    vehicles = [a for a in frame.actors if a.kind in VEHICLES]
    for a in frame.actors:
        if a.kind in VEHICLES:
            check_actions(a, s, JUNCTION_ACTIONS)
        elif a.kind == ActorKind.PEDESTRIAN:
            check_actions(a, s, set(CAN_DO[ActorKind.PEDESTRIAN]))
        else:
            a.actions = []
    roles: List[RoleSpec] = [(a,) + junction_role(a, frame.ego, s.rng) for a in vehicles]
    if frame.map == RING_MAP:
        # a vehicle coming from the left on a roundabout circulates past the ego's entry (not out at its arm)
        roles = [(a, r, "STRAIGHT" if r == JunctionRole.FROM_LEFT and t is None else t) for a, r, t in roles]
        # one already on the ring on the ego's left that cuts in: it passes the ego's entry just ahead of it
        roles = [(a, JunctionRole.RING_CUT, None) if r == JunctionRole.INTO_PATH and Relation.LEFT_OF in a.relations
                 else (a, r, t) for a, r, t in roles]
    return roles


def _maneuver_combos(s: Script, roles: List[RoleSpec], default_ego: Optional[str]) -> None:
    """Section 3: the combinations of the ego's maneuver with one for each vehicle that fit their roles."""
    s.helpers.append("approach")
    ego_cond = f"e.type is ManeuverType.{default_ego}" if default_ego else "True"
    comp = [f"combos = [(e,{''.join(' m' + str(i) + ',' for i in range(len(roles)))})",
            "          for junction in network.intersections for e in junction.maneuvers",
            f"          if {ego_cond}"]
    for i, (actor, role, mtype) in enumerate(roles):
        cond = role_condition(role, mtype)[1].replace("m.", f"m{i}.").replace("(m.", f"(m{i}.")
        cond = re.sub(r"\bm\b", f"m{i}", cond)
        comp.append(f"          for m{i} in junction.maneuvers if {cond}")
    comp[-1] += "]"
    title = _TITLES[s.frame.map]
    s.geometry_title = title + (f"; the ego {default_ego.lower().replace('_', ' ')}" if default_ego else "")
    s.geometry += comp + ["combo = Uniform(*combos)", "egoManeuver = combo[0]",
                          "egoRoute = [egoManeuver.startLane, egoManeuver.connectingLane, egoManeuver.endLane]",
                          "egoEntry = egoManeuver.startLane.centerline.end"]
