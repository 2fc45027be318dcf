"""Fitting the described junction roles to a shipped junction map: what exists there, and what to relax (with a
warning) when the combination does not."""

from __future__ import annotations

from typing import List, Optional, Tuple

from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.junction_roles import MANEUVER_TYPES, Maneuvers, role_condition
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Relation

__all__ = ["RoleSpec", "feasible", "fit_roles"]

RoleSpec = Tuple[ActorFrame, str, Optional[str]]
"""An actor, its junction role and its maneuver type (None: any)."""


def feasible(net: Maneuvers, ego_t: Optional[str], specs: List[RoleSpec]) -> bool:
    """Whether the map has an ego maneuver of type ``ego_t`` (any when None) with a maneuver for every spec."""
    conds = [role_condition(r, t)[0] for _, r, t in specs]
    for e in net.maneuvers:
        if ego_t is not None and e.type.name != ego_t:
            continue
        if all(any(c(e, m, net) for m in net.maneuvers) for c in conds):
            return True
    return False


def fit_roles(s: Script, net: Maneuvers, ego_type: Optional[str],
              roles: List[RoleSpec]) -> Tuple[List[RoleSpec], Optional[str]]:
    """The roles (relaxed where the map has no such maneuvers) and the ego's maneuver type they fit with."""
    frame, ego = s.frame, s.frame.ego
    default_ego = ego_type
    if ego_type is None:
        default_ego = "STRAIGHT" if feasible(net, "STRAIGHT", roles) else None
    if feasible(net, default_ego, roles):
        return roles, default_ego
    roles = [_relax(s, net, default_ego, spec) for spec in roles]
    if not feasible(net, default_ego, roles):
        s.warnings.append("the described manoeuvres do not fit together on this junction: the other vehicles "
                          "come from any approach")
        roles = [(a, JunctionRole.ANY, None) for a, _, _ in roles]
    if not feasible(net, default_ego, roles):
        if ego_type:
            s.warnings.append(f"the ego's {ego_type.lower().replace('_', ' ')} cannot be placed on {frame.map}")
            ego.actions = [x for x in ego.actions if MANEUVER_TYPES.get(x) != ego_type]
        default_ego = None
    return roles, default_ego


def _relax(s: Script, net: Maneuvers, default_ego: Optional[str], spec: RoleSpec) -> RoleSpec:
    """One actor's role, relaxed when it alone does not fit: its maneuver type dropped, else its approach."""
    actor, role, mtype = spec
    frame = s.frame
    if feasible(net, default_ego, [(actor, role, mtype)]):
        return actor, role, mtype
    if mtype is not None and feasible(net, default_ego, [(actor, role, None)]):
        s.warnings.append(f"no '{mtype.lower().replace('_', ' ')}' for a {actor.kind} coming "
                          f"{role.replace('_', ' ')} exists on {frame.map}: its manoeuvre is not placed")
        actor.actions = [x for x in actor.actions if MANEUVER_TYPES.get(x) != mtype]
        return actor, role, None
    if feasible(net, default_ego, [(actor, JunctionRole.ANY, mtype)]):
        s.warnings.append(f"a {actor.kind} coming {role.replace('_', ' ')} cannot be placed on "
                          f"{frame.map} with that manoeuvre: it comes from another approach")
        actor.relations = [r for r in actor.relations
                           if r not in (Relation.ONCOMING, Relation.LEFT_OF, Relation.RIGHT_OF)]
        return actor, JunctionRole.ANY, mtype
    s.warnings.append(f"a {actor.kind} with '{', '.join(actor.actions)}' cannot be placed on "
                      f"{frame.map}: it comes from another approach and drives straight or turns")
    return actor, JunctionRole.ANY, None
