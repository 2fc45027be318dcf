"""Where a vehicle comes from at a junction relative to the ego (its junction role) and the maneuvers of a
shipped junction map that realise it."""

from __future__ import annotations

import random
from typing import Any, Callable, Dict, Optional, Tuple

from dv2s_gym.pipeline.sg.rules.frame import ActorFrame
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole
from scenario_bank.elements import Action, Relation
from scenario_bank.map_cache import load_network
from scenario_bank.maps import resolve_map

__all__ = ["JUNCTION_ACTIONS", "MANEUVER_TYPES", "Maneuvers", "role_condition", "junction_role"]

JUNCTION_ACTIONS = {"brake", "stop", "accelerate", "turn_left", "turn_right", "go_straight", "cross", "collide",
                    "keep_lane", "cut_in", "merge"}
MANEUVER_TYPES = {Action.TURN_LEFT: "LEFT_TURN", Action.TURN_RIGHT: "RIGHT_TURN", Action.GO_STRAIGHT: "STRAIGHT"}


class Maneuvers:
    """The shipped junction map's maneuvers, to check which combinations exist before writing them."""

    _cache: Dict[str, Any] = {}

    def __init__(self, map_name: str) -> None:
        if map_name not in self._cache:
            self._cache[map_name] = load_network(resolve_map(map_name))
        self.network = self._cache[map_name]
        self.maneuvers = [m for j in self.network.intersections for m in j.maneuvers]

    @staticmethod
    def direction(lane):
        d = lane.centerline[-1] - lane.centerline[-2]
        return d.x, d.y, (d.x ** 2 + d.y ** 2) ** 0.5

    def side(self, a, b) -> float:
        ax, ay, an = self.direction(a)
        bx, by, bn = self.direction(b)
        return (ax * by - ay * bx) / max(1e-6, an * bn)

    def opposite(self, a, b) -> bool:
        ax, ay, an = self.direction(a)
        bx, by, bn = self.direction(b)
        return ax * bx + ay * by < -0.7 * an * bn


_SIDE = "approachDir(e.startLane).norm() * approachDir(m.startLane).norm()"
_APPROACHES: Dict[str, Tuple[Callable, str]] = {
    JunctionRole.ONCOMING: (lambda e, m, net: net.opposite(e.startLane, m.startLane),
                            "opposite(e.startLane, m.startLane)"),
    JunctionRole.FROM_LEFT: (lambda e, m, net: net.side(e.startLane, m.startLane) < -0.7,
                             f"sideOf(e.startLane, m.startLane) < -0.7 * {_SIDE}"),
    JunctionRole.FROM_RIGHT: (lambda e, m, net: net.side(e.startLane, m.startLane) > 0.7,
                              f"sideOf(e.startLane, m.startLane) > 0.7 * {_SIDE}"),
    JunctionRole.CROSSING: (lambda e, m, net: m in e.conflictingManeuvers and abs(net.side(e.startLane, m.startLane))
                            > 0.7,
                            f"m in e.conflictingManeuvers and abs(sideOf(e.startLane, m.startLane)) > 0.7 * {_SIDE}"),
    JunctionRole.INTO_PATH: (lambda e, m, net: m.endLane is e.endLane and m.startLane is not e.startLane,
                             "m.endLane is e.endLane and m.startLane is not e.startLane"),
    # on a roundabout: circulating from the left toward the ego's exit, ahead of it
    JunctionRole.RING_CUT: (lambda e, m, net: net.side(e.startLane, m.startLane) < -0.7 and m.endLane is e.endLane,
                            f"sideOf(e.startLane, m.startLane) < -0.7 * {_SIDE} and m.endLane is e.endLane"),
    JunctionRole.AHEAD: (lambda e, m, net: m.startLane is e.startLane, "m.startLane is e.startLane"),
    JunctionRole.BEHIND: (lambda e, m, net: m.startLane is e.startLane, "m.startLane is e.startLane"),
    JunctionRole.ANY: (lambda e, m, net: m.startLane is not e.startLane, "m.startLane is not e.startLane"),
}
"""Junction role -> (predicate on the ego's maneuver ``e``, another ``m`` and the :class:`Maneuvers`, the same
condition as Scenic text with ``e``/``m`` names)."""


def role_condition(role: str, mtype: Optional[str]) -> Tuple[Callable, str]:
    """The condition (predicate, Scenic text) on a maneuver ``m`` for a vehicle of ``role`` whose maneuver is of
    type ``mtype`` (any type when None), given the ego's maneuver ``e``."""
    type_py = (lambda m: True) if mtype is None else (lambda m, t=mtype: m.type.name == t)
    type_sc = "" if mtype is None else f"m.type is ManeuverType.{mtype}"
    py, sc = _APPROACHES.get(role, _APPROACHES[JunctionRole.ANY])
    full_py = lambda e, m, net, p=py, t=type_py: p(e, m, net) and t(m)  # noqa: E731
    full_sc = sc + (f" and {type_sc}" if type_sc else "")
    return full_py, full_sc


def junction_role(actor: ActorFrame, ego: ActorFrame, rng: random.Random) -> Tuple[JunctionRole, Optional[str]]:
    """The actor's junction role and the maneuver type its actions (or crossing the ego's path) give it."""
    rels = set(actor.relations)
    mtype = next((MANEUVER_TYPES[a] for a in ("turn_left", "turn_right", "go_straight") if actor.has(a)), None)
    if (actor.has("cross") or Relation.CROSSING_PATH in rels and not ego.has("turn_left")) and mtype is None:
        mtype = "STRAIGHT"  # across the ego's path
    if actor.has("cut_in") or actor.has("merge"):
        return JunctionRole.INTO_PATH, mtype
    if Relation.ONCOMING in rels:
        return JunctionRole.ONCOMING, mtype or "STRAIGHT"
    if Relation.SAME_LANE not in rels and (Relation.LEFT_OF in rels or Relation.RIGHT_OF in rels):
        side = JunctionRole.FROM_LEFT if Relation.LEFT_OF in rels else JunctionRole.FROM_RIGHT
        if (side, mtype) in ((JunctionRole.FROM_RIGHT, "RIGHT_TURN"), (JunctionRole.FROM_LEFT, "LEFT_TURN")) \
                and not ego.has("turn_left") and not ego.has("turn_right"):
            return JunctionRole.INTO_PATH, mtype  # it turns into the lane the ego drives on in
        return side, mtype
    if Relation.AHEAD_OF in rels or Relation.SAME_LANE in rels:
        return JunctionRole.AHEAD, mtype
    if Relation.BEHIND in rels:
        return JunctionRole.BEHIND, mtype
    if Relation.CROSSING_PATH in rels or actor.has("cross"):
        return JunctionRole.CROSSING, mtype or "STRAIGHT"
    if mtype == "LEFT_TURN" and not ego.has("turn_left"):
        return JunctionRole.ONCOMING, mtype
    if mtype == "RIGHT_TURN" and not ego.has("turn_right"):
        return JunctionRole.INTO_PATH, mtype
    if mtype == "STRAIGHT" and ego.has("turn_left"):
        return JunctionRole.ONCOMING, mtype
    if mtype == "STRAIGHT":
        return JunctionRole.CROSSING, mtype
    if actor.has("brake") or actor.has("stop") or actor.has("keep_lane") or actor.has("accelerate") \
            or not actor.actions:
        return JunctionRole.AHEAD, mtype
    return JunctionRole.ANY, mtype
